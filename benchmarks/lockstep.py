"""Lockstep efficiency of a vmapped stability map: useful steps against executed steps.

Under ``jax.vmap`` diffrax's adaptive ``while`` loop runs until the slowest member of a
batch is done; the other members wait (masked). A chunk of ``n`` members needing ``s_i``
steps therefore executes ``n · max s_i`` member-steps, and the useful fraction is

    efficiency = Σ_i s_i / Σ_chunks (n_chunk · max_{i ∈ chunk} s_i)

(:func:`jrigid.stability.lockstep_efficiency`). This benchmark runs the stability map of
``experiments/stability_map.py`` (a box of sides 1, 2, 3 spun at ``|ω| = 1`` along 10⁴
Fibonacci directions, 50 rotation periods, Tsit5 at rtol 1e-8) through
:func:`jrigid.ensemble.run` and records each member's ``num_steps``. It then

* computes the efficiency for several chunk sizes, with the members chunked in input
  order and grouped (sorted, :func:`jrigid.stability.difficulty_order`) by a predicted
  difficulty: the closed-form ``|L|² = |Iω|²``, the number of ω periods in the run
  (:func:`jrigid.exact.omega_period`), a pilot solve over 1/25 of the time, and the
  true step counts (the best any grouping can do);
* times the whole map twice with the same compiled program, in random order and grouped
  by ``|L|²``, to check that the saved steps are saved time. The machine is shared, so the
  process CPU time (``time.process_time``, all threads) is the measure; wall time is kept
  too.

Two maps: fixed speed ``|ω| = 1`` (step counts vary little) and fixed energy
``2E = I_mid`` (``|ω|`` varies with the direction, and so do the step counts). The Fibonacci
input order is itself sorted by one coordinate, so random order is the unsorted baseline.

Usage: ``python benchmarks/lockstep.py [--quick]`` (quick: 1000 directions, 10 periods).
Writes ``benchmarks/results/lockstep[_quick].json`` and ``.md``.
"""

from __future__ import annotations

import math
import pathlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(pathlib.Path(__file__).parent))

import harness  # noqa: E402

from jrigid import ensemble, exact, inertia, stability  # noqa: E402


def make_member(moments, samples: int, rtol: float):
    """One member: the stability map's computation with the end time as an input."""
    grid = jnp.linspace(0.0, 1.0, samples)

    def member(x):
        ts = x["t_end"] * grid
        out = stability.map_member(
            moments, x["omega0"], ts, 2 * math.pi, rtol=rtol, atol=rtol / 100
        )
        return {"num_steps": out["num_steps"], "flips": out["flips"], "result": out["result"]}

    return member


def timed_run(member, omega0, t_end, order, chunk):
    """Run the map in ``order``: (steps in input order, wall s, process CPU s, info).

    The compiled program is cached by :func:`jrigid.ensemble.run` (same ``member`` and
    shapes), so only the first call compiles; its ``info`` says how long that took.
    """
    info: dict = {}
    inputs = {"omega0": omega0[order], "t_end": np.full(len(order), t_end)}
    cpu = time.process_time()
    out = ensemble.run(member, inputs, chunk_size=chunk, progress=False, info=info)
    cpu = time.process_time() - cpu
    steps = np.empty_like(out["num_steps"])
    steps[order] = out["num_steps"]
    assert np.all(out["result"] == 0), "a member failed"
    return steps, info["run_seconds"], cpu, info


def measure(member, omega0, moments, t_end, chunk, sizes, seed=0) -> dict:
    """Efficiencies by ordering and chunk size, and the two timed runs, for one map."""
    n = len(omega0)
    l2 = np.sum((np.asarray(moments) * omega0) ** 2, axis=-1)
    consts = exact.prepare(moments, jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.asarray(omega0))
    cycles = t_end / np.asarray(exact.omega_period(consts))  # ω periods in the run
    ident = np.arange(n)
    # pilot: same compiled program, 1/25 of the time
    pilot, _, pilot_cpu, info = timed_run(member, omega0, t_end / 25, ident, chunk)
    compile_s = info["compile_seconds"]
    rand = np.random.default_rng(seed).permutation(n)
    # the map itself, in random order, then grouped by L²
    steps, plain_wall, plain_cpu, _ = timed_run(member, omega0, t_end, rand, chunk)
    order_l2 = np.asarray(stability.difficulty_order(l2))
    steps_b, grouped_wall, grouped_cpu, _ = timed_run(member, omega0, t_end, order_l2, chunk)
    orders = {
        "random order": rand,
        "input order (Fibonacci index)": ident,
        "L² (closed form)": order_l2,
        "ω periods in the run (closed form)": np.asarray(stability.difficulty_order(cycles)),
        "pilot solve (1/25 of the time)": np.asarray(stability.difficulty_order(pilot)),
        "true step counts (bound)": np.asarray(stability.difficulty_order(steps)),
    }
    e_plain = float(stability.lockstep_efficiency(steps, chunk, rand))
    e_grouped = float(stability.lockstep_efficiency(steps, chunk, order_l2))
    return {
        "steps_identical_when_grouped": bool(np.array_equal(steps, steps_b)),
        "compile_seconds": compile_s,
        "efficiency": {
            name: {str(s): float(stability.lockstep_efficiency(steps, s, o)) for s in sizes}
            for name, o in orders.items()
        },
        "correlation_with_steps": {
            "L²": float(np.corrcoef(l2, steps)[0, 1]),
            "ω periods": float(np.corrcoef(cycles, steps)[0, 1]),
            "pilot": float(np.corrcoef(pilot, steps)[0, 1]),
        },
        "steps": {
            "min": int(steps.min()),
            "median": float(np.median(steps)),
            "max": int(steps.max()),
            "total": int(steps.sum()),
        },
        "timed": {
            "chunk": chunk,
            "random_order_wall_seconds": plain_wall,
            "grouped_wall_seconds": grouped_wall,
            "random_order_cpu_seconds": plain_cpu,
            "grouped_cpu_seconds": grouped_cpu,
            "pilot_cpu_seconds_with_compile": pilot_cpu,
            "cpu_time_ratio": plain_cpu / grouped_cpu,
            "wall_time_ratio": plain_wall / grouped_wall,
            "efficiency_ratio": e_grouped / e_plain,
            "random_order_efficiency": e_plain,
            "grouped_efficiency": e_grouped,
        },
    }


def main(argv=None) -> dict:
    parser = harness.command_line(__doc__, quick="10³ directions over 10 periods, chunks of 128")
    parser.add_argument("--n", type=int, default=None, help="directions (default 10⁴)")
    parser.add_argument("--periods", type=float, default=None)
    parser.add_argument("--rtol", type=float, default=1e-8)
    parser.add_argument("--chunk", type=int, default=None, help="chunk size of the timed runs")
    args = parser.parse_args(argv)
    n = args.n or (1000 if args.quick else 10_000)
    periods = args.periods or (10.0 if args.quick else 50.0)
    chunk = args.chunk or (128 if args.quick else 1024)
    sizes = [s for s in (32, 64, 128, 256, 512, 1024, 2048, 4096) if s < n] + [n]

    out: dict = {
        "machine": harness.machine_info(),
        "n": n,
        "periods": periods,
        "rtol": args.rtol,
        "solver": "Tsit5",
        "chunk_timed": chunk,
    }
    moments = jnp.asarray(inertia.box(1.0, 1.0, 2.0, 3.0))
    mom = np.asarray(moments)
    dirs = np.asarray(stability.fibonacci_sphere(n))
    t_end = periods * 2 * math.pi
    member = make_member(moments, int(periods * 10) + 1, args.rtol)
    maps = {
        "speed": dirs,  # |ω| = 1
        "energy": np.asarray(
            stability.omega_at_energy(  # 2E = I_mid
                dirs, np.broadcast_to(mom, dirs.shape), np.full(n, 0.5 * np.median(mom))
            )
        ),
    }
    lines = [
        f"**Lockstep efficiency**: {n} directions, box (1, 2, 3), {periods:g} rotation periods "
        f"(2π), Tsit5 rtol {args.rtol:g}; two maps: fixed speed |ω| = 1 and fixed energy "
        "2E = I_mid (|ω| from 0.88 to 1.41).",
    ]
    for mode, omega0 in maps.items():
        r = measure(member, omega0, moments, t_end, chunk, sizes)
        out[mode] = r
        st, tm = r["steps"], r["timed"]
        lines += [
            "",
            f"*Fixed {mode}* — steps per member: min {st['min']}, median {st['median']:.0f}, "
            f"max {st['max']}. Useful fraction of executed member-steps by chunk size:",
            "",
            harness.markdown_table(
                ["members grouped by"] + [str(s) for s in sizes],
                [
                    [name] + [f"{100 * v:.1f}%" for v in row.values()]
                    for name, row in r["efficiency"].items()
                ],
            ),
            "",
            f"Timed, chunk {chunk}, same compiled program: random order "
            f"{tm['random_order_cpu_seconds']:.2f} s CPU ({tm['random_order_wall_seconds']:.1f} s "
            f"wall), grouped by L² {tm['grouped_cpu_seconds']:.2f} s CPU "
            f"({tm['grouped_wall_seconds']:.1f} s wall): CPU time ratio "
            f"{tm['cpu_time_ratio']:.2f} against the efficiency ratio "
            f"{tm['efficiency_ratio']:.2f}. Compile {r['compile_seconds']:.1f} s. Step counts "
            f"identical when grouped: {r['steps_identical_when_grouped']}.",
        ]
    text = harness.machine_line(out["machine"]) + "\n\n" + "\n".join(lines)
    print(text)
    name = harness.stem("lockstep", args.quick)
    folder = harness.results_dir(args.out)
    path = harness.write_json(folder / f"{name}.json", out)
    harness.write_text(folder / f"{name}.md", text + "\n")
    print(f"\nwrote {path}")
    return out


if __name__ == "__main__":
    main()
