"""L-BFGS fits (``jrigid.fit.fit``'s default method): the first fit's compile time, and far starts.

Two measurements:

``first``
    the first L-BFGS fit through a simulated model (``fit.Simulated``, diffrax reverse
    mode) in a fresh Python process, compilation included, then the same fit again in
    that process. Cases: the noise-free record of ``tests/test_fit.py``
    (``test_noise_free_recovery_through_simulate``: 13 gyroscope samples over 3 s,
    rtol 1e-11) and the tumbling record of ``experiments/fit_tumbling.py`` in quick mode
    with ``model="simulate"`` (41 samples over 12 s, σ = 0.02). Reported: wall time of
    the first and second fit, the time JAX spent tracing, lowering and compiling during
    the first (``jax.monitoring`` events, summed; the largest program named), the
    iterations, the stop reason, the final loss and gradient, and the number of loss
    evaluations (value and gradient) when the step exposes them. The first fit's CPU time
    is given too: on a shared machine it moves less with the load than wall time does.
``far``
    the far starts of ``docs/benchmarks.md`` ("Fits that know when they failed"): the
    tumbling record of ``tests/test_fit_verdicts.py`` (moments ∝ (1, 2, 2.5),
    ω0 = (0.3, 2, 0.2), 41 samples over 8 s, σ = 0.02, ``fit.Exact``), 20 starts of each
    kind, with and without ``horizons=(0.25, 0.5)``. Kinds: "raw" (raw shape
    ~ N(0, 2²), ω0 = first sample + N(0, 1); seeds 200–219) and "physical" (body uniform
    over the physical region, ω0 = first sample: ``far_starts`` of
    ``tests/test_fit_verdicts.py``, seeds 100–119). Counted: end points on the edge
    (smallest triangle gap < 1e-5), successes, successes at χ²/dof > 2, stop reasons.

Usage: ``python benchmarks/fit_lbfgs.py [--only first|far] [--methods lbfgs lm]
[--quick] [--out DIR]``. ``--quick``: 5 starts of each kind. Writes
``benchmarks/results/fit_lbfgs[_quick].json`` and ``.md`` and prints the tables, headed
by the machine. About 4 min for ``first`` and 2 min for ``far`` (L-BFGS) on 2 cores.
"""

from __future__ import annotations

import collections
import json
import os
import pathlib
import subprocess
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(pathlib.Path(__file__).parent))

import harness  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jrigid import exact, fit, initial  # noqa: E402
from jrigid.body import RigidBody  # noqa: E402
from jrigid.scene import Scene  # noqa: E402

TRUE_MOMENTS = jnp.array([1.0, 2.0, 2.5]) / 5.5
IDENTITY = jnp.array([1.0, 0.0, 0.0, 0.0])
CASES = ("test_fit_simulate", "fit_tumbling_simulate")
_COMPILE_EVENTS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
)


def _build(theta):
    body = RigidBody(fit.moment_ratios(theta["shape"]))
    return Scene(body), initial.from_omega(None, theta["omega0"])


def _case(name):
    """``(problem, start, fit kwargs)`` of a ``first`` case."""
    if name == "test_fit_simulate":
        ts = jnp.linspace(0.0, 3.0, 13)
        _, om = exact.solve(TRUE_MOMENTS, IDENTITY, jnp.array([0.3, 2.0, 0.2]), ts)
        model = fit.Simulated(_build, rtol=1e-11, atol=1e-13)
        problem = fit.Problem(model, fit.Gyroscope(ts, np.asarray(om), sigma=0.01))
        start = {"shape": jnp.array([0.5, 0.5]), "omega0": jnp.array([0.4, 1.9, 0.3])}
        return problem, start, {"max_iter": 300, "gtol": 1e-9}
    if name == "fit_tumbling_simulate":
        ts = jnp.linspace(0.0, 12.0, 41)
        moments = jnp.array([1.0, 2.0, 2.5]) / 5.5
        _, om = exact.solve(moments, IDENTITY, jnp.array([0.05, 2.0, 0.05]), ts)
        data = np.asarray(om) + 0.02 * np.random.default_rng(0).standard_normal(om.shape)
        problem = fit.Problem(fit.Simulated(_build), fit.Gyroscope(ts, data, sigma=0.02))
        start = {"shape": jnp.array([0.2, 0.1]), "omega0": jnp.asarray(data[0])}
        return problem, start, {"max_iter": 500, "gtol": 1e-9}
    raise ValueError(name)


def _child(name) -> dict:
    """One ``first`` case in this (fresh) process."""
    compile_s: dict = collections.defaultdict(float)
    by_event: dict = collections.defaultdict(float)
    recording = [False]

    def listener(event, duration, **kw):
        if recording[0] and event in _COMPILE_EVENTS:
            compile_s[kw.get("fun_name", "?")] += duration
            by_event[event.rsplit("/", 1)[-1]] += duration

    jax.monitoring.register_event_duration_secs_listener(listener)
    evaluations = [0]
    steps = sys.modules.get("jrigid.fit.steps")
    counted = steps is not None and hasattr(steps, "_value_and_grad")
    if counted:
        inner = steps._value_and_grad

        def counting(*a, **k):
            evaluations[0] += 1
            return inner(*a, **k)

        steps._value_and_grad = counting
    problem, start, kw = _case(name)
    out = {"case": name}
    for run in ("first", "second"):
        evaluations[0] = 0
        recording[0] = run == "first"
        t0, c0 = time.perf_counter(), time.process_time()
        res = fit.fit(problem, start, on_bad_fit="ignore", **kw)
        jax.block_until_ready(res.params)
        out[f"{run}_s"] = time.perf_counter() - t0
        out[f"{run}_cpu_s"] = time.process_time() - c0
        out[f"{run}_evaluations"] = evaluations[0] if counted else None
    total = sum(compile_s.values())
    top = max(compile_s, key=compile_s.get)
    out.update(
        compile_s=total,
        largest_program=top,
        largest_program_s=compile_s[top],
        compile_by_event=dict(by_event),
        compile_by_program=dict(sorted(compile_s.items(), key=lambda kv: -kv[1])[:6]),
        n_iter=res.n_iter,
        reason=res.reason,
        success=res.success,
        loss=res.loss,
        grad_norm=res.grad_norm,
        shape=np.asarray(res.params["shape"]).tolist(),
        omega0=np.asarray(res.params["omega0"]).tolist(),
    )
    return out


def first(log) -> list[dict]:
    rows = []
    for name in CASES:
        log(f"first fit: {name} (fresh process)")
        proc = subprocess.run(
            [sys.executable, __file__, "--child", name], capture_output=True, text=True,
            check=True, env=dict(os.environ),
        )  # fmt: skip
        rows.append(json.loads(proc.stdout.strip().splitlines()[-1]))
        log(f"  {rows[-1]}")
    return rows


def _tumbling_record():
    ts = jnp.linspace(0.0, 8.0, 41)
    _, omega = exact.solve(TRUE_MOMENTS, IDENTITY, jnp.array([0.3, 2.0, 0.2]), ts)
    measured = omega + 0.02 * np.random.default_rng(0).standard_normal(omega.shape)
    problem = fit.Problem(fit.Exact(_build), fit.Gyroscope(ts, measured, sigma=0.02))
    return problem, np.asarray(measured)


def _starts(kind, data, n):
    for seed in range(n):
        if kind == "raw":
            rng = np.random.default_rng(200 + seed)
            shape = 2.0 * rng.standard_normal(2)
            omega0 = data[0] + rng.standard_normal(3)
            yield {"shape": jnp.asarray(shape), "omega0": jnp.asarray(omega0)}
        else:  # tests/test_fit_verdicts.py far_starts
            frac = np.random.default_rng(100 + seed).dirichlet([1.0, 1.0, 1.0])
            yield {"shape": jnp.asarray(np.log(frac[:2] / frac[2])), "omega0": jnp.asarray(data[0])}


def _gap(m):
    m = np.asarray(m)
    return min(m[0] + m[1] - m[2], m[0] + m[2] - m[1], m[1] + m[2] - m[0]) / m.sum()


def far(methods, n, log) -> list[dict]:
    problem, data = _tumbling_record()
    rows = []
    for kind in ("raw", "physical"):
        for method in methods:
            for horizons in (None, (0.25, 0.5)):
                t0 = time.perf_counter()
                ends = []
                for start in _starts(kind, data, n):
                    res = fit.fit(problem, start, method=method, horizons=horizons,
                                  on_bad_fit="ignore")  # fmt: skip
                    m = np.asarray(fit.moment_ratios(res.params["shape"]))
                    ends.append({
                        "edge": bool(_gap(m) < 1e-5), "success": res.success,
                        "chi2_dof": res.chi2_dof, "reason": res.reason, "n_iter": res.n_iter,
                        "truth": bool(np.max(np.abs(m - np.asarray(TRUE_MOMENTS))) < 5e-3),
                    })  # fmt: skip
                row = {
                    "starts": kind, "method": method, "horizons": horizons, "n": n,
                    "edge": sum(e["edge"] for e in ends),
                    "success": sum(e["success"] for e in ends),
                    "success_bad_chi2": sum(e["success"] and e["chi2_dof"] > 2 for e in ends),
                    "success_not_truth": sum(e["success"] and not e["truth"] for e in ends),
                    "reasons": dict(collections.Counter(e["reason"] for e in ends)),
                    "mean_iter": float(np.mean([e["n_iter"] for e in ends])),
                    "seconds": time.perf_counter() - t0, "ends": ends,
                }  # fmt: skip
                rows.append(row)
                log(f"  {kind} {method} horizons={horizons}: edge {row['edge']}, "
                    f"success {row['success']}, reasons {row['reasons']}, "
                    f"{row['seconds']:.0f} s")  # fmt: skip
    return rows


def _tables(first_rows, far_rows) -> str:
    parts = []
    if first_rows:
        parts.append(harness.markdown_table(
            ["case", "first fit (s)", "its CPU time (s)", "compiling (s)", "largest program (s)",
             "second fit (s)", "iterations", "reason", "final loss", "‖∇f‖∞", "evaluations"],
            [[r["case"], f"{r['first_s']:.1f}", f"{r['first_cpu_s']:.1f}", f"{r['compile_s']:.1f}",
              f"{r['largest_program']} {r['largest_program_s']:.1f}", f"{r['second_s']:.2f}",
              r["n_iter"], r["reason"], f"{r['loss']:.6g}", f"{r['grad_norm']:.2g}",
              "—" if r["second_evaluations"] is None else r["second_evaluations"]]
             for r in first_rows],
        ))  # fmt: skip
    if far_rows:
        parts.append(harness.markdown_table(
            ["starts", "method", "horizons", "edge", "success", "success at χ²/dof > 2",
             "success not at the truth", "reasons", "mean iterations", "time (s)"],
            [[r["starts"], r["method"], r["horizons"] or "—", f"{r['edge']}/{r['n']}",
              f"{r['success']}/{r['n']}", r["success_bad_chi2"], r["success_not_truth"],
              ", ".join(f"{k} {v}" for k, v in sorted(r["reasons"].items())),
              f"{r['mean_iter']:.0f}", f"{r['seconds']:.0f}"] for r in far_rows],
        ))  # fmt: skip
    return "\n\n".join(parts)


def main() -> None:
    if "--child" in sys.argv:
        print(json.dumps(_child(sys.argv[sys.argv.index("--child") + 1])))
        return
    parser = harness.command_line(__doc__, quick="5 far starts of each kind", quiet=True)
    parser.add_argument("--only", choices=("first", "far"), default=None)
    parser.add_argument("--methods", nargs="+", default=["lbfgs"], choices=("lbfgs", "lm"))
    args = parser.parse_args()
    log = harness.logger(args.quiet)
    info = harness.machine_info()
    first_rows = first(log) if args.only in (None, "first") else []
    far_rows = far(args.methods, 5 if args.quick else 20, log) if args.only in (None, "far") else []
    out = harness.results_dir(args.out)
    stem = harness.stem("fit_lbfgs", args.quick)
    info["load_average_end"] = harness.machine_info()["load_average"]
    record = {"machine": info, "first": first_rows, "far": far_rows}
    harness.write_json(out / f"{stem}.json", record)
    text = harness.machine_line(info) + "\n\n" + _tables(first_rows, far_rows) + "\n"
    harness.write_text(out / f"{stem}.md", text)
    print(text)


if __name__ == "__main__":
    main()
