"""What a default ``simulate`` call costs with ``T`` output times, jitted and plain.

On the free rotor of ``speed_vs_error.py`` (moments (1, 2, 3), ω0 = (1, 0.3, 0.7),
t = 0…100, float64), for ``T`` = 2, 11, 101 and 1001 evenly spaced output times:

* ``simulate`` with its defaults (rtol 1e-8, atol 1e-10), jitted, returning ``q``;
* the same call without ``jit`` (what a script does in a loop), reading ``q``;
  both are timed twice: interleaved with the other calls (batches of at most 8 calls of
  each, in turn), and in a loop of their own (runs of up to 30 back-to-back calls, the
  two alternating), which is what a script's loop does;
* a hand-written ``diffrax.diffeqsolve`` of ``(q, ω)`` (``Problem.jax_rhs``) with Dopri8,
  diffrax's ``PIDController`` and ``SaveAt(ts=...)``, jitted, at the same tolerances and at
  rtol 1e-9 / atol 1e-11, where its final error is about the default's at 1e-8.

Each call's final-state error (worst of relative ω and sign-invariant q) is measured
against ``jrigid.exact``. Compile time is the first call; run times are medians of
interleaved rounds (``harness.time_interleaved``), so that other load falls on all alike.

Usage: ``python benchmarks/outputs.py`` (about 1 minute on 2 cores; ``--quick``: T = 2
and 101, fewer rounds). Writes ``outputs.json`` and ``.md`` to ``benchmarks/results/``.
"""

from __future__ import annotations

import sys

import harness

COUNTS = (2, 11, 101, 1001)
RTOL, ATOL = 1e-8, 1e-10
HAND_TIGHT = (1e-9, 1e-11)  # the hand-written call's tolerances at about the default's error
JITTED, PLAIN = "jrigid default, jitted", "jrigid default, plain call"
LOOP_JIT, LOOP_PLAIN = f"{JITTED}, in a loop", f"{PLAIN}, in a loop"


def calls(problem, T: int):
    """``{label: (call, compile seconds)}`` for ``T`` output times."""
    import diffrax
    import jax
    import jax.numpy as jnp

    from jrigid import simulate

    scene, state = problem.scene(), problem.state()
    ts = jnp.linspace(0.0, problem.t1, T)
    y0, term = jnp.asarray(problem.y0()), diffrax.ODETerm(problem.jax_rhs())

    def default(scene, state, ts):
        traj = simulate(scene, state, ts, rtol=RTOL, atol=ATOL, throw=False)
        return traj.q, traj.omega

    def hand(y0, ts, rtol, atol):
        sol = diffrax.diffeqsolve(
            term, diffrax.Dopri8(), 0.0, problem.t1, None, y0, saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol), max_steps=100_000,
        )
        return sol.ys[:, :4] / jnp.linalg.norm(sol.ys[:, :4], axis=-1, keepdims=True), sol.ys[:, 4:]

    def plain():
        traj = simulate(scene, state, ts, rtol=RTOL, atol=ATOL)
        return traj.q, traj.omega

    jitted, seconds = harness.warm_jit(jax.jit(default), scene, state, ts)
    hand_jit = jax.jit(hand)
    loose = (jnp.asarray(RTOL), jnp.asarray(ATOL))
    tight = tuple(jnp.asarray(x) for x in HAND_TIGHT)
    _, hand_seconds = harness.warm_jit(hand_jit, y0, ts, *loose)
    return {
        JITTED: (lambda: jitted(scene, state, ts), seconds),
        PLAIN: (plain, None),
        f"hand-written diffrax Dopri8, rtol {RTOL:g}": (lambda: hand_jit(y0, ts, *loose),
                                                        hand_seconds),
        f"hand-written diffrax Dopri8, rtol {HAND_TIGHT[0]:g}": (
            lambda: hand_jit(y0, ts, *tight), None),
    }


def main(argv=None) -> dict:
    parser = harness.command_line(__doc__, quick="T = 2 and 101 only, fewer rounds")
    args = parser.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import speed_vs_error as sve

    problem = sve.FREE_ROTOR
    ref = sve.reference(problem, quick=False)
    machine = harness.machine_line()
    counts = (2, 101) if args.quick else COUNTS
    rows, data = [], []
    for T in counts:
        entries = calls(problem, T)
        timed = harness.time_interleaved({k: c for k, (c, _) in entries.items()},
                                         20 if args.quick else 100, min_time=0.2)
        # A script's loop: the plain call and the jitted one, each in runs of up to 30
        # back-to-back calls (above, the batches of 8 or fewer alternate with the other
        # compiled calls, and the first one or two calls of a batch find cold caches).
        looped = harness.time_interleaved(
            {LOOP_JIT: entries[JITTED][0], LOOP_PLAIN: entries[PLAIN][0]},
            5 if args.quick else 10, min_time=0.3, max_inner=30)
        timed.update(looped)
        entries.update({LOOP_JIT: (None, None), LOOP_PLAIN: (None, None)})
        for label, (timing, out) in timed.items():
            q, w = (np.asarray(a)[-1] for a in out)
            error = max(harness.omega_error(w, ref["omega"]), harness.quaternion_error(q, ref["q"]))
            compile_s = entries[label][1]
            rows.append([T, label, "—" if compile_s is None else f"{compile_s:.1f} s",
                         harness.fmt_seconds(timing.median), f"{error:.1g}"])
            data.append(dict(T=T, method=label, compile=compile_s, median=timing.median,
                             fastest=timing.min, error=error))
            print(f"T={T}: {label}: {timing.median * 1e6:.0f} µs, error {error:.1g}", flush=True)
    table = harness.markdown_table(["T", "call", "compile", "run (median)", "final error"], rows)
    text = (f"# A default call with T output times\n\nMachine: {machine}.\n\n"
            f"Free rotor, t = 0…100, float64; reference {ref['source']}.\n\n{table}\n")
    out = harness.results_dir(args.out)
    name = harness.stem("outputs", args.quick)
    harness.write_text(out / f"{name}.md", text)
    harness.write_json(out / f"{name}.json", {"machine": machine, "rows": data})
    print(text)
    return {"rows": data}


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
