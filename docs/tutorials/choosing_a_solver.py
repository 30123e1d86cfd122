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
# # Choosing a solver
#
# `jrigid.simulate` takes a formulation (which variables are integrated), a diffrax
# solver and tolerances; for torque-free bodies `solver="exact"` evaluates the closed form
# instead. This tutorial measures speed against error on two hard cases — a long
# horizon and a spin near the separatrix — says when to use the exact solver, and shows
# what float32 can and cannot do. The full comparison, with scipy and MuJoCo, is on the
# [benchmarks page](../../benchmarks/).
#
# Errors are always measured against the closed form (`jrigid.exact`), never against the
# method itself at a tighter tolerance.

# %%
# %matplotlib inline
import os
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np

import jrigid
from jrigid import exact, initial, stability, viz
from jrigid import quaternion as quat
from jrigid.solvers import FusedDop853

QUICK = os.environ.get("JRIGID_DOCS_QUICK", "0") not in ("", "0", "false", "False")
RTOLS = np.logspace(-4, -12, 5 if QUICK else 9)
PERIODS = 30 if QUICK else 100

# %% [markdown]
# ## Speed against error on a long horizon
#
# An asymmetric body (1, 2, 3) with `ω0 = (1, 0.3, 0.7)`, integrated over `PERIODS`
# periods of its motion. The error is the worst of the relative `ω` error and the
# rotation angle between the computed and the exact orientation at the end. Three
# configurations:
#
# - the default: Euler's equations in quaternion-acceleration form (17.50) with Hairer's
#   8th-order DOP853 pair (`jrigid.solvers.TightDop853`), with projection onto the
#   constraints and invariants after every step;
# - `formulation="quaternion_omega"` with the same pair, its stages written out
#   (`FusedDop853`), and the same projection;
# - the exact solver.
#
# Tolerances are traced inputs, so one compiled program per configuration serves the
# whole sweep; times are medians of three runs after compilation (on a shared machine
# they are noisy: the benchmarks page has careful ones).

# %%
moments = jnp.array([1.0, 2.0, 3.0])
omega_0 = jnp.array([1.0, 0.3, 0.7])
scene = jrigid.Scene(jrigid.RigidBody(moments))
state = initial.from_omega(omega=omega_0)
period = float(exact.omega_period(exact.prepare(moments, quat.identity(), omega_0)))
ts = jnp.array([0.0, PERIODS * period])
q_ref, w_ref = exact.solve(moments, quat.identity(), omega_0, ts)


def error(traj):
    w_err = jnp.linalg.norm(traj.omega[-1] - w_ref[-1]) / jnp.linalg.norm(w_ref[-1])
    return float(jnp.maximum(w_err, quat.distance(traj.q[-1], q_ref[-1])))


def timed(fn, *args):
    out = jax.block_until_ready(fn(*args))
    runs = []
    for _ in range(3):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        runs.append(time.perf_counter() - t0)
    return out, float(np.median(runs))


configurations = {
    "default (quaternion_acceleration + DOP853)": {},
    "quaternion_omega + DOP853": {"formulation": "quaternion_omega", "solver": FusedDop853()},
}
sweeps = {}
for name, options in configurations.items():
    run = jax.jit(lambda rtol, o=options: jrigid.simulate(scene, state, ts, rtol=rtol, atol=rtol / 100, **o))
    t0 = time.perf_counter()
    jax.block_until_ready(run(jnp.asarray(RTOLS[0])))
    print(f"{name}: compiled in {time.perf_counter() - t0:.1f} s")
    points = []
    for rtol in RTOLS:
        traj, seconds = timed(run, jnp.asarray(rtol))
        points.append((rtol, error(traj), seconds, int(traj.stats["num_steps"])))
    sweeps[name] = points
run_exact = jax.jit(lambda: jrigid.simulate(scene, state, ts, solver="exact"))
traj, exact_seconds = timed(run_exact)
exact_error = error(traj)
for name, points in sweeps.items():
    print(f"\n{name}\n  rtol      error     time      steps")
    for rtol, err, sec, steps in points:
        print(f"  {rtol:7.0e}  {err:8.1e}  {1e3 * sec:7.2f} ms  {steps:6d}")
print(f"\nexact solver: error {exact_error:.1e} in {1e6 * exact_seconds:.0f} µs")

# %%
fig = viz.new_figure(figsize=(12, 4.5), dpi=110)
ax = fig.add_subplot(1, 1, 1)
for (name, points), marker in zip(sweeps.items(), "os", strict=True):
    err = [max(p[1], 1e-16) for p in points]
    ax.loglog(err, [1e3 * p[2] for p in points], marker + "-", label=name)
    for rtol, e, sec, _ in points[:: 2]:
        ax.annotate(f"{rtol:.0e}", (max(e, 1e-16), 1e3 * sec), fontsize=7, xytext=(3, 3),
                    textcoords="offset points")
ax.loglog([max(exact_error, 1e-16)], [1e3 * exact_seconds], "k*", ms=14, label="exact solver")
ax.set_xlabel("final error (relative ω; rotation angle in rad)")
ax.set_ylabel("time after compilation (ms)")
ax.invert_xaxis()
ax.set_title(f"free rotor (1, 2, 3), {PERIODS} periods: labels are rtol")
ax.legend()
fig

# %% [markdown]
# What this shows, and what the benchmarks confirm on more cases:
#
# - The two curves lie close together: with the same pair, the second-order form needs
#   1.1–1.2× the steps of `(q, ω)` for the same error on this body (on the benchmarks
#   page: up to 1.5× near the intermediate axis, and 0.65× on a heavy top, where the
#   second-order form is the faster). The default handles every scene (torques, pivots,
#   free flight) with no option to choose.
# - The exact solver is exact to rounding and costs the same at any horizon: for a
#   torque-free body there is no reason to integrate at all, except to study
#   integrators.
#
# ## Near the separatrix
#
# Spun at `ω0 = (ε, 1, ε)` about the middle axis of (1, 2, 2.5), the body flips every
# `2K(m)/λ`. Near the separatrix an energy error `δ` moves the orbit across it, and the
# flip time is shifted by about `δ/ε²`: the integrator must resolve energy far below
# `ε²`. The default projects the state back onto the conserved energy and `|L|` after
# every step (`jrigid.invariants`), so in float64 the orbit cannot drift across: the time
# between flips (from samples of `ω2`) stays within the tolerance of the closed form even
# at `ε = 1e-6`.

# %%
sep_moments = jnp.array([1.0, 2.0, 2.5])
sep_scene = jrigid.Scene(jrigid.RigidBody(sep_moments))
epsilons = [1e-2, 1e-4, 1e-6]
samples = 2001 if QUICK else 4001


@jax.jit
def flip_interval(eps, rtol):
    w0 = jnp.stack([eps, jnp.ones_like(eps), eps])
    T = exact.omega_period(exact.prepare(sep_moments, quat.identity(), w0))
    ts = jnp.linspace(0.0, 4 * T, samples)
    traj = jrigid.simulate(sep_scene, initial.from_omega(None, w0), ts, rtol=rtol, atol=rtol / 100,
                           throw=False, max_steps=200_000)
    interval, count = stability.flip_interval(ts, traj.omega[:, 1])
    return interval, count, T / 2


print("  ε       rtol    flips  interval/exact − 1")
for eps in epsilons:
    for rtol in (1e-6, 1e-10):
        interval, count, truth = flip_interval(jnp.asarray(eps), jnp.asarray(rtol))
        print(f"  {eps:6.0e}  {rtol:6.0e}  {int(count):4d}   {float(interval / truth - 1):+.2e}")

# %% [markdown]
# ## What float32 can and cannot do
#
# Every jrigid function runs in float32, and on a GPU float32 is much faster. What limits
# it:
#
# 1. **Phase error on long horizons.** The relative error of a step is at least
#    `eps = 1.2e-7`; over many periods the phase error accumulates with the number of
#    steps. The smallest tolerance float32 accepts is `rtol = 10 eps ≈ 1.2e-6`.
# 2. **The separatrix.** An energy rounding of `δ ≈ 1e-7` would carry the orbit across
#    the separatrix once `ε² < δ` (`ε ≲ 3e-4`) and change the flip time by order one. The
#    default's projection onto the conserved energy and `|L|` after every step keeps
#    the orbit on its side: measured below, the flip intervals stay within about `1e-6`
#    of the closed form down to `ε = 1e-3`, and then grow as the separatrix nears (about
#    `2e-5` at `ε = 3e-4`, `2e-4` at `ε = 1e-4`), still far from an error of order one.
# 3. **The time itself.** Near `t = 10⁴` float32 times are `1e-3` apart: over 10⁴
#    periods an adaptive solver cannot advance its step any more
#    (`Result.step_size_collapse`, see the [benchmarks](../../benchmarks/)), and even the
#    exact solver's error is the rounding of `t` (the last column below).
#
# JAX decides the precision globally; we switch x64 off for the next cell and back on
# after it. (Arrays created before keep their dtype, so everything below is built anew.)

# %%
jax.config.update("jax_enable_x64", False)
rows = []
for periods in (10, 100, 1000):
    ts32 = jnp.array([0.0, periods * period], dtype=jnp.float32)
    st32 = initial.from_omega(omega=jnp.asarray(omega_0, dtype=jnp.float32))
    sc32 = jrigid.Scene(jrigid.RigidBody(jnp.asarray(moments, dtype=jnp.float32)))
    integrated = jrigid.simulate(sc32, st32, ts32, rtol=1e-5, atol=1e-7, throw=False, max_steps=200_000)
    closed = jrigid.simulate(sc32, st32, ts32, solver="exact")
    rows.append((periods, integrated, closed))
sep32 = []
for eps in (1e-2, 1e-3, 3e-4, 1e-4):
    w0 = jnp.array([eps, 1.0, eps], dtype=jnp.float32)
    T = float(exact.omega_period(exact.prepare(jnp.asarray(sep_moments, dtype=jnp.float32), quat.identity(dtype=jnp.float32), w0)))
    ts32 = jnp.linspace(0.0, 4 * T, 4001, dtype=jnp.float32)
    traj = jrigid.simulate(jrigid.Scene(jrigid.RigidBody(jnp.asarray(sep_moments, dtype=jnp.float32))),
                           initial.from_omega(omega=w0), ts32, rtol=1e-5, atol=1e-7, throw=False, max_steps=200_000)
    sep32.append((eps, *(np.asarray(x) for x in stability.flip_interval(ts32, traj.omega[:, 1])),
                   jrigid.Result(int(traj.result)).name))
jax.config.update("jax_enable_x64", True)

print("free rotor in float32 (rtol 1e-5):")
print("  periods  integrated: result, error             exact solver: error")


def error_against(tr, q_ref, w_ref):
    """Like error() above, for a float32 trajectory against a float64 reference."""
    q, w = jnp.asarray(tr.q[-1], jnp.float64), jnp.asarray(tr.omega[-1], jnp.float64)
    w_err = jnp.linalg.norm(w - w_ref) / jnp.linalg.norm(w_ref)
    return float(jnp.maximum(w_err, quat.distance(q, q_ref)))


for periods, integrated, closed in rows:
    q64, w64 = exact.solve(moments, quat.identity(), omega_0, jnp.array([0.0, periods * period]))
    name = jrigid.Result(int(integrated.result)).name
    print(f"  {periods:6d}   {name:20s} {error_against(integrated, q64[-1], w64[-1]):9.1e}"
          f"      {error_against(closed, q64[-1], w64[-1]):9.1e}")

# %%
print("near the separatrix in float32 (rtol 1e-5, the smallest float32 allows is 10 eps = 1.2e-6):")
print("  ε       flips  interval/exact − 1   result")
for eps, interval, count, name in sep32:
    w0 = jnp.array([eps, 1.0, eps])
    truth = float(exact.omega_period(exact.prepare(sep_moments, quat.identity(), w0))) / 2
    print(f"  {eps:6.0e}  {int(count):4d}   {float(interval) / truth - 1:+10.2e}        {name}")

# %% [markdown]
# ## Rules of thumb
#
# | situation | use |
# | --- | --- |
# | torque-free body, any horizon | `simulate(..., solver="exact")` (or `jrigid.exact` directly): exact to rounding, about 1 µs per output time, differentiable |
# | torques, pivots, gravity, free flight; the general case | the default (`quaternion_acceleration` + DOP853, projected) |
# | the most speed per digit near an intermediate-axis flip | `formulation="quaternion_omega"` (same pair; 1.2–1.5× fewer steps there) |
# | orientation not needed | `formulation="body_omega"` (ω only; cheapest) |
# | Euler angles wanted as variables | `formulation="euler_angles"`: reports gimbal lock instead of returning garbage |
# | float32 | errors of `1e-4`–`1e-2` over tens to thousands of periods; keep the default projection; check against a float64 run once |
# | many members | `jrigid.ensemble.simulate_many`, with `shared_step=True` for throughput on a CPU |
