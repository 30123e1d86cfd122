# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Inference from a gyroscope record
#
# A body tumbles freely; a gyroscope strapped to it records the body angular velocity
# `ω(t)` with noise. What are its moments of inertia, and how fast was it spinning at the
# start? This tutorial fits both with `jrigid.fit`, puts error bars on them, shows how
# to choose a start, what the fit's verdict says when a fit fails, and compares forward-
# and reverse-mode derivatives through the solver.
#
# Torque-free motion only depends on the *ratios* of the moments (scale them all and
# the motion is the same), so the parameters are the moment ratios (trace fixed to 1,
# `fit.moment_ratios`) and `ω0`: five numbers.

# %%
# %matplotlib inline
import os
import time
import warnings

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np

from jrigid import exact, fit, inertia, initial, viz
from jrigid import quaternion as quat
from jrigid.body import RigidBody
from jrigid.scene import Scene

QUICK = os.environ.get("JRIGID_DOCS_QUICK", "0") not in ("", "0", "false", "False")
SAMPLES = 41 if QUICK else 121
STARTS = 6 if QUICK else 12

# %% [markdown]
# ## A synthetic record
#
# The truth: moments ∝ (1, 2, 2.5), spun near the intermediate axis so that the body
# flips during the record (the flips are what pin the ratios down). The data come from
# the closed-form solution (`jrigid.exact.solve`) plus Gaussian noise of σ = 0.02 rad/s.

# %%
truth = jnp.array([1.0, 2.0, 2.5]) / 5.5
omega_true = jnp.array([0.3, 2.0, 0.2])
sigma = 0.02
ts = jnp.linspace(0.0, 12.0, SAMPLES)
_, omega_clean = exact.solve(truth, quat.identity(), omega_true, ts)
rng = np.random.default_rng(0)
measured = np.asarray(omega_clean) + sigma * rng.standard_normal(omega_clean.shape)

# %% [markdown]
# ## The problem
#
# A fit needs a function from raw, unconstrained parameters to a scene and an initial
# state. `fit.moment_ratios` maps any two real numbers to physical moment ratios (the
# triangle inequality holds everywhere), so the optimiser can roam freely. The forward
# model is `fit.Exact` (the closed form; fast) or `fit.Simulated` (`jrigid.simulate`;
# needed as soon as there is a torque). `fit.Gyroscope` compares the predicted body
# `ω` with the record.


# %%
def build(theta):
    body = RigidBody(fit.moment_ratios(theta["shape"]))
    return Scene(body), initial.from_omega(None, theta["omega0"])


problem = fit.Problem(fit.Exact(build), fit.Gyroscope(ts, measured, sigma=sigma))

# %% [markdown]
# ## A good start, a fit, error bars
#
# Start where the model is not degenerate and near the data: the initial spin from the
# first gyroscope sample (a gyroscope measures `ω(0)` directly), and the proportions of
# a box of roughly the right shape — *not* a sphere or a symmetric body, whose motion
# depends on the shape only through degenerate limits — *with its axes in the right
# order*. Here the record says which is which: the body spins about axis 2 and turns over
# (the intermediate axis), and axis 1 wobbles most (the smallest moment). A box with its
# longest side along axis 1 and its shortest along axis 3 has moments in that order.

# %%
guess = inertia.box(1.0, 2.0, 1.5, 1.0)  # sides along body axes 1, 2, 3
print("moments of the guessed box:", np.asarray(guess))
start = {
    "shape": fit.moment_ratios_raw(guess),
    "omega0": jnp.asarray(measured[0]),
}
t0 = time.perf_counter()
result = fit.fit(problem, start, method="lm")
print(f"fit in {time.perf_counter() - t0:.1f} s (compilation included)")
print(f"success={result.success}, χ²/dof = {result.chi2_dof:.3f} (dof {result.dof}), p = {result.p_value:.2f}")
print(result.message)

# %% [markdown]
# `fit.laplace` gives the Gauss–Newton covariance at the optimum; `fit.propagate`
# carries it through any function of the parameters, here to the moment ratios
# themselves (the delta method). Every estimate should sit within a few σ of the truth.

# %%
lap = fit.laplace(problem, result.params)
ratios, ratios_sigma = fit.propagate(lambda p: fit.moment_ratios(p["shape"]), lap)
omega0, omega0_sigma = result.params["omega0"], lap.sigma["omega0"]
names = ["I1/tr", "I2/tr", "I3/tr", "ω0₁", "ω0₂", "ω0₃"]
estimate = np.concatenate([ratios, omega0])
error_bar = np.concatenate([ratios_sigma, omega0_sigma])
reference = np.concatenate([truth, omega_true])
for n, e, s, r in zip(names, estimate, error_bar, reference, strict=True):
    print(f"{n:6s} {e:9.5f} ± {s:.5f}   truth {r:.5f}   ({(e - r) / s:+.1f} σ)")

# %%
fig = viz.new_figure(figsize=(12, 4.2), dpi=110)
ax = fig.add_subplot(1, 2, 1)
viz.plot_estimates(names, estimate, reference, error_bar, ax=ax)
ax.set_ylabel("(estimate − truth) / σ (dimensionless)")
ax.set_title("each estimate's distance from the truth, in error bars")
ax = fig.add_subplot(1, 2, 2)
prediction = problem.predict(result.params)
for k in range(3):
    ax.plot(ts, measured[:, k], ".", color=f"C{k}", ms=4, label=f"gyroscope ω{k + 1}")
    ax.plot(problem.ts, prediction.omega[:, k], "-", color=f"C{k}", lw=1)
ax.set_xlabel("t (s)")
ax.set_ylabel("body ω (rad/s)")
ax.set_title("record (dots) and the fitted motion (lines)")
ax.legend(fontsize=8, ncols=3)
fig

# %% [markdown]
# ## When a fit fails, it says so
#
# The loss of a long record of rotation has many local minima, and from a far start a
# local optimiser often walks to the edge of the physical region (a rod or a flat body,
# where a moment ratio reaches the triangle inequality). A stopped optimiser is not a good
# fit: `fit.fit` judges its end point and sets `success`, `message` and `causes`, and warns
# with a `fit.FitWarning` (or raises `fit.FitError` with `on_bad_fit="raise"`) when
#
# - χ² is improbable for the given noise (`p_value` below `chi2_alpha`): `"chi2"`;
# - the body is on the edge of the physical region: `"edge"`;
# - the Jacobian is rank-deficient, the data do not determine some combination: `"rank"`;
# - the optimiser stopped short: `"max_iter"`, `"stalled"`, `"nonfinite"`, `"not_stationary"`.
#
# The same box with its axes in the wrong order (longest side along axis 3) is such a
# start:

# %%
wrong = {"shape": fit.moment_ratios_raw(inertia.box(1.0, 1.0, 1.5, 2.0)), "omega0": jnp.asarray(measured[0])}
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always", fit.FitWarning)
    bad = fit.fit(problem, wrong, method="lm")
print(f"success={bad.success}, causes={bad.causes}, χ²/dof = {bad.chi2_dof:.0f}")
print("moments reached:", np.asarray(fit.moment_ratios(bad.params["shape"])))
print("\nFitWarning:", caught[0].message if caught else "(none)")

# %% [markdown]
# More far starts: random raw shapes and a perturbed `ω0`.

# %%
start_rng = np.random.default_rng(1)
far_starts = [
    {
        "shape": jnp.asarray(start_rng.normal(0.0, 2.0, size=2)),
        "omega0": jnp.asarray(measured[0] + start_rng.normal(0.0, 1.0, size=3)),
    }
    for _ in range(STARTS)
]


def attempt(start, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", fit.FitWarning)
        r = fit.fit(problem, start, method="lm", **kwargs)
    return r, [w for w in caught if issubclass(w.category, fit.FitWarning)]


plain = [attempt(s) for s in far_starts]
for i, (r, _) in enumerate(plain):
    print(f"start {i}: success={r.success!s:5}  χ²/dof={r.chi2_dof:9.2f}  causes={r.causes}")

# %% [markdown]
# The remedy is not a cleverer optimiser but a gentler loss: a short record's loss is
# nearly quadratic over a much wider region. `horizons=(0.25, 0.5)` fits the first
# quarter of the record, then the first half, each from the previous optimum, then the
# whole record (nothing recompiles: `Problem.until` zeroes the later residuals).

# %%
grown = [attempt(s, horizons=(0.25, 0.5)) for s in far_starts]
for i, ((r0, _), (r1, _)) in enumerate(zip(plain, grown, strict=True)):
    print(f"start {i}: plain success={r0.success!s:5}  with horizons success={r1.success!s:5}  χ²/dof={r1.chi2_dof:.2f}")
print(f"\nsuccesses: {sum(r.success for r, _ in plain)}/{STARTS} plain, "
      f"{sum(r.success for r, _ in grown)}/{STARTS} with horizons")

# %%
fig = viz.new_figure(figsize=(12, 4), dpi=110)
ax = fig.add_subplot(1, 1, 1)
x = np.arange(STARTS)
ax.semilogy(x - 0.1, [r.chi2_dof for r, _ in plain], "o", label="whole record at once")
ax.semilogy(x + 0.1, [r.chi2_dof for r, _ in grown], "s", label="growing record, horizons=(0.25, 0.5)")
for i, (r, _) in enumerate(plain):
    if not r.success:
        ax.annotate(",".join(r.causes), (i - 0.1, r.chi2_dof), fontsize=8, xytext=(4, 4),
                    textcoords="offset points")
ax.axhline(1.0, color="0.5", lw=0.8, ls="--")
ax.set_xticks(x)
ax.set_xlabel("far start (index)")
ax.set_ylabel("χ²/dof at the end point (dimensionless)")
ax.set_title("far starts: where the fit ended, and why the verdict rejected it")
ax.legend()
fig

# %% [markdown]
# ## Forward against reverse mode
#
# Two ways to differentiate through the model:
#
# - **reverse mode** (`jax.grad`): one backward pass per scalar output, whatever the
#   number of parameters. L-BFGS (`method="lbfgs"`, the default) and Adam use it on the
#   loss `½ Σ r²`.
# - **forward mode** (`jax.jacfwd`): one tangent per parameter, carried along with the
#   solution. For five parameters it gives the whole Jacobian of the 3 × `SAMPLES`
#   residuals at about the price of one gradient; Levenberg–Marquardt (`method="lm"`) and
#   the error bars use it. Through `jrigid.simulate` (model `fit.Simulated`) forward mode
#   needs `diffrax.ForwardMode`, which `Problem.residuals(..., forward_mode=True)` selects.
#
# Both give the same gradient `Jᵀ r`:

# %%
@jax.jit
def forward_gradient(theta):
    residuals = lambda t: problem.residuals(t, forward_mode=True)  # noqa: E731
    r, jac = residuals(theta), jax.jacfwd(residuals)(theta)
    return jax.tree.map(lambda j: jnp.tensordot(r, j, axes=1), jac)


p = start  # away from the optimum, where the gradient is large
g_reverse = jax.jit(jax.grad(problem.loss))(p)
g_forward = forward_gradient(p)
for key in p:
    print(f"{key:7s} reverse {np.asarray(g_reverse[key])}\n        forward {np.asarray(g_forward[key])}")

# %% [markdown]
# and the two families of optimiser reach the same optimum from the same start;
# Levenberg–Marquardt, stepping on the Gauss–Newton model built from the forward-mode
# Jacobian, needs far fewer iterations. (Measured through `jrigid.simulate` for records of
# several lengths: [Benchmarks, gradients through a fit](../../benchmarks/#gradients-through-a-fit).)

# %%
for method in ("lm", "lbfgs"):
    t0 = time.perf_counter()
    r = fit.fit(problem, start, method=method, max_iter=500)
    print(f"{method:6s}: success={r.success}, {r.n_iter:3d} iterations, {time.perf_counter() - t0:5.1f} s "
          f"(wall time), ratios {np.round(np.asarray(fit.moment_ratios(r.params['shape'])), 5)}")
