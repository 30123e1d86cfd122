"""A tumbling box bouncing on a floor, in 2D and 3D: energy at each bounce, Project 17.3.

A box (sides ``a × b × c``, mass ``M``, :func:`jrigid.inertia.box`) is thrown spinning
above a floor: a :class:`~jrigid.scene.Scene` with :class:`~jrigid.scene.FreeFlight`,
:class:`~jrigid.scene.Gravity` and a :class:`jrigid.contact.Floor` whose contact points
are the box's corners, run by :func:`jrigid.contact.simulate_bounces` (diffrax event at
the lowest corner, impulse with restitution ``e`` and Coulomb friction ``μ``). Two
motions:

* **2D** — the box turns about its ``y`` axis and moves in the ``xz`` plane; the contact
  points are the four corners of the ``a × c`` rectangle (edge midpoints), so every
  impulse keeps the motion planar;
* **3D** — a general tumble (rotation and translation together), contact at the eight
  corners.

Each motion is run elastic and frictionless (``e = 1``, ``μ = 0``) and dissipative.
Checked at every bounce: energy (translational + rotational kinetic + potential) is
unchanged for ``e = 1, μ = 0``; the normal velocity of the contact corner is reversed
and scaled by ``e``; a frictionless impulse is vertical, so the horizontal momentum is
unchanged; any impulse conserves the angular momentum about the contact point.

*Translation against rotation (the chapter's question).* With ``e = 1, μ = 0`` the
horizontal momentum is conserved and in 3D so is ``L_z`` (a vertical impulse has no
torque about the vertical). What is left exchanges energy between the vertical motion,
the rotation and the height. If the bouncing is ergodic on its energy shell, the
microcanonical ensemble gives each momentum degree of freedom the same mean kinetic
energy (generalised equipartition, ``⟨p_i ∂H/∂p_i⟩ = Φ(E)/Φ'(E)``; the floor restricts
only positions). In 2D (``p_z``, ``p_θ``): ``⟨K_z⟩ = ⟨K_rot⟩ =
∫(E' − M g h(θ))² dθ / (4 ∫(E' − M g h(θ)) dθ)`` with ``h(θ)`` the height of the centre
when the lowest corner touches and ``E'`` the energy without the constant horizontal
part. In 3D with ``L_z = 0`` the rotation keeps two momentum degrees of freedom
(``p_θ, p_ψ`` at ``p_φ = 0``): ``⟨K_rot⟩ = 2 ⟨K_z⟩``. The averages below are time
averages over the run.

Run it with ``jrigid run falling_box [--quick]``.
"""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import contact, inertia, initial, viz
from jrigid import quaternion as quat
from jrigid.body import RigidBody
from jrigid.report import Report
from jrigid.scene import FreeFlight, Gravity, Scene
from jrigid.viz import render

RECT = [0, 1, 3, 2]  # polygon order of box_corners(planar=True)


def box_scene(size, mass, g, e, mu, planar):
    """The box above a floor; planar corners are listed twice (8 points, one compile)."""
    pts = contact.box_corners(size, planar=planar)
    if planar:
        pts = jnp.concatenate([pts, pts])  # same shapes as 3D: the solve compiles once
    body = RigidBody(inertia.box(mass, *size), mass)
    return Scene(body, FreeFlight(), (Gravity(g), contact.Floor(pts, 0.0, e, mu)))


def start(planar, height, tilt, spin):
    """Initial state: 2D spin about ``y``; 3D a tumble with ``L_z = 0`` (space frame)."""
    if planar:
        q0 = quat.from_axis_angle(jnp.array([0.0, 1.0, 0.0]), tilt)
        return initial.from_omega(q0, (0.0, spin, 0.0), frame="space",
                                  x=(0.0, 0.0, height), v=(0.4, 0.0, 0.0))  # fmt: skip
    axis = jnp.array([0.3, 1.0, 0.5]) / math.sqrt(1.34)
    q0 = quat.from_axis_angle(axis, tilt)
    return initial.from_omega(q0, (0.6 * spin, spin, 0.0), frame="space",
                              x=(0.0, 0.0, height), v=(0.0, 0.0, 0.0))  # fmt: skip


def equipartition_2d(scene, v_x, energy, n=4096):
    """Microcanonical ``⟨K_z⟩ = ⟨K_rot⟩`` of the planar elastic box (see the docstring)."""
    m, g = float(scene.body.mass), float(-scene.loads[0].g[2])
    pts = np.asarray(scene.loads[1].points)[:4]
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    # corner heights below the centre: z-component of R_y(θ) p = −x sin θ + z cos θ
    h = np.max(-(-np.outer(np.sin(th), pts[:, 0]) + np.outer(np.cos(th), pts[:, 2])), axis=1)
    free = energy - 0.5 * m * v_x**2 - m * g * h
    return float(np.sum(free**2) / (4 * np.sum(free)))


def energies(traj):
    """``(T,)`` arrays: vertical, horizontal, rotational kinetic and potential energy."""
    m = float(traj.scene.body.mass)
    v = np.asarray(traj.v)
    k_rot = 0.5 * np.sum(np.asarray(traj.omega) * np.asarray(traj.L), axis=-1)
    return dict(vertical=0.5 * m * v[:, 2] ** 2, horizontal=0.5 * m * np.sum(v[:, :2] ** 2, -1),
                rotation=k_rot, potential=np.asarray(traj.potential_energy))  # fmt: skip


def run_case(scene, state, t_end, n, max_bounces):
    """Simulate; return the run and its checks."""
    ts = np.linspace(0.0, t_end, n)
    run = contact.simulate_bounces(scene, state, ts, rtol=1e-10, atol=1e-12,
                                   max_bounces=max_bounces)  # fmt: skip
    b, traj = run.bounces, run.trajectory
    E = np.asarray(traj.energy)
    ok = np.isfinite(E)
    single = b["impulses"] == 1
    e = float(scene.loads[1].restitution)
    eb, ea = b["energy_before"].sum(1), b["energy_after"].sum(1)
    lo = b["L_point_after"] - b["L_point_before"]
    parts = energies(traj)
    span = ok & (ts <= run.t_stop)
    lz = np.asarray(traj.L_space)[ok, 2]
    out = dict(
        status=run.status, bounces=len(b["t"]), t_stop=run.t_stop, steps=run.num_steps,
        energy_start=float(E[0]), energy_end=float(E[ok][-1]),
        energy_rel_drift=float(np.max(np.abs(E[ok] / E[0] - 1))),
        bounce_energy_change_max=float(np.max(np.abs(ea - eb))) if len(eb) else 0.0,
        energy_lost_per_bounce_mean=float(np.mean(eb - ea)) if len(eb) else 0.0,
        energy_gain_max=float(np.max(ea - eb)) if len(eb) else 0.0,
        multi_impulse_bounces=int(np.sum(b["impulses"] > 1)),
        single_impulse_bounces=int(single.sum()),
        restitution_ratio_max_error=float(np.max(np.abs(
            b["un_after"][single] / b["un_before"][single] + e))) if single.any() else 0.0,
        horizontal_momentum_change_max=float(np.max(np.abs(
            b["momentum_after"][:, :2] - b["momentum_before"][:, :2]))) if len(eb) else 0.0,
        L_contact_change_max=float(np.max(np.abs(lo[single]))) if single.any() else 0.0,
        Lz_drift=float(np.ptp(lz)),
        max_depth=float(np.max(b["depth"])) if len(eb) else 0.0,
        dropped_energy=run.dropped_energy,
        mean_kinetic_vertical=float(np.mean(parts["vertical"][span])),
        mean_kinetic_horizontal=float(np.mean(parts["horizontal"][span])),
        mean_kinetic_rotation=float(np.mean(parts["rotation"][span])),
    )  # fmt: skip
    out["rotation_over_vertical"] = out["mean_kinetic_rotation"] / out["mean_kinetic_vertical"]
    if run.status == "t_end":  # the ratio over each quarter: its spread shows the noise
        blocks = np.array_split(np.nonzero(span)[0], 4)
        out["rotation_over_vertical_quarters"] = [
            float(np.mean(parts["rotation"][i]) / np.mean(parts["vertical"][i])) for i in blocks
        ]
    if e < 1.0 or float(scene.loads[1].friction) > 0:  # per-bounce bookkeeping (short runs)
        out["bounce_table"] = dict(t=b["t"], corner=b["point"], un_before=b["un_before"],
                                   un_after=b["un_after"], energy_before=b["energy_before"],
                                   energy_after=b["energy_after"])  # fmt: skip
    return run, parts, out


def draw_2d(ax, run, size, k=9, t_max=4.0):
    """Side view up to ``t_max``: the rectangle at ``k`` times, floor line, centre path."""
    traj = run.trajectory
    pts = contact.box_corners(size, planar=True)
    ts = np.asarray(traj.ts)
    last = np.searchsorted(ts, min(run.t_stop, t_max))
    x = np.asarray(traj.x)[:last]
    ax.plot(x[:, 0], x[:, 2], color="#999999", lw=0.6)
    for j, i in enumerate(np.linspace(0, last - 1, k).astype(int)):
        c = np.asarray(contact.point_positions(traj.q[i], traj.x[i], pts))[RECT]
        ax.fill(c[:, 0], c[:, 2], alpha=0.35, color=f"C{j % 10}", ec="k", lw=0.6)
    ax.axhline(0.0, color="k", lw=1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")


def _floor_mesh(extent):
    return viz.shapes.transform_mesh(
        viz.box(2 * extent, 2 * extent, 0.02, color="#d9d9d9", accent="#d9d9d9", n=16),
        render.body_transform(np.array([1.0, 0, 0, 0]), np.array([0, 0, -0.02])),
    )


def scene_polygons(meshes_T, camera):
    """Depth-sorted polygons of several (mesh, transform) pairs."""
    return render.combine(*(render.mesh_polygons(m, T, camera) for m, T in meshes_T))


def draw_3d(ax, run, size, k=6, camera=None, t_max=4.0):
    """Filmstrip of the box at ``k`` equal time steps over the floor (:mod:`jrigid.viz.render`).

    Snapshot ``j`` is drawn shifted by ``j`` box lengths along ``x`` so they do not overlap.
    """
    camera = render.Camera(elev=15.0, azim=-80.0) if camera is None else camera
    traj = run.trajectory
    ts = np.asarray(traj.ts)
    idx = np.linspace(0, np.searchsorted(ts, min(run.t_stop, t_max)) - 1, k).astype(int)
    x = np.asarray(traj.x)[idx]
    step = 1.4 * max(size)
    x = x - np.array([x[:, 0].mean(), x[:, 1].mean(), 0.0])
    x[:, 0] += step * (np.arange(k) - (k - 1) / 2)
    extent = 0.5 * step * k + max(size)
    box = viz.box(*size)
    T = render.body_transform(np.asarray(traj.q)[idx], x)
    polys = scene_polygons([(_floor_mesh(extent), np.eye(4))] + [(box, t) for t in T], camera)
    render.draw_polygons(ax, polys)
    render.setup_axes(ax, extent)
    ax.set_ylim(-0.3 * extent, max(float(x[:, 2].max()) + max(size), 0.4 * extent))
    for j in range(k):
        ax.text(x[j, 0], -0.28 * extent, f"t = {ts[idx[j]]:.2g} s", fontsize=7, ha="center")


def plot_energies(ax, run, parts, title):
    ts = np.asarray(run.trajectory.ts)
    for key, lab in (("vertical", "K vertical"), ("horizontal", "K horizontal"),
                     ("rotation", "K rotation"), ("potential", "potential")):  # fmt: skip
        ax.plot(ts, parts[key], lw=0.8, label=lab)
    ax.plot(ts, sum(parts.values()), "k", lw=1.0, label="total")
    for t in run.bounces["t"]:
        ax.axvline(t, color="#bbbbbb", lw=0.4, zorder=0)
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("t (s)")
    ax.set_xlim(0, min(float(ts[-1]), 10.0))


def main(
    out_dir,
    quick: bool = False,
    *,
    size: tuple = (1.0, 0.6, 0.3),
    mass: float = 1.0,
    g: float = 9.81,
    height: float = 1.5,
    tilt: float = 0.4,
    spin: float = 4.0,
    restitution: float = 0.7,
    friction: float = 0.3,
    elastic_time: float = 400.0,
    dissipative_time: float = 10.0,
    samples_per_second: int = 50,
    max_bounces: int = 2000,
    gif: bool = True,
) -> dict:
    """Drop a spinning box on a floor in 2D and 3D; bounce energies and equipartition.

    Args:
        out_dir: results folder.
        quick: short runs, no GIF.
        size: box sides ``(a, b, c)``.
        mass: box mass.
        g: gravitational acceleration.
        height: initial height of the centre of mass.
        tilt: initial tilt (radians).
        spin: initial angular speed scale (rad/s).
        restitution, friction: ``e`` and ``μ`` of the dissipative runs.
        elastic_time: duration of the elastic runs (time averages).
        dissipative_time: duration of the dissipative runs.
        samples_per_second: output samples per unit time.
        max_bounces: bounce budget per run.
        gif: animate the 3D dissipative run (full mode only).

    Returns:
        the numbers written to ``numbers.json``.
    """
    size = tuple(float(s) for s in size)
    t_el = 3.0 if quick else elastic_time
    t_di = 3.0 if quick else dissipative_time
    rate = 25 if quick else samples_per_second
    cases = {}
    for dim, planar in (("2d", True), ("3d", False)):
        for kind, e, mu, t_end in (("elastic", 1.0, 0.0, t_el),
                                   ("dissipative", restitution, friction, t_di)):  # fmt: skip
            scene = box_scene(size, mass, g, e, mu, planar)
            state = start(planar, height, tilt, spin)
            n = int(t_end * rate) + 1
            cases[f"{dim}_{kind}"] = (scene,) + run_case(scene, state, t_end, n, max_bounces)
    numbers = {k: v[3] for k, v in cases.items()}
    sc, run, _, el2 = cases["2d_elastic"]
    v_x = float(np.asarray(run.trajectory.v)[0, 0])
    pred2 = equipartition_2d(sc, v_x, el2["energy_start"])
    numbers["2d_elastic"]["equipartition_prediction"] = pred2
    for key in ("vertical", "rotation"):
        dev = el2[f"mean_kinetic_{key}"] / pred2 - 1
        numbers["2d_elastic"][f"{key}_vs_prediction_rel"] = dev
    numbers["3d_elastic"]["equipartition_ratio_prediction"] = 2.0
    numbers.update(size=size, mass=mass, g=g, restitution=restitution, friction=friction,
                   elastic_time=t_el, dissipative_time=t_di)  # fmt: skip

    rep = Report(Path(out_dir), title="A falling box bouncing on a floor (2D and 3D)")
    rep.text(
        f"Box {size[0]:g} × {size[1]:g} × {size[2]:g}, M = {mass:g}, g = {g:g}, dropped from "
        f"z = {height:g} spinning. Contacts: diffrax event at the lowest corner, impulse with "
        f"restitution e and Coulomb friction μ (`jrigid.contact`). Elastic runs e = 1, μ = 0 "
        f"for {t_el:g} s; dissipative e = {restitution:g}, μ = {friction:g} for {t_di:g} s."
    )
    rows = []
    for name, (_, _, _, o) in cases.items():
        rows.append((name, o["bounces"], o["status"], o["t_stop"], o["energy_rel_drift"],
                     o["bounce_energy_change_max"], o["restitution_ratio_max_error"],
                     o["horizontal_momentum_change_max"], o["L_contact_change_max"]))  # fmt: skip
    rep.table(rows, headers=("run", "bounces", "stop", "at t", "max |E/E0 − 1|",
                             "max |ΔE| at a bounce",
                             "max |u⁺/u⁻ + e|", "max |Δp_horizontal|", "max |ΔL_contact|"),
              digits=3)  # fmt: skip
    d2, d3 = numbers["2d_dissipative"], numbers["3d_dissipative"]
    rep.text(
        f"The dissipative runs stop when contacts pile up (2D at t = {d2['t_stop']:.3f}, 3D at "
        f"{d3['t_stop']:.3f}) with energies {d2['energy_end']:.4f} and {d3['energy_end']:.4f}: "
        f"lying flat, M g c/2 = {mass * g * size[2] / 2:.4f}; the kinetic energy dropped there "
        f"is {d2['dropped_energy']:.1e} and {d3['dropped_energy']:.1e}. No bounce gained energy "
        f"(largest change {max(d2['energy_gain_max'], d3['energy_gain_max']):.1e})."
    )
    b = cases["2d_dissipative"][1].bounces
    rep.text(
        "Energy bookkeeping of the first bounces of the 2D dissipative run (K translational, "
        "K rotational, potential; before → after):"
    )
    rep.table([(t, int(k), ub, ua, ua / ub, *eb_, *ea_) for t, k, ub, ua, eb_, ea_ in zip(
        b["t"][:8], b["point"][:8], b["un_before"][:8], b["un_after"][:8],
        b["energy_before"][:8], b["energy_after"][:8], strict=True)],
        headers=("t", "corner", "u_n before", "u_n after", "ratio", "K_tr", "K_rot", "V",
                 "K_tr after", "K_rot after", "V after"), digits=4)  # fmt: skip
    el3 = numbers["3d_elastic"]
    rep.text(
        "**Translation against rotation** (time averages, elastic runs). 2D: ⟨K_vertical⟩ = "
        f"{el2['mean_kinetic_vertical']:.4f}, ⟨K_rotation⟩ = {el2['mean_kinetic_rotation']:.4f} "
        f"(ratio {el2['rotation_over_vertical']:.3f}); the microcanonical value for both is "
        f"{pred2:.4f}; the horizontal part {el2['mean_kinetic_horizontal']:.4f} is constant "
        f"(conserved momentum). 3D (L_z = 0, no horizontal motion): ⟨K_vertical⟩ = "
        f"{el3['mean_kinetic_vertical']:.4f}, ⟨K_rotation⟩ = {el3['mean_kinetic_rotation']:.4f}, "
        f"ratio {el3['rotation_over_vertical']:.3f} against 2 for equipartition over the two "
        "free rotational momenta. Ratio by quarter of the run: 2D "
        f"{np.round(el2.get('rotation_over_vertical_quarters', []), 2).tolist()}, 3D "
        f"{np.round(el3.get('rotation_over_vertical_quarters', []), 2).tolist()} (the spread "
        "is the sampling noise of a few hundred bounces). So the answer to the chapter's "
        "question is: not the total "
        "translational against the total rotational energy, but the same mean energy per "
        "momentum degree of freedom that the bounces can exchange energy with, to the extent "
        "the bouncing explores its energy shell (ergodicity); conserved quantities (horizontal "
        "momentum, L_z) keep their own energy out of the sharing."
    )
    fig = viz.new_figure(figsize=(10, 3.6))
    draw_2d(fig.add_subplot(1, 2, 1), cases["2d_elastic"][1], size)
    fig.axes[0].set_title("2D, e = 1, μ = 0", fontsize=9)
    draw_2d(fig.add_subplot(1, 2, 2), cases["2d_dissipative"][1], size)
    fig.axes[1].set_title(f"2D, e = {restitution:g}, μ = {friction:g}", fontsize=9)
    rep.figure(
        "snapshots_2d",
        fig,
        dpi=70,
        caption="side view at equal time steps, first 4 s (or until rest)",
    )
    fig = viz.new_figure(figsize=(9, 5), layout=None)
    for k, name in enumerate(("3d_elastic", "3d_dissipative")):
        ax = fig.add_axes((0.0, 0.5 * (1 - k), 1.0, 0.45))
        draw_3d(ax, cases[name][1], size)
        ax.set_title(name.replace("_", ", "), fontsize=9)
    rep.figure(
        "snapshots_3d",
        fig,
        dpi=70,
        caption="3D filmstrip at equal time steps, first 4 s (or until rest)",
    )
    fig = viz.new_figure(figsize=(10, 6))
    for k, (name, (_, r, parts, _)) in enumerate(cases.items()):
        ax = fig.add_subplot(2, 2, k + 1)
        plot_energies(ax, r, parts, name.replace("_", ", "))
        if k == 0:
            ax.legend(fontsize=7, ncol=2)
    rep.figure("energies", fig, caption="energies against time (first 10 s); grey lines: bounces",
               dpi=70)  # fmt: skip
    if gif and not quick:
        rep.image(animate_3d(cases["3d_dissipative"][1], size, rep.path("falling_box.gif")),
                  "the 3D dissipative run")  # fmt: skip
    rep.numbers(numbers)
    rep.write_summary()
    print(f"falling_box: 2D ⟨K_rot⟩/⟨K_z⟩ = {el2['rotation_over_vertical']:.3f} (1), "
          f"3D {el3['rotation_over_vertical']:.3f} (2)")  # fmt: skip
    return numbers


def animate_3d(run, size, path, frames=80, fps=20):
    """GIF of a 3D run up to its stop time (:func:`jrigid.viz.write_animation`)."""
    traj = run.trajectory
    ts = np.asarray(traj.ts)
    idx = np.linspace(0, np.searchsorted(ts, run.t_stop) - 1, frames).astype(int)
    x = np.asarray(traj.x)[idx]
    centre = np.array([x[:, 0].mean(), x[:, 1].mean(), 0.0])
    extent = float(np.max(np.abs(x[:, :2] - centre[:2]))) + max(size)
    camera = render.Camera(elev=18.0, azim=-70.0)
    box, floor = viz.box(*size), _floor_mesh(extent)
    T = render.body_transform(np.asarray(traj.q)[idx], x - centre)
    fig = viz.new_figure(figsize=(4, 3), dpi=80, layout=None)
    ax = fig.add_axes((0, 0, 1, 1))
    render.setup_axes(ax, extent * 1.05)
    ax.set_ylim(-0.6 * extent, max(float(x[:, 2].max()) + max(size), 0.6 * extent))
    state = {}

    def update(i):
        polys = scene_polygons([(floor, np.eye(4)), (box, T[i])], camera)
        state["c"] = render.draw_polygons(ax, polys, state.get("c"))

    return viz.write_animation(fig, update, frames, path, fps=fps, mp4=False)[0]


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "falling_box")
