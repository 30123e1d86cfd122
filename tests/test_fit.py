"""jrigid.fit: losses and their gradients, recovery, Laplace error bars, bad observations."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jrigid import exact, fit, initial
from jrigid.body import RigidBody
from jrigid.scene import Scene

TRUE_MOMENTS = jnp.array([1.0, 2.0, 2.5]) / 5.5  # trace 1
TRUE_OMEGA0 = jnp.array([0.3, 2.0, 0.2])  # near the intermediate axis: tumbling
TRUE_Q0 = jnp.asarray(Rotation.from_euler("ZXZ", [0.3, 0.7, -0.2]).as_quat(scalar_first=True))


def build(theta):
    """Torque-free body: moment ratios (trace 1), initial spin, initial orientation."""
    body = RigidBody(fit.moment_ratios(theta["shape"]))
    q0 = fit.unit_quaternion(theta["q0"]) if "q0" in theta else None
    return Scene(body), initial.from_omega(q0, theta["omega0"])


def truth(with_q0=False):
    theta = {"shape": fit.moment_ratios_raw(TRUE_MOMENTS), "omega0": TRUE_OMEGA0}
    if with_q0:
        theta["q0"] = TRUE_Q0
    return theta


def truth_arrays():
    return TRUE_MOMENTS, TRUE_Q0, TRUE_OMEGA0


def gyro_record(ts, sigma, seed):
    """Exact torque-free ω(t) (closed form, independent of the integrator), plus noise."""
    _, om = exact.solve(TRUE_MOMENTS, TRUE_Q0, TRUE_OMEGA0, ts)
    rng = np.random.default_rng(seed)
    return np.asarray(om) + sigma * rng.standard_normal(om.shape)


# --------------------------------------------------------------------------- plain losses


def test_orientation_loss_sign_invariant_and_is_sin2_half_angle():
    a = Rotation.from_rotvec([0.2, -0.4, 0.9])
    rel = Rotation.from_rotvec([0.0, 0.5, 0.0])  # 0.5 rad apart
    q = jnp.asarray(a.as_quat(scalar_first=True))[None]
    q_obs = jnp.asarray((a * rel).as_quat(scalar_first=True))[None]
    expected = np.sin(0.25) ** 2
    np.testing.assert_allclose(fit.orientation_loss(q, q_obs), expected, rtol=1e-12)
    np.testing.assert_allclose(fit.orientation_loss(q, -q_obs), expected, rtol=1e-12)
    assert float(fit.orientation_loss(q, -q)) < 1e-15
    # residual form: |r|² σ²/4 = 1 - (q·q̂)²
    obs = fit.Orientations([0.0, 1.0], np.concatenate([-q_obs, q_obs]), sigma=0.1)
    pred = fit.Prediction(jnp.concatenate([q, q]), jnp.zeros((2, 3)), jnp.array([1.0, 0, 0, 0]))
    r = obs.residuals(pred).reshape(2, 3)
    np.testing.assert_allclose(jnp.sum(r * r, axis=1) * 0.01 / 4, [expected] * 2, rtol=1e-12)


def test_gyroscope_and_axis_losses_values():
    om = jnp.array([[1.0, 2.0, 3.0]])
    assert float(fit.gyroscope_loss(om, om + 0.2, 0.1)) == pytest.approx(0.5 * 3 * 4)
    u = jnp.array([[1.0, 0.0, 0.0]])
    v = jnp.array([[0.0, 1.0, 0.0]])
    assert float(fit.axis_loss(u, v, 1.0)) == pytest.approx(1.0)


# --------------------------------------------------------------------------- gradients


def _central_fd(f, flat, h):
    cols = []
    for i in range(flat.shape[0]):
        e = jnp.zeros_like(flat).at[i].set(h)
        cols.append((f(flat + e) - f(flat - e)) / (2 * h))
    return jnp.stack(cols, axis=-1)


def test_every_loss_gradient_matches_finite_differences():
    """∂(loss)/∂θ through ``simulate`` against central differences, rel 1e-6.

    (The closed-form model's gradients are exercised by the recovery tests.)"""
    ts = jnp.linspace(0.0, 2.0, 9)
    q, om = exact.solve(TRUE_MOMENTS, TRUE_Q0, TRUE_OMEGA0, ts)
    rng = np.random.default_rng(0)
    observations = [
        fit.Gyroscope(ts, np.asarray(om) + 0.05 * rng.standard_normal(om.shape), sigma=0.05),
        fit.Orientations(ts, np.asarray(q)[:, [0, 2, 1, 3]], sigma=0.1),  # perturbed data
        fit.AxisDirections(ts, np.tile([0.1, 0.2, 1.0], (9, 1)), sigma=0.1, axis=2),
    ]
    problem = fit.Problem(fit.Simulated(build, rtol=1e-12, atol=1e-14), observations)
    theta = truth(with_q0=True)
    theta = {k: v * 1.03 for k, v in theta.items()}  # off the optimum
    flat, unravel = jax.flatten_util.ravel_pytree(theta)

    def losses(x):
        pred = problem.predict(unravel(x))
        out = []
        for obs, idx in zip(problem.observations, problem.index, strict=True):
            sub = fit.Prediction(pred.q[idx], pred.omega[idx], pred.frame)
            out.append(obs.loss(sub))
        return jnp.stack(out)

    grad = jax.jit(jax.jacrev(losses))(flat)
    fd = _central_fd(jax.jit(losses), flat, 1e-5)
    assert bool(jnp.all(jnp.abs(grad) > 0))  # every parameter matters to every loss
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-6 * float(jnp.max(jnp.abs(fd))))
    # the problem's total loss is the sum of the parts
    np.testing.assert_allclose(problem.loss(theta), jnp.sum(losses(flat)), rtol=1e-12)


# --------------------------------------------------------------------------- recovery


def _fit_problem(model, ts, omega_obs, sigma):
    return fit.Problem(model, fit.Gyroscope(ts, omega_obs, sigma=sigma))


START = {"shape": jnp.array([0.5, 0.5]), "omega0": jnp.array([0.4, 1.9, 0.3])}


def test_noise_free_recovery_exact_model():
    ts = jnp.linspace(0.0, 8.0, 41)
    problem = _fit_problem(fit.Exact(build), ts, gyro_record(ts, 0.0, 0), 0.01)
    res = fit.fit(problem, START, max_iter=300, gtol=1e-10)
    assert res.converged, res.reason
    np.testing.assert_allclose(fit.moment_ratios(res.params["shape"]), TRUE_MOMENTS, atol=1e-6)
    np.testing.assert_allclose(res.params["omega0"], TRUE_OMEGA0, atol=1e-6)
    # history: one entry per iterate, loss decreasing overall
    assert len(res.history["loss"]) == res.n_iter + 1 == len(res.history["params"])
    assert res.history["loss"][-1] < 1e-8 * res.history["loss"][0]


def test_noise_free_recovery_through_simulate():
    ts = jnp.linspace(0.0, 3.0, 13)
    problem = _fit_problem(
        fit.Simulated(build, rtol=1e-11, atol=1e-13), ts, gyro_record(ts, 0.0, 0), 0.01
    )
    res = fit.fit(problem, START, max_iter=300, gtol=1e-9)
    assert res.converged, res.reason
    np.testing.assert_allclose(fit.moment_ratios(res.params["shape"]), TRUE_MOMENTS, atol=1e-6)
    np.testing.assert_allclose(res.params["omega0"], TRUE_OMEGA0, atol=1e-6)


def test_levenberg_marquardt_recovers_through_simulate_in_few_steps():
    """Forward-mode Gauss–Newton steps: the same optimum as L-BFGS, in fewer iterations."""
    ts = jnp.linspace(0.0, 3.0, 13)
    problem = _fit_problem(
        fit.Simulated(build, rtol=1e-11, atol=1e-13), ts, gyro_record(ts, 0.0, 0), 0.01
    )
    res = fit.fit(problem, START, method="lm", max_iter=50, gtol=1e-9)
    assert res.converged, res.reason
    np.testing.assert_allclose(fit.moment_ratios(res.params["shape"]), TRUE_MOMENTS, atol=1e-6)
    np.testing.assert_allclose(res.params["omega0"], TRUE_OMEGA0, atol=1e-6)
    assert np.all(np.diff(res.history["loss"]) <= 0)  # every accepted step decreases
    assert res.n_iter <= 20
    with pytest.raises(ValueError, match="Problem"):
        fit.fit(_quadratic, {"x": jnp.zeros(3)}, method="lm")


def test_noisy_truth_within_three_sigma():
    """Seeded noisy record: every estimate within 3σ of the truth, χ² plausible."""
    ts = jnp.linspace(0.0, 8.0, 41)
    sigma = 0.02
    problem = _fit_problem(fit.Exact(build), ts, gyro_record(ts, sigma, 1), sigma)
    res = fit.fit(problem, START, max_iter=300, gtol=1e-10)
    assert res.converged and res.success, res.message
    lap = fit.laplace(problem, res.params)
    assert lap.rank == 5 and lap.dof == 3 * 41 - 5
    assert (res.chi2, res.dof) == (pytest.approx(lap.chi2, rel=1e-12), lap.dof)
    assert abs(lap.chi2 - lap.dof) < 5 * np.sqrt(2 * lap.dof)
    m, m_sigma = fit.propagate(lambda p: fit.moment_ratios(p["shape"]), lap)
    assert bool(jnp.all(m_sigma > 0))
    assert bool(jnp.all(jnp.abs(m - TRUE_MOMENTS) < 3 * m_sigma)), (m - TRUE_MOMENTS, m_sigma)
    dw = jnp.abs(res.params["omega0"] - TRUE_OMEGA0)
    assert bool(jnp.all(dw < 3 * lap.sigma["omega0"])), (dw, lap.sigma["omega0"])
    assert "±" in lap.summary()


def test_laplace_matches_linear_regression():
    """For a model linear in θ, (JᵀJ)⁻¹ is the ordinary least-squares covariance."""
    ts = jnp.linspace(0.0, 1.0, 7)

    def model(theta, t, forward_mode=False):
        om = theta["a"][None, :] + t[:, None] * theta["b"][None, :]
        return fit.Prediction(None, om, jnp.array([1.0, 0.0, 0.0, 0.0]))

    obs = fit.Gyroscope(ts, np.zeros((7, 3)), sigma=0.3)
    lap = fit.laplace(fit.Problem(model, obs), {"a": jnp.ones(3), "b": jnp.ones(3)})
    x = np.stack([np.ones(7), np.asarray(ts)], axis=1)
    cov = 0.09 * np.linalg.inv(x.T @ x)
    np.testing.assert_allclose(lap.sigma["a"], np.sqrt(cov[0, 0]) * np.ones(3), rtol=1e-10)
    np.testing.assert_allclose(lap.sigma["b"], np.sqrt(cov[1, 1]) * np.ones(3), rtol=1e-10)


# --------------------------------------------------------------------------- driver


def _quadratic(p):
    return jnp.sum((p["x"] - jnp.arange(3.0)) ** 2 * jnp.array([1.0, 10.0, 100.0]))


@pytest.mark.parametrize("method", ["lbfgs", "adam"])
def test_driver_methods_and_stopping(method):
    kw = dict(learning_rate=0.05) if method == "adam" else {}
    res = fit.fit(_quadratic, {"x": jnp.zeros(3)}, method=method, max_iter=3000, gtol=1e-7, **kw)
    assert res.converged and res.reason in ("gtol", "ftol")
    np.testing.assert_allclose(res.params["x"], [0.0, 1.0, 2.0], atol=1e-5)
    with pytest.warns(fit.FitWarning, match="iteration limit"):
        short = fit.fit(_quadratic, {"x": jnp.zeros(3)}, method=method, max_iter=2, **kw)
    assert short.reason == "max_iter" and not short.converged and short.n_iter == 2
    assert not short.success and short.causes == ("max_iter",)


def _rosenbrock(p):
    x = p["x"]
    return jnp.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1.0 - x[:-1]) ** 2)


def _ill_conditioned_quadratic():
    """``½ (x − x*)ᵀ A (x − x*)`` in 6 dimensions, eigenvalues 1 … 1e4, rotated."""
    q, _ = np.linalg.qr(np.random.default_rng(7).standard_normal((6, 6)))
    a = jnp.asarray(q @ np.diag(np.logspace(0, 4, 6)) @ q.T)
    optimum = jnp.asarray(np.linspace(-1.0, 2.0, 6))
    return (lambda p: 0.5 * (p["x"] - optimum) @ a @ (p["x"] - optimum)), optimum


@pytest.mark.parametrize(
    "case", ["rosenbrock 2", "rosenbrock 4", "separable quadratic", "rotated quadratic"]
)
def test_lbfgs_finds_analytic_optima_to_tight_gtol(case):
    """Stopped by the gradient alone (``ftol=0``): the known optimum, to rounding."""
    if case.startswith("rosenbrock"):
        n = int(case.split()[1])
        loss, x0, optimum = _rosenbrock, jnp.array([-1.2, 1.0, -0.5, 0.3][:n]), jnp.ones(n)
    elif case == "separable quadratic":
        loss, x0, optimum = _quadratic, jnp.zeros(3), jnp.arange(3.0)
    else:
        (loss, optimum), x0 = _ill_conditioned_quadratic(), jnp.zeros(6)
    res = fit.fit(loss, {"x": x0}, gtol=1e-10, ftol=0.0, max_iter=500)
    assert res.success and res.reason == "gtol" and res.grad_norm <= 1e-10, res.message
    np.testing.assert_allclose(res.params["x"], optimum, rtol=0, atol=1e-9)
    assert res.n_iter >= (20 if case.startswith("rosenbrock") else 2)
    assert np.all(np.diff(res.history["loss"]) <= 0)  # every line search decreased the loss


def test_lbfgs_compiles_the_loss_gradient_once():
    """The line search calls one compiled ``value_and_grad`` of the loss at every trial
    point: the loss is traced once over a whole fit of many iterations, and not again for
    another start, for the horizon stages of a problem, or for another problem that
    differs only in its data."""
    traces = []

    def counted(p):
        traces.append(1)
        return _rosenbrock(p)

    res = fit.fit(counted, {"x": jnp.array([-1.2, 1.0, -0.5, 0.3])}, gtol=1e-10, ftol=0.0)
    assert res.n_iter > 30 and len(traces) == 1
    fit.fit(counted, {"x": jnp.array([0.5, -0.3, 0.2, 0.1])}, gtol=1e-10)
    assert len(traces) == 1

    loss_traces = []  # traces of the model in reverse mode, i.e. of the loss's gradient

    def wave(theta, t, forward_mode=False):
        if not forward_mode:
            loss_traces.append(1)
        om = theta["a"] * jnp.stack([jnp.cos(theta["f"] * t), jnp.sin(theta["f"] * t), 0 * t], -1)
        return fit.Prediction(None, om, jnp.array([1.0, 0.0, 0.0, 0.0]))

    ts = np.linspace(0.0, 10.0, 101)
    start = {"f": jnp.asarray(1.9), "a": jnp.asarray(0.8)}
    for seed in (0, 1):
        om = np.stack([np.cos(2.0 * ts), np.sin(2.0 * ts), 0 * ts], axis=-1)
        data = om + 0.05 * np.random.default_rng(seed).standard_normal(om.shape)
        problem = fit.Problem(wave, fit.Gyroscope(ts, data, sigma=0.05))
        res = fit.fit(problem, start, horizons=(0.25, 0.5))
        assert res.success and res.n_iter > 5 and abs(float(res.params["f"]) - 2.0) < 0.01
    assert len(loss_traces) == 1


def _white_noise(x, level):
    """A deterministic noise of size ``level`` that changes with every bit of ``x``."""
    bits = jax.lax.bitcast_convert_type(x, jnp.uint64)
    h = jnp.sum((bits * jnp.uint64(0x9E3779B97F4A7C15)) >> jnp.uint64(40))
    return level * (h % jnp.uint64(1000)).astype(jnp.float64) / 1000.0


def test_lbfgs_ends_by_ftol_where_the_loss_is_only_known_to_its_noise():
    """A loss known only to 1e-9 (as one computed by an adaptive ODE solver, which jumps
    where the solver's steps change), its gradient exact: near the minimum no step
    decreases it by more than its noise, and the line search that fails there sees it —
    the fit ends by ``ftol``, converged. (A gradient that does not match the loss stalls:
    ``tests/test_fit_verdicts.py``.)"""

    def noisy(p):
        return _rosenbrock(p) + jax.lax.stop_gradient(_white_noise(p["x"], 1e-9))

    res = fit.fit(noisy, {"x": jnp.array([-1.2, 1.0])}, gtol=1e-12, max_iter=500)
    assert res.success and res.reason == "ftol", res.message
    np.testing.assert_allclose(res.params["x"], [1.0, 1.0], rtol=0, atol=1e-6)


def test_lbfgs_line_search_backs_off_where_the_loss_is_not_finite():
    """A loss that is NaN beyond ``x = 2`` (as a failed integration makes it): the trial
    points there are rejected, and the fit converges to the optimum at 1.9."""

    def loss(p):
        x = p["x"]
        return jnp.sum((x - 1.9) ** 2) + jnp.where(jnp.all(x < 2.0), 0.0, jnp.nan)

    res = fit.fit(loss, {"x": jnp.array([-8.0, 0.0])}, learning_rate=5.0, gtol=1e-10)
    assert res.success and res.reason in ("gtol", "ftol"), res.message
    np.testing.assert_allclose(res.params["x"], [1.9, 1.9], atol=1e-6)
    assert np.all(np.isfinite(res.history["loss"]))


def test_lbfgs_line_search_shortens_its_first_step_into_a_narrow_valley(monkeypatch):
    """An ill-conditioned loss (curvatures 1 and 1e10) from a start whose steepest-descent
    minimum lies ~1e-6 along the unit direction optax's first L-BFGS step takes, 20
    halvings below the first trial step, beyond the search's 21 trials: the search is
    repeated from the minimum of a quadratic through its shortest trial, and the fit
    converges. Without the repeat it stalls at the start (as a tumbling-body fit did)."""
    from jrigid.fit import steps

    def valley(p):
        x = p["x"]
        return 0.5 * (x[0] ** 2 + 1e10 * x[1] ** 2)

    start = {"x": jnp.array([1.0, 1e-6])}
    res = fit.fit(valley, start, gtol=1e-9, max_iter=200)
    assert res.success, res.message
    np.testing.assert_allclose(res.params["x"], [0.0, 0.0], atol=1e-8)
    monkeypatch.setattr(steps, "_RESCALES", 0)
    res = fit.fit(valley, start, gtol=1e-9, max_iter=200, on_bad_fit="ignore")
    assert not res.success and res.reason == "stalled" and res.n_iter <= 1


def test_driver_progress_bar(capsys):
    res = fit.fit(_quadratic, {"x": jnp.zeros(3)}, max_iter=100, progress=True)
    assert res.converged
    assert "fit (lbfgs)" in capsys.readouterr().err


def test_driver_errors():
    with pytest.raises(ValueError, match="method"):
        fit.fit(_quadratic, {"x": jnp.zeros(3)}, method="newton")
    with pytest.raises(ValueError, match="max_iter"):
        fit.fit(_quadratic, {"x": jnp.zeros(3)}, max_iter=0)
    with pytest.raises(ValueError, match="not finite"):
        fit.fit(lambda p: jnp.sum(p["x"]) * jnp.nan, {"x": jnp.zeros(3)})


# --------------------------------------------------------------------------- bad observations


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: fit.Gyroscope(np.arange(5.0), np.full((5, 3), np.nan)), "NaN"),
        (lambda: fit.Gyroscope(np.arange(5.0), np.zeros((5, 4))), r"shape \(T, 3\)"),
        (lambda: fit.Gyroscope(np.arange(5.0), np.zeros((4, 3))), "must match"),
        (lambda: fit.Gyroscope([0.0], np.zeros((1, 3))), "too few samples"),
        (lambda: fit.Gyroscope(np.zeros((2, 2)), np.zeros((2, 3))), "1-D"),
        (lambda: fit.Gyroscope([0.0, 2.0, 1.0], np.zeros((3, 3))), "strictly increasing"),
        (lambda: fit.Gyroscope([0.0, np.nan], np.zeros((2, 3))), "non-finite"),
        (lambda: fit.Gyroscope(np.arange(3.0), np.zeros((3, 3)), sigma=0.0), "sigma"),
        (lambda: fit.Gyroscope(np.arange(3.0), np.zeros((3, 3)), sigma=np.ones(4)), "sigma"),
        (lambda: fit.Gyroscope(np.arange(3.0), np.zeros((3, 3)), frame="lab"), "frame"),
        (lambda: fit.Orientations(np.arange(3.0), np.zeros((3, 4))), "zero-length"),
        (lambda: fit.Orientations(np.arange(3.0), np.zeros((3, 3))), r"shape \(T, 4\)"),
        (lambda: fit.AxisDirections(np.arange(3.0), np.ones((3, 3)), axis=3), "axis"),
        (lambda: fit.AxisDirections(np.arange(3.0), np.full((3, 3), np.inf)), "NaN or inf"),
        (lambda: fit.AxisDirections(np.arange(3.0), np.ones((3, 3)), axis=True), "axis"),
        (lambda: fit.Gyroscope(np.arange(3.0), np.ones((3, 3)) + 0j), "must be real"),
        (lambda: fit.WobbleRatio(np.linspace(0.0, 1.0, 3), 2.0, 1.0, axis=2.0), "axis"),
        (lambda: fit.moment_ratios_raw(jnp.array([1.0, 2.0, 3.0])), "flat body"),
        (
            lambda: fit.Problem(
                fit.Exact(build), fit.Gyroscope([0.0, 1.0], np.zeros((2, 3))), t0=0.5
            ),
            "before the initial time",
        ),
        (lambda: fit.Problem(fit.Exact(build), []), "at least one observation"),
        (lambda: fit.Problem(fit.Exact(build), [np.zeros(3)]), "observations must be"),
    ],
)
def test_bad_observations_raise_clear_errors(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_union_time_grid_and_t0():
    a = fit.Gyroscope([0.5, 1.0, 2.0], np.zeros((3, 3)))
    b = fit.AxisDirections([1.0, 1.5], np.ones((2, 3)))
    problem = fit.Problem(fit.Exact(build), [a, b], t0=0.0)
    np.testing.assert_array_equal(problem.ts, [0.0, 0.5, 1.0, 1.5, 2.0])
    np.testing.assert_array_equal(problem.ts[problem.index[1]], [1.0, 1.5])
    assert problem.size == 15


def test_reference_and_space_frames_against_scipy():
    """Gyroscope and orientation records in the reference / space frame (scipy rotations)."""
    rng = np.random.default_rng(3)
    frame = Rotation.random(random_state=4)
    qs = Rotation.random(3, random_state=5)
    om = rng.standard_normal((3, 3))
    pred = fit.Prediction(
        jnp.asarray(qs.as_quat(scalar_first=True)),
        jnp.asarray(om),
        jnp.asarray(frame.as_quat(scalar_first=True)),
    )
    ts = [0.0, 1.0, 2.0]
    ref = fit.Gyroscope(ts, np.zeros((3, 3)), frame="reference").predicted(pred)
    np.testing.assert_allclose(ref, frame.apply(om), atol=1e-12)
    space = fit.Gyroscope(ts, np.zeros((3, 3)), frame="space").predicted(pred)
    np.testing.assert_allclose(space, qs.apply(om), atol=1e-12)
    q_ref = fit.Orientations(ts, np.ones((3, 4)), frame="reference").predicted(pred)
    expected = (qs * frame.inv()).as_quat(scalar_first=True)
    np.testing.assert_allclose(np.abs(np.sum(np.asarray(q_ref) * expected, axis=1)), 1.0)
    axis = fit.AxisDirections(ts, np.ones((3, 3)), axis=[1.0, 1.0, 0.0]).predicted(pred)
    np.testing.assert_allclose(axis, qs.apply(np.array([1.0, 1.0, 0.0]) / np.sqrt(2)), atol=1e-12)


def test_laplace_raw_quaternion_has_one_null_direction():
    """The norm of a raw quaternion is unobservable: rank P − 1, σ of the angle finite."""
    ts = jnp.linspace(0.0, 1.0, 5)
    q_true = jnp.asarray(Rotation.from_rotvec([0.3, -0.2, 0.5]).as_quat(scalar_first=True))

    def model(theta, t, forward_mode=False):
        q = jnp.broadcast_to(fit.unit_quaternion(theta["q"]), (t.shape[0], 4))
        return fit.Prediction(q, jnp.zeros((t.shape[0], 3)), jnp.array([1.0, 0.0, 0.0, 0.0]))

    obs = fit.Orientations(ts, np.tile(np.asarray(q_true), (5, 1)), sigma=0.01)
    lap = fit.laplace(fit.Problem(model, obs), {"q": 2.0 * q_true})
    assert lap.rank == 3
    # rotation-vector error of one axis: 5 samples of σ = 0.01 → σ/√5 per component
    _, s = fit.propagate(lambda p: fit.unit_quaternion(p["q"])[1:], lap)
    np.testing.assert_allclose(
        np.sqrt(np.sum(np.asarray(s) ** 2)), 0.5 * 0.01 / np.sqrt(5) * np.sqrt(3), rtol=0.3
    )


def test_float32_fit_recovers(float32):
    ts = jnp.linspace(0.0, 8.0, 41)
    m32, q32, w32 = (jnp.asarray(np.asarray(x), jnp.float32) for x in truth_arrays())
    _, om = exact.solve(m32, q32, w32, ts)
    problem = _fit_problem(fit.Exact(build), ts, om, 0.01)
    start = {"shape": jnp.array([0.5, 0.5]), "omega0": jnp.array([0.4, 1.9, 0.3])}
    res = fit.fit(problem, start, max_iter=300, gtol=1e-4)
    assert res.params["omega0"].dtype == jnp.float32
    m = fit.moment_ratios(res.params["shape"])
    np.testing.assert_allclose(m, np.asarray(TRUE_MOMENTS, np.float32), atol=2e-5)
    np.testing.assert_allclose(res.params["omega0"], np.asarray(TRUE_OMEGA0), atol=2e-5)
    assert fit.laplace(problem, res.params).rank == 5


def test_a_new_observation_subclasses_abstract_observation():
    """The extension point: a user's observation (here samples of ``|L|``) fits like the
    built-in ones; ``Observation`` is the same class under its former name."""
    assert fit.Observation is fit.AbstractObservation
    for kind in (fit.Gyroscope, fit.Orientations, fit.AxisDirections, fit.WobbleRatio):
        assert issubclass(kind, fit.AbstractObservation)

    class MomentumMagnitude(fit.AbstractObservation):
        ts: jax.Array
        magnitude: jax.Array

        def __init__(self, ts, magnitude):
            self.ts = fit.observations.sample_times(ts)
            self.magnitude = jnp.asarray(magnitude)

        @property
        def size(self):
            return self.ts.shape[0]

        def residuals(self, pred):
            return jnp.linalg.norm(pred.moments[None] * pred.omega, axis=-1) - self.magnitude

    ts = jnp.linspace(0.0, 1.0, 5)
    magnitude = np.full(5, float(jnp.linalg.norm(TRUE_MOMENTS * TRUE_OMEGA0)))
    problem = fit.Problem(fit.Exact(build), MomentumMagnitude(ts, magnitude))
    assert problem.size == 5
    assert float(problem.loss(truth())) < 1e-20


def test_closed_form_models_take_every_torque_free_scene_and_refuse_a_top():
    """``Exact`` follows ``Scene.torque_free``: a body in free flight under gravity rotates
    as the free rotor (same q, ω as ``exact.solve``); a top on a pivot is refused."""
    from jrigid.scene import FreeFlight, Gravity, Pivot

    ts = jnp.linspace(0.0, 2.0, 5)

    def flying(theta):
        scene, state = build(theta)
        return Scene(scene.body, FreeFlight(), (Gravity(),)), state

    pred = fit.Exact(flying)(truth(), ts)
    q, omega = exact.solve(TRUE_MOMENTS, jnp.array([1.0, 0.0, 0.0, 0.0]), TRUE_OMEGA0, ts)
    np.testing.assert_allclose(pred.omega, omega, rtol=0, atol=1e-10)
    np.testing.assert_allclose(pred.q, q, rtol=0, atol=1e-10)

    def top(theta):
        scene, state = build(theta)
        return Scene(scene.body, Pivot(), (Gravity(),)), state

    for model in (fit.Exact, fit.Invariants):
        with pytest.raises(ValueError, match="torque-free scenes"):
            model(top)(truth(), ts)
