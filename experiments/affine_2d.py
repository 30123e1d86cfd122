"""Affine 2D: a polygon and an arrow under rotation, scaling, skew and translation (17.1-17.7).

Exercises 17.1-17.2 in homogeneous coordinates (:mod:`jrigid.affine`): polygon vertices
are points (``w = 1``), the arrow is a vector (``w = 0``). Checks that

* a rotation turns about the origin, and ``about_point`` turns about a vertex, which stays
  fixed (Exercise 17.2a-b);
* the arrow does not translate, it only turns (Exercise 17.2b);
* the skew (17.6) keeps horizontal lines, tilts vertical ones by ``atan 0.2`` and keeps areas;
* parallel lines stay parallel under an arbitrary affine matrix, and do not under a
  projective one (bottom row not ``(0, 0, 1)``): the restriction of Exercise 17.2d;
* the 30° clockwise rotation ``R`` and the x-scaling ``S`` by 2 do not commute (Exercise
  17.1a): ``‖RS − SR‖_F = √2 |sin 30°| |2 − 1| = 1/√2``.

Run it with ``jrigid run affine_2d [--quick]`` or ``python experiments/affine_2d.py``.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import affine, viz
from jrigid.report import Report

# an asymmetric "house" so that turns and mirror images read at a glance
POLYGON = np.array([[1.0, 0.5], [2.0, 0.5], [2.0, 1.3], [1.5, 1.8], [1.0, 1.3]])
ARROW_TAIL, ARROW = np.array([1.5, 1.0]), np.array([0.0, 0.6])


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _parallel_error(T, rng, n=8):
    """Largest |sin| of the angle between images of pairs of parallel segments under T."""
    p1, p2 = rng.normal(size=(n, 2)), rng.normal(size=(n, 2))
    u = rng.normal(size=(n, 2))
    k = rng.uniform(0.3, 2.0, size=(n, 1))
    img = lambda p: np.asarray(affine.apply_to_points(T, jnp.asarray(p)))
    a, b = img(p1 + u) - img(p1), img(p2 + k * u) - img(p2)
    sin = _cross2(a, b) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return float(np.max(np.abs(sin)))


def _fixed_point(T):
    """The point x with T x = x (A x + d = x), from the blocks of T."""
    A, d = (np.asarray(x) for x in affine.to_blocks(T))
    return np.linalg.solve(A - np.eye(2), -d)


def main(
    out_dir,
    quick: bool = False,
    *,
    angle_deg: float = -30.0,
    scale_x: float = 2.0,
    skew: float = 0.2,
    shift: tuple = (-1.5, -1.0),
    seed: int = 0,
) -> dict:
    """Transform a polygon and an arrow; check the claims of Exercises 17.1-17.2.

    Args:
        out_dir: results folder.
        quick: no effect (the experiment is instantaneous); kept for the test runner.
        angle_deg: rotation angle, degrees; negative is clockwise (the chapter's −30°).
        scale_x: x-scaling factor (the chapter's 2).
        skew: the shear factor of (17.6).
        shift: translation ``(dx, dy)``.
        seed: random seed of the arbitrary affine and projective matrices.

    Returns:
        the numbers written to ``numbers.json``.
    """
    theta = np.radians(angle_deg)
    R, S = affine.rotation_2d(theta), affine.scaling(jnp.array([scale_x, 1.0]))
    K, D = affine.shear_2d(skew), affine.translation(jnp.asarray(shift, dtype=float))
    vertex = POLYGON[0]
    R_vertex = affine.about_point(R, jnp.asarray(vertex))
    pts = affine.to_homogeneous(jnp.asarray(POLYGON), 1.0)
    arrow = affine.to_homogeneous(jnp.asarray(ARROW), 0.0)

    commutator = float(jnp.linalg.norm(R @ S - S @ R))
    commutator_theory = float(np.sqrt(2) * abs(np.sin(theta)) * abs(scale_x - 1.0))
    img_vertex = np.asarray(affine.apply_to_points(R_vertex, jnp.asarray(vertex)))
    shifted_arrow = np.asarray(affine.apply(D, arrow))
    turned_arrow = np.asarray(affine.apply(R_vertex, arrow))[:2]
    # skew: y unchanged, the vertical side (x = 1 from y = 0.5 to 1.3) tilts by atan(skew)
    sk = np.asarray(affine.apply_to_points(K, jnp.asarray(POLYGON)))
    side = sk[4] - sk[0]
    rng = np.random.default_rng(seed)
    T_affine = affine.from_blocks(
        jnp.asarray(rng.normal(size=(2, 2))), jnp.asarray(rng.normal(size=2))
    )
    T_proj = T_affine.at[2, :2].set(jnp.asarray([0.3, -0.2]))
    numbers = {
        "commutator_norm": commutator,
        "commutator_norm_theory": commutator_theory,
        "rotation_fixed_point": _fixed_point(R),
        "vertex_rotation_fixed_point": _fixed_point(R_vertex),
        "vertex_displacement": float(np.linalg.norm(img_vertex - vertex)),
        "arrow_change_under_translation": float(np.max(np.abs(shifted_arrow - arrow))),
        "arrow_w_after_translation": float(shifted_arrow[2]),
        "arrow_turn_error": float(np.max(np.abs(turned_arrow - np.asarray(R)[:2, :2] @ ARROW))),
        "skew_y_change": float(np.max(np.abs(sk[:, 1] - POLYGON[:, 1]))),
        "skew_tilt_deg": float(np.degrees(np.arctan2(side[0], side[1]))),
        "skew_tilt_deg_theory": float(np.degrees(np.arctan(skew))),
        "skew_det": float(jnp.linalg.det(K)),
        "parallel_sin_affine": _parallel_error(T_affine, np.random.default_rng(seed + 1)),
        "parallel_sin_projective": _parallel_error(T_proj, np.random.default_rng(seed + 1)),
    }

    panels = [
        ("rotate 30° cw about origin" if angle_deg == -30 else f"rotate {angle_deg:g}°", R),
        (f"scale x by {scale_x:g}", S),
        (f"skew (17.6), k = {skew:g}", K),
        (f"translate by {tuple(shift)}", D),
        ("rotate about a vertex", R_vertex),
        ("R·S (S first)", R @ S),
        ("S·R (R first)", S @ R),
        ("random affine", T_affine),
    ]
    fig = viz.new_figure(figsize=(12, 6.2))
    for ax, (title, T) in zip(fig.subplots(2, 4).ravel(), panels, strict=True):
        _draw(ax, T, pts, arrow, title)
    rep = Report(Path(out_dir), title="Affine transformations in two dimensions")
    rep.text(
        f"The 30° clockwise rotation and the x-scaling by {scale_x:g} do not commute: "
        f"‖RS − SR‖ = {commutator:.6f} (theory √2|sin θ||s−1| = {commutator_theory:.6f}). "
        f"The rotation turns about {np.round(numbers['rotation_fixed_point'], 12).tolist()}; "
        f"about a vertex the vertex moves by {numbers['vertex_displacement']:.1e}. The arrow "
        f"(w = 0) changes by {numbers['arrow_change_under_translation']:.1e} under translation. "
        f"Parallel lines: |sin| between images {numbers['parallel_sin_affine']:.1e} (affine) "
        f"against {numbers['parallel_sin_projective']:.2f} (projective bottom row)."
    )
    rep.figure("transforms", fig, caption="grey: before; blue: after (arrow in red)", dpi=70)
    rep.numbers(numbers)
    rep.write_summary()
    print(f"affine_2d: commutator {commutator:.6f} (theory {commutator_theory:.6f})")
    return numbers


def _draw(ax, T, pts, arrow, title):
    """Polygon and arrow before (grey) and after ``T`` (blue, red)."""
    new_pts = np.asarray(affine.apply(T, pts))
    tail = np.asarray(affine.apply_to_points(T, jnp.asarray(ARROW_TAIL)))
    vec = np.asarray(affine.apply(T, arrow))[:2]
    ax.fill(POLYGON[:, 0], POLYGON[:, 1], color="#cccccc", alpha=0.6)
    ax.arrow(*ARROW_TAIL, *ARROW, width=0.03, color="#999999", length_includes_head=True)
    ax.fill(new_pts[:, 0], new_pts[:, 1], color="#6a9fd4", alpha=0.7)
    ax.arrow(*tail, *vec, width=0.03, color="#d62728", length_includes_head=True)
    ax.plot([0], [0], "k+", ms=8)
    ax.set_xlim(-2.5, 4.5)
    ax.set_ylim(-2.5, 3.0)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.tick_params(labelsize=7)


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "affine_2d")
