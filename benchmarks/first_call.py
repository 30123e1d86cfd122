"""A new script's first call: what a user waits for before the first trajectory.

Each run is a fresh Python process running the script a new user writes (float64):
import jax and jrigid, build a ``RigidBody`` and a ``Scene``, ``initial.from_omega``,
then ``simulate`` over t = 0…100 with 301 output times and read ``q``; then the same call
again (compiled by then). Two scenes: the free rotor and the heavy top of
``speed_vs_error.py``. The first ``simulate`` is split with JAX's own monitoring events
into tracing (``jaxpr_trace_duration``), lowering (``jaxpr_to_mlir_module_duration``)
and XLA's compilation (``backend_compile_duration``), summed over every program the
call compiles; the rest of the first call is Python (the lazy import of diffrax and of
jrigid's integration modules, the input checks) and the run itself.

The issue's target is a first compile of the default within 3 s: here, the tracing,
lowering and XLA compilation of the first ``simulate``.

Each run starts from an empty persistent compilation cache (``jrigid._cache``: a fresh
directory in ``JRIGID_CACHE_DIR``), and is followed by a second fresh process with the
same directory: the script run again, its programs loaded from the cache ("cached"
rows) instead of compiled by XLA.

Usage: ``python benchmarks/first_call.py [--runs N]`` (default 5 runs per scene, about
2 minutes on 2 cores). Writes ``first_call.json`` and ``.md`` to ``benchmarks/results/``.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile

import harness

SCRIPT = r"""
import json, sys, time
t_start = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
durations = {}
def listen(event, seconds, **kwargs):
    durations[event] = durations.get(event, 0.0) + seconds
jax.monitoring.register_event_duration_secs_listener(listen)
hits = []
jax.monitoring.register_event_listener(
    lambda event, **kwargs: hits.append(event) if event.endswith("cache_hits") else None)
import jax.numpy as jnp
import jrigid
from jrigid import initial
t_import = time.perf_counter()
if sys.argv[1] == "rotor":
    body = jrigid.RigidBody(jnp.array([1.0, 2.0, 3.0]))
    scene = jrigid.Scene(body, jrigid.FreeRotation())
    t_body = time.perf_counter()
    state = initial.from_omega(omega=jnp.array([1.0, 0.3, 0.7]))
else:
    body = jrigid.RigidBody(jnp.array([1.0, 1.0, 0.5]), mass=1.0,
                            com=jnp.array([0.0, 0.0, 1.0]))
    scene = jrigid.Scene(body, jrigid.Pivot(), loads=(jrigid.Gravity(1.0),))
    t_body = time.perf_counter()
    state = initial.from_euler_rates([0.0, 0.6, 0.0], [0.2, 0.1, 5.0])
state.q.block_until_ready()
t_state = time.perf_counter()
before = dict(durations)
ts = jnp.linspace(0.0, 100.0, 301)
traj = jrigid.simulate(scene, state, ts)
traj.q.block_until_ready()
t_first = time.perf_counter()
first = {k: v - before.get(k, 0.0) for k, v in durations.items()}
traj = jrigid.simulate(scene, state, ts)
traj.q.block_until_ready()
t_second = time.perf_counter()
print(json.dumps({
    "import": t_import - t_start, "body": t_body - t_import, "state": t_state - t_body,
    "first_simulate": t_first - t_state, "second_simulate": t_second - t_first,
    "trace": first.get("/jax/core/compile/jaxpr_trace_duration", 0.0),
    "lower": first.get("/jax/core/compile/jaxpr_to_mlir_module_duration", 0.0),
    "xla": first.get("/jax/core/compile/backend_compile_duration", 0.0),
    "cache_hits": len(hits),
}))
"""

COLUMNS = ("import", "body", "state", "first_simulate", "trace", "lower", "xla", "compile",
           "second_simulate")


def one_run(scene: str, cache: str) -> dict[str, float]:
    """The timings (seconds) of one fresh process running the script for ``scene``, with
    ``cache`` as its persistent compilation cache's directory."""
    env = dict(os.environ, JRIGID_CACHE_DIR=cache)
    out = subprocess.run([sys.executable, "-c", SCRIPT, scene], capture_output=True,
                         text=True, check=True, env=env)
    timing = json.loads(out.stdout.strip().splitlines()[-1])
    timing["compile"] = timing["trace"] + timing["lower"] + timing["xla"]
    return timing


def _cell(values, seconds=True) -> str:
    med, lo, hi = statistics.median(values), min(values), max(values)
    if seconds:
        return f"{med:.2f} s ({lo:.2f}–{hi:.2f})"
    return f"{1e3 * med:.2f} ms ({1e3 * lo:.2f}–{1e3 * hi:.2f})"


def main(argv=None) -> bool:
    parser = harness.command_line(__doc__)
    parser.add_argument("--runs", type=int, default=5, help="fresh processes per scene")
    args = parser.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)  # as the script does (the machine line says)
    machine = harness.machine_line()
    runs = {"rotor": [], "top": []}
    cached = {"rotor": [], "top": []}
    for i in range(args.runs):  # interleaved, so that load falls on both alike
        for scene in runs:
            cache = tempfile.mkdtemp(prefix="jrigid-first-call-")
            try:
                runs[scene].append(one_run(scene, cache))  # empty cache: XLA compiles
                cached[scene].append(one_run(scene, cache))  # the same script again
            finally:
                shutil.rmtree(cache, ignore_errors=True)
            print(f"run {i + 1}/{args.runs} {scene}: "
                  f"first simulate {runs[scene][-1]['first_simulate']:.2f} s, "
                  f"compile {runs[scene][-1]['compile']:.2f} s; cached: first simulate "
                  f"{cached[scene][-1]['first_simulate']:.2f} s", flush=True)
    headers = ["scene", "cache"] + [c.replace("_", " ") for c in COLUMNS]
    rows = [[scene, label] + [_cell([r[c] for r in rs], seconds=c != "second_simulate")
                              for c in COLUMNS]
            for scene in runs for label, rs in (("empty", runs[scene]), ("cached", cached[scene]))]
    worst = max(r["compile"] for rs in runs.values() for r in rs)
    worst_cached = max(r["first_simulate"] for rs in cached.values() for r in rs)
    table = harness.markdown_table(headers, rows)
    text = (f"Machine: {machine}\n\nmedian (min–max) of {args.runs} fresh processes per "
            f"scene and cache; compile = trace + lower + XLA of the first simulate; "
            f"\"cached\": the same script run again, its programs loaded from the "
            f"persistent compilation cache\n\n{table}\n\n"
            f"Largest first compile: {worst:.2f} s (target 3 s)\n"
            f"Largest first simulate with the cache filled: {worst_cached:.2f} s\n")
    out = harness.results_dir(args.out)
    harness.write_json(out / "first_call.json", {"machine": machine, "runs": runs,
                                                 "cached": cached})
    harness.write_text(out / "first_call.md", text)
    print(text)
    return worst <= 3.0


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
