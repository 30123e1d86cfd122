"""solve: the shared solve kit — float32 precision warnings and their threshold."""


import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _simulate import (
    MOMENTS,
    OMEGA0,
    Q0,
    free_scene,
)

from jrigid import initial
from jrigid.integrate import simulate
from jrigid.solve import PrecisionWarning, precision_problem

# --------------------------------------------------------------------------- precision


def test_float32_warns_once_when_the_horizon_defeats_the_tolerance(float32):
    """|ω| t_end eps32 = 1.54 · 1e3 · 1.2e-7 = 1.8e-4 > rtol = 1e-5: one warning, at the
    caller's line, and the solve still runs."""
    state = initial.from_omega(Q0.astype(jnp.float32), OMEGA0.astype(jnp.float32))
    with pytest.warns(PrecisionWarning, match=r"float32 resolves times near t = 1000") as got:
        traj = simulate(free_scene(), state, jnp.linspace(0.0, 1000.0, 21))
    assert len(got) == 1 and got[0].filename == __file__
    assert int(traj.result) == 0


def test_precision_problem_threshold():
    """The floor |ω| max|t| eps against rtol; float64 and traced inputs are never examined."""
    omega = np.array([0.0, 0.0, 2.0])
    eps32 = float(np.finfo(np.float32).eps)
    state = initial.from_omega(omega=jnp.asarray(omega, jnp.float32))
    rtol = jnp.asarray(1e-5, jnp.float32)
    t_edge = 1e-5 / (2.0 * eps32)  # floor = rtol here
    for t_end, warns in ((0.9 * t_edge, False), (1.1 * t_edge, True)):
        ts = jnp.asarray([-1.0, t_end], jnp.float32)
        assert (precision_problem(state, ts, rtol) is not None) == warns
    ts = jnp.asarray([-1.1 * t_edge, 0.0], jnp.float32)  # |t0| counts as well
    assert "coarser than rtol = 1e-05 asks" in precision_problem(state, ts, rtol)
    tiny_rtol = jnp.asarray(1e-7, jnp.float32)  # below 10 eps: refused by the checks instead
    assert precision_problem(state, ts, tiny_rtol) is None
    state64 = initial.from_omega(omega=jnp.asarray(omega))
    assert precision_problem(state64, jnp.asarray([0.0, 1e12]), jnp.asarray(1e-10)) is None
    traced = jax.jit(lambda s: precision_problem(s, ts, rtol) is None)
    assert traced(state)


# --------------------------------------------------------------------------- flat state


def _translating_scene():
    from jrigid import FreeFlight, Gravity, RigidBody, Scene

    return Scene(RigidBody(MOMENTS, mass=2.0), holder=FreeFlight(), loads=(Gravity(9.8),))


@pytest.mark.parametrize("name", ["quaternion_acceleration", "quaternion_omega", "euler_angles"])
def test_flat_layout_round_trips_and_evaluates_the_formulation(name):
    """ravel ∘ unravel is the identity on every leaf (translation included), and the flat
    vector field and projection are the formulation's, raveled."""
    from jrigid.formulations import get_formulation
    from jrigid.solve import Flat

    formulation = get_formulation(name)
    scene = _translating_scene()
    state = initial.from_omega(Q0, OMEGA0, x=jnp.array([1.0, 2.0, 3.0]),
                               v=jnp.array([0.5, -0.5, 2.0]))
    y = formulation.from_state(scene, state)
    flat = Flat.of(formulation, y)
    y_flat = flat.ravel(y)
    n = sum(a.size for a in jax.tree_util.tree_leaves(y))
    assert y_flat.shape == (n,)
    back = flat.unravel(y_flat)
    assert jax.tree_util.tree_structure(back) == jax.tree_util.tree_structure(y)
    for a, b in zip(jax.tree_util.tree_leaves(back), jax.tree_util.tree_leaves(y), strict=True):
        np.testing.assert_array_equal(a, b)
    expected = formulation.vector_field(0.3, y, scene)
    np.testing.assert_allclose(flat.vector_field(0.3, y_flat, scene), flat.ravel(expected),
                               rtol=1e-15, atol=0)
    stretched = y_flat * 1.01
    np.testing.assert_allclose(flat.project(stretched, scene),
                               flat.ravel(formulation.project(flat.unravel(stretched), scene)),
                               rtol=1e-15, atol=0)
    states = flat.states(jnp.stack([y_flat, 2 * y_flat]))
    np.testing.assert_array_equal(jax.tree_util.tree_leaves(states)[0][1],
                                  2 * jax.tree_util.tree_leaves(y)[0])
    assert Flat.of(formulation, y) == flat  # static layout: equal across traces
    for wrong in (y_flat[:-1], jnp.stack([y_flat, y_flat])):
        with pytest.raises(ValueError, match=f"has shape \\({n},\\), got"):
            flat.unravel(wrong)


def test_user_event_sees_the_formulation_state():
    """A user's event condition gets the formulation's own variables (a State with q and
    q̇), not the flat array the loop carries: it stops where q₀ changes sign."""
    import diffrax
    import optimistix as optx

    seen = []

    def cond(t, y, args, **kwargs):
        seen.append(type(y).__name__)
        return y.q[0]

    state = initial.from_omega(jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.array([0.0, 0.0, 1.0]))
    event = diffrax.Event(cond, root_finder=optx.Newton(1e-10, 1e-10))
    traj = simulate(free_scene(), state, jnp.linspace(0.0, 10.0, 11), event=event, throw=False)
    # q = (cos(t/2), 0, 0, sin(t/2)): q₀ = 0 at t = π
    np.testing.assert_allclose(float(traj.t_stop), np.pi, rtol=1e-7)
    assert set(seen) == {"State"}


def test_dense_output_gives_the_formulation_state():
    """Trajectory.at on a flat solve returns the formulation's variables: at the output
    times it agrees with the saved trajectory to the interpolation's accuracy."""
    ts = jnp.linspace(0.0, 5.0, 11)
    state = initial.from_omega(Q0, OMEGA0)
    traj = simulate(free_scene(), state, ts, dense=True)
    again = traj.at(ts[1:-1])
    assert type(again.y).__name__ == "State" and again.y.q.shape == (9, 4)
    np.testing.assert_allclose(again.omega, traj.omega[1:-1], atol=1e-7)


def test_saved_outputs_are_projected_and_unfilled_slots_kept():
    """ProjectedSolver.outputs puts finite saved states on the constraints (|q| = 1,
    q·q̇ = 0), leaves non-finite slots as they are, and its derivative stays finite."""
    from jrigid.formulations import QuaternionAcceleration
    from jrigid.solve import Flat, ProjectedSolver
    from jrigid.solvers import FusedTsit5

    formulation = QuaternionAcceleration()
    scene = free_scene()
    y0 = formulation.from_state(scene, initial.from_omega(Q0, OMEGA0))
    flat = Flat.of(formulation, y0)
    solver = ProjectedSolver(FusedTsit5(), flat, None)
    y0_flat = flat.ravel(y0)
    ys = jnp.stack([1.1 * y0_flat + 0.01, jnp.full_like(y0_flat, jnp.inf),
                    jnp.full_like(y0_flat, jnp.nan)])
    out = solver.outputs(ys, scene, y0_flat)
    q, qd = out[0, :4], out[0, 4:]
    np.testing.assert_allclose(jnp.dot(q, q), 1.0, rtol=1e-14)
    np.testing.assert_allclose(jnp.dot(q, qd), 0.0, atol=1e-14)
    assert bool(jnp.all(jnp.isinf(out[1]))) and bool(jnp.all(jnp.isnan(out[2])))
    def loss(scale):
        # the unfilled slot depends on it with derivative 0, as diffrax's padding does
        scaled = ys.at[0].multiply(scale).at[1].add(0.0 * scale)
        projected = solver.outputs(scaled, scene, y0_flat)
        return jnp.sum(jnp.where(jnp.isfinite(projected), projected, 0.0))

    assert np.isfinite(float(jax.grad(loss)(1.0)))


def test_plain_inputs_are_converted_or_named():
    """Python floats and lists are accepted as tolerances and times (converted without an
    XLA dispatch) and give the same solve as arrays; a non-numeric one is named."""
    state = initial.from_omega(Q0, OMEGA0)
    as_arrays = simulate(free_scene(), state, jnp.array([0.0, 0.5, 1.0]),
                         rtol=jnp.asarray(1e-7), atol=jnp.asarray(1e-9))
    as_python = simulate(free_scene(), state, [0.0, 0.5, 1.0], rtol=1e-7, atol=1e-9)
    np.testing.assert_array_equal(as_python.q, as_arrays.q)
    for bad in ({"rtol": "tight"}, {"atol": [1e-9, "x"]}):
        with pytest.raises(ValueError, match=f"{next(iter(bad))} must be numeric"):
            simulate(free_scene(), state, [0.0, 1.0], **bad)
    with pytest.raises(ValueError, match="ts must be numeric"):
        simulate(free_scene(), state, ["start", "end"])


# --------------------------------------------------------------------------- step control


def test_vector_lengths_per_leaf_and_flat():
    """Each entry becomes its vector's length: per leaf (last axis, batches kept) and on
    the flat layout, segment by segment."""
    from jrigid.formulations import get_formulation
    from jrigid.solve import Flat, vector_lengths

    got = vector_lengths({"a": jnp.array([[3.0, 4.0], [0.0, -2.0]]), "b": jnp.array(-1.5)})
    np.testing.assert_array_equal(got["a"], [[5.0, 5.0], [2.0, 2.0]])
    assert float(got["b"]) == 1.5
    formulation = get_formulation("quaternion_acceleration")
    y = formulation.from_state(free_scene(), initial.from_omega(Q0, OMEGA0))
    flat = Flat.of(formulation, y)
    lengths = np.asarray(flat.lengths(flat.ravel(y)))
    np.testing.assert_allclose(lengths[:4], np.linalg.norm(y.q), rtol=1e-15)
    np.testing.assert_allclose(lengths[4:], np.linalg.norm(y.qdot), rtol=1e-15)


def _rotated_runs(stepsize_controller=None):
    from scipy.spatial.transform import Rotation

    from jrigid import quaternion as quat

    ts = jnp.linspace(0.0, 30.0, 4)
    runs = []
    for r in Rotation.random(6, random_state=1).as_quat(scalar_first=True):
        state = initial.from_omega(quat.multiply(jnp.asarray(r), Q0), OMEGA0)
        tolerances = dict(rtol=1e-6, atol=1e-8) if stepsize_controller is None else {}
        traj = simulate(free_scene(), state, ts, stepsize_controller=stepsize_controller,
                        **tolerances)
        runs.append((jnp.asarray(r), traj))
    return runs


def test_steps_do_not_depend_on_the_frame():
    """The same motion seen from six rotated space frames (q₀ → r ⊗ q₀): the default
    controller (per-vector error scale, DOP853's estimate from whole-state norms, the
    starting step on the same scale) takes the same steps, and the orientations agree
    with r ⊗ q(t). diffrax's per-entry scale does not (measured over eight such frames:
    72–104 steps)."""
    import diffrax

    from jrigid import quaternion as quat

    runs = _rotated_runs()
    steps = {int(traj.stats["num_steps"]) for _, traj in runs}
    assert len(steps) == 1, steps
    r0, first = runs[0]
    for r, traj in runs[1:]:
        expected = quat.multiply(quat.multiply(r, quat.conjugate(r0)), first.q)
        err = np.minimum(np.abs(traj.q - expected).max(), np.abs(traj.q + expected).max())
        assert err < 1e-12, err
        np.testing.assert_allclose(traj.omega, first.omega, rtol=0, atol=1e-12)
    plain = _rotated_runs(diffrax.PIDController(rtol=1e-6, atol=1e-8))
    assert len({int(traj.stats["num_steps"]) for _, traj in plain}) > 1


def test_starting_step_is_hairers_on_the_vector_scale():
    """With ``dt0=None`` the first step is Hairer's starting step (Solving ODEs I, II.4),
    written out here in numpy with the per-vector scale ``atol + rtol |v|``."""
    import diffrax

    from jrigid.formulations import get_formulation
    from jrigid.solve import Flat, controller
    from jrigid.solvers import TightDop853

    formulation = get_formulation("quaternion_acceleration")
    scene = free_scene()
    y = formulation.from_state(scene, initial.from_omega(Q0, OMEGA0))
    flat = Flat.of(formulation, y)
    y0 = flat.ravel(y)
    rtol, atol = 1e-6, 1e-9
    ts = jnp.array([0.0, 10.0])
    ctrl = controller(ts, rtol, atol, layout=flat)
    term = diffrax.ODETerm(flat.vector_field)
    t1, _ = ctrl.init(term, 0.0, 10.0, y0, None, scene, TightDop853().func, 8)

    def f(t, y):
        return np.asarray(flat.vector_field(t, jnp.asarray(y), scene))

    y0n = np.asarray(y0)
    scale = atol + rtol * np.asarray(flat.lengths(y0))

    def rms(v):
        return np.sqrt(np.mean((v / scale) ** 2))

    f0 = f(0.0, y0n)
    d0, d1 = rms(y0n), rms(f0)
    h0 = 0.01 * d0 / d1
    d2 = rms(f(h0, y0n + h0 * f0) - f0) / h0
    h1 = (0.01 / max(d1, d2)) ** (1 / 8)
    np.testing.assert_allclose(float(t1), min(100 * h0, h1), rtol=1e-12)


def test_acceptance_keeps_more_steps_and_chooses_every_step_as_before():
    """A controller with ``acceptance = c`` keeps a step whose scaled error is below ``c``
    (not 1) and proposes the same next step as diffrax's rule (``c = 1``) for the same
    error history; the second-order form's controller gets the form's ``acceptance``,
    the ``(q, ω)`` form's stays at 1."""
    from jrigid.formulations import QuaternionAcceleration, QuaternionOmega
    from jrigid.solve import controller

    ts = jnp.array([0.0, 10.0])
    y0, y1 = jnp.array([1.0, 0.0, 0.0]), jnp.array([1.0, 0.1, 0.0])
    c, prev = 4.6, 0.7  # the previous step's inverse scaled error under c = 1
    plain = controller(ts, 1e-6, 1e-8)
    wide = controller(ts, 1e-6, 1e-8, acceptance=c)
    for error, kept in ((0.2, True), (0.9, True), (3.0, False), (6.0, False)):
        y_error = jnp.full(3, error * 1e-6)  # scaled error about `error` (|y| ≈ 1, rtol 1e-6)
        runs = []
        for ctrl, inv in ((plain, prev), (wide, prev * c)):
            state = ((jnp.asarray(inv), jnp.asarray(1.0), jnp.asarray(False)),
                     jnp.asarray(False))
            runs.append(ctrl.adapt_step_size(0.0, 0.5, y0, y1, None, y_error, 8, state))
        (keep1, _, next1, *_), (keep_c, _, next_c, *_) = runs
        assert bool(keep1) == kept and bool(keep_c) == (error < c)
        if kept:
            np.testing.assert_allclose(float(next_c), float(next1), rtol=1e-12)
    for form, expected in ((QuaternionAcceleration(), 4.6), (QuaternionOmega(), 1.0)):
        assert controller(ts, 1e-6, 1e-8, formulation=form).acceptance == expected
    for bad in (0.5, float("nan"), True):
        with pytest.raises(ValueError, match="acceptance must be a number >= 1"):
            controller(ts, 1e-6, 1e-8, acceptance=bad)


def test_a_step_proposed_at_dtmin_ends_the_solve():
    """A proposal exactly at ``dtmin`` (the times are rounded, so one can land there) is
    reported as ``dt_min_reached``: diffrax would keep every later step of that size
    whatever its error (a singular solution then ran into NaN and the step budget)."""
    import diffrax

    from jrigid.solve import controller

    ts = jnp.array([0.0, 10.0])
    ctrl = controller(ts, 1e-6, 1e-8)
    dtmin = float(ctrl.dtmin)
    y0, y1 = jnp.array([1.0, 0.0, 0.0]), jnp.array([1.0, 0.0, 0.0])
    state = ((jnp.asarray(1.0), jnp.asarray(1.0), jnp.asarray(False)), jnp.asarray(False))
    for error, expected in ((0.5e-6, diffrax.RESULTS.dt_min_reached),  # step stays at dtmin
                            (1e-12, diffrax.RESULTS.successful)):  # step grows
        keep, _, t_next, _, _, result = ctrl.adapt_step_size(
            0.0, dtmin, y0, y1, None, jnp.full(3, error), 8, state)
        assert bool(keep)
        assert result == expected, (error, float(t_next) - dtmin)


def test_controller_records_nonfinite_trial_steps():
    """The controller's state says whether a trial step since the last accepted one was
    not finite (state or error estimate): what a collapsed step size is blamed on. An
    accepted step clears the record; rejected finite trials after a non-finite one keep it."""
    from jrigid.solve import controller

    ctrl = controller(jnp.array([0.0, 10.0]), 1e-6, 1e-8)
    _, state = ctrl.init(None, 0.0, 10.0, jnp.ones(3), 0.1, None, None, 8)
    assert not bool(ctrl.nonfinite_trials(state))
    y0 = jnp.array([1.0, 0.0, 0.0])
    good, nan = jnp.array([1.0, 0.1, 0.0]), jnp.array([1.0, jnp.nan, 0.0])
    history = []
    for y1, error in ((good, 1e-3), (nan, 1e-3), (good, jnp.inf), (good, 1e-3),
                      (good, 1e-12)):
        keep, _, _, _, state, _ = ctrl.adapt_step_size(
            0.0, 0.5, y0, y1, None, jnp.full(3, error), 8, state)
        history.append((bool(keep), bool(ctrl.nonfinite_trials(state))))
    assert history == [(False, False), (False, True), (False, True), (False, True),
                       (True, False)]


# --------------------------------------------------------------------------- unit time


def _driven_scene():
    """A body under a torque that depends on time (so a wrong clock shows)."""
    from jrigid.body import RigidBody
    from jrigid.scene import Scene, Torque

    def drive(t, kin, amplitude):
        return amplitude * jnp.stack([jnp.sin(t), 0.2 * kin.omega[1], jnp.cos(2.0 * t)])

    return Scene(RigidBody(jnp.array([1.0, 2.0, 3.0])), loads=(Torque(drive, 0.3),))


@pytest.mark.parametrize("solver_name", ["TightDop853", "Tsit5", "FusedDopri8", "FusedDop853",
                                         "TightDop853-fused"])
def test_a_solve_in_unit_time_takes_the_steps_of_the_solve_in_t(solver_name):
    """``run(..., unit_time=True)`` (τ = (t − t0) / T from 0 to 1, what the default solve
    runs) takes as many steps, reaches the same end state and interpolates the same
    states as the solve in ``t``, for diffrax's and jrigid's solvers (the fused ones take
    their increments from the term's control), with a field that depends on ``t``.

    Not to rounding: an error estimate is a difference of nearly equal sums, so the
    rounding of ``T (τ1 − τ0)`` against ``t1 − t0`` changes it by about 1e-6 of itself,
    and the steps by about 1e-7 of theirs (up to 2e-4 with Dopri8's estimate): the states
    agree to a hundredth of the tolerance."""
    import diffrax

    from jrigid.formulations import get_formulation
    from jrigid.solve import Flat, controller, run, unit_times
    from jrigid.solvers import FusedDop853, FusedDopri8, TightDop853

    solver = {"TightDop853": TightDop853(), "Tsit5": diffrax.Tsit5(),
              "FusedDopri8": FusedDopri8(), "FusedDop853": FusedDop853(),
              "TightDop853-fused": TightDop853(fuse_below=10_000)}[solver_name]
    formulation = get_formulation("quaternion_acceleration")
    scene = _driven_scene()
    y = formulation.from_state(scene, initial.from_omega(Q0, OMEGA0))
    flat = Flat.of(formulation, y)
    ts = jnp.array([2.0, 4.3, 7.0])
    sols = []
    for unit_time, times in ((False, ts), (True, unit_times(ts))):
        sols.append(run(
            flat, solver, ts, None, flat.ravel(y), scene,
            saveat=diffrax.SaveAt(ts=times[1:2], t1=True),
            stepsize_controller=controller(ts, 1e-8, 1e-10, layout=flat, unit_time=unit_time),
            adjoint=diffrax.RecursiveCheckpointAdjoint(), max_steps=10_000,
            unit_time=unit_time,
        ))
    in_t, in_unit = sols
    assert in_t.result == in_unit.result == diffrax.RESULTS.successful
    assert int(in_unit.stats["num_accepted_steps"]) == int(in_t.stats["num_accepted_steps"])
    assert int(in_unit.stats["num_steps"]) == int(in_t.stats["num_steps"])
    np.testing.assert_allclose(in_unit.ys, in_t.ys, rtol=0, atol=1e-10)
    np.testing.assert_allclose(unit_times(ts)[1:], in_unit.ts, rtol=1e-15)


def test_the_default_solve_has_constant_ends():
    """The default solve runs in unit time, so diffrax's rounding threshold for the end
    (100 chained ``nextafter`` on ``t1``: about 1700 operations when ``t1`` is traced) is
    folded by XLA and is not in the compiled program; a solve in ``t`` has it."""
    import diffrax

    state = initial.from_omega(Q0, OMEGA0)
    ts = jnp.linspace(0.0, 10.0, 5)

    def compiled(**options):
        solve = jax.jit(lambda s: simulate(free_scene(), s, ts, **options).q)
        return solve.lower(state).compile().as_text()

    assert compiled().count("nextafter") < 10
    assert compiled(saveat=diffrax.SaveAt(ts=ts)).count("nextafter") >= 100


def _calls(jaxpr, name) -> int:
    """How many calls of the jitted function ``name`` a jaxpr holds, inner jaxprs included."""
    total = 0
    for eqn in jaxpr.eqns:
        total += eqn.primitive.name in ("pjit", "jit") and eqn.params.get("name") == name
        for param in eqn.params.values():
            for inner in param if isinstance(param, (tuple, list)) else (param,):
                inner = getattr(inner, "jaxpr", inner)
                if hasattr(inner, "eqns"):
                    total += _calls(inner, name)
    return total


def test_the_default_solve_compiles_the_vector_field_twice():
    """In the default solve's program the vector field appears twice: in the starting-step
    rule and in the step's stage loop, which also holds the dense output's stages. A
    collapsed step is blamed on NaN through the controller's record, not by probing the
    field after the solve. (Each copy of a heavy top's field costs about 0.2 s of XLA
    compilation.)"""
    import diffrax

    state = initial.from_omega(Q0, OMEGA0)
    ts = jnp.linspace(0.0, 10.0, 5)

    def copies(**options):
        program = jax.make_jaxpr(lambda s: simulate(free_scene(), s, ts, **options).q)(state)
        return _calls(program.jaxpr, "vector_field")

    assert copies() == 2
    assert copies(saveat=diffrax.SaveAt(ts=ts)) == 2


def test_derivative_with_respect_to_the_end_time_is_the_field_there():
    """The ends enter the unit-time solve through its start and span: d ω(T) / dT of the
    default solve is Euler's ω̇ at T (torque free: ω̇ = I⁻¹ (Iω × ω)), and d ω(T) / d t0
    agrees with a central difference."""
    moments = jnp.array([1.0, 2.0, 3.0])
    state = initial.from_omega(Q0, OMEGA0)

    def final_omega(t0, t1):
        scene = free_scene()
        return simulate(scene, state, jnp.stack([t0, 0.5 * (t0 + t1), t1]), rtol=1e-11,
                        atol=1e-13).omega[-1]

    t0, t1 = jnp.asarray(0.3), jnp.asarray(4.0)
    d_t0, d_t1 = jax.jacfwd(final_omega, argnums=(0, 1))(t0, t1)
    w = final_omega(t0, t1)
    np.testing.assert_allclose(d_t1, jnp.cross(moments * w, w) / moments, atol=1e-9)
    h = 1e-5
    fd = (final_omega(t0 + h, t1) - final_omega(t0 - h, t1)) / (2 * h)
    np.testing.assert_allclose(d_t0, fd, atol=1e-7)


def test_unit_times_refuse_what_they_cannot_map():
    from jrigid.solve import saved_times, unit_times

    ts = jnp.array([1.0, 2.0, 5.0])
    np.testing.assert_array_equal(unit_times(ts), [0.0, 0.25, 1.0])
    np.testing.assert_array_equal(saved_times(jnp.array([0.0, 0.25, jnp.inf, 0.5]), ts),
                                  [1.0, 2.0, jnp.inf, 3.0])
    for bad in (jnp.array(1.0), jnp.array([1.0]), jnp.ones((2, 2))):
        with pytest.raises(ValueError, match="shape \\(T,\\) with T >= 2"):
            unit_times(bad)
    with pytest.raises(ValueError, match="shape \\(T \\+ 1,\\)"):
        saved_times(jnp.zeros(3), ts)


def test_nonfinite_trials_refuses_a_state_that_is_not_the_controllers():
    """Reading the record from a solve that did not save the controller's state (``None``)
    or from another controller's state is an error that names the remedy."""
    from jrigid.solve import controller

    ctrl = controller(jnp.array([0.0, 10.0]), 1e-6, 1e-8)
    for bad in (None, (jnp.asarray(1.0), jnp.asarray(1.0), jnp.asarray(False))):
        with pytest.raises(ValueError, match="controller_state=True"):
            ctrl.nonfinite_trials(bad)
