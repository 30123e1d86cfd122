"""Methane: CH₄ with unit H–H distance, the tetrahedral angle, an isotropic inertia (Problem 17.1).

The chapter's hint places the first hydrogen at ``(0, 0, 0.75 h)`` with
``h² = 1 − 4 cos²(π/6)/9``. The hint is verified here rather than trusted: the other three
hydrogens sit on the circle ``z = −h/4`` of radius ``(2/3) cos(π/6) = 1/√3`` (the
circumradius of a unit equilateral triangle), so ``h`` is the height of the unit regular
tetrahedron, ``h² = 1 − 1/3 = 2/3``, and ``0.75 h`` is the apex's distance from the centroid
(which lies a quarter of the way up). All six H–H distances come out 1 and the carbon at
the origin is the centre. The H–C–H angle is ``arccos(−1/3) ≈ 109.47°`` and the inertia
tensor (:func:`jrigid.inertia.from_point_masses`) is isotropic, ``(8/3) m_H d²·1 = m_H·1``
with ``d² = 3/8`` the squared C–H distance, in every orientation. The molecule is drawn
with the painter's algorithm of :mod:`jrigid.viz.render`.

Run it with ``jrigid run methane [--quick]`` or ``python experiments/methane.py``.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import affine, inertia, viz
from jrigid import quaternion as quat
from jrigid.report import Report


def hydrogens_from_hint() -> tuple[np.ndarray, float]:
    """The four H positions built from the chapter's hint, and ``h``."""
    c = np.cos(np.pi / 6)
    h = np.sqrt(1.0 - 4.0 * c**2 / 9.0)
    rho = 2.0 * c / 3.0  # circumradius of the unit base triangle
    az = 2 * np.pi * np.arange(3) / 3
    base = np.stack([rho * np.cos(az), rho * np.sin(az), np.full(3, -0.25 * h)], axis=-1)
    return np.concatenate([[[0.0, 0.0, 0.75 * h]], base]), float(h)


def main(
    out_dir,
    quick: bool = False,
    *,
    mass_c: float = 12.011,
    mass_h: float = 1.008,
    seed: int = 0,
) -> dict:
    """Build CH₄ from the hint; check distances, the bond angle and the inertia tensor.

    Args:
        out_dir: results folder.
        quick: no effect (the experiment is instantaneous); kept for the test runner.
        mass_c, mass_h: atomic masses (u).
        seed: random seed of the orientations in which the inertia is recomputed.

    Returns:
        the numbers written to ``numbers.json``.
    """
    H, h = hydrogens_from_hint()
    iu = np.triu_indices(4, 1)
    hh = np.linalg.norm(H[:, None] - H[None], axis=-1)[iu]
    ch = np.linalg.norm(H, axis=-1)
    unit = H / ch[:, None]
    angles = np.degrees(np.arccos(np.clip((unit @ unit.T)[iu], -1.0, 1.0)))
    masses = jnp.asarray([mass_c] + [mass_h] * 4)
    pos = jnp.asarray(np.concatenate([[[0.0, 0.0, 0.0]], H]))
    tensor = np.asarray(inertia.from_point_masses(masses, pos))
    # the same molecule turned at random: an isotropic tensor does not change
    qs = quat.normalize(jnp.asarray(np.random.default_rng(seed).normal(size=(5, 4))))
    turned = affine.apply_to_points(affine.rotation_3d(qs)[:, None], pos[None])
    I_turned = np.asarray(inertia.from_point_masses(masses[None], turned))
    numbers = {
        "h": h,
        "h_theory": float(np.sqrt(2.0 / 3.0)),
        "hh_distances": hh,
        "ch_distance": ch,
        "ch_distance_theory": float(np.sqrt(6.0) / 4.0),
        "centroid_of_H": H.mean(0),
        "hch_angles_deg": angles,
        "hch_angle_theory_deg": float(np.degrees(np.arccos(-1.0 / 3.0))),
        "inertia_tensor": tensor,
        "inertia_eigenvalues": np.linalg.eigvalsh(tensor),
        "inertia_theory": float(8.0 / 3.0 * mass_h * 3.0 / 8.0),
        "inertia_turned_max_change": float(np.max(np.abs(I_turned - tensor[None]))),
        "hint_correct": bool(np.allclose(hh, 1.0, atol=1e-12)),
    }

    rep = Report(Path(out_dir), title="Methane")
    rep.text(
        f"The hint gives h = {h:.12f} = √(2/3) and H–H distances {hh.min():.12f}…"
        f"{hh.max():.12f}: the hint is correct. C–H = {ch[0]:.6f} = √6/4; every H–C–H angle is "
        f"{angles.mean():.6f}° (arccos(−1/3) = {numbers['hch_angle_theory_deg']:.6f}°). "
        f"Inertia eigenvalues {np.round(numbers['inertia_eigenvalues'], 12).tolist()} "
        f"= m_H: isotropic, and unchanged by rotation "
        f"({numbers['inertia_turned_max_change']:.1e})."
    )
    rep.figure("methane", _figure(H), caption="CH₄, painter's algorithm", dpi=80)
    rep.numbers(numbers)
    rep.write_summary()
    print(f"methane: H-C-H {angles.mean():.6f} deg, inertia {numbers['inertia_eigenvalues']}")
    return numbers


def _molecule(H, camera):
    """Depth-sorted polygons of the atoms (spheres) and the bonds (thick polylines)."""
    parts = [
        viz.render.mesh_polygons(
            viz.ellipsoid(0.22, 0.22, 0.22, color="#444444", accent="#555555"), np.eye(4), camera
        )
    ]
    sphere = viz.ellipsoid(0.13, 0.13, 0.13, color="#f2f2f2", accent="#dddddd")
    for p in H:
        T = np.asarray(affine.translation(jnp.asarray(p)))
        parts.append(viz.render.mesh_polygons(sphere, T, camera))
        bond = np.linspace(np.zeros(3), p, 16)
        parts.append(viz.render.polyline_polygons(bond, camera, "#888888", width=0.05, fade=False))
    return viz.render.combine(*parts)


def _figure(H):
    fig = viz.new_figure(figsize=(7, 3.6))
    views = [(viz.Camera(elev=15, azim=20), "side view"),
             (viz.Camera(elev=90, azim=0), "down the C–H₁ axis")]  # fmt: skip
    for ax, (cam, title) in zip(fig.subplots(1, 2), views, strict=True):
        viz.render.draw_polygons(ax, _molecule(H, cam))
        viz.render.setup_axes(ax, 0.9, title)
    return fig


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "methane")
