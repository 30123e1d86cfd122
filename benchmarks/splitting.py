"""Splitting integrators and the heavy top in closed form: orders, long-run invariants, cost.

Measured on this machine, each against a reference that is not the method under test:

1. **Orders.** The final-state error (worst of relative ω and sign-invariant q) of every
   composition of :mod:`jrigid.splitting` at four step sizes on a symmetric heavy top
   against its closed form (:mod:`jrigid.lagrange_top`); the order is the slope of log
   error against log step.
2. **No drift.** An asymmetric top on a pivot (moments (1.25, 1.75, 2) about the pivot,
   so only the energy and the momentum along gravity are conserved), Strang at
   h = 0.01 for 10⁶ steps (10⁴ time units): the largest energy error (over the kinetic
   energy) in the first and in the second half of the run, and the largest change of
   ``L·ĝ`` (over ``|L|``). Beside it, over the same run: diffrax Tsit5 on the (q, ω)
   equations without invariant projection (``project="manifold"``) and scipy DOP853, at
   rtol 1e-8, whose energy error drifts. jrigid's default is not in this row: it projects
   onto these two invariants after every step, so their error is rounding by
   construction.
3. **The closed form's cost.** ``jrigid.lagrange_top``: time per call after compilation
   for 1 and 1000 output times, at a horizon of 10 and of 10⁶ nutation periods (its cost
   does not depend on the horizon), and its agreement with scipy DOP853 at rtol 1e-13 over
   100 nutation periods. Its accuracy against a 30-digit reference is tested in
   ``tests/test_lagrange_top.py``.

Usage::

    python benchmarks/splitting.py            # ~3 min on 2 cores
    python benchmarks/splitting.py --quick    # 10⁵ steps in part 2, ~1 min

Writes ``splitting[_quick].json`` and ``.md`` to ``benchmarks/results/`` (or ``--out``).
"""

from __future__ import annotations

import math
import pathlib
import sys
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp
from scipy.stats import linregress

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import harness  # noqa: E402

from jrigid import lagrange_top  # noqa: E402
from jrigid import quaternion as quat  # noqa: E402
from jrigid.integrate import simulate  # noqa: E402
from jrigid.splitting import COMPOSITIONS, Splitting  # noqa: E402
from jrigid.state import Kinematics  # noqa: E402

ORDER_T = 30.0
ORDER_STEPS = {  # coarse to fine, inside each method's asymptotic range and above rounding
    "strang": (0.02, 0.01, 0.005, 0.0025),
    "yoshida4": (0.1, 0.05, 0.025, 0.0125),
    "suzuki4": (0.1, 0.05, 0.03, 0.015),
    "kahan_li6": (0.3, 0.15, 0.1, 0.05),
    "kahan_li8": (0.3, 0.2, 0.15, 0.1),
}
DRIFT_H = 0.01
DRIFT_RTOL = 1e-8
# A symmetric top (the closed form applies) and an asymmetric one (moments about the pivot
# (1.25, 1.75, 2): only the energy and L·ĝ are conserved), both released with a spin.
SYMMETRIC = harness.Problem("symmetric", "symmetric top", (1.0, 1.0, 1.5), euler0=(0.0, 0.5, 0.0),
                        rates0=(0.0, 0.0, 4.0), com=(0.0, 0.0, 1.0), g=1.0, t1=ORDER_T)
ASYMMETRIC = harness.Problem("asymmetric", "asymmetric top", (1.0, 1.5, 2.0),
                         euler0=(0.0, 0.5, 0.0), rates0=(0.3, 0.0, 3.0), com=(0.0, 0.0, 0.5),
                         g=1.0)


def _final_error(q, w, q_ref, w_ref) -> float:
    return max(harness.omega_error(w, w_ref), harness.quaternion_error(q, q_ref))


def _closed_form(problem: harness.Problem, ts):
    """``jrigid.lagrange_top.solve`` for the problem's scene and state at ``ts``."""
    scene, state = problem.scene(), problem.state()
    b = scene.body
    return lagrange_top.solve(b.moments, b.mass, b.com, lagrange_top.scene_gravity(scene),
                              state.q, state.omega, jnp.asarray(ts))


def _dop853(problem: harness.Problem, ts, rtol: float):
    """scipy DOP853 on the problem's numpy (q, ω) equations: ``(q, ω, seconds, nfev)``."""
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy raises rtol below 100 eps and says so
        sol = solve_ivp(problem.numpy_rhs(), (0.0, float(ts[-1])), problem.y0(), method="DOP853",
                        rtol=rtol, atol=min(1e-2 * rtol, 1e-15) if rtol < 1e-12 else 1e-2 * rtol,
                        t_eval=np.asarray(ts))
    seconds = time.perf_counter() - start
    q = sol.y[:4].T / np.linalg.norm(sol.y[:4].T, axis=-1, keepdims=True)
    return q, sol.y[4:].T, seconds, int(sol.nfev)


def orders() -> dict:
    """Part 1: ``{method: {"order", "slope", "steps", "errors"}}`` on the symmetric top."""
    ts = jnp.array([0.0, ORDER_T])
    q_ref, w_ref = _closed_form(SYMMETRIC, ts)
    scene, state = SYMMETRIC.scene(), SYMMETRIC.state()
    out = {}
    for method, dts in ORDER_STEPS.items():
        run = jax.jit(lambda dt, m=method: simulate(
            scene, state, ts, solver=Splitting(m, dt=dt, max_steps=2**14)))
        hs, errs = [], []
        for dt in dts:
            traj = run(dt)
            hs.append(ORDER_T / math.ceil(ORDER_T / dt - 1e-9))
            errs.append(_final_error(traj.q[-1], traj.omega[-1], q_ref[-1], w_ref[-1]))
        out[method] = {"order": COMPOSITIONS[method].order,
                       "slope": float(linregress(np.log(hs), np.log(errs)).slope),
                       "steps": hs, "errors": errs}
    return out


def _bands(scene, q, w) -> dict:
    """Largest energy error (over the initial kinetic energy) in each half, and of ``L·ĝ``."""
    q, w = jnp.asarray(q), jnp.asarray(w)
    kin = jax.vmap(Kinematics)(q, w)
    energy = np.asarray(jax.vmap(scene.kinetic_energy)(w) + jax.vmap(scene.potential_energy)(kin))
    lg = np.asarray(jax.vmap(lambda q, w: quat.rotate(q, scene.angular_momentum(w))[2])(q, w))
    de = np.abs(energy - energy[0]) / float(scene.kinetic_energy(w[0]))
    half = len(de) // 2
    l0 = float(jnp.linalg.norm(scene.angular_momentum(w[0])))
    return {"energy_first_half": float(de[:half].max()),
            "energy_second_half": float(de[half:].max()),
            "L_g": float(np.max(np.abs(lg - lg[0])) / l0)}


def drift(steps: int) -> dict:
    """Part 2: energy and ``L·ĝ`` bands over ``steps`` Strang steps and of adaptive methods."""
    t1 = steps * DRIFT_H
    ts = jnp.linspace(0.0, t1, 1001)
    scene, state = ASYMMETRIC.scene(), ASYMMETRIC.state()
    runs = {
        f"jrigid splitting strang, h = {DRIFT_H:g}": jax.jit(lambda: simulate(
            scene, state, ts, solver=Splitting("strang", dt=DRIFT_H, max_steps=steps))),
        f"jrigid quaternion_omega + Tsit5, rtol {DRIFT_RTOL:g}, no invariant projection":
            jax.jit(lambda: simulate(scene, state, ts, formulation="quaternion_omega",
                                     project="manifold", rtol=DRIFT_RTOL,
                                     atol=1e-2 * DRIFT_RTOL, max_steps=10**7)),
    }
    out = {"t1": t1, "steps": steps, "methods": {}}
    for label, run in runs.items():
        jax.block_until_ready(run())  # compile
        start = time.perf_counter()
        traj = jax.block_until_ready(run())
        out["methods"][label] = dict(_bands(scene, traj.q, traj.omega),
                                     seconds=time.perf_counter() - start,
                                     steps=int(traj.stats["num_steps"]))
    q, w, seconds, nfev = _dop853(ASYMMETRIC, ts, DRIFT_RTOL)
    out["methods"][f"scipy DOP853, rtol {DRIFT_RTOL:g}"] = dict(
        _bands(scene, q, w), seconds=seconds, steps=(nfev - 1) // 12)
    return out


def closed_form() -> dict:
    """Part 3: time per call of the Lagrange top's closed form; agreement with DOP853."""
    scene, state = SYMMETRIC.scene(), SYMMETRIC.state()
    b = scene.body
    g = lagrange_top.scene_gravity(scene)
    period = float(lagrange_top.nutation_period(
        lagrange_top.prepare(b.moments, b.mass, b.com, g, state.q, state.omega)))
    solve = jax.jit(lagrange_top.solve)
    out = {"nutation_period": period, "seconds": {}}
    for n in (1, 1000):
        for periods in (10.0, 1e6):
            ts = jnp.linspace(0.0, periods * period, n + 1)[1:]
            args = (b.moments, b.mass, b.com, g, state.q, state.omega, ts)
            jax.block_until_ready(solve(*args))  # compile
            timing, _ = harness.time_runs(lambda a=args: solve(*a), 7, min_time=0.05)
            out["seconds"][f"{n} output time{'s' if n > 1 else ''}, t up to "
                           f"{periods:g} nutation periods"] = timing.median
    ts = np.linspace(0.0, 100 * period, 201)
    q, w = _closed_form(SYMMETRIC, ts)
    q_ref, w_ref, _, _ = _dop853(SYMMETRIC, ts, 1e-13)
    out["max_difference_vs_dop853_100_periods"] = max(
        _final_error(q[k], w[k], q_ref[k], w_ref[k]) for k in range(1, len(ts)))
    return out


def report(res: dict, machine: dict) -> str:
    lines = ["# Splitting integrators and the heavy top in closed form", "",
             f"Machine: {harness.machine_line(machine)}.", "",
             f"## Orders (symmetric top, final error at t = {ORDER_T:g} against the closed form)",
             ""]
    rows = [[m, r["order"], f"{r['slope']:.2f}", " ".join(f"{h:.3g}" for h in r["steps"]),
             " ".join(f"{e:.1e}" for e in r["errors"])] for m, r in res["orders"].items()]
    lines += [harness.markdown_table(["method", "order", "measured slope", "steps h",
                                      "final errors"], rows), ""]
    d = res["drift"]
    lines += [f"## No drift (asymmetric top, {d['steps']:,} steps of h = {DRIFT_H:g}, "
              f"t = {d['t1']:g})", ""]
    rows = [[label, f"{r['energy_first_half']:.1e}", f"{r['energy_second_half']:.1e}",
             f"{r['L_g']:.1e}", f"{r['steps']:,}", harness.fmt_seconds(r["seconds"])]
            for label, r in d["methods"].items()]
    lines += [harness.markdown_table(["method", "max energy error, first half",
                                      "second half", "max L·ĝ error", "steps", "time"], rows),
              "", "Energy errors are over the initial kinetic energy, L·ĝ over |L|.", ""]
    c = res["closed_form"]
    lines += ["## The heavy symmetric top in closed form (`jrigid.lagrange_top`)", ""]
    rows = [[k, harness.fmt_seconds(v)] for k, v in c["seconds"].items()]
    lines += [harness.markdown_table(["call (jitted, after compilation)", "time"], rows), "",
              f"Largest difference from scipy DOP853 (rtol 1e-13) over 100 nutation periods: "
              f"{c['max_difference_vs_dop853_100_periods']:.1e}.", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict:
    parser = harness.command_line(__doc__, quick="10⁵ steps in part 2, ~1 min")
    args = parser.parse_args(argv)
    machine = harness.machine_info()
    start = time.perf_counter()
    res = {"orders": orders(), "drift": drift(10**5 if args.quick else 10**6),
           "closed_form": closed_form()}
    res["total_seconds"] = time.perf_counter() - start
    text = report(res, machine)
    out_dir = harness.results_dir(args.out)
    stem = harness.stem("splitting", args.quick)
    harness.write_text(out_dir / f"{stem}.md", text)
    harness.write_json(out_dir / f"{stem}.json", {"machine": machine, **res})
    print(text)
    return res


if __name__ == "__main__":
    main()
