"""Body meshes for drawing: box, ellipsoid, disk, rod, cylinder and a T-handle.

A :class:`Mesh` is a set of planar polygons in the body frame with the centre of mass at
the origin and the principal axes along body ``x, y, z``, matching the shapes of
:mod:`jrigid.inertia` (same argument meanings: full side lengths for a box, semi-axes for
an ellipsoid, ...). Each face is a triangle or a quadrilateral stored as four vertex
indices (a triangle repeats its last vertex), with an outward unit normal, its centroid
and a base colour. Faces carry two alternating shades in sectors or bands so that a
spinning symmetric body visibly turns (a uniformly coloured disk looks the same at every
spin angle).

Meshes are static drawing data, built once with numpy; placing parts (the T-handle, whose
mass model is :func:`jrigid.inertia.t_handle_parts`) goes through :mod:`jrigid.affine`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib import colors as mcolors

from jrigid import affine
from jrigid.inertia import t_handle_parts

from ._jit import bucket, float_dtype, pad

__all__ = [
    "Mesh",
    "box",
    "cylinder",
    "disk",
    "ellipsoid",
    "merge",
    "rod",
    "t_handle",
    "t_handle_parts",
    "transform_mesh",
]

PALETTE = {
    "body": "#8fb3d9",
    "accent": "#e8a33d",
    "plate": "#d9d3c7",
    "rim": "#b0a58f",
    "handle": "#9fc98f",
    "stem": "#c98f8f",
}


class Mesh(NamedTuple):
    """Polygons of a body in its own frame.

    Attributes:
        vertices: ``(V, 3)`` float.
        faces: ``(F, 4)`` int vertex indices (a triangle repeats its last index).
        normals: ``(F, 3)`` outward unit normals.
        centers: ``(F, 3)`` face centroids (used for depth sorting).
        colors: ``(F, 3)`` RGB base colours in ``[0, 1]``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    centers: np.ndarray
    colors: np.ndarray

    @property
    def radius(self) -> float:
        """Largest distance of a vertex from the origin (the body's drawing size)."""
        return float(np.max(np.linalg.norm(self.vertices, axis=-1)))


def _rgb(c) -> np.ndarray:
    return np.asarray(mcolors.to_rgb(c), dtype=float)


def _finish(vertices, faces, colors, inside_point=None) -> Mesh:
    """Centroids and outward normals (Newell's method); inward faces are turned around."""
    V = np.asarray(vertices, dtype=float)
    F = np.asarray(faces, dtype=int)
    P = V[F]  # (F, 4, 3)
    nxt = np.roll(P, -1, axis=1)
    normal = np.stack(
        [
            np.sum((P[..., 1] - nxt[..., 1]) * (P[..., 2] + nxt[..., 2]), axis=1),
            np.sum((P[..., 2] - nxt[..., 2]) * (P[..., 0] + nxt[..., 0]), axis=1),
            np.sum((P[..., 0] - nxt[..., 0]) * (P[..., 1] + nxt[..., 1]), axis=1),
        ],
        axis=-1,
    )
    distinct = np.concatenate([np.ones((len(F), 3), bool), (F[:, 3] != F[:, 2])[:, None]], axis=1)
    centers = np.sum(P * distinct[..., None], axis=1) / np.sum(distinct, axis=1)[:, None]
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-300)
    inside = np.zeros(3) if inside_point is None else np.asarray(inside_point, float)
    flip = np.sum(normal * (centers - inside), axis=-1) < 0
    normal[flip] *= -1
    # reverse the winding of flipped faces too (counter-clockwise seen from outside)
    tri = F[:, 3] == F[:, 2]
    F = F.copy()
    F[flip & ~tri] = F[flip & ~tri][:, ::-1]
    F[flip & tri] = F[flip & tri][:, [2, 1, 0, 0]]
    return Mesh(V, F, normal, centers, np.asarray(colors, dtype=float).reshape(len(F), 3))


def box(
    a: float, b: float, c: float, color=PALETTE["body"], accent=PALETTE["accent"], n: int = 3
) -> Mesh:
    """Box with full side lengths ``a, b, c`` along body ``x, y, z`` (:func:`jrigid.inertia.box`).

    Each side is split into an ``n × n`` grid (smaller faces sort better by depth); the
    ``+x`` side is drawn in ``accent`` so the orientation reads at a glance.

    Returns:
        :class:`Mesh`.
    """
    half = np.array([a, b, c], dtype=float) / 2
    verts, faces, cols = [], [], []
    g = np.linspace(-1.0, 1.0, n + 1)
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for sign in (-1.0, 1.0):
            col = _rgb(accent if (axis == 0 and sign > 0) else color)
            for i in range(n):
                for j in range(n):
                    quad = []
                    for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        p = np.zeros(3)
                        p[axis] = sign
                        p[u], p[v] = g[i + di], g[j + dj]
                        quad.append(len(verts))
                        verts.append(p * half)
                    faces.append(quad)
                    cols.append(col)
    return _finish(verts, faces, cols)


def ellipsoid(
    a: float,
    b: float,
    c: float,
    color=PALETTE["body"],
    accent=PALETTE["accent"],
    n_lat: int = 10,
    n_lon: int = 20,
    bands: int = 4,
) -> Mesh:
    """Ellipsoid, semi-axes ``a, b, c`` along body ``x, y, z`` (:func:`jrigid.inertia.ellipsoid`).

    A latitude-longitude grid; longitude bands alternate between ``color`` and ``accent``
    (``bands`` pairs), so rotation about ``z`` shows.

    Returns:
        :class:`Mesh`.
    """
    th = np.linspace(0.0, np.pi, n_lat + 1)
    ph = np.linspace(0.0, 2 * np.pi, n_lon, endpoint=False)
    scale = np.array([a, b, c], dtype=float)
    verts = [np.array([0.0, 0.0, 1.0]) * scale]  # north pole
    for t in th[1:-1]:
        for p in ph:
            verts.append(
                np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)]) * scale
            )
    verts.append(np.array([0.0, 0.0, -1.0]) * scale)  # south pole
    south = len(verts) - 1

    def ring(k, i):  # k-th interior ring (0-based), i-th longitude
        return 1 + k * n_lon + (i % n_lon)

    faces, cols = [], []
    per_band = max(n_lon // (2 * bands), 1)
    for i in range(n_lon):
        col = _rgb(accent if (i // per_band) % 2 else color)
        faces.append([0, ring(0, i), ring(0, i + 1), ring(0, i + 1)])
        cols.append(col)
        for k in range(n_lat - 2):
            faces.append([ring(k, i), ring(k + 1, i), ring(k + 1, i + 1), ring(k, i + 1)])
            cols.append(col)
        faces.append([ring(n_lat - 2, i), south, ring(n_lat - 2, i + 1), ring(n_lat - 2, i + 1)])
        cols.append(col)
    mesh = _finish(verts, faces, cols)
    # exact ellipsoid normals at the face centroids (gradient of x²/a² + y²/b² + z²/c²)
    nrm = mesh.centers / scale**2
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    return mesh._replace(normals=nrm)


def cylinder(
    radius: float,
    length: float,
    n: int = 24,
    color=PALETTE["plate"],
    accent=PALETTE["accent"],
    side_color=None,
    sectors: int = 4,
) -> Mesh:
    """Closed solid cylinder along body ``z`` (as :func:`jrigid.inertia.solid_cylinder`).

    The end caps are fans of ``n`` triangles coloured in ``sectors`` alternating pairs of
    ``color``/``accent``; one side panel is ``accent`` as a marker.

    Args:
        radius, length: cylinder radius and height along ``z``.
        n: number of segments around the axis.

    Returns:
        :class:`Mesh`.
    """
    ang = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    ring = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.zeros(n)], axis=-1)
    h = length / 2
    bottom = ring + [0.0, 0.0, -h]
    top = ring + [0.0, 0.0, h]
    verts = np.concatenate([bottom, top, [[0.0, 0.0, -h], [0.0, 0.0, h]]])
    bc, tc = 2 * n, 2 * n + 1
    side = _rgb(side_color if side_color is not None else color)
    faces, cols = [], []
    per = max(n // (2 * sectors), 1)
    for i in range(n):
        j = (i + 1) % n
        faces.append([i, j, n + j, n + i])
        cols.append(_rgb(accent) if i == 0 else side)
        cap = _rgb(accent if (i // per) % 2 else color)
        faces.append([tc, n + i, n + j, n + j])
        cols.append(cap)
        faces.append([bc, j, i, i])
        cols.append(cap)
    return _finish(verts, faces, cols)


def disk(radius: float, thickness: float, n: int = 32, **kwargs) -> Mesh:
    """Plate of finite ``thickness``, normal along body ``z`` (as :func:`jrigid.inertia.disk`).

    Returns:
        :class:`Mesh`; a :func:`cylinder` with the rim shaded darker.
    """
    kwargs.setdefault("side_color", PALETTE["rim"])
    return cylinder(radius, thickness, n=n, **kwargs)


def rod(length: float, radius: float | None = None, n: int = 12, **kwargs) -> Mesh:
    """Rod along body ``z`` (as :func:`jrigid.inertia.thin_rod`), drawn with a finite radius.

    Args:
        length: rod length.
        radius: drawing radius, default ``length / 30``.

    Returns:
        :class:`Mesh`.
    """
    kwargs.setdefault("color", PALETTE["body"])
    return cylinder(length / 30 if radius is None else radius, length, n=n, sectors=2, **kwargs)


@jax.jit
def _transform_kernel(T, vertices, centers, normals):
    T = T[None]
    return (
        affine.apply_to_points(T, vertices),
        affine.apply_to_points(T, centers),
        affine.apply_to_vectors(T, normals),
    )


@jax.jit
def _placement(orientation, center):
    """``translation(center) @ rotation_3d(orientation)`` (17.9)."""
    return affine.compose(affine.translation(center), affine.rotation_3d(orientation))


def transform_mesh(mesh: Mesh, T) -> Mesh:
    """Apply a rigid homogeneous transform ``T (4, 4)`` (:mod:`jrigid.affine`) to a mesh."""
    nv, nf, dt = len(mesh.vertices), len(mesh.faces), float_dtype()
    v, c, n = _transform_kernel(
        jnp.asarray(T, dtype=dt),
        jnp.asarray(pad(mesh.vertices, bucket(nv)), dtype=dt),
        jnp.asarray(pad(mesh.centers, bucket(nf)), dtype=dt),
        jnp.asarray(pad(mesh.normals, bucket(nf)), dtype=dt),
    )
    return mesh._replace(
        vertices=np.asarray(v, dtype=float)[:nv],
        centers=np.asarray(c, dtype=float)[:nf],
        normals=np.asarray(n, dtype=float)[:nf],
    )


def merge(*meshes: Mesh) -> Mesh:
    """One mesh from several (vertex indices are offset)."""
    offset, faces = 0, []
    for m in meshes:
        faces.append(m.faces + offset)
        offset += len(m.vertices)
    return Mesh(
        np.concatenate([m.vertices for m in meshes]),
        np.concatenate(faces),
        np.concatenate([m.normals for m in meshes]),
        np.concatenate([m.centers for m in meshes]),
        np.concatenate([m.colors for m in meshes]),
    )


def t_handle(
    bar_length: float = 1.0,
    bar_radius: float = 0.08,
    stem_length: float = 0.7,
    stem_radius: float = 0.06,
    n: int = 16,
) -> Mesh:
    """T-handle (Dzhanibekov's wing nut): bar along body ``x``, stem along ``+y``.

    The parts and their placement are the mass model :func:`jrigid.inertia.t_handle_parts`
    (re-exported here), centred on the centre of mass of a uniform body.

    Returns:
        :class:`Mesh`.
    """
    meshes = []
    colors = (PALETTE["handle"], PALETTE["stem"])
    parts = t_handle_parts(bar_length, bar_radius, stem_length, stem_radius)
    for part, color in zip(parts, colors, strict=True):
        m = cylinder(part["radius"], part["length"], n=n, color=color, sectors=2)
        T = _placement(jnp.asarray(part["orientation"]), jnp.asarray(part["center"]))
        meshes.append(transform_mesh(m, T))
    return merge(*meshes)
