"""What a solve returns: the :class:`Trajectory` pytree and its :class:`Result` codes.

:func:`jrigid.simulate`, the leapfrog, the splitting integrators, the contact solver and
the lockstep ensembles all return a :class:`Trajectory`; its ``result`` is a
:class:`Result` code (one per member under ``vmap``), and a failed solve raises
:class:`SimulationError` when asked to (``throw=True``), with the cause and a remedy
from :data:`CAUSES`.
"""

from __future__ import annotations

import dataclasses
import enum
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from jrigid import quaternion as quat
from jrigid._checks import all_arrays
from jrigid.formulations import AbstractFormulation
from jrigid.scene import Scene

__all__ = ["CAUSES", "Result", "SimulationError", "Trajectory", "replace"]


class Result(enum.IntEnum):
    """Outcome codes in ``Trajectory.result`` (an int32 array, one per ``vmap`` member).

    - ``success`` (0): reached the final time;
    - ``max_steps`` (1): the step budget ran out;
    - ``step_size_collapse`` (2): the step size fell below ``4 eps |t|`` with a finite
      vector field (a singular or very stiff solution);
    - ``nonfinite`` (3): NaN/inf in the vector field or state (e.g. a NaN torque);
    - ``gimbal_lock`` (4): the Euler-angle formulation reached ``sin θ ≈ 0``;
    - ``solver_failure`` (5): any other diffrax failure (e.g. an implicit solver's
      root find);
    - ``invalid_input`` (6): the inputs failed a check (a zero quaternion, a
      non-physical inertia, NaN values, bad tolerances): nothing was integrated and
      every output is NaN. With ``throw=True`` this is a ``ValueError`` instead;
    - ``event`` (7): a user's ``event`` stopped the solve (not a failure: the outputs
      after ``t_stop`` are NaN).
    """

    success = 0
    max_steps = 1
    step_size_collapse = 2
    nonfinite = 3
    gimbal_lock = 4
    solver_failure = 5
    invalid_input = 6
    event = 7

    @property
    def failed(self) -> bool:
        """Whether the code is a failure (everything but ``success`` and ``event``)."""
        return self not in (Result.success, Result.event)


#: ``Result -> (cause, remedy)`` texts of the failure codes (``{max_steps}`` is filled in).
CAUSES: dict[Result, tuple[str, str]] = {
    Result.max_steps: (
        "max_steps={max_steps} exhausted before reaching the final time",
        "raise max_steps, loosen rtol/atol, or shorten the time span",
    ),
    Result.step_size_collapse: (
        "the step size collapsed (below 4 machine epsilons of t): the solution is "
        "singular or too stiff there",
        "check the torque and parameters for a singularity, or try an implicit solver "
        "such as diffrax.Kvaerno5()",
    ),
    Result.nonfinite: (
        "the vector field or state became non-finite (NaN or inf)",
        "check the scene parameters and torque function for NaN/inf (e.g. division by "
        "zero, a NaN parameter)",
    ),
    Result.gimbal_lock: (
        "Euler-angle gimbal lock: |sin θ| fell below min_sin_theta, where the "
        "Euler-angle rates (eq. 17.36) are singular",
        "use formulation='quaternion_acceleration' (or 'quaternion_omega')",
    ),
    Result.solver_failure: (
        "the solver reported a failure (e.g. an implicit solver's root find did not "
        "converge)",
        "loosen rtol/atol or change the solver",
    ),
    Result.invalid_input: (
        "the inputs failed a check (see the ValueError raised with throw=True)",
        "fix the input named there",
    ),
}


class SimulationError(RuntimeError):
    """A failed integration (cause, time reached, step counts and a remedy in the text)."""


def _quantity(name: str, scene: Scene, formulation: AbstractFormulation, y):
    """The physical quantity ``name`` (a :class:`Trajectory` property) at one state."""
    if name == "norm_error":
        raw = formulation.raw_quaternion(y)
        return None if raw is None else jnp.sqrt(jnp.dot(raw, raw)) - 1.0
    if name == "tangent_error":
        return formulation.tangent_error(y)
    kin = formulation.kinematics(scene, y)
    if name in ("x", "v"):
        return getattr(kin, name)
    if name == "kinetic_energy":
        return scene.kinetic_energy(kin.omega, kin.v)
    if name == "potential_energy":
        if kin.q is None:
            return jnp.zeros((), kin.omega.dtype)
        return scene.potential_energy(kin)
    L = scene.angular_momentum(kin.omega)
    if name == "L":
        return L
    if kin.q is None:
        return None
    if name == "omega_space":
        return quat.rotate(kin.q, kin.omega)
    if name == "L_space":
        return quat.rotate(kin.q, L)
    if name == "axes":
        return quat.to_matrix(kin.q)
    raise AttributeError(name)  # pragma: no cover - every _Derived name is handled above


def _quantities(name, formulation, scene, y, batch_ndim):
    """``name`` at every state of ``y`` (leading axes: ``batch_ndim`` member axes, which
    the scene's arrays have too, then the time axis)."""
    def over_time(scene, y):
        return jax.vmap(lambda y: _quantity(name, scene, formulation, y))(y)

    fn = over_time
    for _ in range(batch_ndim):
        fn = eqx.filter_vmap(fn)
    return fn(scene, y)


#: ``_quantities`` compiled: with ``jax.jit`` (dispatch 5–10 µs, against about 40 µs for
#: ``equinox.filter_jit``, which a scene holding other leaves than arrays needs).
_COMPILED = (jax.jit(_quantities, static_argnums=(0, 1, 4)), eqx.filter_jit(_quantities))


def _evaluate(name, traj):
    args = (name, traj.formulation, traj.scene, traj.y, jnp.ndim(traj.result))
    try:
        return _COMPILED[0](*args)
    except TypeError:  # jax.jit refuses a leaf that is not an array (a string parameter)
        if all_arrays(traj.scene):
            raise
        return _COMPILED[1](*args)


class _Derived:
    """A :class:`Trajectory` quantity computed from its states on first access and kept
    (on the instance; a transformed or rebuilt trajectory computes it again)."""

    def __init__(self, doc: str):
        self.__doc__ = doc

    def __set_name__(self, owner, name):
        self.name = name

    def __get__(self, traj, owner=None):
        if traj is None:
            return self
        kept = traj.__dict__
        if self.name not in kept:
            kept[self.name] = _evaluate(self.name, traj)
        return kept[self.name]


class Trajectory(eqx.Module):
    """A solved motion sampled at times ``ts`` (arrays have leading axis ``T``).

    The solve returns the formulation's states ``y``, ``q``, ``omega`` and the outcome;
    the other physical quantities (``L``, the energies, the axes, ...) are computed from
    the states on first access and then kept, so that a compiled call returns few arrays
    (each costs it a copy). (Under ``vmap`` every array, the scene's included, has the
    member axes first.)

    Attributes:
        ts: ``(T,)`` times.
        y: the formulation's own state at ``ts`` (pytree, leading axis ``T``).
        q: ``(T, 4)`` unit orientation (principal body frame → space), or ``None``
            (``body_omega``).
        omega: ``(T, 3)`` body angular velocity.
        omega_space: ``(T, 3)`` space angular velocity (or ``None``).
        L: ``(T, 3)`` body-frame angular momentum about the rotation centre (pivot or
            centre of mass).
        L_space: ``(T, 3)`` space-frame angular momentum (or ``None``).
        kinetic_energy: ``(T,)`` rotational (+ translational) kinetic energy.
        potential_energy: ``(T,)`` potential energy of the conservative loads.
        norm_error: ``(T,)`` ``|q| − 1`` of the integrated quaternion (``None`` when ``q``
            is not a variable).
        tangent_error: ``(T,)`` ``q·q̇`` (``quaternion_acceleration`` only, else ``None``).
        axes: ``(T, 3, 3)`` rotation matrices; column ``i`` is body axis ``i + 1`` in
            the space frame (or ``None``).
        x, v: ``(T, 3)`` centre-of-mass position and velocity (free flight), else ``None``.
        stats: dict with ``num_steps``, ``num_accepted_steps``, ``num_rejected_steps``.
        result: ``()`` int, a :class:`Result` code (0 = success). Values at times
            after a failure are ``NaN``.
        t_stop: ``()`` the time the integration reached (``ts[-1]`` on success).
        scene: the simulated :class:`~jrigid.scene.Scene`.
        formulation: static, the formulation used.
        interpolation: dense diffrax interpolation (``simulate(..., dense=True)``) or
            ``None``; see :meth:`at`.
    """

    ts: jax.Array
    y: Any
    q: jax.Array | None
    omega: jax.Array
    stats: dict
    result: jax.Array
    t_stop: jax.Array
    scene: Scene
    formulation: AbstractFormulation = eqx.field(static=True)
    interpolation: Any = None

    omega_space = _Derived("``(T, 3)`` space angular velocity (or ``None``).")
    L = _Derived("``(T, 3)`` body-frame angular momentum about the rotation centre.")
    L_space = _Derived("``(T, 3)`` space-frame angular momentum (or ``None``).")
    kinetic_energy = _Derived("``(T,)`` rotational (+ translational) kinetic energy.")
    potential_energy = _Derived("``(T,)`` potential energy of the conservative loads.")
    norm_error = _Derived("``(T,)`` ``|q| − 1`` of the integrated quaternion, or ``None``.")
    tangent_error = _Derived("``(T,)`` ``q·q̇`` (``quaternion_acceleration``), or ``None``.")
    axes = _Derived("``(T, 3, 3)`` rotation matrices (columns: body axes in space), or "
                    "``None``.")
    x = _Derived("``(T, 3)`` centre-of-mass position (free flight), else ``None``.")
    v = _Derived("``(T, 3)`` centre-of-mass velocity (free flight), else ``None``.")

    @classmethod
    def build(
        cls, scene, formulation, ts, ys, *, stats, result, t_stop, interpolation=None
    ) -> Trajectory:
        """Assemble a trajectory from formulation states ``ys`` (leading axis ``T``)."""
        kin = jax.vmap(lambda y: formulation.kinematics(scene, y))(ys)
        return cls(ts=ts, y=ys, q=kin.q, omega=kin.omega, stats=stats, result=result,
                   t_stop=t_stop, scene=scene, formulation=formulation,
                   interpolation=interpolation)

    @property
    def energy(self) -> jax.Array:
        """``(T,)`` total energy, kinetic plus potential."""
        return self.kinetic_energy + self.potential_energy

    @property
    def succeeded(self) -> jax.Array:
        """``()`` bool, whether the integration reached ``ts[-1]``."""
        return self.result == 0

    def euler(self, seq: str = "ZXZ") -> jax.Array:
        """``(T, 3)`` Euler angles of the orientation in sequence ``seq`` (scipy meaning)."""
        if self.q is None:
            raise ValueError(f"the {self.formulation.name} formulation carries no orientation")
        return quat.to_euler(seq, self.q)

    def at(self, t) -> Trajectory:
        """The trajectory at new times ``t (K,)`` from the dense interpolation (a scalar
        ``t`` gives ``K = 1``: every field keeps its time axis).

        Needs ``simulate(..., dense=True)``. The solver statistics are carried over.
        Outside the solved interval (or after a failed solve stopped) a numerical
        solve's interpolation gives NaN; the closed forms (``solver="exact"``) give the
        exact motion at any time.
        For a batch of trajectories (``jax.vmap(simulate)``) call it under ``jax.vmap``
        too.

        Raises:
            ValueError: no dense output, ``t`` not a scalar or ``(K,)``, or a batched
                trajectory.
        """
        if self.interpolation is None:
            raise ValueError("no dense output: call simulate(..., dense=True)")
        t = jnp.atleast_1d(jnp.asarray(t, dtype=self.ts.dtype))
        if t.ndim != 1:
            raise ValueError(f"t must be a scalar or a (K,) array of times, got shape {t.shape}")
        if self.ts.ndim != 1:
            raise ValueError(f"this Trajectory is a batch (ts of shape {self.ts.shape}): "
                             "evaluate each member, e.g. jax.vmap(lambda tr: tr.at(t))(traj)")
        return _at(self, t)


@eqx.filter_jit
def _at(traj: Trajectory, t: jax.Array) -> Trajectory:
    ys = jax.vmap(traj.interpolation.evaluate)(t)
    return Trajectory.build(
        traj.scene,
        traj.formulation,
        t,
        ys,
        stats=traj.stats,
        result=traj.result,
        t_stop=traj.t_stop,
        interpolation=traj.interpolation,
    )


_FIELDS = tuple(f.name for f in dataclasses.fields(Trajectory))


def replace(traj: Trajectory, **changes) -> Trajectory:
    """A copy of ``traj`` with the fields ``changes`` changed (no quantities kept).

    Made as unflattening a pytree makes one: ``dataclasses.replace`` runs the module's
    ``__init__``, and a method of a module is bound on each access, 30 µs each, more than
    the rest of what a plain ``simulate`` call spends in Python.
    """
    if not isinstance(traj, Trajectory):
        raise ValueError(f"replace needs a Trajectory, got {type(traj).__name__}")
    unknown = sorted(set(changes) - set(_FIELDS))
    if unknown:
        raise ValueError(f"Trajectory has no field(s) {unknown}; its fields are {list(_FIELDS)} "
                         "(the other quantities are computed from them)")
    new = object.__new__(Trajectory)
    fields = traj.__dict__
    for name in _FIELDS:
        object.__setattr__(new, name, changes[name] if name in changes else fields[name])
    return new
