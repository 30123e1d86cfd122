"""Affine 3D: a prism of two congruent polygons; transform order; xy projection and depth (17.9).

Exercise 17.3 with :mod:`jrigid.affine`. The lower polygon's vertices are points
(``w = 1``), the segments joining them to the upper polygon are vectors (``w = 0``), so a
translation moves the polygons and leaves the segments alone, and ``T(p + v) = T p + T v``
rebuilds the upper polygon. Checks that two rotations about different axes give different
results in different orders, two translations commute, and a rotation and a translation do
not (``T(d) R − R T(d)`` has translation column ``d − R d``).

The xy projection (:func:`jrigid.affine.orthographic`, viewer on ``+z``) is then drawn in
the order of the element tree (lower polygon, upper polygon, sides) and in the
painter's order (back to front by centroid depth). A pixel test finds the pairs of faces
whose overlap is painted with the farther face on top: the naive order gets some wrong,
the sorted one none in the figure's orientation. Sorting by centroid depth is not exact in
general (over the default 40 random orientations it fails once, at a back face next to a
front one); adding back-face culling, as :mod:`jrigid.viz.render` does, makes it exact for a
convex body.

Run it with ``jrigid run affine_3d [--quick]`` or ``python experiments/affine_3d.py``.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import affine, viz
from jrigid import quaternion as quat
from jrigid.report import Report

COLORS = ("#e8a33d", "#6a9fd4", "#9fc98f", "#c98f8f", "#b39ddb", "#80cbc4", "#ffcc80", "#bcaaa4")


def prism(n: int, height: float, offset: float):
    """Lower polygon points ``(n, 3)`` and the joining segments ``(n, 3)`` (all equal)."""
    ang = 2 * np.pi * np.arange(n) / n
    lower = np.stack([np.cos(ang), np.sin(ang), np.full(n, -height / 2)], axis=-1)
    seg = np.broadcast_to(np.array([offset, 0.0, height]), (n, 3)).copy()
    return lower, seg


def faces_of(lower, upper):
    """Faces in tree order: lower polygon, upper polygon, then the side quads."""
    n = len(lower)
    sides = [
        np.stack([lower[i], lower[(i + 1) % n], upper[(i + 1) % n], upper[i]]) for i in range(n)
    ]
    return [lower, upper, *sides]


def wrong_pairs(faces, order, grid: int):
    """Pairs (i, j) drawn in the wrong order: face i hides j somewhere in the xy
    projection (larger z, the viewer is on +z) but j is painted after i."""
    lo = np.min([f[:, :2].min(0) for f in faces], axis=0)
    hi = np.max([f[:, :2].max(0) for f in faces], axis=0)
    xs = [np.linspace(lo[k], hi[k], grid) for k in range(2)]
    P = np.stack(np.meshgrid(*xs, indexing="ij"), axis=-1).reshape(-1, 2)
    z = np.full((len(faces), len(P)), -np.inf)
    for k, f in enumerate(faces):
        normal = np.cross(f[1] - f[0], f[2] - f[0])
        if abs(normal[2]) < 1e-9 * np.linalg.norm(normal):
            continue  # edge-on: covers no area
        edges = np.roll(f[:, :2], -1, axis=0) - f[:, :2]
        cr = edges[:, None, 0] * (P[None, :, 1] - f[:, None, 1])
        cr = cr - edges[:, None, 1] * (P[None, :, 0] - f[:, None, 0])
        inside = np.all(cr > 1e-9, axis=0) | np.all(cr < -1e-9, axis=0)
        zf = (
            f[0, 2]
            - (normal[0] * (P[:, 0] - f[0, 0]) + normal[1] * (P[:, 1] - f[0, 1])) / normal[2]
        )
        z[k, inside] = zf[inside]
    rank = np.empty(len(faces), int)
    rank[np.asarray(order)] = np.arange(len(faces))
    bad = set()
    for i in range(len(faces)):
        for j in range(len(faces)):
            if rank[i] < rank[j] and np.any(np.isfinite(z[j]) & (z[i] > z[j] + 1e-9)):
                bad.add((i, j))
    return sorted(bad)


def main(
    out_dir,
    quick: bool = False,
    *,
    sides: int = 5,
    height: float = 1.2,
    offset: float = 0.3,
    tilt: tuple = (0.3, 2.2, 0.4),
    orientations: int = 40,
    seed: int = 0,
) -> dict:
    """Transform the prism, check the order claims, count painter's-order errors.

    Args:
        out_dir: results folder.
        quick: fewer random orientations and a coarser pixel grid.
        sides: vertices of each polygon.
        height, offset: the joining segment is ``(offset, 0, height)``.
        tilt: ZXZ Euler angles (radians) of the orientation drawn in the projection figure.
        orientations: random orientations over which the orders are compared.
        seed: random seed.

    Returns:
        the numbers written to ``numbers.json``.
    """
    lower, seg = prism(sides, height, offset)
    Rx = affine.rotation_3d_axis_angle(jnp.array([1.0, 0.0, 0.0]), jnp.pi / 2)
    Ry = affine.rotation_3d_axis_angle(jnp.array([0.0, 1.0, 0.0]), jnp.pi / 2)
    d1, d2 = jnp.array([0.5, -0.2, 0.3]), jnp.array([-0.1, 0.7, 0.2])
    T1, T2 = affine.translation(d1), affine.translation(d2)
    P = lambda T, x: np.asarray(affine.apply_to_points(T, jnp.asarray(x)))
    V = lambda T, v: np.asarray(affine.apply_to_vectors(T, jnp.asarray(v)))
    upper = lower + seg
    RT, TR = affine.compose(Rx, T1), affine.compose(T1, Rx)
    Rd = np.asarray(Rx)[:3, :3] @ np.asarray(d1)
    numbers = {
        "rotations_order_max_vertex_difference": float(
            np.max(np.abs(P(Rx @ Ry, upper) - P(Ry @ Rx, upper)))
        ),
        "translations_order_max_difference": float(jnp.max(jnp.abs(T1 @ T2 - T2 @ T1))),
        "rotation_translation_difference": float(
            np.linalg.norm(P(TR, lower) - P(RT, lower), axis=-1).max()
        ),
        "rotation_translation_difference_theory": float(np.linalg.norm(np.asarray(d1) - Rd)),
        "segment_change_under_translation": float(np.max(np.abs(V(T1, seg) - seg))),
        "upper_rebuilt_error": float(np.max(np.abs(P(RT, lower) + V(RT, seg) - P(RT, upper)))),
    }
    # painter's order against the element-tree order, over random orientations
    rng = np.random.default_rng(seed)
    n_orient = 8 if quick else orientations
    qs = [quat.from_euler("ZXZ", jnp.asarray(tilt))]
    qs += list(quat.normalize(jnp.asarray(rng.normal(size=(n_orient - 1, 4)))))
    naive, sorted_, culled, grid = [], [], [], 60 if quick else 120
    for q in qs:
        R = affine.rotation_3d(q)
        faces = faces_of(P(R, lower), P(R, lower) + V(R, seg))
        centers = np.asarray([f.mean(0) for f in faces])
        _, depth = affine.orthographic(jnp.asarray(centers), axis=2)
        order = np.argsort(-np.asarray(depth))
        naive.append(len(wrong_pairs(faces, range(len(faces)), grid)))
        sorted_.append(len(wrong_pairs(faces, order, grid)))
        # back-face culling: keep faces whose outward normal points to the viewer (+z)
        normals = [np.cross(f[1] - f[0], f[2] - f[0]) for f in faces]
        outward = [
            n * np.sign(n @ (c - centers.mean(0))) for n, c in zip(normals, centers, strict=True)
        ]
        front = [faces[k] for k in order if outward[k][2] > 0]
        culled.append(len(wrong_pairs(front, range(len(front)), grid)))
    numbers.update(
        wrong_pairs_naive_drawn=naive[0],
        wrong_pairs_sorted_drawn=sorted_[0],
        orientations=len(qs),
        orientations_naive_wrong=int(np.sum(np.asarray(naive) > 0)),
        orientations_sorted_wrong=int(np.sum(np.asarray(sorted_) > 0)),
        wrong_pairs_naive_total=int(np.sum(naive)),
        wrong_pairs_sorted_total=int(np.sum(sorted_)),
        orientations_culled_wrong=int(np.sum(np.asarray(culled) > 0)),
    )

    rep = Report(Path(out_dir), title="Affine transformations in three dimensions")
    rep.text(
        "Rotations by 90° about x and y in the two orders move a vertex by up to "
        f"{numbers['rotations_order_max_vertex_difference']:.3f}; translations commute "
        f"(difference {numbers['translations_order_max_difference']:.1e}); rotation and "
        f"translation differ by |d − R d| = {numbers['rotation_translation_difference']:.4f}. "
        f"Projection onto xy: in {numbers['orientations_naive_wrong']} of {len(qs)} "
        "orientations the tree order paints a far face over a near one "
        f"({numbers['wrong_pairs_naive_total']} pairs); sorted back to front: "
        f"{numbers['orientations_sorted_wrong']} ({numbers['wrong_pairs_sorted_total']} pairs); "
        f"sorted with back faces culled: {numbers['orientations_culled_wrong']}."
    )
    rep.figure(
        "order", _order_figure(lower, seg, Rx, Ry, T1, T2), caption="order of transforms", dpi=70
    )
    rep.figure(
        "projection",
        _projection_figure(lower, seg, qs[0], naive[0]),
        caption="xy projection",
        dpi=70,
    )
    rep.numbers(numbers)
    rep.write_summary()
    print(
        f"affine_3d: naive order wrong in {numbers['orientations_naive_wrong']}/{len(qs)}, "
        f"sorted in {numbers['orientations_sorted_wrong']}/{len(qs)}"
    )
    return numbers


def _wire(ax, lower, upper, camera, color):
    uv_l, _ = viz.render.project(lower, camera)
    uv_u, _ = viz.render.project(upper, camera)
    for uv in (uv_l, uv_u):
        ax.fill(uv[:, 0], uv[:, 1], color=color, alpha=0.35, edgecolor=color)
    for a, b in zip(uv_l, uv_u, strict=True):
        ax.plot([a[0], b[0]], [a[1], b[1]], color=color, lw=1)


def _order_figure(lower, seg, Rx, Ry, T1, T2):
    cam = viz.Camera(elev=25, azim=30)
    cases = [("Rx then Ry", Ry @ Rx, "Ry then Rx", Rx @ Ry),
             ("T1 then T2", T2 @ T1, "T2 then T1", T1 @ T2),
             ("Rx then T1", T1 @ Rx, "T1 then Rx", Rx @ T1)]  # fmt: skip
    fig = viz.new_figure(figsize=(10, 3.6))
    for ax, (la, A, lb, B) in zip(fig.subplots(1, 3), cases, strict=True):
        for T, color in ((A, "#1f77b4"), (B, "#d62728")):
            p = np.asarray(affine.apply_to_points(T, jnp.asarray(lower)))
            v = np.asarray(affine.apply_to_vectors(T, jnp.asarray(seg)))
            _wire(ax, p, p + v, cam, color)
        viz.render.setup_axes(ax, 2.2, f"blue: {la}; red: {lb}")
    return fig


def _projection_figure(lower, seg, q, n_wrong):
    R = affine.rotation_3d(q)
    p = np.asarray(affine.apply_to_points(R, jnp.asarray(lower)))
    faces = faces_of(p, p + np.asarray(affine.apply_to_vectors(R, jnp.asarray(seg))))
    uv, depth = affine.orthographic(jnp.asarray([f.mean(0) for f in faces]), axis=2)
    orders = [("element-tree order", range(len(faces))),
              ("sorted back to front", np.argsort(-np.asarray(depth)))]  # fmt: skip
    fig = viz.new_figure(figsize=(7, 3.6))
    for ax, (title, order) in zip(fig.subplots(1, 2), orders, strict=True):
        for k in order:
            f = np.asarray(affine.orthographic(jnp.asarray(faces[k]), axis=2)[0])
            ax.fill(f[:, 0], f[:, 1], color=COLORS[k % len(COLORS)], edgecolor="k", lw=0.6)
            c = np.asarray(uv[k])
            ax.text(c[0], c[1], str(k), fontsize=7, ha="center", va="center")
        viz.render.setup_axes(ax, 1.8, title)
    fig.suptitle(f"xy projection: {n_wrong} face pairs wrong in tree order", fontsize=9)
    return fig


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "affine_3d")
