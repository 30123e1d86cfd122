"""Feynman's wobbling plate: the chapter's leapfrog and the adaptive solver; wobble/spin → 2.

Eqs. 17.45–17.46 and Problem 17.4. A plate (radius ``r``, thickness ``h``) spins about its
symmetry axis, tilted by ``θ`` from ``L``. Its axis wobbles about ``L`` at ``φ̇ = |L|/I1``
while it spins at ``ψ̇ = ω3 (I1 − I3)/I1``: ``|φ̇/ψ̇| = 2/((1 − h²/3r²) cos θ)``, → 2 for a
thin plate and small tilt (:func:`jrigid.theory.plate_theory`; measured by line fits,
:func:`jrigid.theory.wobble_to_spin`). The plate is integrated by :func:`jrigid.simulate`
(adaptive Tsit5, via :func:`jrigid.demo.run_plate`) and by the chapter's leapfrog
(:func:`jrigid.leapfrog.leapfrog`, both the literal listing, ``variant="chapter"``, and the
midpoint form). Checks

a. the measured ratio against theory over a sweep of tilts (small wobble → 2; the
   departure at large tilt is the 1/cos θ of the theory, not numerical error);
b. energy and ``|L|`` conservation of each method; the leapfrog keeps ``L`` exactly (no
   torque: the kicks vanish) and its orientation error against the adaptive run falls as
   ``dt²`` (midpoint) or ``dt`` (the chapter's listing, which takes ``q̇`` at ``q(t)``);
c. a rectangular tray (:func:`jrigid.inertia.box`, thin): the same 2:1 ratio at small tilt,
   but ``θ`` nutates (an elliptical wobble);
d. a spin near a diameter: no 2:1 wobble (ratio ``I3/((I3 − I1) cos θ)`` with θ near 90°);
e. the body-frame view beside the space-frame view.

Run it with ``jrigid run feynman_plate [--quick]``.
"""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import demo, inertia, initial, theory, viz
from jrigid import quaternion as quat
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.leapfrog import leapfrog
from jrigid.report import Report
from jrigid.scene import Scene


def _floats(values: dict) -> dict:
    """A :mod:`jrigid.theory` result as Python numbers."""
    return {k: float(v) for k, v in values.items()}


def _drift(x):
    x = np.asarray(x)
    return float(np.max(np.abs(x - x[0])) / np.max(np.abs(x[0])))


def _free(moments, omega0, span, n):
    """Torque-free run from ``omega0`` (body), identity start; wobble measurement."""
    ts = jnp.linspace(0.0, span, n)
    tr = simulate(
        Scene(RigidBody(jnp.asarray(moments))),
        initial.from_omega(None, jnp.asarray(omega0)),
        ts,
        rtol=1e-10,
        atol=1e-12,
    )
    ang = viz.euler_about(tr.q, tr.L_space, axis=2)
    return _floats(theory.wobble_to_spin(tr.ts, tr.q, tr.L_space)), float(np.ptp(ang[:, 1]))


def main(
    out_dir,
    quick: bool = False,
    *,
    radius: float = 1.0,
    thickness: float = 0.1,
    tilt_deg: float = 10.0,
    spin_hz: float = 1.0,
    tilts_deg: tuple = (1.0, 3.0, 10.0, 20.0, 40.0, 60.0),
    dts: tuple = (4e-3, 2e-3, 1e-3),
    tray: tuple = (1.0, 0.6, 0.02),
    tray_tilt_deg: float = 2.0,
    diameter_tilt_deg: float = 10.0,
    samples: int = 1201,
    frames: int = 90,
    gif: bool = True,
) -> dict:
    """Run the plate with both integrators, the tilt sweep, the tray and the diameter spin.

    Args:
        out_dir: results folder.
        quick: fewer samples, wobbles and sweep points; a tiny GIF.
        radius, thickness: the plate (mass 1).
        tilt_deg: angle θ between the plate's axis and ``L``.
        spin_hz: ``ω3 / 2π``.
        tilts_deg: tilts of the sweep of the ratio.
        dts: leapfrog steps (decreasing).
        tray: tray sides ``(a, b, c)``, ``c`` the thickness.
        tray_tilt_deg: tilt of the tray's ``L`` from its normal.
        diameter_tilt_deg: angle of ``ω`` from a diameter toward the axis.
        samples: output samples.
        frames: GIF frames.
        gif: write the animation.

    Returns:
        the numbers written to ``numbers.json``.
    """
    n = 401 if quick else samples
    wobbles = 2.5 if quick else 6.0
    tilts = tuple(tilts_deg)[1::2] if quick else tuple(tilts_deg)
    p = demo.run_plate(radius, thickness, tilt_deg, spin_hz, n, wobbles)
    tp, th = p["traj"], p["theory"]
    s0 = initial.from_omega(tp.q[0], jnp.asarray(p["omega0"]))
    lf = {}
    for variant in ("midpoint", "chapter"):
        for dt in dts:
            tr = leapfrog(tp.scene, s0, tp.ts, dt=dt, variant=variant)
            lf[variant, dt] = dict(
                q_error=float(np.max(np.asarray(quat.distance(tr.q, tp.q)))),
                energy_drift=_drift(tr.energy), L_drift=_drift(tr.L_space),
                ratio=float(theory.wobble_to_spin(tr.ts, tr.q, tr.L_space)["ratio"]))  # fmt: skip
    # the leapfrog cuts each output interval into ceil(Δ/dt) equal steps: fit the steps used
    gap = float(tp.ts[1] - tp.ts[0])
    steps = [gap / math.ceil(gap / dt) for dt in dts]
    order = {v: float(np.polyfit(np.log(steps), np.log([lf[v, d]["q_error"] for d in dts]), 1)[0])
             for v in ("midpoint", "chapter")}  # fmt: skip
    e_order = float(np.polyfit(np.log(steps), np.log([lf["midpoint", d]["energy_drift"]
                                                    for d in dts]), 1)[0])  # fmt: skip
    sweep = [demo.run_plate(radius, thickness, t, spin_hz, n, wobbles) for t in tilts]
    w3 = 2 * math.pi * spin_hz
    tm = np.asarray(inertia.box(1.0, *tray))
    tray_w = np.array([w3 * math.tan(math.radians(tray_tilt_deg)) * tm[2] / tm[0], 0.0, w3])
    tray_m, tray_nut = _free(tm, tray_w, wobbles * math.pi / w3, n)
    d = math.radians(diameter_tilt_deg)
    diam_w = w3 * np.array([math.cos(d), 0.0, math.sin(d)])
    diam_th = _floats(theory.plate_theory(p["moments"], diam_w))
    diam_m, _ = _free(p["moments"], diam_w, wobbles * 2 * math.pi / diam_th["precession_rate"], n)
    plate_nut = float(np.ptp(viz.euler_about(tp.q, tp.L_space, axis=2)[:, 1]))
    mid, chap = lf["midpoint", dts[-1]], lf["chapter", dts[-1]]
    numbers = {
        "moments": p["moments"],
        "theta_deg": math.degrees(th["theta"]),
        "ratio_adaptive": p["measured"]["ratio"],
        "ratio_leapfrog_midpoint": mid["ratio"],
        "ratio_leapfrog_chapter": chap["ratio"],
        "ratio_theory": th["ratio"],
        "ratio_thin_2_over_cos": th["ratio_thin"],
        "adaptive_energy_drift": _drift(tp.energy),
        "adaptive_L_drift": _drift(tp.L_space),
        "leapfrog_dts": list(dts),
        "leapfrog_steps_used": steps,
        "leapfrog": {f"{v}_{dt:g}": r for (v, dt), r in lf.items()},
        "leapfrog_q_error_order": order,
        "leapfrog_midpoint_energy_error_order": e_order,
        "plate_nutation_ptp_deg": math.degrees(plate_nut),
        "sweep_tilt_deg": list(tilts),
        "sweep_theta_deg": [math.degrees(s["theory"]["theta"]) for s in sweep],
        "sweep_ratio_measured": [s["measured"]["ratio"] for s in sweep],
        "sweep_ratio_theory": [s["theory"]["ratio"] for s in sweep],
        "sweep_ratio_thin": [s["theory"]["ratio_thin"] for s in sweep],
        "tray_moments": tm,
        "tray_ratio": tray_m["ratio"],
        "tray_theta_mean_deg": math.degrees(tray_m["theta"]),
        "tray_nutation_ptp_deg": math.degrees(tray_nut),
        "diameter_theta_deg": math.degrees(diam_th["theta"]),
        "diameter_ratio_measured": diam_m["ratio"],
        "diameter_ratio_theory": diam_th["ratio"],
        "samples": n,
    }

    rep = Report(Path(out_dir), title="Feynman's wobbling plate (Problem 17.4)")
    rep.text(
        f"Plate r = {radius:g}, h = {thickness:g}, tilt θ = {numbers['theta_deg']:.3f}°: wobble/"
        f"spin {p['measured']['ratio']:.8f} (adaptive), {mid['ratio']:.6f} (midpoint leapfrog, "
        f"dt = {dts[-1]:g}), {chap['ratio']:.6f} (the chapter's listing); theory "
        f"{th['ratio']:.8f}, thin plate 2/cos θ = {th['ratio_thin']:.6f}. Energy drift: adaptive "
        f"{numbers['adaptive_energy_drift']:.1e}, leapfrog {mid['energy_drift']:.1e} / "
        f"{chap['energy_drift']:.1e}; |L| drift: adaptive {numbers['adaptive_L_drift']:.1e}, "
        f"leapfrog {mid['L_drift']:.1e}. Leapfrog orientation error ∝ dt^{order['midpoint']:.2f} "
        f"(midpoint), dt^{order['chapter']:.2f} (chapter). A tray {tuple(tray)} at "
        f"{tray_tilt_deg:g}° wobbles {tray_m['ratio']:.4f}× as fast as it spins, with θ nutating "
        f"by {numbers['tray_nutation_ptp_deg']:.2f}°. Spun {diameter_tilt_deg:g}° off a diameter, "
        f"the plate's ratio is {diam_m['ratio']:.4f} (theory {diam_th['ratio']:.4f})."
    )
    rep.table(
        [
            (f"{v}, dt = {dt:g}", r["q_error"], r["energy_drift"], r["L_drift"], r["ratio"])
            for (v, dt), r in lf.items()
        ],
        headers=("leapfrog", "max q error (rad)", "energy drift", "|L| drift", "ratio"),
    )
    mesh = viz.disk(radius, thickness)
    dt_s = float(tp.ts[1] - tp.ts[0])
    fig = viz.space_body_views(tp, mesh, trail=int(p["wobble_period"] / dt_s), dpi=60)
    rep.figure("plate", fig, caption="space frame (left) and body frame (right)", dpi=60)
    fig = viz.new_figure(figsize=(9, 3.2))
    ax = fig.add_subplot(1, 2, 1)
    ax.plot(numbers["sweep_theta_deg"], numbers["sweep_ratio_measured"], "o", label="measured")
    grid = np.linspace(0.0, max(numbers["sweep_theta_deg"]), 100)
    c = th["ratio"] * math.cos(th["theta"])
    ax.plot(grid, c / np.cos(np.radians(grid)), "k-", lw=0.8, label="2/((1−h²/3r²) cos θ)")
    ax.plot(grid, 2 / np.cos(np.radians(grid)), "k:", lw=0.8, label="2/cos θ")
    ax.set_xlabel("θ (degrees)")
    ax.set_ylabel("wobble / spin")
    ax.legend(fontsize=7)
    ax = fig.add_subplot(1, 2, 2)
    for v, mark in (("midpoint", "o-"), ("chapter", "s-")):
        errs = [lf[v, d]["q_error"] for d in dts]
        ax.loglog(steps, errs, mark, label=f"{v} (order {order[v]:.2f})")
    ax.set_xlabel("dt (s)")
    ax.set_ylabel("max orientation error (rad)")
    ax.legend(fontsize=7)
    rep.figure("ratio_and_leapfrog", fig, caption="wobble/spin; leapfrog error", dpi=70)
    if gif:
        nf = 12 if quick else frames
        span = min(float(tp.ts[-1]), 3 * p["wobble_period"], nf / (8 * spin_hz))
        paths = viz.animate(tp, mesh, rep.path("plate.gif"), n_frames=nf, t_span=(0.0, span),
                            trail=nf // 3, mp4=False,
                            size_px=(240, 120) if quick else (400, 200))  # fmt: skip
        rep.image(paths[0], "the wobbling plate")
    rep.numbers(numbers)
    rep.write_summary()
    print(f"feynman_plate: wobble/spin {p['measured']['ratio']:.8f} (theory {th['ratio']:.8f})")
    return numbers


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "feynman_plate")
