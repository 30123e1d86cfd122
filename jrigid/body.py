"""Rigid bodies: principal moments, mass and where the centre of mass sits.

A :class:`RigidBody` is described in its *principal* body frame: the inertia tensor about
the centre of mass is ``diag(moments)`` there (chapter Table 17.1 and eq. 17.31). A body
given by a full tensor is diagonalised once (:meth:`RigidBody.from_tensor`); the rotation
from the principal frame back to the frame the tensor was given in is kept in
:attr:`RigidBody.frame`, so results can be mapped back.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import inertia
from jrigid import quaternion as quat
from jrigid._checks import as_float, check_shape, is_traced
from jrigid._folds import every, some

__all__ = ["RigidBody"]


def _exactly(x: jax.Array, shape: tuple[int, ...], name: str, hint: str = "") -> None:
    """A body holds one body: ``x`` must have exactly ``shape`` (no batch axes)."""
    check_shape(x, name, shape)  # the trailing shape first, naming what is expected
    if x.shape != shape:
        raise ValueError(
            f"RigidBody: {name} must have shape {shape}, got {x.shape}: a RigidBody is one "
            "body; for many, build them inside jax.vmap (or use jrigid.ensemble)" + hint
        )


def _frame_error(frame: jax.Array) -> jax.Array:
    """Whether ``frame`` is not a finite unit quaternion (within the default tolerance)."""
    tol = quat.default_atol(frame.dtype)
    return ~(every(jnp.isfinite(frame), axis=-1) & (jnp.abs(quat.norm(frame) - 1) <= tol))


@functools.partial(jax.jit, static_argnums=4)
def _value_flags(moments, mass, com, frame, allow_nonphysical: bool) -> jax.Array:
    """``(n,)`` bool: the value checks of :meth:`RigidBody.problems`, as one compiled
    program. A body built from concrete values is checked through it: run one operation
    at a time, the checks compiled about 45 small programs on a process's first body
    (1 s); this is one."""
    body = RigidBody(moments, mass, com, frame, allow_nonphysical=allow_nonphysical)
    return jnp.stack([bad for bad, _ in body.problems()])


_FRAME_MESSAGE = (
    "RigidBody: frame must be a unit quaternion (w, x, y, z) (non-zero, finite, norm 1 "
    "within {tol:g}); normalise it with jrigid.quaternion.normalize"
)


class RigidBody(eqx.Module):
    """A rigid body in its principal frame.

    Attributes:
        moments: ``(3,)`` principal moments of inertia ``(I1, I2, I3)`` **about the centre
            of mass**, along the body axes 1, 2, 3. A scene held at a pivot adds the
            parallel-axis shift itself (see :class:`jrigid.scene.Pivot`).
        mass: ``()`` total mass ``M > 0``.
        com: ``(3,)`` centre of mass relative to the support point, in body (principal)
            coordinates. Only a pivoted scene uses it; for free rotation and free flight
            the body turns about its centre of mass.
        frame: ``(4,)`` unit quaternion taking principal-frame vectors to the frame the
            body was specified in (``identity`` when built from moments): a vector
            ``v`` in principal coordinates is ``quaternion.rotate(frame, v)`` in the
            original coordinates. See :meth:`reference_orientation`. It is not
            normalised here: a zero, non-finite or non-unit frame (beyond
            :func:`jrigid.quaternion.default_atol`) is refused, since it most likely is
            a mistake (an axis vector, a scalar-last quaternion).
        allow_nonphysical: static; skip the triangle inequality ``Ia + Ib ≥ Ic`` (e.g.
            for the Hairer–Lubich–Wanner test body ``(2, 1, 2/3)``).

    Shapes are checked always (also under ``jit``): exactly ``(3,)``, ``()``, ``(3,)``
    and ``(4,)``, so a batch of moments, a vector mass or a full tensor passed as
    ``moments`` (use :meth:`from_tensor`) raise ``ValueError``. Construction with
    concrete values also validates them and raises ``ValueError`` for a non-finite,
    non-positive or (unless allowed) non-physical inertia (:func:`jrigid.inertia.validate`),
    a non-positive mass, a non-finite centre of mass or a frame that is not a unit
    quaternion. Inside a JAX transformation the value checks are deferred to
    :meth:`check`, which :func:`jrigid.simulate` runs with ``equinox.error_if``.
    """

    moments: jax.Array = eqx.field(converter=as_float)
    mass: jax.Array = eqx.field(converter=as_float, default=1.0)
    com: jax.Array = eqx.field(converter=as_float, default=(0.0, 0.0, 0.0))
    frame: jax.Array = eqx.field(converter=as_float, default=(1.0, 0.0, 0.0, 0.0))
    allow_nonphysical: bool = eqx.field(static=True, default=False, kw_only=True)

    def __check_init__(self):
        tensor_hint = (
            "; a full inertia tensor goes through RigidBody.from_tensor"
            if self.moments.shape[-2:] == (3, 3)
            else ""
        )
        _exactly(self.moments, (3,), "moments", tensor_hint)
        _exactly(self.mass, (), "mass")
        _exactly(self.com, (3,), "com")
        _exactly(self.frame, (4,), "frame")
        if is_traced(self.moments, self.mass, self.com, self.frame):
            return
        flags = _value_flags(self.moments, self.mass, self.com, self.frame,
                             self.allow_nonphysical)
        if not np.asarray(flags).any():
            return
        # a check failed: find which, and say it with the values
        inertia.validate(
            self.moments, kind="moments", allow_nonphysical=self.allow_nonphysical
        )
        if not bool(jnp.isfinite(self.mass) & (self.mass > 0)):
            raise ValueError(f"RigidBody: mass must be finite and positive, got {self.mass}")
        if not bool(jnp.all(jnp.isfinite(self.com))):
            raise ValueError(f"RigidBody: com must be finite, got {self.com}")
        if bool(_frame_error(self.frame)):
            tol = quat.default_atol(self.frame.dtype)
            raise ValueError(
                _FRAME_MESSAGE.format(tol=tol)
                + f" (got {self.frame}, norm {float(quat.norm(self.frame)):g})"
            )

    @classmethod
    def from_tensor(
        cls,
        tensor: ArrayLike,
        mass: ArrayLike = 1.0,
        com: ArrayLike = (0.0, 0.0, 0.0),
        *,
        allow_nonphysical: bool = False,
    ) -> RigidBody:
        """Build a body from a full inertia tensor about its centre of mass.

        The tensor is diagonalised once with :func:`jrigid.inertia.principal_axes`
        (moments ascending). The simulation then runs in the principal frame; ``frame``
        keeps the principal → given-frame rotation.

        Derivatives with respect to ``tensor`` are exact for distinct moments. At two
        equal moments (a symmetric body) the principal frame is not a differentiable
        function of the tensor: a change that splits the pair turns the frame within
        their plane by a finite angle. Its derivative there is taken as zero, so
        derivatives of the motion along such a change (an off-diagonal entry of
        ``diag(1, 1, 1.6)``) come out zero, not the motion's: differentiate at a
        slightly asymmetric tensor, or with respect to ``RigidBody(moments, frame=...)``.

        Args:
            tensor: ``(3, 3)`` symmetric inertia tensor about the centre of mass, in some
                body-fixed reference frame.
            mass: total mass.
            com: ``(3,)`` centre of mass relative to the support point, **in the same
                reference frame as** ``tensor``; it is rotated into the principal frame.
            allow_nonphysical: skip the triangle inequality.

        Returns:
            A :class:`RigidBody`.

        Raises:
            ValueError: for a non-symmetric, non-finite or non-physical tensor; under a
                JAX transformation the same checks raise at run time
                (``equinox.error_if``: :func:`jrigid.inertia.check`).
        """
        tensor, com = as_float(tensor), as_float(com)
        _exactly(tensor, (3, 3), "tensor")
        _exactly(com, (3,), "com")
        # Traced (jit, vmap, grad): checked at run time, since the moments and frame
        # keep no trace of an asymmetric tensor (principal_axes takes its symmetric part).
        tensor = inertia.validate(tensor, kind="tensor", allow_nonphysical=allow_nonphysical)
        moments, frame = inertia.principal_axes(tensor)
        com_principal = quat.rotate_inverse(frame, com)
        return cls(moments, mass, com_principal, frame, allow_nonphysical=allow_nonphysical)

    def tensor(self) -> jax.Array:
        """``(3, 3)`` inertia tensor about the centre of mass in the principal frame."""
        return self.moments[..., :, None] * jnp.eye(3, dtype=self.moments.dtype)

    def reference_orientation(self, q: ArrayLike) -> jax.Array:
        """Orientation of the body's reference frame given the principal-frame one.

        Simulations evolve the orientation ``q`` of the principal frame (body → space).
        The frame the body was specified in then has orientation ``q ⊗ frame*``.

        Args:
            q: ``(..., 4)`` principal-frame orientation.

        Returns:
            ``(..., 4)`` reference-frame orientation.
        """
        return quat.multiply(q, quat.conjugate(self.frame))

    def problems(self) -> list[tuple[jax.Array, str]]:
        """``[(bad, message), ...]``: the body's value checks as traced ``()`` flags.

        The inertia conditions of :func:`jrigid.inertia.validate` (finite, positive,
        triangle inequality unless ``allow_nonphysical``), a finite positive mass, a
        finite centre of mass and a unit ``frame``. Used by the solvers to check inputs
        inside ``jit``/``vmap``.
        """
        conditions = inertia.conditions(
            self.moments, kind="moments", allow_nonphysical=self.allow_nonphysical
        )
        out = [(some(bad), f"inertia is not valid: {name}") for name, bad, _, _ in conditions]
        out.append(
            (
                ~every(jnp.isfinite(self.mass) & (self.mass > 0)),
                "RigidBody: mass must be finite and positive",
            )
        )
        out.append((~every(jnp.isfinite(self.com)), "RigidBody: com must be finite"))
        out.append(
            (
                _frame_error(self.frame),
                _FRAME_MESSAGE.format(tol=quat.default_atol(self.frame.dtype)),
            )
        )
        return out

    def check(self) -> RigidBody:
        """Jit-safe validation (``equinox.error_if``); returns the body unchanged."""
        moments = inertia.check(
            self.moments, kind="moments", allow_nonphysical=self.allow_nonphysical
        )
        mass = eqx.error_if(
            self.mass, ~(jnp.isfinite(self.mass) & (self.mass > 0)),
            "RigidBody: mass must be finite and positive",
        )
        com = eqx.error_if(self.com, ~jnp.isfinite(self.com), "RigidBody: com must be finite")
        frame = eqx.error_if(
            self.frame,
            _frame_error(self.frame),
            _FRAME_MESSAGE.format(tol=quat.default_atol(self.frame.dtype)),
        )
        return eqx.tree_at(
            lambda b: (b.moments, b.mass, b.com, b.frame), self, (moments, mass, com, frame)
        )
