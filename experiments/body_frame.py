"""Euler's equations in the body frame: a block is stable about its largest and smallest axes only.

Problem 17.3. A block with sides ``a, b, c`` along body x, y, z (moments from
:func:`jrigid.inertia.box`; with ``a > b > c``, ``I1 < I2 < I3``) starts spinning about each
principal axis in turn, with ``ω`` tilted by a small angle ``ε`` toward the next axis
(:func:`jrigid.initial.tilted`). Only ``ω(t)`` is integrated, by Euler's equations (17.35)
(the ``body_omega`` formulation of :func:`jrigid.simulate`): there is no orientation, and the
block is drawn fixed with the tips of ``ω`` and ``L`` tracing their body-frame paths (the
polhodes). Checks that over two flip intervals of the intermediate axis
(:func:`jrigid.theory.flip_interval`)

* about axes 1 and 3 the angle between ``ω`` and the axis stays below a few ``ε``;
* about axis 2 it exceeds 90°: ``ω`` turns over;
* ``E`` and ``|L|`` (both computable in the body frame) are conserved.

Run it with ``jrigid run body_frame [--quick]`` or ``python experiments/body_frame.py``.
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

AXIS_NAMES = ("1 (smallest I)", "2 (intermediate I)", "3 (largest I)")


def main(
    out_dir,
    quick: bool = False,
    *,
    sides: tuple = (3.0, 2.0, 1.0),
    mass: float = 1.0,
    rate: float = 2.0,
    tilt_deg: float = 1.0,
    samples: int = 1201,
) -> dict:
    """Spin the block about each principal axis with a small tilt; measure the wander of ω.

    Args:
        out_dir: results folder.
        quick: fewer samples.
        sides: block sides ``(a, b, c)`` along body x, y, z.
        mass: block mass.
        rate: ``|ω|`` (rad/s).
        tilt_deg: initial tilt ``ε`` of ω from the principal axis (degrees).
        samples: output samples.

    Returns:
        the numbers written to ``numbers.json``.
    """
    n = 401 if quick else samples
    moments = np.asarray(inertia.box(mass, *sides))
    if not (moments[0] < moments[1] < moments[2]):
        raise ValueError(f"sides must give I1 < I2 < I3 (a > b > c), got moments {moments}")
    eps = np.radians(tilt_deg)
    w_mid = np.array([0.0, rate * np.cos(eps), rate * np.sin(eps)])
    flip = float(theory.flip_interval(moments, w_mid))
    ts = jnp.linspace(0.0, 2.2 * flip, n)
    scene = Scene(RigidBody(jnp.asarray(moments), mass))
    runs = []
    for axis in range(3):
        traj = simulate(scene, initial.tilted(axis, eps, rate), ts, formulation="body_omega")
        w, L = np.asarray(traj.omega), np.asarray(traj.L)
        cosang = w[:, axis] / np.linalg.norm(w, axis=-1)
        dev = np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))
        E = np.asarray(traj.kinetic_energy)
        Ln = np.linalg.norm(L, axis=-1)
        runs.append(dict(omega=w, L=L, dev=dev, max_dev=float(dev.max()),
                         E_drift=float(np.max(np.abs(E / E[0] - 1))),
                         L_drift=float(np.max(np.abs(Ln / Ln[0] - 1)))))  # fmt: skip
    numbers = {
        "moments": moments,
        "tilt_deg": tilt_deg,
        "duration": float(ts[-1]),
        "flip_interval_theory": flip,
        "max_deviation_deg": [r["max_dev"] for r in runs],
        "max_deviation_over_tilt": [r["max_dev"] / tilt_deg for r in runs],
        "energy_rel_drift": max(r["E_drift"] for r in runs),
        "L_norm_rel_drift": max(r["L_drift"] for r in runs),
        "samples": n,
    }

    rep = Report(Path(out_dir), title="Body-frame solution of Euler's equations (Problem 17.3)")
    rep.text(
        f"A block {tuple(sides)} (moments {np.round(moments, 5).tolist()}) spins at "
        f"|ω| = {rate:g} rad/s about each principal axis, tilted {tilt_deg:g}°; Euler's "
        f"equations (17.35) alone are integrated for {float(ts[-1]):.3f} s (2.2 flip intervals "
        "of the intermediate axis). Largest angle between ω and its starting axis:"
    )
    rep.table(
        [(AXIS_NAMES[k], r["max_dev"], r["max_dev"] / tilt_deg) for k, r in enumerate(runs)],
        headers=("axis", "max angle (°)", "÷ tilt"),
    )
    rep.text(
        f"Energy and |L| are conserved to {numbers['energy_rel_drift']:.1e} and "
        f"{numbers['L_norm_rel_drift']:.1e}. Stable about the smallest and largest axes; "
        "about the intermediate axis ω turns over."
    )
    rep.figure("body_view", _body_views(sides, runs), caption=(
        "body-frame view: the block fixed, ω (orange) and L (purple) with their tip paths"
    ), dpi=70)  # fmt: skip
    fig = viz.new_figure(figsize=(6, 3))
    ax = fig.add_subplot(1, 1, 1)
    for k, r in enumerate(runs):
        ax.semilogy(np.asarray(ts), np.maximum(r["dev"], 1e-3), label=f"axis {AXIS_NAMES[k]}")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("angle of ω from its axis (°)")
    ax.legend(fontsize=7)
    rep.figure("deviation", fig, caption="angle between ω and the starting axis", dpi=70)
    rep.numbers(numbers)
    rep.write_summary()
    print("body_frame: max deviation (deg) " + ", ".join(f"{r['max_dev']:.3f}" for r in runs))
    return numbers


def _body_views(sides, runs):
    cam = viz.Camera(elev=25, azim=35)
    mesh = viz.box(*sides)
    ext = 0.6 * float(np.linalg.norm(sides))
    fig = viz.new_figure(figsize=(10, 3.6), layout=None)
    for k, r in enumerate(runs):
        ax = fig.add_axes((k / 3, 0.0, 1 / 3, 0.9))
        sw = 1.4 * ext / np.linalg.norm(r["omega"][0])
        sl = 1.4 * ext / np.linalg.norm(r["L"][0])
        parts = [viz.render.mesh_polygons(mesh, np.eye(4), cam, alpha=0.5)]
        for vec, s, color in ((r["omega"], sw, "#ff7f0e"), (r["L"], sl, "#9467bd")):
            parts.append(viz.render.polyline_polygons(s * vec, cam, color, width=0.01))
            parts.append(viz.render.arrow_polygons(np.zeros(3), s * vec[-1], cam, color,
                                                   width=0.03))  # fmt: skip
        viz.render.draw_polygons(ax, viz.render.combine(*parts))
        viz.render.setup_axes(ax, 1.5 * ext, f"spin about axis {AXIS_NAMES[k]}")
    return fig


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "body_frame")
