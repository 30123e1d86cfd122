"""Adjoint choice for fits: cost of a gradient relative to a forward solve.

A 9-parameter torque-free fit (moment ratios 2, initial spin 3, raw initial orientation
4) to a gyroscope record and an orientation record, through :func:`jrigid.simulate`
(Tsit5, rtol 1e-8). For records of several lengths, compare

- ``forward``: the loss alone;
- ``grad (reverse)``: ``jax.grad`` with diffrax's ``RecursiveCheckpointAdjoint``
  (simulate's default);
- ``grad (forward)``: ``jax.jacfwd`` of the loss with ``diffrax.ForwardMode()``;
- ``jacobian (forward)``: ``jax.jacfwd`` of the residual vector with ``ForwardMode`` (what
  :func:`jrigid.fit.laplace` uses);
- ``jacobian (reverse)``: ``jax.jacrev`` of the residuals (one backward pass per residual).

Time: median of several runs after ahead-of-time compilation (compile time reported
apart), interleaved so that machine load falls on all alike. Memory: XLA's
``memory_analysis()`` of the compiled program — the temporary buffers (scratch) plus
outputs, i.e. the peak the program needs beyond its inputs. Ratios are to ``forward``.

Usage: ``python benchmarks/fit_adjoint.py [--durations 4 16 64] [--quick]``. Prints a
markdown table and writes ``benchmarks/results/fit_adjoint[_quick].json``.
"""

from __future__ import annotations

import pathlib
import sys

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(pathlib.Path(__file__).parent))

import diffrax  # noqa: E402
import harness  # noqa: E402
from jax.flatten_util import ravel_pytree  # noqa: E402

from jrigid import exact, fit, initial  # noqa: E402
from jrigid.body import RigidBody  # noqa: E402
from jrigid.integrate import simulate  # noqa: E402
from jrigid.scene import Scene  # noqa: E402

MOMENTS = jnp.array([1.0, 2.0, 2.5]) / 5.5
OMEGA0 = jnp.array([0.3, 2.0, 0.2])
Q0 = jnp.array([0.9, 0.1, -0.3, 0.2]) / jnp.linalg.norm(jnp.array([0.9, 0.1, -0.3, 0.2]))


def build(theta):
    body = RigidBody(fit.moment_ratios(theta["shape"]))
    return Scene(body), initial.from_omega(fit.unit_quaternion(theta["q0"]), theta["omega0"])


def make_problem(duration: float, samples: int, adjoint) -> fit.Problem:
    ts = jnp.linspace(0.0, duration, samples)
    q, om = exact.solve(MOMENTS, Q0, OMEGA0, ts)
    rng = np.random.default_rng(0)
    obs = [
        fit.Gyroscope(ts, np.asarray(om) + 0.01 * rng.standard_normal(om.shape), sigma=0.01),
        fit.Orientations(ts, q, sigma=0.01),
    ]
    return fit.Problem(fit.Simulated(build, rtol=1e-8, atol=1e-10, adjoint=adjoint), obs)


def memory_bytes(compiled) -> int | None:
    try:
        m = compiled.memory_analysis()
        return int(m.temp_size_in_bytes + m.output_size_in_bytes)
    except Exception:  # noqa: BLE001 - backend without memory analysis
        return None


def measure(duration: float, samples: int, repeats: int) -> dict:
    theta = {"shape": fit.moment_ratios_raw(MOMENTS) + 0.1, "omega0": OMEGA0 * 1.02, "q0": Q0}
    flat, unravel = ravel_pytree(theta)
    reverse = make_problem(duration, samples, diffrax.RecursiveCheckpointAdjoint())
    forward = make_problem(duration, samples, diffrax.ForwardMode())
    fns = {
        "forward": jax.jit(lambda x: reverse.loss(unravel(x))),
        "grad (reverse)": jax.jit(jax.grad(lambda x: reverse.loss(unravel(x)))),
        "grad (forward)": jax.jit(jax.jacfwd(lambda x: forward.loss(unravel(x)))),
        "jacobian (forward)": jax.jit(jax.jacfwd(lambda x: forward.residuals(unravel(x)))),
        "jacobian (reverse)": jax.jit(jax.jacrev(lambda x: reverse.residuals(unravel(x)))),
    }
    compiled, compile_s, mem = {}, {}, {}
    for name, f in fns.items():
        compiled[name], compile_s[name] = harness.compile_jax(f, flat)
        mem[name] = memory_bytes(compiled[name])
    results = harness.time_interleaved(
        {k: (lambda c=c: c(flat)) for k, c in compiled.items()}, repeats, min_time=0.5
    )
    g_rev = np.asarray(results["grad (reverse)"][1])
    g_fwd = np.asarray(results["grad (forward)"][1])
    agree = float(np.max(np.abs(g_rev - g_fwd)) / np.max(np.abs(g_rev)))
    steps = int(
        simulate(*build(theta), reverse.ts, rtol=1e-8, atol=1e-10).stats["num_accepted_steps"]
    )
    t_fwd = results["forward"][0].median
    rows = {}
    for name in fns:
        t = results[name][0].median
        rows[name] = {
            "median_s": t,
            "time_ratio": t / t_fwd,
            "compile_s": compile_s[name],
            "memory_bytes": mem[name],
            "memory_ratio": None
            if mem[name] is None or not mem["forward"]
            else mem[name] / mem["forward"],
        }
    return {
        "duration": duration,
        "samples": samples,
        "parameters": int(flat.shape[0]),
        "residuals": reverse.size,
        "accepted_steps": steps,
        "grad_reverse_vs_forward_rel_diff": agree,
        "rows": rows,
    }


def main(argv=None) -> dict:
    parser = harness.command_line(__doc__, quick="one short record, few repeats", out=False)
    parser.add_argument("--durations", type=float, nargs="+", default=[4.0, 16.0, 64.0])
    args = parser.parse_args(argv)
    durations = [4.0] if args.quick else args.durations
    repeats = 3 if args.quick else 7
    out = {"machine": harness.machine_info(), "cases": []}
    lines = []
    for d in durations:
        samples = int(min(200, 10 * d)) + 1
        case = measure(d, samples, repeats)
        out["cases"].append(case)
        lines.append(
            f"\n**record {d:g} s, {samples} samples, {case['accepted_steps']} steps, "
            f"{case['parameters']} parameters, {case['residuals']} residuals** "
            "(reverse vs forward gradient rel. diff "
            f"{case['grad_reverse_vs_forward_rel_diff']:.1e})\n"
        )
        rows = []
        for name, r in case["rows"].items():
            mem = "n/a" if r["memory_bytes"] is None else f"{r['memory_bytes'] / 2**20:.2f} MiB"
            mem_ratio = "n/a" if r["memory_ratio"] is None else f"{r['memory_ratio']:.1f}×"
            rows.append(
                [
                    name,
                    f"{r['median_s'] * 1e3:.2f} ms",
                    f"{r['time_ratio']:.1f}×",
                    mem,
                    mem_ratio,
                    f"{r['compile_s']:.1f} s",
                ]
            )
        lines.append(
            harness.markdown_table(
                ["computation", "time", "time / forward", "memory", "memory / forward", "compile"],
                rows,
            )
        )
    text = harness.machine_line(out["machine"]) + "\n" + "\n".join(lines)
    print(text)
    name = harness.stem("fit_adjoint", args.quick)
    path = harness.write_json(harness.results_dir() / f"{name}.json", out)
    harness.write_text(harness.results_dir() / f"{name}.md", text + "\n")
    print(f"\nwrote {path}")
    return out


if __name__ == "__main__":
    main()
