"""jrigid.solvers: the fused Runge–Kutta pairs and TightDop853 against diffrax's own,
scipy's DOP853 and theory."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import DOP853, solve_ivp
from scipy.stats import linregress

from jrigid.solvers import FusedDop853, FusedDopri8, FusedTsit5, TightDop853

PAIRS = [(FusedTsit5, diffrax.Tsit5, 5), (FusedDopri8, diffrax.Dopri8, 8)]
ORDERS = [(FusedTsit5, 5), (FusedDopri8, 8), (FusedDop853, 8), (TightDop853, 8)]


def kepler(t, y, args):
    """Planar Kepler problem as a pytree ``{'x': (2,), 'v': (2,)}`` (nonlinear, smooth)."""
    r3 = jnp.sum(y["x"] ** 2) ** 1.5
    return {"x": y["v"], "v": -y["x"] / r3}


Y0 = {"x": jnp.array([0.6, 0.0]), "v": jnp.array([0.0, np.sqrt(1 / 0.6 * 1.4)])}


def solve(solver, **kw):
    args = dict(
        stepsize_controller=diffrax.PIDController(rtol=1e-9, atol=1e-11),
        saveat=diffrax.SaveAt(ts=jnp.linspace(0.0, 6.0, 37)),
        max_steps=100_000,
    )
    args.update(kw)
    # dt0 large enough that the first error estimate is not at rounding level (where the
    # next step would depend on the last bits of the estimate).
    return diffrax.diffeqsolve(diffrax.ODETerm(kepler), solver, 0.0, 6.0, 0.1, Y0, **args)


@pytest.mark.parametrize("fused, reference, order", PAIRS)
def test_same_steps_and_values_as_diffrax(fused, reference, order):
    a, b = solve(fused()), solve(reference())
    assert int(a.stats["num_steps"]) == int(b.stats["num_steps"])
    assert int(a.stats["num_rejected_steps"]) == int(b.stats["num_rejected_steps"])
    for key in ("x", "v"):
        np.testing.assert_allclose(a.ys[key], b.ys[key], rtol=0, atol=1e-11)


@pytest.mark.parametrize("fused, reference, order", PAIRS)
def test_dense_output_matches_diffrax(fused, reference, order):
    a = solve(fused(), saveat=diffrax.SaveAt(dense=True))
    b = solve(reference(), saveat=diffrax.SaveAt(dense=True))
    t = jnp.linspace(0.0, 6.0, 301)
    ya, yb = jax.vmap(a.evaluate)(t), jax.vmap(b.evaluate)(t)
    np.testing.assert_allclose(ya["x"], yb["x"], atol=1e-11)


@pytest.mark.parametrize("fused, order", ORDERS)
def test_order_of_convergence(fused, order):
    # Fixed steps on the (nonlinear) Kepler problem against scipy's DOP853 at rtol 1e-13;
    # the slope of log error against log h. (On a linear problem Tsit5 reaches order 6.)
    y0 = np.concatenate([np.asarray(Y0["x"]), np.asarray(Y0["v"])])

    def rhs(t, y):
        r3 = np.sum(y[:2] ** 2) ** 1.5
        return np.concatenate([y[2:], -y[:2] / r3])

    ref = solve_ivp(rhs, (0.0, 2.0), y0, method="DOP853", rtol=1e-13, atol=1e-15).y[:2, -1]
    hs = [0.1, 0.05, 0.025] if order == 5 else [0.2, 0.1, 0.05]
    errors = []
    for h in hs:
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(kepler), fused(), 0.0, 2.0, h, Y0,
            stepsize_controller=diffrax.ConstantStepSize(),
        )
        errors.append(float(np.max(np.abs(np.asarray(sol.ys["x"][-1]) - ref))))
    slope = linregress(np.log(hs), np.log(errors)).slope
    assert abs(slope - order) < 0.5, (slope, errors)


@pytest.mark.parametrize("fused, order", ORDERS)
def test_gradients_reverse_forward_and_differences(fused, order):
    def final(v0, adjoint):
        y0 = {"x": Y0["x"], "v": jnp.array([0.0, v0])}
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(kepler), fused(), 0.0, 3.0, 0.01, y0,
            adjoint=diffrax.RecursiveCheckpointAdjoint() if adjoint is None else adjoint,
            stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-12),
        )
        return sol.ys["x"][-1, 0]

    v0 = float(Y0["v"][1])
    rev = jax.grad(final)(v0, diffrax.RecursiveCheckpointAdjoint())
    fwd = jax.jacfwd(final)(v0, diffrax.ForwardMode())
    h = 1e-5
    fd = (final(v0 + h, None) - final(v0 - h, None)) / (2 * h)
    np.testing.assert_allclose(rev, fwd, rtol=1e-8)
    np.testing.assert_allclose(rev, fd, rtol=1e-5)


def _flat_kepler(t, y, args):
    return jnp.concatenate([y[2:], -y[:2] / jnp.sum(y[:2] ** 2) ** 1.5])


@pytest.mark.parametrize("solver, factor", [(FusedDop853(), 1.0), (TightDop853(factor=1.0), 1.0),
                                            (TightDop853(), 10.0)])
def test_dop853_step_error_and_dense_output_are_scipys(solver, factor):
    # One step of h = 0.4 from the Kepler state: the solver's y1, error estimate (times
    # TightDop853's factor) and dense output against scipy's DOP853 taking the same step
    # (huge tolerances: accepted). The estimate's direction scipy does not return (its
    # ``_estimate_error`` combines e5 and e3 entry by entry, which its
    # steps never use: "left for testing purposes"); its size is the one scipy's step
    # control uses.
    y0 = np.concatenate([np.asarray(Y0["x"]), np.asarray(Y0["v"])])
    h = 0.4
    ref = DOP853(lambda t, y: np.asarray(_flat_kepler(t, jnp.asarray(y), None)), 0.0, y0, h,
                 first_step=h, max_step=h, rtol=1e3, atol=1e3)
    ref.step()
    assert ref.t == h
    dense = ref.dense_output()
    term = diffrax.ODETerm(_flat_kepler)
    y0j = jnp.asarray(y0)
    state = solver.init(term, 0.0, h, y0j, None)
    y1, err, info, _, _ = solver.step(term, 0.0, h, y0j, None, state, False)
    np.testing.assert_allclose(y1, ref.y, rtol=0, atol=1e-14)
    # scipy controls steps with |e5|² / √(n (|e5|² + 0.01 |e3|²)) of the scaled e5 and e3;
    # on a uniform scale that is the RMS of the solver's estimate, which points along e5
    uniform = np.ones_like(y0)
    rms = np.sqrt(np.mean(np.asarray(err) ** 2))
    np.testing.assert_allclose(rms, factor * ref._estimate_error_norm(ref.K, h, uniform),
                               rtol=1e-9)
    e5 = h * ref.K.T @ ref.E5
    np.testing.assert_allclose(np.asarray(err) / rms, e5 / np.sqrt(np.mean(e5**2)), rtol=1e-9)
    interp = solver.interpolation_cls(t0=0.0, t1=h, **info)
    for t in np.linspace(0.0, h, 9):
        np.testing.assert_allclose(interp.evaluate(t), dense(t), rtol=0, atol=1e-14)


def test_dop853_coefficients_are_scipys_without_importing_scipy_integrate():
    """jrigid loads scipy's coefficient file on its own (importing ``scipy.integrate``
    costs a first solve 0.2–0.5 s): the same numbers as scipy's module, and a fresh
    process that imports the default solver does not import ``scipy.integrate``."""
    import subprocess
    import sys

    from scipy.integrate._ivp import dop853_coefficients as scipys

    from jrigid.solvers._dop853_coefficients import coefficients as ours

    for name in ("A", "B", "C", "E3", "E5", "D"):
        np.testing.assert_array_equal(getattr(ours, name), getattr(scipys, name))
    for name in ("N_STAGES", "N_STAGES_EXTENDED", "INTERPOLATOR_POWER"):
        assert getattr(ours, name) == getattr(scipys, name)
    code = ("import sys, jrigid.integrate, jrigid.solvers; "
            "print('scipy.integrate' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


def test_tight_dop853_takes_the_steps_of_dop853_at_tolerances_divided_by_its_factor():
    tight = solve(TightDop853())
    fused = solve(FusedDop853(), stepsize_controller=diffrax.PIDController(rtol=1e-10,
                                                                            atol=1e-12))
    plain = solve(FusedDop853())
    assert int(tight.stats["num_steps"]) == int(fused.stats["num_steps"])
    assert int(tight.stats["num_steps"]) > int(plain.stats["num_steps"])
    for key in ("x", "v"):
        np.testing.assert_allclose(tight.ys[key], fused.ys[key], rtol=0, atol=1e-12)


@pytest.mark.parametrize("solver", [FusedDop853, lambda: TightDop853(factor=1.0)],
                         ids=["fused", "tight"])
def test_dop853_dense_output_as_accurate_inside_steps_as_at_their_ends(solver):
    # Adaptive solve at rtol 1e-10: the worst error at 301 output times (mostly inside
    # steps) within 4x the worst error at the step ends (Dormand-Prince 8(7)'s interpolant,
    # measured: over 10x), against scipy's DOP853 at rtol 1e-13.
    y0 = np.concatenate([np.asarray(Y0["x"]), np.asarray(Y0["v"])])

    def rhs(t, y):
        return np.asarray(_flat_kepler(t, jnp.asarray(y), None))

    ref = solve_ivp(rhs, (0.0, 6.0), y0, method="DOP853", rtol=1e-13, atol=1e-15,
                    dense_output=True)
    ctrl = diffrax.PIDController(rtol=1e-10, atol=1e-12)

    def errors(solver, saveat):
        sol = diffrax.diffeqsolve(diffrax.ODETerm(_flat_kepler), solver, 0.0, 6.0, 0.1,
                                  jnp.asarray(y0), stepsize_controller=ctrl, saveat=saveat)
        ts = np.asarray(sol.ts)
        keep = np.isfinite(ts)
        return np.abs(np.asarray(sol.ys)[keep] - ref.sol(ts[keep]).T).max()

    inside = errors(solver(), diffrax.SaveAt(ts=jnp.linspace(0.0, 6.0, 301)))
    ends = errors(solver(), diffrax.SaveAt(steps=True))
    assert inside < 4 * ends, (inside, ends)
    inside8 = errors(FusedDopri8(), diffrax.SaveAt(ts=jnp.linspace(0.0, 6.0, 301)))
    ends8 = errors(FusedDopri8(), diffrax.SaveAt(steps=True))
    assert inside8 > 4 * ends8, (inside8, ends8)  # the check can fail


def test_event_locates_crossing():
    # x-coordinate crosses zero a quarter orbit in; the fused interpolant finds it.
    event = diffrax.Event(lambda t, y, args, **kw: y["x"][0])
    a = solve(FusedTsit5(), event=event, saveat=diffrax.SaveAt(t1=True))
    b = solve(diffrax.Tsit5(), event=event, saveat=diffrax.SaveAt(t1=True))
    assert float(a.ts[-1]) < 6.0
    np.testing.assert_allclose(a.ts[-1], b.ts[-1], rtol=1e-8)  # the root finder's tolerance


def test_jump_recomputes_first_stage():
    # A step-size controller with jump_ts makes the solver re-evaluate the field there.
    ctrl = diffrax.PIDController(rtol=1e-9, atol=1e-11, jump_ts=jnp.array([1.5, 3.0]))
    a = solve(FusedTsit5(), stepsize_controller=ctrl)
    b = solve(diffrax.Tsit5(), stepsize_controller=ctrl)
    np.testing.assert_allclose(a.ys["x"], b.ys["x"], atol=1e-11)


def test_tight_dop853_written_out_and_in_diffrax_stage_loop_take_the_same_steps():
    # the Kepler field is small (written out with fuse_below=300); by default diffrax's loop
    term = diffrax.ODETerm(kepler)
    written = TightDop853(fuse_below=300)
    assert written.fused(term, 0.0, Y0, None)
    assert not TightDop853().fused(term, 0.0, Y0, None)
    assert not TightDop853(fuse_below=5).fused(term, 0.0, Y0, None)
    dense = diffrax.SaveAt(ts=jnp.linspace(0.0, 6.0, 37), dense=True)
    fused, looped = solve(written, saveat=dense), solve(TightDop853(), saveat=dense)
    for key in ("num_steps", "num_rejected_steps"):
        assert int(fused.stats[key]) == int(looped.stats[key])
    for key in ("x", "v"):
        np.testing.assert_allclose(fused.ys[key], looped.ys[key], rtol=0, atol=1e-12)
    t = jnp.linspace(0.0, 6.0, 301)  # the dense output (increments either way)
    np.testing.assert_allclose(jax.vmap(fused.evaluate)(t)["x"],
                               jax.vmap(looped.evaluate)(t)["x"], rtol=0, atol=1e-12)
    # a reverse-mode derivative through the written-out stages is the looped one's
    def final(solver, v0):
        y0 = {"x": Y0["x"], "v": Y0["v"].at[1].set(v0)}
        return diffrax.diffeqsolve(term, solver, 0.0, 2.0, 0.1, y0,
                                   stepsize_controller=diffrax.PIDController(rtol=1e-9,
                                                                             atol=1e-11),
                                   ).ys["x"][-1, 0]
    v0 = Y0["v"][1]
    np.testing.assert_allclose(jax.grad(lambda v: final(written, v))(v0),
                               jax.grad(lambda v: final(TightDop853(), v))(v0), rtol=1e-9)


@pytest.mark.parametrize("fuse_below", [-1, 1.5, True, "300"])
def test_tight_dop853_refuses_a_fuse_below_that_is_not_a_count(fuse_below):
    with pytest.raises(ValueError, match="fuse_below must be an int"):
        TightDop853(fuse_below=fuse_below)


@pytest.mark.parametrize("factor", [0.0, -1.0, float("nan"), True, "10"])
def test_tight_dop853_refuses_a_factor_that_is_not_a_positive_number(factor):
    with pytest.raises(ValueError, match="factor must be a number > 0"):
        TightDop853(factor=factor)


def test_dense_stages_only_where_an_output_time_falls():
    """``at_outputs(ts)``: a step holding an output time in ``(t0, t1]`` has the dense
    output's stages of the eager solver; a step without one leaves them zero (and the
    interpolation still starts at ``y0``); its state carries the index of the first
    output time after the step; a whole solve saving at ``ts`` is unchanged."""
    term = diffrax.ODETerm(_flat_kepler)
    y0 = jnp.concatenate([Y0["x"], Y0["v"]])
    out_ts = jnp.array([0.0, 0.5, 1.0])
    eager, lazy = TightDop853(), TightDop853().at_outputs(out_ts)
    for (t0, t1), inside in (((0.0, 0.4), False), ((0.4, 0.5), True), ((0.5, 0.8), False),
                             ((0.8, 1.2), True), ((-1.0, 0.6), True)):
        state = eager.init(term, t0, t1, y0, None)
        ref = eager.step(term, t0, t1, y0, None, state, False)
        got = lazy.step(term, t0, t1, y0, None, lazy.init(term, t0, t1, y0, None), False)
        assert int(got[3][-1]) == int(np.searchsorted(out_ts, t1, side="right"))
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_array_equal(got[1], ref[1])
        f_ref, f_got = ref[2]["f"], got[2]["f"]
        assert f_ref.shape == f_got.shape == (16, 4)
        np.testing.assert_array_equal(f_got[:13], f_ref[:13])
        if inside:
            np.testing.assert_array_equal(f_got, f_ref)
        else:
            assert np.all(f_got[13:] == 0) and np.all(f_ref[13:] != 0)
            interp = lazy.interpolation_cls(t0=t0, t1=t1, **got[2])
            np.testing.assert_array_equal(interp.evaluate(t0), y0)
    ts = jnp.linspace(0.0, 3.0, 7)
    for fuse_below in (0, 300):  # diffrax's stage loop: bit for bit; written out: rounding
        ys = []
        for solver in (TightDop853(fuse_below=fuse_below),
                       TightDop853(fuse_below=fuse_below).at_outputs(ts)):
            sol = diffrax.diffeqsolve(term, solver, 0.0, 3.0, None, y0,
                                      saveat=diffrax.SaveAt(ts=ts),
                                      stepsize_controller=diffrax.PIDController(rtol=1e-9,
                                                                                atol=1e-9))
            ys.append(sol.ys)
        np.testing.assert_allclose(ys[1], ys[0], rtol=0, atol=0 if fuse_below == 0 else 1e-13)
    # no output time (a solve saving its ends only): no step has the dense stages
    none = TightDop853().at_outputs(jnp.zeros(0))
    state = none.init(term, 0.0, 0.4, y0, None)
    assert len(state) == 2
    got = none.step(term, 0.0, 0.4, y0, None, state, False)
    ref = eager.step(term, 0.0, 0.4, y0, None, eager.init(term, 0.0, 0.4, y0, None), False)
    np.testing.assert_array_equal(got[0], ref[0])
    assert np.all(got[2]["f"][13:] == 0) and len(got[3]) == 2
    for wrong in (jnp.array(1.0), jnp.ones((2, 3))):
        with pytest.raises(ValueError, match="output times must have shape"):
            TightDop853().at_outputs(wrong)


def test_single_precision_coefficients_keep_dop853_consistent():
    # Each coefficient a float32 number, all but one per row DOP853's rounded, and the
    # consistency conditions exact to about 1e-10 (rounded one by one they miss by ~5e-7)
    from scipy.integrate._ivp import dop853_coefficients as dop853

    from jrigid.solvers.tight import _SinglePrecision

    tab, ref = _SinglePrecision.tableau, TightDop853.tableau
    rows = [*tab.a_lower, tab.c, tab.b_sol, tab.b_error, _SinglePrecision.error3]
    for row in rows:
        np.testing.assert_array_equal(np.asarray(row, np.float32).astype(np.float64), row)
    for new, old in [(tab.b_sol, ref.b_sol), (tab.b_error, ref.b_error),
                     (_SinglePrecision.error3, dop853.E3),
                     *zip(tab.a_lower, ref.a_lower, strict=True)]:
        rounded = np.asarray(old, np.float32).astype(np.float64)
        assert np.sum(new != rounded) <= 1
        np.testing.assert_allclose(new, old, rtol=0, atol=2e-6)
    assert abs(np.sum(tab.b_sol) - 1.0) < 1e-9
    assert abs(np.sum(tab.b_error)) < 1e-9 and abs(np.sum(_SinglePrecision.error3)) < 1e-9
    for a_i, c_i in zip(tab.a_lower, tab.c, strict=True):
        assert abs(np.sum(a_i) - c_i) < 1e-9
    naive = np.asarray(ref.b_sol, np.float32).astype(np.float64)
    assert abs(np.sum(naive) - 1.0) > 1e-8  # what the adjustment is for
    np.testing.assert_array_equal(tab.a_lower[-1], tab.b_sol[:-1])  # first same as last


def test_tight_dop853_uses_the_single_precision_coefficients_for_float32_states():
    solver = TightDop853(factor=3.0, fuse_below=7).at_outputs(jnp.array([0.0, 1.0]))
    single = solver.in_precision_of(jnp.zeros(4, jnp.float32))
    assert type(single).__name__ == "_SinglePrecision"
    assert (single.factor, single.fuse_below) == (3.0, 7)
    np.testing.assert_array_equal(single.output_ts, solver.output_ts)
    assert single.in_precision_of(jnp.zeros(4, jnp.float32)) is single
    assert solver.in_precision_of(jnp.zeros(4, jnp.float64)) is solver


def test_float32_free_rotor_phase_is_set_by_the_tolerance_not_the_coefficients(float32):
    # A free rotor over 10 periods in float32 at rtol 1e-5, against scipy's DOP853 at rtol
    # 1e-12 in float64 (numpy): with DOP853's weights rounded one by one to float32 the
    # orientation error was 3.3e-5 rad whatever the tolerance; measured now 3.8e-6
    from jrigid import Scene, initial, simulate
    from jrigid.body import RigidBody

    moments, omega0 = np.array([1.0, 2.0, 3.0]), np.array([0.1, 0.05, 1.0])

    def rhs(t, y):
        q, w = y[:4], y[4:]
        qdot = 0.5 * np.array([-q[1] * w[0] - q[2] * w[1] - q[3] * w[2],
                               q[0] * w[0] + q[2] * w[2] - q[3] * w[1],
                               q[0] * w[1] - q[1] * w[2] + q[3] * w[0],
                               q[0] * w[2] + q[1] * w[1] - q[2] * w[0]])
        return np.concatenate([qdot, np.cross(moments * w, w) / moments])

    ts = np.linspace(0.0, 10 * 2 * np.pi / np.linalg.norm(omega0), 41)
    ref = solve_ivp(rhs, (0.0, ts[-1]), np.concatenate([[1.0, 0, 0, 0], omega0]),
                    method="DOP853", t_eval=ts, rtol=1e-12, atol=1e-14).y[:4].T
    traj = simulate(Scene(RigidBody(jnp.asarray(moments, jnp.float32))),
                    initial.from_omega(omega=jnp.asarray(omega0, jnp.float32)),
                    jnp.asarray(ts, jnp.float32), rtol=1e-5, atol=1e-7)
    assert traj.q.dtype == jnp.float32
    q = np.asarray(traj.q, np.float64)
    err = np.minimum(np.linalg.norm(q - ref, axis=-1), np.linalg.norm(q + ref, axis=-1))
    assert 2 * err.max() < 1e-5, 2 * err.max()


@pytest.mark.parametrize("solver", [FusedTsit5, FusedDopri8, FusedDop853])
def test_written_out_pairs_take_consistent_coefficients_in_float32(solver):
    from jrigid.solvers.fused import in_precision

    tab = solver.tableau
    assert in_precision(tab, jnp.float64) is tab
    single = in_precision(tab, jnp.float32)
    assert in_precision(tab, jnp.float32) is single
    assert abs(np.sum(single.b_sol) - 1.0) < 1e-9 and abs(np.sum(single.b_error)) < 1e-9
    for a_i, c_i in zip(single.a_lower, single.c, strict=True):  # a row of large entries
        assert abs(np.sum(a_i) - c_i) < 2.5e-7  # only to its smallest entry's float32 ulp
        np.testing.assert_array_equal(np.asarray(a_i, np.float32).astype(np.float64), a_i)
