"""The spinning top in closed form (Problem 17.2): the analytic heavy top beside the integrated one.

Problem 17.2 asks for a spinning-top visualization from "the Euler angle analytic solution
found in mechanics textbooks", with the initial spin and precession rates as inputs. The top
is the chapter's gyroscope (:func:`gyroscope.top`: ellipsoid ``R, R, R/10``, mass 1, centre
``z0`` up the axle from a frictionless pivot, ``g = 1``), started at tilt ``θ0`` with
precession rate ``φ̇0``, nutation rate ``θ̇0`` and spin rate ``ψ̇0`` (ZXZ angles about the
vertical; ``ω3 = ψ̇0 + φ̇0 cos θ0``).

The closed form (:mod:`jrigid.lagrange_top`) is the textbook one — ``u = cos θ`` oscillates
between two roots ``u1 < u2`` of the cubic ``f(u) = (1−u²)(α−βu) − (b−au)²`` as a Jacobi
``sn²``, and ``φ``, ``ψ`` follow from elliptic integrals of the third kind — written in
half-angle form so that it stays valid through ``θ = 0``. It is evaluated at every output
time independently and drawn beside :func:`jrigid.simulate` (``rtol = 1e-10``); the run fails
unless they agree (quaternions to ``1e-7`` rad, ``ω`` to ``1e-7`` relative). Reported: the
nutation period ``2K(m)/ω_n`` and range ``[acos u2, acos u1]`` against the ones measured on
the integrated run, the conservation of energy, ``L_z`` and ``L·e3`` along the closed form,
and the shape of the path of the axle's tip, which the sign of ``φ̇ = (b − a u)/(1 − u²)``
at the two turning points decides: waves (same sign), loops (opposite signs) or cusps
(``φ̇ = 0`` at the top, e.g. released with ``φ̇0 = θ̇0 = 0``).

Run it with ``jrigid run spinning_top [--quick] spin=10 precession=-0.5 tilt_deg=30``.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import initial, lagrange_top, theory, viz
from jrigid import quaternion as quat
from jrigid.integrate import simulate
from jrigid.report import Report
from jrigid.viz import render

try:
    from .gyroscope import top
except ImportError:  # run as a script
    from gyroscope import top

Q_TOL = 1e-7  # rad, closed form against the integrator at rtol 1e-10
W_TOL = 1e-7  # relative to max |ω|


def locus_kind(b_minus_au1: float, b_minus_au2: float, scale: float) -> str:
    """Shape of the path of the axle's tip from ``b − a u`` at the turning points ``u1 < u2``.

    ``φ̇ = (b − a u)/(1 − u²)``: of one sign at both turning points the tip waves, of
    opposite signs it loops, zero at the upper turning point ``u2`` it has cusps (zero at
    both: no nutation). ``scale`` sets what counts as zero (``1e-9 scale``).
    """
    tol = 1e-9 * scale
    lo, hi = (0.0 if abs(v) <= tol else math.copysign(1.0, v) for v in (b_minus_au1, b_minus_au2))
    if hi == 0.0:
        return "steady" if lo == 0.0 else "cusps"
    if lo == 0.0 or lo == hi:
        return "waves"
    return "loops"


def main(
    out_dir,
    quick: bool = False,
    *,
    spin: float = 10.0,
    precession: float = 0.0,
    tilt_deg: float = 30.0,
    nutation_rate: float = 0.0,
    radius: float = 1.0,
    z0: float = 1.0,
    nutations: float = 4.0,
    samples: int = 801,
) -> dict:
    """Draw the closed-form heavy top beside the integrated one and check they agree.

    Args:
        out_dir: results folder.
        quick: fewer samples and nutation periods.
        spin: initial spin rate ``ψ̇0`` (rad/s).
        precession: initial precession rate ``φ̇0`` (rad/s).
        tilt_deg: initial angle ``θ0`` of the axle from the vertical (degrees).
        nutation_rate: initial ``θ̇0`` (rad/s).
        radius: ellipsoid radius ``R``.
        z0: distance from the pivot to the centre of mass.
        nutations: nutation periods shown (steady motion: spin turns of ``2π/ω3``).
        samples: output samples.

    Returns:
        the numbers written to ``numbers.json``.

    Raises:
        AssertionError: the closed form and the integrator disagree.
    """
    n = 201 if quick else samples
    nutations = min(nutations, 2.0) if quick else nutations
    scene = top(radius, z0)
    theta0 = math.radians(tilt_deg)
    state = initial.from_euler_rates(
        (0.0, theta0, 0.0), (precession, nutation_rate, spin)
    )  # fmt: skip
    consts = lagrange_top.prepare_scene(scene, state.q, state.omega)
    period = float(lagrange_top.nutation_period(consts))
    u1, u2 = (float(u) for u in lagrange_top.nutation_range(consts))
    omega3 = float(state.omega[2])
    span = nutations * (period if math.isfinite(period) else 2 * math.pi / max(abs(omega3), 1e-3))
    ts = jnp.linspace(0.0, span, n)

    solve = jax.jit(lagrange_top.evaluate)
    t0 = time.perf_counter()
    q_an, w_an = jax.block_until_ready(solve(consts, ts))
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    q_an, w_an = jax.block_until_ready(solve(consts, ts))
    t_closed = time.perf_counter() - t0
    t0 = time.perf_counter()
    traj = simulate(scene, state, ts, rtol=1e-10, atol=1e-12, max_steps=1_000_000)
    jax.block_until_ready(traj.q)
    t_integrated = time.perf_counter() - t0

    q_err = float(jnp.max(quat.distance(q_an, traj.q)))
    w_scale = float(jnp.max(jnp.linalg.norm(traj.omega, axis=-1)))
    w_err = float(jnp.max(jnp.abs(w_an - traj.omega))) / w_scale
    if not (q_err < Q_TOL and w_err < W_TOL):
        raise AssertionError(
            f"closed form and integrator disagree: q by {q_err:.3g} rad (tolerance {Q_TOL:g}), "
            f"ω by {w_err:.3g} relative (tolerance {W_TOL:g})"
        )

    # invariants along the closed form: energy, L_z (space vertical), L·e3
    inertia = np.asarray(scene.inertia())
    big_a, big_c = inertia[0, 0], inertia[2, 2]
    mgl = float(scene.body.mass) * float(np.linalg.norm(scene.loads[0].g)) * z0
    q_np, w_np = np.asarray(q_an), np.asarray(w_an)
    axle = np.asarray(quat.rotate(q_an, jnp.array([0.0, 0.0, 1.0])))
    L_body = w_np * np.array([big_a, big_a, big_c])
    L_z = np.asarray(quat.rotate(q_an, jnp.asarray(L_body)))[:, 2]
    energy = 0.5 * np.sum(w_np * L_body, axis=-1) + mgl * axle[:, 2]
    drift = {name: float(np.ptp(v) / max(abs(v[0]), 1e-300))
             for name, v in (("energy", energy), ("L_z", L_z), ("L_3", L_body[:, 2]))}  # fmt: skip

    # the integrated run, measured: nutation period from crossings of the mid angle, range
    th_int = np.arccos(np.clip(np.asarray(traj.axes[:, 2, 2]), -1.0, 1.0))
    th_an = np.arccos(np.clip(axle[:, 2], -1.0, 1.0))
    t_np = np.asarray(ts)
    mid = 0.5 * (math.acos(u1) + math.acos(u2))
    crossings = np.asarray(theory.zero_crossings(t_np, th_int - mid))
    period_measured = float(np.mean(np.diff(crossings[::2]))) if len(crossings) > 2 else math.nan
    a, b = big_c * omega3 / big_a, float(L_z[0]) / big_a
    kind = locus_kind(b - a * u1, b - a * u2, abs(a) + abs(b) + 1e-300)

    numbers = {
        "spin": spin, "precession": precession, "tilt_deg": tilt_deg,
        "nutation_rate": nutation_rate, "omega3": omega3,
        "moments_about_pivot": [float(big_a), float(big_a), float(big_c)], "mgl": mgl,
        "nutation_period_closed_form": period, "nutation_period_measured": period_measured,
        "theta_min_deg_closed_form": math.degrees(math.acos(u2)),
        "theta_max_deg_closed_form": math.degrees(math.acos(u1)),
        "theta_min_deg_measured": math.degrees(float(th_int.min())),
        "theta_max_deg_measured": math.degrees(float(th_int.max())),
        "locus": kind, "b_minus_a_u1": b - a * u1, "b_minus_a_u2": b - a * u2,
        "q_closed_vs_integrated_max_rad": q_err, "omega_closed_vs_integrated_max_rel": w_err,
        "energy_drift_closed_form": drift["energy"], "Lz_drift_closed_form": drift["L_z"],
        "L3_drift_closed_form": drift["L_3"],
        "closed_form_s_per_sample": t_closed / n, "closed_form_compile_s": t_compile,
        "integrated_s": t_integrated, "span": span, "samples": n,
    }  # fmt: skip

    rep = Report(Path(out_dir), title="The spinning top in closed form (Problem 17.2)")
    rep.text(
        f"The chapter's top (ellipsoid R = {radius:g}, axle z0 = {z0:g}, M = g = 1; about the "
        f"pivot I1 = {big_a:.4f}, I3 = {big_c:.4f}) started at θ0 = {tilt_deg:g}° with "
        f"precession φ̇0 = {precession:g}, nutation θ̇0 = {nutation_rate:g} and spin ψ̇0 = "
        f"{spin:g} (ω3 = {omega3:.4f}). Closed form (`jrigid.lagrange_top`) and integrator "
        f"(`jrigid.simulate`, rtol 1e-10) agree to {q_err:.1e} rad in orientation and "
        f"{w_err:.1e} in ω over {span:.3g} s. The axle nutates between θ = "
        f"{numbers['theta_min_deg_closed_form']:.4f}° and "
        f"{numbers['theta_max_deg_closed_form']:.4f}° with period {period:.6g} s "
        f"(measured on the integrated run: {period_measured:.6g} s, "
        f"{numbers['theta_min_deg_measured']:.4f}° – {numbers['theta_max_deg_measured']:.4f}°); "
        f"its tip traces **{kind}**. Along the closed form energy, L_z and L·e3 stay constant "
        f"to {max(drift.values()):.1e}. Cost: {1e6 * t_closed / n:.2f} µs per sample after a "
        f"{t_compile:.1f} s compile, against {t_integrated:.2f} s for the integration "
        "(compilation included)."
    )
    rep.figure("tops", _draw_tops(scene, radius, z0, q_np, np.asarray(traj.q), axle,
               np.asarray(traj.axes[:, :, 2])), caption="left: closed form; right: integrated; "
               "the line is the path of the axle's tip", dpi=70)  # fmt: skip
    fig = viz.new_figure(figsize=(10, 3.2))
    ax = fig.add_subplot(1, 3, 1)
    ax.plot(t_np, np.degrees(th_an), lw=1.5, label="closed form")
    ax.plot(t_np[::4], np.degrees(th_int[::4]), ".", ms=3, label="integrated")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("θ (°)")
    ax.legend(fontsize=7)
    ax = fig.add_subplot(1, 3, 2)
    phi_an = np.unwrap(np.arctan2(axle[:, 0], -axle[:, 1]))
    axle_int = np.asarray(traj.axes[:, :, 2])
    phi_int = np.unwrap(np.arctan2(axle_int[:, 0], -axle_int[:, 1]))
    ax.plot(t_np, phi_an, lw=1.5, label="closed form")
    ax.plot(t_np[::4], phi_int[::4], ".", ms=3, label="integrated")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("φ (rad)")
    ax = fig.add_subplot(1, 3, 3)
    ax.plot(axle[:, 0], axle[:, 1], lw=1.2, label="closed form")
    ax.plot(axle_int[::4, 0], axle_int[::4, 1], ".", ms=3, label="integrated")
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_title(f"tip of the axle: {kind}", fontsize=9)
    rep.figure("angles", fig, caption="nutation θ, precession φ, and the axle's tip seen "
               "from above", dpi=70)  # fmt: skip
    rep.numbers(numbers)
    rep.write_summary()
    print(f"spinning_top: nutation period {period:.6f} (measured {period_measured:.6f}), "
          f"θ in [{numbers['theta_min_deg_closed_form']:.3f}°, "
          f"{numbers['theta_max_deg_closed_form']:.3f}°], {kind}; "
          f"closed form vs integrated {q_err:.1e} rad")  # fmt: skip
    return numbers


def _draw_tops(scene, radius, z0, q_an, q_int, tip_an, tip_int):
    """Two panels: the top at the last sample with the path of the axle's tip."""
    length = 2.0 * z0
    mesh = viz.shapes.merge(
        viz.shapes.transform_mesh(viz.cylinder(0.03 * radius, length), _lift(0.5 * length)),
        viz.shapes.transform_mesh(viz.ellipsoid(radius, radius, radius / 10), _lift(z0)),
    )
    camera = render.Camera(elev=40.0, azim=35.0)
    extent = 1.1 * max(length, math.hypot(z0, radius))
    fig = viz.new_figure(figsize=(7, 3.6), layout=None)
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=0.9, wspace=0.02)
    axes = fig.subplots(1, 2)
    panels = (("closed form", q_an, tip_an), ("integrated", q_int, tip_int))
    for ax, (title, q, tip) in zip(axes, panels, strict=True):
        render.setup_axes(ax, extent, title)
        ax.set_ylim(-0.6 * extent, extent)
        body = render.mesh_polygons(mesh, render.body_transform(q[-1]), camera)
        trail = render.polyline_polygons(length * tip, camera, "#d62728", width=0.015 * extent)
        render.draw_polygons(ax, render.combine(body, trail))
    return fig


def _lift(z0):
    T = np.eye(4)
    T[2, 3] = z0
    return T


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "spinning_top")
