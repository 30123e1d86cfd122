"""What float32 can and cannot do: a free rotor over many periods, float32 against float64.

An asymmetric free body, moments (1, 2, 3), spun near its stable axis of largest moment,
ω0 = (0.1, 0.05, 1), is integrated with the default :func:`jrigid.simulate` over 10,
100, 1000 and 10⁴ rotation periods (period 2π/|ω0|) in float32 and in float64, with the
default projection (onto |q| = 1 and the conserved energy and |L|) and with
``project="manifold"`` (|q| = 1 only, as for a scene that conserves nothing), at rtol
1e-5 (the float32 default) and 2e-6 (near the float32 limit of 10 eps). The error is
the largest orientation error (degrees, sign-invariant) over 101 output times against the float64
closed form (``solver="exact"``). Also reported: the result code, the step count and
whether :class:`jrigid.PrecisionWarning` was issued.

Each precision runs in its own process (``jax_enable_x64`` is global).

Usage: ``python benchmarks/float32_horizon.py [--periods 10 100 1000 10000]`` (4–5 min).
Prints a markdown table and writes ``benchmarks/results/float32_horizon.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import subprocess
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import harness  # noqa: E402

MOMENTS = (1.0, 2.0, 3.0)
OMEGA0 = (0.1, 0.05, 1.0)
RTOLS = (1e-5, 2e-6)
PROJECT = (True, "manifold")
SAMPLES = 101


def _times(periods: float) -> np.ndarray:
    return np.linspace(0.0, periods * 2 * math.pi / math.hypot(*OMEGA0), SAMPLES)


def child(bits: int, periods: list[float]) -> list[dict]:
    """Run every case in this process's precision; orientations as float64 lists."""
    import jax

    jax.config.update("jax_enable_x64", bits == 64)
    import jax.numpy as jnp

    import jrigid

    scene = jrigid.Scene(jrigid.RigidBody(jnp.asarray(MOMENTS)))
    state = jrigid.initial.from_omega(omega=jnp.asarray(OMEGA0))
    rows = []
    budget = int(400 * max(periods)) + 10_000  # one static budget: one compilation per mode
    for n in periods:
        ts = jnp.asarray(_times(n))
        for rtol in RTOLS:
            for project in PROJECT:
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    t0 = time.perf_counter()
                    traj = jrigid.simulate(scene, state, ts, rtol=rtol, atol=rtol * 1e-2,
                                           project=project, throw=False,
                                           max_steps=budget)
                    q = np.asarray(traj.q, dtype=np.float64)
                    seconds = time.perf_counter() - t0
                warned = any(issubclass(w.category, jrigid.PrecisionWarning) for w in caught)
                rows.append(dict(bits=bits, periods=n, rtol=rtol, project=str(project),
                                 result=jrigid.Result(int(traj.result)).name,
                                 steps=int(traj.stats["num_steps"]), seconds=seconds,
                                 warned=warned, q=q.tolist()))
    return rows


def table(rows: list[dict]) -> str:
    """Markdown: one line per horizon and rtol, the four precision × projection errors."""
    cell = {(r["periods"], r["rtol"], r["bits"], r["project"]): r for r in rows}
    cols = [(32, "True"), (64, "True"), (32, "manifold"), (64, "manifold")]
    lines = [
        "| periods | rtol | float32, invariants | float64, invariants | float32, manifold only "
        "| float64, manifold only | steps (float32) | PrecisionWarning (float32) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for n, rtol in sorted({(r["periods"], r["rtol"]) for r in rows}, key=lambda k: (k[0], -k[1])):
        errs = []
        for bits, project in cols:
            r = cell[(n, rtol, bits, project)]
            e = r["max_error_deg"]
            errs.append(("—" if e is None else f"{e:.2g}°")
                        + ("" if r["result"] == "success" else f" ({r['result']})"))
        first = cell[(n, rtol, 32, "True")]
        lines.append(f"| {n:g} | {rtol:g} | " + " | ".join(errs)
                     + f" | {first['steps']} | {'yes' if first['warned'] else 'no'} |")
    return "\n".join(lines)


def main() -> None:
    parser = harness.command_line(__doc__, out=False)
    parser.add_argument("--periods", type=float, nargs="+", default=[10, 100, 1000, 10_000])
    parser.add_argument("--child", type=int, choices=(32, 64), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        json.dump(child(args.child, args.periods), sys.stdout)
        return
    rows = []
    for bits in (32, 64):
        out = subprocess.run(
            [sys.executable, __file__, "--child", str(bits), "--periods",
             *map(str, args.periods)],
            check=True, capture_output=True, text=True,
        )
        rows += json.loads(out.stdout)

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    import jrigid

    scene = jrigid.Scene(jrigid.RigidBody(jnp.asarray(MOMENTS)))
    state = jrigid.initial.from_omega(omega=jnp.asarray(OMEGA0))
    refs = {n: jrigid.simulate(scene, state, jnp.asarray(_times(n)), solver="exact").q
            for n in args.periods}
    for row in rows:
        q = jnp.asarray(row.pop("q"))
        angle = np.degrees(np.asarray(jrigid.quaternion.distance(q, refs[row["periods"]])))
        row["max_error_deg"] = float(np.nanmax(angle)) if np.isfinite(angle).any() else None
    print(table(rows))
    path = harness.results_dir() / "float32_horizon.json"
    path.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
