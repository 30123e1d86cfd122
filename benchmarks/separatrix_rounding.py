"""Near the separatrix at tight tolerances: how much of the error is rounding.

Close to the intermediate axis's separatrix the motion amplifies every small change of
the state (the time between flips grows like ``log(1/ε)``), so at tight tolerances the
final error of a solve stops following the tolerance and depends on the rounding of its
arithmetic. This script measures that floor: each hard case is started from ``--starts``
initial states that differ from the case's by a few units in the last place (``ω0``
times ``1 + k·eps``, ``k = 0 … starts − 1``), each solve is compared with the closed form
(``jrigid.exact``, within 1e-12 of a 30-digit evaluation: ``tests/test_hard_cases.py``)
started from exactly the state it solves, and the spread of the errors over the starts
is the part of the error that rounding decides. Two methods: ``simulate``'s default and
the ``quaternion_omega`` form (the comparison of issue #14's accuracy target), both at
``atol = 1e-2·rtol``, over the small horizon of ``benchmarks/hard_cases.py`` (1.2 periods,
which ends between two flips, where a time shift shows most).

Usage: ``python benchmarks/separatrix_rounding.py [--cases a,b] [--starts N] [--quick]``
(default: ``separatrix_1e-6`` and ``separatrix_1e-4``, 16 starts, nine tolerances, about
a minute on 2 cores). Writes ``separatrix_rounding[_quick].json`` and ``.md`` to
``benchmarks/results/``.
"""

from __future__ import annotations

import statistics
import sys

import harness

CASES = ("separatrix_1e-6", "separatrix_1e-4")
TOLERANCES = (1e-6, 1e-8, 1e-9, 3e-10, 1e-10, 5e-11, 3e-11, 1e-11, 1e-12)
QUICK_TOLERANCES = (1e-8, 1e-10, 1e-12)
METHODS = ("quaternion_acceleration", "quaternion_omega")
LABELS = {"quaternion_acceleration": "default", "quaternion_omega": "(q, ω)"}


def starts(case, n: int):
    """``n`` initial states of ``case`` a few ulps apart, each with its closed-form final
    state at the small horizon: ``[(state, q_ref (4,), ω_ref (3,)), ...]``."""
    import hard_cases as hc
    import jax.numpy as jnp
    import numpy as np

    from jrigid import exact, initial

    prob = hc.problem(case, "small")
    base = prob.state()
    t1 = hc.horizon(case, "small")
    eps = float(np.finfo(np.float64).eps)
    out = []
    for k in range(n):
        state = initial.from_omega(base.q, base.omega * (1.0 + k * eps))
        q, w = exact.solve(jnp.asarray(case.moments, jnp.float64), state.q, state.omega,
                           jnp.asarray([0.0, t1], jnp.float64))
        out.append((state, np.asarray(q[-1]), np.asarray(w[-1])))
    return out


def errors(case, method: str, rtol: float, runs) -> list[float]:
    """Final errors (relative ω, sign-invariant q; the larger) of ``method`` at ``rtol``
    from each start of ``runs`` (:func:`starts`)."""
    import hard_cases as hc
    import jax.numpy as jnp

    from jrigid import simulate

    scene = hc.problem(case, "small").scene()
    ts = jnp.asarray([0.0, hc.horizon(case, "small")])
    out = []
    for state, q_ref, w_ref in runs:
        traj = simulate(scene, state, ts, formulation=method, rtol=rtol, atol=1e-2 * rtol,
                        max_steps=1_000_000)
        out.append(max(harness.omega_error(traj.omega[-1], w_ref),
                       harness.quaternion_error(traj.q[-1], q_ref)))
    return out


def summary(rtol: float, by_method: dict[str, list[float]]) -> dict:
    """Median, min and max of each method's error (in units of ``rtol``), the ratio of the
    default's median to ``(q, ω)``'s and the range of the per-start ratios."""
    row: dict = {"rtol": rtol}
    for method, errs in by_method.items():
        row[method] = {"median": statistics.median(errs) / rtol, "min": min(errs) / rtol,
                       "max": max(errs) / rtol}
    default, omega = by_method["quaternion_acceleration"], by_method["quaternion_omega"]
    ratios = [a / b for a, b in zip(default, omega, strict=True)]
    row["median_ratio"] = statistics.median(default) / statistics.median(omega)
    row["ratio_range"] = (min(ratios), max(ratios))
    return row


def _cell(stats: dict) -> str:
    return f"{stats['median']:.3g} ({stats['min']:.2g}–{stats['max']:.2g})"


def table(rows: list[dict]) -> str:
    headers = ["rtol", "default: error / rtol, median (min–max)", "(q, ω): error / rtol",
               "(q, ω) max ÷ min", "default ÷ (q, ω), medians", "default ÷ (q, ω), per start"]
    body = []
    for r in rows:
        omega = r["quaternion_omega"]
        lo, hi = r["ratio_range"]
        body.append([f"{r['rtol']:.0e}", _cell(r["quaternion_acceleration"]), _cell(omega),
                     f"{omega['max'] / omega['min']:.2g}", f"{r['median_ratio']:.2f}",
                     f"{lo:.2f}–{hi:.2f}"])
    return harness.markdown_table(headers, body)


def main(argv=None) -> bool:
    parser = harness.command_line(__doc__, quick="three tolerances, 4 starts, ε = 1e-6 only")
    parser.add_argument("--cases", default=",".join(CASES),
                        help="comma-separated hard cases (torque free)")
    parser.add_argument("--starts", type=int, default=None,
                        help="initial states a few ulps apart per case (default 16)")
    args = parser.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import hard_cases as hc

    keys = [CASES[0]] if args.quick else [k for k in args.cases.split(",") if k]
    n = args.starts or (4 if args.quick else 16)
    if n < 2:
        parser.error("--starts must be at least 2")
    for key in keys:
        if key not in hc.CASES or not hc.CASES[key].torque_free:
            parser.error(f"{key!r} is not a torque-free hard case")
    tolerances = QUICK_TOLERANCES if args.quick else TOLERANCES
    machine = harness.machine_line()
    results, sections = {}, []
    for key in keys:
        case = hc.CASES[key]
        runs = starts(case, n)
        rows = []
        for rtol in tolerances:
            rows.append(summary(rtol, {m: errors(case, m, rtol, runs) for m in METHODS}))
            print(f"{key} rtol {rtol:.0e}: medians default {rows[-1][METHODS[0]]['median']:.3g}"
                  f"·rtol, (q, ω) {rows[-1][METHODS[1]]['median']:.3g}·rtol", flush=True)
        results[key] = rows
        sections.append(f"### {key} ({case.title}), {n} starts\n\n{table(rows)}")
    worst = max(r["median_ratio"] for rows in results.values() for r in rows)
    text = (f"Machine: {machine}\n\nfinal error at the small horizon over {n} starts a few "
            "ulps apart, each against the closed form from its own start\n\n"
            + "\n\n".join(sections)
            + f"\n\nLargest ratio of the medians, default ÷ (q, ω): {worst:.2f} (target 2)\n")
    out = harness.results_dir(args.out)
    stem = harness.stem("separatrix_rounding", args.quick)
    harness.write_json(out / f"{stem}.json", {"machine": machine, "starts": n,
                                              "results": results})
    harness.write_text(out / f"{stem}.md", text)
    print(text)
    return worst <= 2.0


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
