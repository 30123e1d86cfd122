"""Constraint drift of the quaternion-acceleration form: projection vs stabilisation.

An asymmetric free body, moments (1, 2, 3), ω0 = (1, 0.3, 0.7), integrated with
:func:`jrigid.simulate`'s default solver over 10⁴ rotation periods (period 2π/|ω0|) at a
moderate tolerance. For each remedy — none, projection after every step (onto the
constraints and the invariants: the default), the stabilising term with gain γ, and
none with the chapter's ``q̈`` (``QuaternionAcceleration(centripetal=True)``) — report
the largest |q| − 1, q·q̇, relative energy and |L| errors (against their
exact initial values, which the torque-free motion conserves), the step count and the
run time (fastest of three runs after compilation). A pointwise trajectory error is not
reported: over 10⁴ periods at this tolerance it is dominated by the accumulated phase
error, O(1) for every remedy.

Usage: ``python benchmarks/constraint_drift.py [--periods 10000] [--rtol 1e-6]``.
Prints a markdown table and writes ``benchmarks/results/constraint_drift_rtol<rtol>.json``.
"""

from __future__ import annotations

import json
import math
import pathlib
import sys
import time

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import harness  # noqa: E402

from jrigid.body import RigidBody  # noqa: E402
from jrigid.formulations import QuaternionAcceleration  # noqa: E402
from jrigid.initial import from_omega  # noqa: E402
from jrigid.integrate import simulate  # noqa: E402
from jrigid.scene import Scene  # noqa: E402


def run(periods: float, rtol: float, atol: float, samples: int) -> list[dict]:
    scene = Scene(RigidBody(jnp.array([1.0, 2.0, 3.0])))
    omega0 = jnp.array([1.0, 0.3, 0.7])
    state = from_omega(None, omega0)
    period = 2 * math.pi / float(jnp.linalg.norm(omega0))
    ts = jnp.linspace(0.0, periods * period, samples)
    budget = int(200 * periods) + 10_000

    e0 = 0.5 * float(jnp.dot(omega0, scene.body.moments * omega0))
    l0 = float(jnp.linalg.norm(scene.body.moments * omega0))

    variants = [
        ("none", dict(project=False)),
        ("none, the chapter's q̈", dict(project=False,
                                        formulation=QuaternionAcceleration(centripetal=True))),
        ("projection", dict(project=True)),
    ] + [
        (f"stabilisation γ={g:g}", dict(project=False, formulation=QuaternionAcceleration(g)))
        for g in (0.5, 1.0, 2.0)
    ]
    rows = []
    for name, kwargs in variants:
        def call(kwargs=kwargs):
            return simulate(scene, state, ts, rtol=rtol, atol=atol, max_steps=budget, **kwargs)

        traj = call()
        jax.block_until_ready(traj.q)
        times = []
        for _ in range(3):  # fastest of three: robust to other load on the machine
            start = time.perf_counter()
            traj = call()
            jax.block_until_ready(traj.q)
            times.append(time.perf_counter() - start)
        seconds = min(times)
        energy = jnp.abs(traj.kinetic_energy - e0) / e0
        momentum = jnp.abs(jnp.linalg.norm(traj.L_space, axis=-1) - l0) / l0
        rows.append(
            dict(
                variant=name,
                max_norm_error=float(jnp.max(jnp.abs(traj.norm_error))),
                max_tangent_error=float(jnp.max(jnp.abs(traj.tangent_error))),
                max_energy_error=float(jnp.max(energy)),
                max_momentum_error=float(jnp.max(momentum)),
                steps=int(traj.stats["num_steps"]),
                seconds=seconds,
            )
        )
    return rows


def main() -> None:
    parser = harness.command_line(__doc__, out=False)
    parser.add_argument("--periods", type=float, default=1e4)
    parser.add_argument("--rtol", type=float, default=1e-6)
    parser.add_argument("--atol", type=float, default=1e-8)
    parser.add_argument("--samples", type=int, default=2001)
    args = parser.parse_args()
    rows = run(args.periods, args.rtol, args.atol, args.samples)
    print(
        f"Asymmetric free body (1, 2, 3), default solver, rtol={args.rtol:g}, atol={args.atol:g}, "
        f"{args.periods:g} rotation periods\n"
    )
    print("| remedy | max abs(abs(q)−1) | max abs(q·q̇) | max rel. energy err | "
          "max rel. abs(L) err | steps | time (s) |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['variant']} | {r['max_norm_error']:.2e} | {r['max_tangent_error']:.2e} | "
            f"{r['max_energy_error']:.2e} | {r['max_momentum_error']:.2e} | "
            f"{r['steps']} | {r['seconds']:.2f} |"
        )
    out = harness.results_dir()
    payload = dict(
        periods=args.periods, rtol=args.rtol, atol=args.atol, solver="default", rows=rows
    )
    (out / f"constraint_drift_rtol{args.rtol:g}.json").write_text(json.dumps(payload, indent=2))


if __name__ == "__main__":
    main()
