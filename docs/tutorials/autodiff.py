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
# # Teaching autodiff through ODEs
#
# How does the final orientation of a tumbling body change when its moments of inertia
# change? This tutorial computes the Jacobian `∂q(D)/∂I` (4 × 3) four ways side by side:
#
# - **reverse mode**, `jax.jacrev` through `jrigid.simulate` (diffrax's
#   `RecursiveCheckpointAdjoint`: the backward pass recomputes forward steps from stored
#   checkpoints);
# - **forward mode**, `jax.jacfwd` with `diffrax.ForwardMode()` (one tangent per moment,
#   carried along with the solve);
# - **central finite differences** of the simulated `q(D)`;
# - the **exact** derivative, `jax.jacfwd` through the closed-form solution
#   (`jrigid.exact.solve`, Jacobi elliptic functions): no discretisation at all.
#
# Then it shows how the sensitivity grows as the spin approaches the separatrix, where
# the time between flips, and with it every derivative, grows like `log(1/ε)`.

# %%
# %matplotlib inline
import os
import time

import diffrax
import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np

import jrigid
from jrigid import exact, initial, viz
from jrigid import quaternion as quat

QUICK = os.environ.get("JRIGID_DOCS_QUICK", "0") not in ("", "0", "false", "False")
EPSILONS = np.logspace(-1, -6, 6 if QUICK else 16)


def f64(x):
    """A float64 array. (A Python float would be "weakly typed" and a numpy one not: a
    jitted function called with both compiles twice.)"""
    return jnp.asarray(x, dtype=jnp.float64)

# %% [markdown]
# ## The motion
#
# Moments `I = (1, 2, 2.5)`, spun close to the intermediate axis, `ω0 = (ε, 1, ε)` with
# `ε = 0.05`: the body flips every half period `T/2`. We look at the orientation at
# `D = 1.25 T`, after its second flip and before its third, where it is sensitive.

# %%
moments = jnp.array([1.0, 2.0, 2.5])


def omega0(eps):
    return jnp.stack([eps, jnp.ones_like(eps), eps])


def period(eps):
    return exact.omega_period(exact.prepare(moments, quat.identity(), omega0(eps)))


eps = f64(0.05)
D = 1.25 * period(eps)
print(f"period of ω: {float(period(eps)):.4f} s; D = {float(D):.4f} s")


def final_q(moments, eps, D, rtol, adjoint=None):
    """q(D) by jrigid.simulate (its default adaptive pair, atol = rtol / 100)."""
    scene = jrigid.Scene(jrigid.RigidBody(moments))
    traj = jrigid.simulate(scene, initial.from_omega(None, omega0(eps)), jnp.stack([0.0, D]),
                           rtol=rtol, atol=rtol / 100, adjoint=adjoint)
    return traj.q[-1]


def final_q_exact(moments, eps, D):
    """q(D) from the closed form."""
    q, _ = exact.solve(moments, quat.identity(), omega0(eps), jnp.stack([0.0, D]))
    return q[-1]


# %% [markdown]
# ## Four Jacobians
#
# Each is compiled once (`jax.jit`; the tolerance, `ε` and `D` are traced inputs, so
# later calls with other values reuse the program) and then timed. Finite differences
# take six solves (`± h` per moment) at a tight tolerance; their step `h = 10⁻⁵` balances
# truncation (`∝ h²`) against the solver's error divided by `h`.

# %%
jac_exact = jax.jit(jax.jacfwd(final_q_exact))
jac_reverse = jax.jit(jax.jacrev(final_q))
jac_forward = jax.jit(jax.jacfwd(lambda m, e, d, r: final_q(m, e, d, r, adjoint=diffrax.ForwardMode())))
solve = jax.jit(final_q)


def finite_differences(m, eps, D, h=1e-5):
    tight = f64(1e-13)
    cols = [(solve(m + h * e, eps, D, tight) - solve(m - h * e, eps, D, tight)) / (2 * h) for e in jnp.eye(3)]
    return jnp.stack(cols, axis=-1)


rtol = f64(1e-10)
methods = {
    "exact (closed form)": lambda m: jac_exact(m, eps, D),
    "reverse mode": lambda m: jac_reverse(m, eps, D, rtol),
    "forward mode": lambda m: jac_forward(m, eps, D, rtol),
    "finite differences": lambda m: finite_differences(m, eps, D),
}
jacobians, times = {}, {}
for name, fn in methods.items():
    t0 = time.perf_counter()
    jacobians[name] = jax.block_until_ready(fn(moments))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    jax.block_until_ready(fn(moments))
    times[name] = (first, time.perf_counter() - t0)
reference = jacobians["exact (closed form)"]
print(f"{'method':22s} {'first call':>10s} {'then':>9s}  {'max |J − J_exact|':>18s}  {'|Σ I_k ∂q/∂I_k|':>16s}")
for name, J in jacobians.items():
    euler = float(jnp.max(jnp.abs(J @ moments)))  # degree-0 homogeneity: must vanish
    print(f"{name:22s} {times[name][0]:9.1f}s {1e3 * times[name][1]:7.1f}ms  "
          f"{float(jnp.max(jnp.abs(J - reference))):18.2e}  {euler:16.1e}")
gap = float(jnp.max(jnp.abs(jacobians["reverse mode"] - jacobians["forward mode"])))
print(f"reverse against forward mode: {gap:.1e}")

# %% [markdown]
# Reverse and forward mode differentiate the *discretised* solve (diffrax holds the step
# sizes fixed), so they can only approach the exact derivative as the tolerance shrinks; finite
# differences are limited by the step `h`. Torque-free motion only sees the moment
# *ratios*, so `Σ_k I_k ∂q/∂I_k = 0` (Euler's theorem for a function homogeneous of
# degree zero): every method passes this check to its own accuracy.
#
# How the distance to the exact Jacobian falls with the tolerance, next to the error of
# the solution itself (same compiled programs, other `rtol`):

# %%
rtols = np.logspace(-4, -12, 3 if QUICK else 9)
q_exact = final_q_exact(moments, eps, D)
err_rev = [float(jnp.max(jnp.abs(jac_reverse(moments, eps, D, f64(r)) - reference))) for r in rtols]
err_fwd = [float(jnp.max(jnp.abs(jac_forward(moments, eps, D, f64(r)) - reference))) for r in rtols]
err_q = [float(quat.distance(solve(moments, eps, D, f64(r)), q_exact)) for r in rtols]

fig = viz.new_figure(figsize=(12, 4.2), dpi=110)
ax = fig.add_subplot(1, 1, 1)
ax.loglog(rtols, err_rev, "o-", label="reverse mode: max |J − J_exact|")
ax.loglog(rtols, err_fwd, "x--", ms=9, label="forward mode: max |J − J_exact|")
ax.loglog(rtols, err_q, "s:", label="the solution itself: angle between q(D) and the exact q(D) (rad)")
ax.set_xlabel("relative tolerance rtol (dimensionless)")
ax.set_ylabel("error (per unit of moment; rad)")
ax.invert_xaxis()
ax.legend()
ax.set_title("derivatives of the discretised solve converge with it")
print(f"at rtol {rtols[-1]:.0e}: reverse {err_rev[-1]:.1e}, forward {err_fwd[-1]:.1e} from the exact Jacobian")
fig

# %% [markdown]
# Both modes follow the solution all the way down: they differentiate the same discrete
# steps, so they agree with each other to far below the error they share with the exact
# Jacobian. For a handful of parameters forward mode is the cheap choice, for many
# parameters (a loss over a whole trajectory) reverse mode.

# %% [markdown]
# ## Sensitivity near the separatrix
#
# As `ε → 0` the spin approaches the separatrix through the intermediate axis: the time
# between flips grows like `log(1/ε)`, and a small change of the moments shifts every
# flip by an amount that grows with the flip time. The exact Jacobian (the same compiled
# program, other `ε` and `D`) measures it; for a unit quaternion `2‖∂q/∂I_k‖` is the angle
# the final orientation turns per unit change of `I_k`, and the final time follows the
# flips, `D = 1.25 T(ε)`.

# %%
T_eps, S_eps = [], []
for e in EPSILONS:
    T = period(f64(e))
    J = jac_exact(moments, f64(e), 1.25 * T)
    T_eps.append(float(T))
    S_eps.append(2 * float(jnp.linalg.norm(J)))

fig = viz.new_figure(figsize=(12, 4.2), dpi=110)
ax = fig.add_subplot(1, 2, 1)
ax.semilogx(EPSILONS, T_eps, "o-")
ax.set_xlabel("ε, tilt of ω0 from the intermediate axis (rad/s)")
ax.set_ylabel("period of ω, T (s)")
ax.invert_xaxis()
ax.set_title("the period grows like log(1/ε)")
ax = fig.add_subplot(1, 2, 2)
ax.plot(T_eps, S_eps, "o-")
ax.set_xlabel("period of ω, T (s)")
ax.set_ylabel("rotation of q(1.25 T) per unit moment (rad)")
ax.set_title("and the sensitivity with it")
fig

# %% [markdown]
# The sensitivity grows with the flip time, hence only like `log(1/ε)`: gradients
# through a near-separatrix record are large but finite, and a fit can use them. What
# breaks first near the separatrix is the *forward* solve in low precision — see
# [Choosing a solver](../choosing_a_solver/).
