"""A thin rod spinning freely: ω precesses about the rod's axis while L stays fixed in space.

Problem 17.7. A solid cylinder of length ``ℓ`` and radius ``r ≪ ℓ``
(:func:`jrigid.inertia.solid_cylinder`: ``I1 = I2 = m(3r² + ℓ²)/12``, ``I3 = m r²/2``)
tumbles with ``ω = (ω⊥, 0, ω3)`` in the body frame. No torque acts, so ``L`` is constant in
space; but ``L = (I1 ω1, I1 ω2, I3 ω3)`` is not parallel to ``ω``, and in the body frame
Euler's equations turn ``ω`` about the rod's axis at ``Ω = (I3/I1 − 1) ω3`` (the form of
17.47): backwards, at nearly ``−ω3`` for a thin rod (``I3 ≪ I1``), i.e. ``ω`` and ``L`` hold
still in space while the rod spins under them. Seen from space, the rod's axis turns about
``L`` at ``φ̇ = |L|/I1``. Checks, with :func:`jrigid.simulate`, that

* ``L_space`` is constant and ``ω3`` is constant;
* the measured body-frame precession rate of ``ω`` equals ``(I3/I1 − 1) ω3`` and the space
  precession of the axis ``|L|/I1``, over a sweep of the rod's radius (``I3/I1`` from
  ~1e-4 to ~0.1): the frequency is set by the moments of inertia.

Run it with ``jrigid run thin_rod [--quick]``.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import inertia, initial, theory, viz
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.report import Report
from jrigid.scene import Scene


def tumble(moments, omega0, n, periods=3.0):
    """Simulate; measured and theoretical body and space precession rates."""
    body_rate = float(theory.body_precession_rate(moments, omega0))
    space_rate = float(theory.plate_theory(moments, omega0)["precession_rate"])
    span = periods * 2 * np.pi / min(abs(body_rate), space_rate)
    ts = jnp.linspace(0.0, span, n)
    traj = simulate(Scene(RigidBody(jnp.asarray(moments))),
                    initial.from_omega(None, jnp.asarray(omega0)), ts)  # fmt: skip
    w = np.asarray(traj.omega)
    measured = float(theory.omega_phase_rate(ts, w, axis=2))
    space = float(theory.wobble_to_spin(traj.ts, traj.q, traj.L_space)["precession_rate"])
    return traj, dict(body=measured, body_theory=body_rate, space=space, space_theory=space_rate)


def main(
    out_dir,
    quick: bool = False,
    *,
    length: float = 1.0,
    radius: float = 0.02,
    omega_perp: float = 1.0,
    omega_axis: float = 3.0,
    radii: tuple = (0.005, 0.01, 0.02, 0.05, 0.1, 0.2),
    samples: int = 1201,
) -> dict:
    """Tumble the rod, measure the precession of ω (body) and of the axis (space).

    Args:
        out_dir: results folder.
        quick: fewer samples and sweep points.
        length: rod length ``ℓ`` (mass 1).
        radius: rod radius ``r`` of the main run.
        omega_perp, omega_axis: initial ``ω⊥`` and ``ω3`` (rad/s, body frame).
        radii: radii for the sweep of the precession frequency.
        samples: output samples.

    Returns:
        the numbers written to ``numbers.json``.
    """
    n = 401 if quick else samples
    radii = tuple(radii)[::2] if quick else tuple(radii)
    omega0 = np.array([omega_perp, 0.0, omega_axis])
    moments = np.asarray(inertia.solid_cylinder(1.0, radius, length))
    traj, r = tumble(moments, omega0, n)
    Ls = np.asarray(traj.L_space)
    w = np.asarray(traj.omega)
    sweep = [tumble(np.asarray(inertia.solid_cylinder(1.0, a, length)), omega0, n)[1]
             for a in radii]  # fmt: skip
    ratios = [float(m[2] / m[0]) for m in (inertia.solid_cylinder(1.0, a, length) for a in radii)]
    col = lambda key: np.array([s[key] for s in sweep])  # noqa: E731
    numbers = {
        "moments": moments,
        "I3_over_I1": float(moments[2] / moments[0]),
        "L_space_max_rel_change": float(
            np.max(np.linalg.norm(Ls - Ls[0], axis=-1)) / np.linalg.norm(Ls[0])
        ),  # fmt: skip
        "omega3_spread": float(np.ptp(w[:, 2])),
        "angle_L_omega_deg": float(
            np.degrees(
                np.arccos(
                    np.dot(Ls[0], np.asarray(traj.omega_space[0]))
                    / (np.linalg.norm(Ls[0]) * np.linalg.norm(omega0))
                )
            )
        ),  # fmt: skip
        "body_precession_measured": r["body"],
        "body_precession_theory": r["body_theory"],
        "space_precession_measured": r["space"],
        "space_precession_theory": r["space_theory"],
        "sweep_radius": list(radii),
        "sweep_I3_over_I1": ratios,
        "sweep_body_measured": col("body"),
        "sweep_body_theory": col("body_theory"),
        "sweep_space_measured": col("space"),
        "sweep_space_theory": col("space_theory"),
        "samples": n,
    }

    rep = Report(Path(out_dir), title="Free rotation of a thin rod (Problem 17.7)")
    rep.text(
        f"A rod ℓ = {length:g}, r = {radius:g} (I3/I1 = {numbers['I3_over_I1']:.3e}) starts with "
        f"ω = {omega0.tolist()} (body). L stays fixed in space (largest relative change "
        f"{numbers['L_space_max_rel_change']:.1e}), at {numbers['angle_L_omega_deg']:.2f}° "
        f"from ω. In the body frame ω turns about the rod's axis at {r['body']:.8f} rad/s, "
        f"(I3/I1 − 1) ω3 = {r['body_theory']:.8f}: nearly −ω3, the rod spinning under a fixed ω. "
        f"From space the axis precesses about L at {r['space']:.8f} rad/s, |L|/I1 = "
        f"{r['space_theory']:.8f}."
    )
    rep.table(list(zip(radii, ratios, col("body"), col("body_theory"), col("space"),
                       col("space_theory"), strict=True)),
              headers=("r", "I3/I1", "Ω body", "(I3/I1−1)ω3", "φ̇ space", "|L|/I1"),
              digits=7)  # fmt: skip
    dt = float(traj.ts[1] - traj.ts[0])
    fig = viz.space_body_views(
        traj,
        viz.rod(length, max(radius, length / 40)),
        trail=int(2 * np.pi / abs(r["body_theory"]) / dt),
        dpi=60,
    )
    rep.figure("rod", fig, caption="space frame: L fixed, the axis circles it; body frame: "
               "ω and L circle the rod's axis", dpi=60)  # fmt: skip
    fig = viz.new_figure(figsize=(5, 3.2))
    ax = fig.add_subplot(1, 1, 1)
    ax.semilogx(ratios, col("body"), "o", label="Ω of ω about the axis (body)")
    ax.semilogx(ratios, col("body_theory"), "k-", lw=0.8, label="(I3/I1 − 1) ω3")
    ax.semilogx(ratios, col("space"), "s", label="φ̇ of the axis about L (space)")
    ax.semilogx(ratios, col("space_theory"), "k--", lw=0.8, label="|L|/I1")
    ax.set_xlabel("I3 / I1")
    ax.set_ylabel("rate (rad/s)")
    ax.legend(fontsize=7)
    rep.figure("rates", fig, caption="precession rates against the moments of inertia", dpi=70)
    rep.numbers(numbers)
    rep.write_summary()
    print(f"thin_rod: Ω {r['body']:.8f} (theory {r['body_theory']:.8f})")
    return numbers


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "thin_rod")
