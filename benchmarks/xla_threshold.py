"""What raising XLA:CPU's small-while-loop threshold on import (``jrigid._xla``) buys.

Each setting runs in a fresh interpreter (``XLA_FLAGS`` is read once, when JAX starts its
backend): jrigid's 100 MB threshold, and XLA's own 1 kB default (what a process gets when
the threshold is set back, or when jrigid is imported after JAX has run). Both time the
same calls, on the free rotor of ``speed_vs_error.py`` (moments (1, 2, 3), ω0 = (1, 0.3,
0.7), ``harness.Problem``), float64:

* ``simulate`` with its defaults (rtol 1e-8) over t = 0…100, saving 2 and 101 times;
* a hand-written ``diffrax.diffeqsolve`` of ``(q, ω)`` (``Problem.jax_rhs``) with ``Tsit5``
  and ``PIDController`` (rtol 1e-8, atol 1e-10), saving the same 101 times: the peer, whose
  loop the threshold changes the same way (it depends on ``XLA_FLAGS`` only);
* the reverse-mode gradient of a loss over 41 saved states (t = 0…20) with respect to
  the moments and ω0, through ``simulate``'s defaults;
* ``simulate_many`` over 1024 random ω0, 41 saved times over t = 0…20.

Compile time is the first call; run time is the median (and fastest) of the next calls
(at least 20, and 0.5 s of them). The outputs of the two settings are compared: their
largest difference is printed.

Usage: ``python benchmarks/xla_threshold.py`` (about 2 minutes on 2 cores). Writes
``xla_threshold.json`` and ``.md`` to ``benchmarks/results/`` (``--out DIR``).
"""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys
import time

HERE = pathlib.Path(__file__).resolve().parent
OPTION = "xla_cpu_small_while_loop_byte_threshold"
SETTINGS = {"jrigid (100 MB)": 100_000_000, "XLA default (1 kB)": 1024}
CASES = {
    "simulate, 2 times": "default call saving t0 and t1",
    "simulate, 101 times": "default call saving 101 times",
    "hand-written diffrax, 101 times": "diffeqsolve of (q, ω) + Tsit5",
    "gradient through simulate": "jax.grad of a loss over 41 states",
    "simulate_many, 1024 members": "41 times each",
}


def _child() -> None:
    """Time every case in this process (``XLA_FLAGS`` set by the parent); print JSON."""
    sys.path.insert(0, str(HERE))
    import diffrax
    import harness
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jrigid import initial, simulate
    from jrigid.body import RigidBody
    from jrigid.ensemble import simulate_many
    from jrigid.scene import Scene

    jax.config.update("jax_enable_x64", True)
    rotor = harness.Problem(key="free_rotor", title="free rotor", moments=(1.0, 2.0, 3.0),
                            omega0=(1.0, 0.3, 0.7))
    scene, state = rotor.scene(), rotor.state()
    calls = {}
    for n in (2, 101):
        ts = jnp.linspace(0.0, rotor.t1, n)
        calls[f"simulate, {n} times"] = (
            jax.jit(lambda s, ts=ts: simulate(scene, s, ts).q), (state,))

    ts101 = jnp.linspace(0.0, rotor.t1, 101)

    def peer(y0):
        return diffrax.diffeqsolve(
            diffrax.ODETerm(rotor.jax_rhs()), diffrax.Tsit5(), 0.0, rotor.t1, None, y0,
            saveat=diffrax.SaveAt(ts=ts101),
            stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-10),
            max_steps=100_000).ys

    calls["hand-written diffrax, 101 times"] = (jax.jit(peer), (jnp.asarray(rotor.y0()),))
    ts41 = jnp.linspace(0.0, 20.0, 41)

    def loss(m, w):
        traj = simulate(Scene(RigidBody(m)), initial.from_omega(state.q, w), ts41)
        return jnp.sum(traj.omega ** 2) + jnp.sum(traj.q[:, 1])

    calls["gradient through simulate"] = (
        jax.jit(jax.grad(loss, argnums=(0, 1))), (jnp.array(rotor.moments), state.omega))
    omegas = jnp.asarray(np.random.default_rng(0).normal(size=(1024, 3)))
    states = jax.vmap(lambda w: initial.from_omega(state.q, w))(omegas)
    calls["simulate_many, 1024 members"] = (
        lambda s: simulate_many(scene, s, ts41, progress=False)["q"], (states,))
    out = {}
    for name, (fn, args) in calls.items():
        start = time.perf_counter()
        value = jax.block_until_ready(fn(*args))
        compile_s = time.perf_counter() - start
        runs = []
        while len(runs) < 20 or sum(runs) < 0.5:
            start = time.perf_counter()
            jax.block_until_ready(fn(*args))
            runs.append(time.perf_counter() - start)
        flat = np.concatenate([np.ravel(np.asarray(v)) for v in jax.tree_util.tree_leaves(value)])
        out[name] = {"compile_s": compile_s, "median_s": float(np.median(runs)),
                     "min_s": float(np.min(runs)), "runs": len(runs), "value": flat.tolist()}
    print(json.dumps(out))


def _run_child(threshold: int) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env.update(JAX_PLATFORMS="cpu", XLA_FLAGS=f"--xla_backend_extra_options={OPTION}={threshold}")
    proc = subprocess.run([sys.executable, __file__, "--child"], env=env, check=True,
                          capture_output=True, text=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    sys.path.insert(0, str(HERE))
    import harness
    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)  # as in the timed interpreters

    parser = harness.command_line(__doc__)
    args = parser.parse_args()
    log = harness.logger()
    machine = harness.machine_line()
    log(machine)
    results = {}
    for label, threshold in SETTINGS.items():
        results[label] = _run_child(threshold)
        log(f"{label}: done")
    fast, slow = (results[k] for k in SETTINGS)
    rows = []
    for case, what in CASES.items():
        a, b = fast[case], slow[case]
        diff = float(np.max(np.abs(np.asarray(a["value"]) - np.asarray(b["value"]))))
        rows.append([
            f"{case} ({what})",
            f"{a['compile_s']:.1f} s / {b['compile_s']:.1f} s",
            f"{a['median_s'] * 1e3:.3g} ms ({a['min_s'] * 1e3:.3g})",
            f"{b['median_s'] * 1e3:.3g} ms ({b['min_s'] * 1e3:.3g})",
            f"**{b['median_s'] / a['median_s']:.2g}×**",
            f"{diff:.1e}",
        ])
    table = harness.markdown_table(
        ["call", "compile, 100 MB / 1 kB", "run, 100 MB (fastest)", "run, 1 kB (fastest)",
         "1 kB ÷ 100 MB", "largest output difference"], rows)
    text = f"# XLA:CPU small-while-loop threshold\n\nMachine: {machine}.\n\n{table}\n"
    out = harness.results_dir(args.out)
    for r in results.values():
        for v in r.values():
            v.pop("value", None)
    harness.write_json(out / "xla_threshold.json", {"machine": machine, "results": results})
    harness.write_text(out / "xla_threshold.md", text)
    print(text)


if __name__ == "__main__":
    if sys.argv[1:] == ["--child"]:
        _child()
    else:
        main()
