"""Dzhanibekov's T-handle: spun about its middle axis it flips periodically, every 2K(m)/λ.

A T-handle (two solid cylinders, :func:`jrigid.inertia.t_handle_moments`) spins about its
intermediate principal axis with ``ω`` tilted by a small angle ``ε`` toward the axis of
largest moment. Torque free, it turns over and back again and again. Euler's equations are
solved by Jacobi elliptic functions; the intermediate component ``ω_B ∝ sn(λt + c | m)``
changes sign every ``2K(m)/λ`` (:func:`jrigid.theory.flip_theory`). Checks that

* the mean spacing of the sign changes of ``ω_B`` in the simulation (:func:`jrigid.simulate`)
  equals ``2K/λ`` and half the period of the closed-form solution
  (:func:`jrigid.exact.omega_period`), and the simulated ``ω(t)``, ``q(t)`` follow
  :func:`jrigid.exact.solve`;
* the flip interval grows like ``log(1/ε)`` as the tilt shrinks (a sweep over ``ε``).

Run it with ``jrigid run dzhanibekov [--quick]`` or ``python experiments/dzhanibekov.py``.
"""

from __future__ import annotations

import math
from pathlib import Path

import jax
import numpy as np

from jrigid import demo, viz
from jrigid.report import Report


def main(
    out_dir,
    quick: bool = False,
    *,
    tilt_deg: float = 1.0,
    spin_hz: float = 1.5,
    intervals: float = 4.6,
    sweep_deg: tuple = (0.1, 0.3, 1.0, 3.0, 10.0),
    samples: int = 1201,
    frames: int = 90,
    gif: bool = True,
) -> dict:
    """Spin the T-handle about its middle axis, time its flips, compare with theory.

    Args:
        out_dir: results folder.
        quick: fewer samples and flips, a short sweep, a tiny GIF.
        tilt_deg: tilt ``ε`` of the initial ω from the intermediate axis (degrees).
        spin_hz: ``|ω| / 2π``.
        intervals: simulated time in flip intervals.
        sweep_deg: tilts of the sweep of flip interval against ``ε``.
        samples: output samples per simulation.
        frames: GIF frames.
        gif: write the animation.

    Returns:
        the numbers written to ``numbers.json``.
    """
    n = 401 if quick else samples
    intervals = min(intervals, 2.6) if quick else intervals
    sweep = tuple(sweep_deg)[1:4] if quick else tuple(sweep_deg)
    h = demo.run_t_handle(tilt_deg, spin_hz, n, intervals, compare_exact=True)
    th, traj, mid = h["theory"], h["traj"], h["mid"]
    E = np.asarray(traj.energy)
    Ls = np.linalg.norm(np.asarray(traj.L_space), axis=-1)

    rows = []
    for eps in sweep:
        s = demo.run_t_handle(eps, spin_hz, n, 2.6, compare_exact=False)
        rows.append((eps, s["flip_interval"], s["theory"]["flip_interval"], len(s["crossings"])))
    sweep_meas = np.array([r[1] for r in rows])
    sweep_theory = np.array([r[2] for r in rows])
    # log(1/ε) law: slope of the interval against ln(1/ε) -> 2/λ0 with λ0 the linear growth rate
    slope = float(np.polyfit(np.log(1 / np.radians(sweep)), sweep_theory, 1)[0])
    A, B, C = np.sort(h["moments"])
    w = 2 * math.pi * spin_hz
    growth = w * math.sqrt((C - B) * (B - A) / (A * C))  # linearised rate about the middle axis
    numbers = {
        "moments": h["moments"],
        "intermediate_axis_index": mid,  # 0-based, as theory.flip_theory's axis
        "tilt_deg": tilt_deg,
        "flip_interval_measured": h["flip_interval"],
        "flip_interval_theory": th["flip_interval"],
        "flip_interval_exact_solution": h["exact"]["period"] / 2,
        "period_theory": th["period"],
        "elliptic_m1": th["m1"],
        "flips_seen": len(h["crossings"]),
        "crossing_times": h["crossings"],
        "omega_vs_exact_max_rel_error": h["exact"]["omega_error"],
        "q_vs_exact_max_angle": h["exact"]["q_error"],
        "energy_rel_drift": float(np.max(np.abs(E / E[0] - 1))),
        "L_norm_rel_drift": float(np.max(np.abs(Ls / Ls[0] - 1))),
        "sweep_tilt_deg": list(sweep),
        "sweep_flip_interval_measured": sweep_meas,
        "sweep_flip_interval_theory": sweep_theory,
        "sweep_max_rel_error": float(np.max(np.abs(sweep_meas / sweep_theory - 1))),
        "sweep_slope_vs_log_inverse_tilt": slope,
        "linear_growth_rate": growth,
        "slope_theory_2_over_growth": 2 / growth,
        "samples": n,
    }

    rep = Report(Path(out_dir), title="Dzhanibekov's T-handle")
    rep.text(
        f"A T-handle with moments {np.round(h['moments'], 5).tolist()} spins at {spin_hz:g} Hz "
        f"about its intermediate axis {mid + 1}, tilted {tilt_deg:g}°. It flips every "
        f"{h['flip_interval']:.6f} s (mean spacing of the sign changes of ω{mid + 1}); "
        f"theory 2K(m)/λ = {th['flip_interval']:.6f} s (1 − m = {th['m1']:.3e}), half the "
        f"period of the closed-form solution {numbers['flip_interval_exact_solution']:.6f} s. "
        f"The simulated ω follows `jrigid.exact` to {h['exact']['omega_error']:.1e} (relative), "
        f"q to {h['exact']['q_error']:.1e} rad."
    )
    rep.table(
        [(f"{e:g}", m, t, c) for e, m, t, c in rows],
        headers=("tilt ε (°)", "flip interval (measured)", "2K/λ", "flips seen"),
        digits=8,
    )
    fig = viz.plot_omega(traj)
    for t in h["crossings"]:
        fig.axes[0].axvline(t, color="#999999", lw=0.8, ls="--")
    rep.figure("omega", fig, caption="body angular velocity; dashed: the flips", dpi=70)
    fig = viz.new_figure(figsize=(5, 3.2))
    ax = fig.add_subplot(1, 1, 1)
    ax.semilogx(sweep, sweep_meas, "o", label="measured")
    ax.semilogx(sweep, sweep_theory, "k-", lw=0.8, label="2K(m)/λ")
    ax.set_xlabel("tilt ε (degrees)")
    ax.set_ylabel("flip interval (s)")
    ax.legend(fontsize=8)
    rep.figure("sweep", fig, caption="flip interval against the tilt: grows like log(1/ε)", dpi=70)
    mesh = viz.t_handle()
    dt = float(traj.ts[1] - traj.ts[0])
    fig = viz.space_body_views(traj, mesh, trail=int(1.5 * h["turn"] / dt), dpi=60)
    rep.figure("t_handle", fig, caption="space frame and body frame", dpi=60)
    if gif:
        nf = 6 if quick else frames
        span = min(float(traj.ts[-1]), 1.8 * th["flip_interval"], nf * h["turn"] / 8)
        paths = viz.animate(traj, mesh, rep.path("t_handle.gif"), n_frames=nf, fps=20,
                            t_span=(0.0, span), trail=nf // 3, mp4=False,
                            size_px=(240, 120) if quick else (400, 200))  # fmt: skip
        rep.image(paths[0], "the T-handle flipping")
    rep.numbers(numbers)
    rep.write_summary()
    print(f"dzhanibekov: flip interval {h['flip_interval']:.6f} s "
          f"(theory {th['flip_interval']:.6f})")  # fmt: skip
    return numbers


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "dzhanibekov")
