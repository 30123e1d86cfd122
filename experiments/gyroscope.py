"""The chapter's gyroscope: slow and fast steady precession (17.51), and nutation otherwise.

Section 17.6 and Problem 17.8. An ellipsoid of radius ``R`` and thickness ``R/5`` (semi-axes
``R, R, R/10``, :func:`jrigid.inertia.ellipsoid`; mass ``M = 1``) on a massless axle, its
centre ``z0`` from a frictionless pivot, ``g = 1``: a :class:`~jrigid.scene.Scene` with
:class:`~jrigid.scene.Pivot` and :class:`~jrigid.scene.Gravity`, integrated by
:func:`jrigid.simulate`. ``I1`` below is the moment about the pivot, ``I1c + M z0²``.

*Steady precession.* In ZXZ Euler angles (``θ`` the axle's angle from the vertical,
``φ̇ = Ω``, ``ω3 = ψ̇ + Ω cos θ``) the ``θ`` equation of the heavy top with ``θ̇ = θ̈ = 0``
is ``I1 Ω² cos θ − I3 ω3 Ω + M g l = 0`` (``l = z0``), whose two roots are the steady
rates. For a fast top (``I3² ω3² ≫ 4 I1 M g l cos θ``) they are close to

    slow  Ω ≈ M g l / (I3 ω3)          (the chapter's 17.51b),
    fast  Ω ≈ I3 ω3 / (I1 cos θ)       (17.51a; its ``Is`` is ``I1``, its ``w3`` is ``ω3``).

Started exactly on a root (:func:`jrigid.initial.from_euler_rates`) the top precesses at
that rate without nutation. Released with ``φ̇ = θ̇ = 0`` it nutates: ``θ`` oscillates
between ``θ0`` and about ``θ0 + 2 M g l I1 sin θ0 / (I3 ω3)²`` at the frequency
``I3 ω3 / I1``, and precesses on average at the slow rate. Checks all of these, and the
conservation of ``E``, ``L_z`` and ``L·e3 = I3 ω3``. Figures: the elevation angle of the
axle against time, and the space-frame view with the axle's trail.

Run it with ``jrigid run gyroscope [--quick]``.
"""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import inertia, initial, theory, viz
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.report import Report
from jrigid.scene import Gravity, Pivot, Scene


def top(radius: float = 1.0, z0: float = 1.0, g: float = 1.0) -> Scene:
    """The chapter's gyroscope: ellipsoid ``(R, R, R/10)``, mass 1, centre ``z0`` up the axle."""
    moments = inertia.ellipsoid(1.0, radius, radius, radius / 10)
    return Scene(RigidBody(moments, 1.0, (0.0, 0.0, z0)), Pivot(), Gravity(g))


def steady_roots(scene: Scene, theta, omega3):
    """Exact slow and fast roots of ``I1 Ω² cos θ − I3 ω3 Ω + M g l = 0`` and (17.51)
    (:func:`jrigid.theory.gyroscope_rates`), with ``I1``, ``I3`` and ``mgl``."""
    I1, I3 = float(scene.inertia()[0, 0]), float(scene.inertia()[2, 2])
    mgl = float(scene.body.mass * np.linalg.norm(scene.loads[0].g) * scene.body.com[2])
    rates = theory.gyroscope_rates(I1, I3, mgl, theta, omega3)
    return {**{k: float(v) for k, v in rates.items()}, "I1": I1, "I3": I3, "mgl": mgl}


def run(scene, theta, omega3, phi_dot, span, n, **kw):
    """Start at ``θ`` with ``φ̇ = phi_dot``, ``θ̇ = 0``, spin ``ω3``; return traj and angles."""
    state = initial.from_euler_rates(
        (0.0, theta, 0.0), (phi_dot, 0.0, omega3 - phi_dot * math.cos(theta))
    )
    traj = simulate(scene, state, jnp.linspace(0.0, span, n), **kw)
    axle = np.asarray(traj.axes[:, :, 2])  # body axis 3 in space
    th = np.arccos(np.clip(axle[:, 2], -1.0, 1.0))
    phi = np.unwrap(np.arctan2(axle[:, 0], -axle[:, 1]))
    return traj, th, phi


def main(
    out_dir,
    quick: bool = False,
    *,
    radius: float = 1.0,
    z0: float = 1.0,
    omega3: float = 20.0,
    theta_deg: float = 60.0,
    samples: int = 1201,
    nutations: float = 10.0,
) -> dict:
    """Demonstrate slow and fast steady precession and nutation of the chapter's top.

    Args:
        out_dir: results folder.
        quick: fewer samples.
        radius: ellipsoid radius ``R``.
        z0: distance from the pivot to the centre of mass.
        omega3: spin ``ω3`` (rad/s).
        theta_deg: angle ``θ0`` of the axle from the vertical.
        samples: output samples.
        nutations: nutation periods in the released run.

    Returns:
        the numbers written to ``numbers.json``.
    """
    n = 401 if quick else samples
    scene, theta = top(radius, z0), math.radians(theta_deg)
    r = steady_roots(scene, theta, omega3)
    out, runs = {}, {}
    for name in ("slow", "fast"):
        traj, th, phi = run(scene, theta, omega3, r[name], 2 * math.pi / r[name], n)
        runs[name] = (traj, th)
        E, Lz = np.asarray(traj.energy), np.asarray(traj.L_space[:, 2])
        out[name] = dict(rate_measured=viz.fit_rate(traj.ts, phi), rate_exact=r[name],
                         rate_approx=r[name + "_approx"], theta_ptp=float(np.ptp(th)),
                         energy_drift=float(np.ptp(E) / abs(E[0])),
                         Lz_drift=float(np.ptp(Lz) / abs(Lz[0])))  # fmt: skip
    fast_top = theory.fast_top_nutation(r["I1"], r["I3"], r["mgl"], theta, omega3)
    w_nut = float(fast_top["frequency"])
    traj, th, phi = run(scene, theta, omega3, 0.0, nutations * 2 * math.pi / w_nut, n)
    runs["released"] = (traj, th)
    crossings = np.asarray(theory.zero_crossings(traj.ts, th - th.mean()))
    L3 = np.asarray(traj.L[:, 2])
    nut = dict(
        frequency_measured=float(math.pi / np.mean(np.diff(crossings))),
        frequency_fast_top=w_nut,
        dip_measured=float(th.max() - theta),
        dip_fast_top=float(fast_top["dip"]),
        mean_rate_measured=viz.fit_rate(traj.ts, phi),
        mean_rate_slow=r["slow"],
        energy_drift=float(np.ptp(np.asarray(traj.energy)) / abs(float(traj.energy[0]))),
        L3_drift=float(np.ptp(L3) / abs(L3[0])),
    )
    numbers = {"moments_about_pivot": [r["I1"], r["I1"], r["I3"]], "mgl": r["mgl"],
               "theta0_deg": theta_deg, "omega3": omega3, **out, "nutation": nut,
               "samples": n}  # fmt: skip

    rep = Report(Path(out_dir), title="The gyroscope: steady precession and nutation")
    rep.text(
        f"Ellipsoid R = {radius:g} (thickness R/5), z0 = {z0:g}, M = g = 1: I1 = {r['I1']:.5f} "
        f"(about the pivot), I3 = {r['I3']:.5f}; spin ω3 = {omega3:g}, θ0 = {theta_deg:g}°. "
        "Steady precession rates (roots of I1 Ω² cos θ − I3 ω3 Ω + Mgl = 0) started exactly:"
    )
    rep.table([(k, v["rate_measured"], v["rate_exact"], v["rate_approx"], math.degrees(
        v["theta_ptp"])) for k, v in out.items()],
        headers=("", "Ω measured", "exact root", "(17.51)", "θ range (°)"), digits=8)  # fmt: skip
    rep.text(
        f"Released with φ̇ = 0 the axle nutates at {nut['frequency_measured']:.5f} rad/s (fast "
        f"top I3ω3/I1 = {w_nut:.5f}), dipping {math.degrees(nut['dip_measured']):.4f}° (fast top "
        f"{math.degrees(nut['dip_fast_top']):.4f}°), and precesses on average at "
        f"{nut['mean_rate_measured']:.5f} rad/s (slow root {r['slow']:.5f})."
    )
    fig = viz.new_figure(figsize=(9, 3))
    for k, (name, (tr, th_)) in enumerate(runs.items()):
        ax = fig.add_subplot(1, 3, k + 1)
        ax.plot(np.asarray(tr.ts), 90 - np.degrees(th_), lw=0.8)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("t (s)")
        ax.set_ylim(87.5 - theta_deg, 90.5 - theta_deg)  # same scale: steady runs are flat
        if k == 0:
            ax.set_ylabel("elevation of the axle (°)")
    rep.figure("elevation", fig, caption="elevation angle of the axle", dpi=70)
    mesh = viz.shapes.merge(
        viz.cylinder(0.03 * radius, 2 * z0), viz.shapes.transform_mesh(
            viz.ellipsoid(radius, radius, radius / 10), _lift(z0)))  # fmt: skip
    fig = viz.space_body_views(runs["released"][0], mesh, trail=n, dpi=60)
    rep.figure("top", fig, caption="released top: space frame with trails; body frame", dpi=60)
    rep.numbers(numbers)
    rep.write_summary()
    print(f"gyroscope: slow {out['slow']['rate_measured']:.6f} ({r['slow']:.6f}), "
          f"fast {out['fast']['rate_measured']:.6f} ({r['fast']:.6f})")  # fmt: skip
    return numbers


def _lift(z0):
    T = np.eye(4)
    T[2, 3] = z0
    return T


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "gyroscope")
