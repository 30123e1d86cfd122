"""Projection and painter's-algorithm drawing of bodies, arrows and trails on 2D axes.

Why not matplotlib's 3D axes: ``mplot3d`` sorts each collection by one average depth,
so a body's faces, the arrows through it and the trails around it are drawn in the order
the artists were added, not by where they are (the chapter's remark that a naive 2D
projection draws faces in the wrong order, section 17.2). Here every primitive becomes a
screen-space polygon with its own depth:

1. place the body with a homogeneous transform (:func:`jrigid.affine.rotation_3d`,
   :func:`jrigid.affine.translation`) and :func:`jrigid.affine.apply_to_points`;
2. project with the camera: :func:`jrigid.affine.look_at` plus
   :func:`jrigid.affine.orthographic` (default) or :func:`jrigid.affine.perspective`,
   both of which return a depth (larger is farther);
3. drop faces turned away from the viewer (back-face culling), shade the rest by a
   Lambert term;
4. cut arrows and trails into short pieces, each a thin polygon with its own depth, so a
   body can hide part of an arrow;
5. sort everything back to front and draw it as one ``PolyCollection`` (painter's
   algorithm), which is also cheap to update frame by frame for animations.

Face depth is the depth of the face centroid; with small faces (the meshes of
:mod:`jrigid.viz.shapes` are subdivided) and back-face culling this is right for the
convex parts drawn here.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib import colors as mcolors
from matplotlib.collections import PolyCollection

from jrigid import affine

from ._jit import bucket, float_dtype, pad
from .shapes import Mesh

__all__ = [
    "Camera",
    "Polygons",
    "MeshView",
    "arrow_from_projected",
    "arrow_points",
    "arrow_polygons",
    "body_transform",
    "combine",
    "draw_polygons",
    "mesh_polygons",
    "polyline_from_projected",
    "polyline_polygons",
    "project",
    "shade_mesh",
    "view_mesh",
    "setup_axes",
]


class Camera(NamedTuple):
    """Where the viewer stands.

    Attributes:
        elev: elevation above the ``xy`` plane, degrees.
        azim: azimuth about ``z`` from ``+x``, degrees.
        distance: ``None`` for an orthographic projection (screen units = world units),
            else the eye's distance from the origin for a perspective camera.
        fov: vertical field of view in degrees (perspective only).
        scale: world extent mapped to the perspective image edge (perspective only;
            screen units then match world units near the target).
    """

    elev: float = 20.0
    azim: float = 35.0
    distance: float | None = None
    fov: float = 30.0
    scale: float = 1.0

    @property
    def direction(self) -> np.ndarray:
        """Unit vector from the origin toward the eye."""
        e, a = np.radians(self.elev), np.radians(self.azim)
        return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])

    @property
    def up(self) -> np.ndarray:
        """The world ``z`` axis, or the screen-up direction when looking along it."""
        if abs(self.elev) < 89.0:
            return np.array([0.0, 0.0, 1.0])
        a = np.radians(self.azim)
        return -np.sign(self.elev) * np.array([np.cos(a), np.sin(a), 0.0])

    def view_matrix(self) -> np.ndarray:
        """World → camera homogeneous matrix ``(4, 4)`` (:func:`jrigid.affine.look_at`)."""
        return _view_matrix(self)


@jax.jit
def _look_at_kernel(eye, up):
    return affine.look_at(eye, jnp.zeros_like(eye), up)


@functools.lru_cache(maxsize=64)
def _view_matrix(camera: Camera) -> np.ndarray:
    dist = 10.0 if camera.distance is None else camera.distance
    dt = float_dtype()
    eye = jnp.asarray(camera.direction * dist, dtype=dt)
    return np.asarray(_look_at_kernel(eye, jnp.asarray(camera.up, dtype=dt)), dtype=float)


@jax.jit
def _ortho_kernel(V, p):
    """World points ``p (N, 3)`` → camera (``V (4, 4)``) → orthographic along camera ``z``."""
    pc = affine.apply_to_points(V[None], p)
    return affine.orthographic(pc, axis=2)


@jax.jit
def _perspective_kernel(p, eye, up, fov):
    return affine.perspective(p, eye[None], jnp.zeros_like(eye)[None], fov, up=up[None])


@jax.jit
def _place_kernel(T, V, vertices, centers, normals):
    """Place a mesh with ``T (B, 4, 4)``: world vertices and centroids, and the normals and
    centroids in camera coordinates (``V (4, 4)``)."""
    Tb = T[:, None]
    world = affine.apply_to_points(Tb, vertices[None])
    cw = affine.apply_to_points(Tb, centers[None])
    VT = affine.compose(V[None], T)
    ncam = affine.apply_to_vectors(VT[:, None], normals[None])
    ccam = affine.apply_to_points(V[None, None], cw)
    return world, cw, ncam, ccam


def project(points, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Project world points to screen coordinates and depth.

    Orthographic: :func:`jrigid.affine.look_at` then :func:`jrigid.affine.orthographic`
    along the camera axis; perspective: :func:`jrigid.affine.perspective` (its image
    coordinates scaled by ``camera.scale · distance · tan(fov/2)`` so that screen units
    match world units at the target). Sizes are padded to powers of two so the jitted
    kernels compile once per size class.

    Args:
        points: ``(..., 3)`` world coordinates.
        camera: :class:`Camera`.

    Returns:
        ``(uv (..., 2), depth (...))`` as numpy arrays; larger depth is farther.
    """
    points = np.asarray(points, dtype=float)
    lead = points.shape[:-1]
    flat = points.reshape(-1, 3)
    n = len(flat)
    dt = float_dtype()
    p = jnp.asarray(pad(flat, bucket(n)), dtype=dt)
    if camera.distance is None:
        uv, depth = _ortho_kernel(jnp.asarray(camera.view_matrix(), dtype=dt), p)
    else:
        uv, depth = _perspective_kernel(
            p,
            jnp.asarray(camera.direction * camera.distance, dtype=dt),
            jnp.asarray(camera.up, dtype=dt),
            jnp.asarray(np.radians(camera.fov), dtype=dt),
        )
        uv = uv * (camera.scale * camera.distance * np.tan(np.radians(camera.fov) / 2))
    uv = np.asarray(uv, dtype=float)[:n].reshape(lead + (2,))
    return uv, np.asarray(depth, dtype=float)[:n].reshape(lead)


class Polygons(NamedTuple):
    """Screen-space polygons ready to sort and draw.

    Attributes:
        verts: ``(N, 4, 2)`` screen coordinates (triangles repeat a vertex).
        depth: ``(N,)`` larger is farther.
        facecolors: ``(N, 4)`` RGBA.
        edgecolors: ``(N, 4)`` RGBA.
        linewidths: ``(N,)`` edge widths in points.
    """

    verts: np.ndarray
    depth: np.ndarray
    facecolors: np.ndarray
    edgecolors: np.ndarray
    linewidths: np.ndarray

    @staticmethod
    def empty() -> Polygons:
        """No polygons."""
        return Polygons(
            np.zeros((0, 4, 2)), np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4)), np.zeros(0)
        )


def body_transform(q, position=None) -> np.ndarray:
    """Body → world homogeneous matrices from unit quaternions and optional positions.

    Uses :func:`jrigid.affine.rotation_3d` and :func:`jrigid.affine.translation` (17.9).

    Args:
        q: ``(..., 4)``.
        position: ``(..., 3)`` or ``None`` (the origin).

    Returns:
        ``(..., 4, 4)``.
    """
    q = np.asarray(q, dtype=float)
    batch = q.shape[:-1]
    qf = q.reshape(-1, 4)
    n = len(qf)
    pos = np.zeros((n, 3)) if position is None else np.broadcast_to(position, batch + (3,))
    T = _transform_kernel(
        jnp.asarray(pad(qf, bucket(n), [1.0, 0.0, 0.0, 0.0]), dtype=float_dtype()),
        jnp.asarray(pad(np.reshape(pos, (-1, 3)), bucket(n)), dtype=float_dtype()),
    )
    return np.asarray(T, dtype=float)[:n].reshape(batch + (4, 4))


@jax.jit
def _transform_kernel(q, position):
    return affine.compose(affine.translation(position), affine.rotation_3d(q))


class MeshView(NamedTuple):
    """A mesh seen by a camera, for one or many placements (leading batch ``...``).

    Attributes:
        uv: ``(..., V, 2)`` projected vertices.
        depth: ``(..., F)`` depth of the face centroids.
        normals: ``(..., F, 3)`` face normals in camera coordinates.
        centers: ``(..., F, 3)`` face centroids in camera coordinates.
    """

    uv: np.ndarray
    depth: np.ndarray
    normals: np.ndarray
    centers: np.ndarray


def view_mesh(mesh: Mesh, transforms, camera: Camera) -> MeshView:
    """Place a mesh with ``transforms (..., 4, 4)`` and project it, all placements at once.

    The whole batch goes through :func:`jrigid.affine.apply_to_points` and the camera
    in one jitted call; per-frame drawing is then plain array indexing.

    Returns:
        :class:`MeshView` with the leading batch shape of ``transforms``.
    """
    T = np.asarray(transforms, dtype=float)
    batch = T.shape[:-2]
    Tf = T.reshape(-1, 4, 4)
    B, nv, nf = len(Tf), len(mesh.vertices), len(mesh.faces)
    dt = float_dtype()
    world, cw, ncam, ccam = _place_kernel(
        jnp.asarray(pad(Tf, bucket(B), np.eye(4)), dtype=dt),
        jnp.asarray(camera.view_matrix(), dtype=dt),
        jnp.asarray(pad(mesh.vertices, bucket(nv)), dtype=dt),
        jnp.asarray(pad(mesh.centers, bucket(nf)), dtype=dt),
        jnp.asarray(pad(mesh.normals, bucket(nf)), dtype=dt),
    )
    world = np.asarray(world, float)[:B, :nv]
    cw = np.asarray(cw, float)[:B, :nf]
    uv, _ = project(world, camera)
    _, depth = project(cw, camera)
    return MeshView(
        uv.reshape(batch + (nv, 2)),
        depth.reshape(batch + (nf,)),
        np.asarray(ncam, float)[:B, :nf].reshape(batch + (nf, 3)),
        np.asarray(ccam, float)[:B, :nf].reshape(batch + (nf, 3)),
    )


def shade_mesh(
    mesh: Mesh,
    view: MeshView,
    camera: Camera,
    *,
    light=(-0.4, 0.6, 1.0),
    ambient: float = 0.45,
    alpha: float = 1.0,
    cull: bool = True,
    edge_width: float = 0.3,
) -> Polygons:
    """Face polygons of one placement of a projected mesh: culled, Lambert-shaded.

    Args:
        mesh: the mesh (for faces and colours).
        view: one placement from :func:`view_mesh` (no batch dimension).
        camera: the camera used for ``view``.
        light: direction toward the light in camera coordinates (x right, y up, z to viewer).
        ambient: brightness of unlit faces in ``[0, 1]``.
        alpha: face opacity.
        cull: drop faces whose normal points away from the viewer (back-face culling).
        edge_width: face outline width in points.

    Returns:
        :class:`Polygons` (unsorted).
    """
    if camera.distance is None:
        facing = view.normals[:, 2]
    else:
        facing = -np.sum(view.normals * view.centers, axis=-1)
    keep = facing > 0 if cull else np.ones(len(mesh.faces), bool)
    lvec = np.asarray(light, float) / np.linalg.norm(light)
    lambert = np.clip(view.normals @ lvec, 0.0, 1.0)
    shade = ambient + (1.0 - ambient) * lambert
    rgb = np.clip(mesh.colors * shade[:, None], 0.0, 1.0)
    face = np.concatenate([rgb, np.full((len(rgb), 1), alpha)], axis=1)
    edge = np.concatenate([rgb * 0.6, np.full((len(rgb), 1), alpha)], axis=1)
    return Polygons(
        view.uv[mesh.faces][keep],
        view.depth[keep],
        face[keep],
        edge[keep],
        np.full(int(keep.sum()), edge_width),
    )


def mesh_polygons(mesh: Mesh, transform, camera: Camera, **kwargs) -> Polygons:
    """Project a mesh placed by ``transform (4, 4)`` and shade its faces.

    :func:`view_mesh` followed by :func:`shade_mesh` (whose keyword options it takes).

    Returns:
        :class:`Polygons` (unsorted).
    """
    return shade_mesh(mesh, view_mesh(mesh, transform, camera), camera, **kwargs)


def _rgba(color, n: int, alpha=None) -> np.ndarray:
    c = np.tile(np.asarray(mcolors.to_rgba(color), float), (n, 1))
    if alpha is not None:
        c[:, 3] = alpha
    return c


def _ribbon(uv0, uv1, width) -> np.ndarray:
    """Quads of ``width`` around 2D segments ``uv0 -> uv1`` ``(N, 2)``; shape ``(N, 4, 2)``."""
    d = uv1 - uv0
    length = np.linalg.norm(d, axis=-1, keepdims=True)
    d = np.where(length > 1e-12, d / np.maximum(length, 1e-12), [1.0, 0.0])
    w = np.broadcast_to(np.asarray(width, float), (len(uv0),))[:, None] / 2
    n = np.stack([-d[:, 1], d[:, 0]], axis=-1) * w
    return np.stack([uv0 - n, uv1 - n, uv1 + n, uv0 + n], axis=1)


def arrow_points(start, vector, pieces: int = 12) -> np.ndarray:
    """Points ``start + s·vector``, ``s`` in ``[0, 1]``, along 3D arrows; ``(..., pieces+1, 3)``."""
    s = np.linspace(0.0, 1.0, pieces + 1)[:, None]
    start = np.asarray(start, float)[..., None, :]
    return start + s * np.asarray(vector, float)[..., None, :]


def arrow_from_projected(
    uv, depth, color, *, width: float = 0.03, head_length: float = 0.15, head_width: float = 0.1
) -> Polygons:
    """Arrow polygons from projected shaft points (``uv (P, 2)``, ``depth (P,)``, tail first).

    The shaft becomes ``P - 1`` thin quads, each with its own depth, and the head a
    triangle; sizes are in screen units.
    """
    tip = uv[-1]
    screen_len = float(np.linalg.norm(tip - uv[0]))
    if not np.isfinite(screen_len) or screen_len < 1e-9:
        return Polygons.empty()
    hl = min(head_length, 0.5 * screen_len)
    d = (tip - uv[0]) / screen_len
    base = tip - hl * d
    frac = np.linalg.norm(uv - uv[0], axis=-1) / screen_len
    keep = frac <= 1.0 - hl / screen_len + 1e-12
    su = np.concatenate([uv[keep], base[None]])
    sd = np.concatenate([depth[keep], depth[-1:]])
    quads = _ribbon(su[:-1], su[1:], width)
    qdepth = 0.5 * (sd[:-1] + sd[1:])
    nrm = np.array([-d[1], d[0]]) * head_width / 2
    head = np.stack([base - nrm, tip, base + nrm, base + nrm])[None]
    verts = np.concatenate([quads, head])
    dep = np.concatenate([qdepth, depth[-1:]])
    fc = _rgba(color, len(verts))
    return Polygons(verts, dep, fc, fc.copy(), np.zeros(len(verts)))


def arrow_polygons(start, vector, camera: Camera, color, *, pieces: int = 12, **kwargs) -> Polygons:
    """A 3D arrow from ``start`` along ``vector`` as depth-tagged screen polygons.

    The shaft is cut into ``pieces`` thin quads (each with its own depth, so a body can
    hide part of it) and the head is a triangle; ``width``, ``head_length`` and
    ``head_width`` are in screen units (world units for the orthographic camera).

    Args:
        start, vector: ``(3,)`` world coordinates.
        camera: :class:`Camera`.
        color: any matplotlib colour.

    Returns:
        :class:`Polygons` (unsorted).
    """
    uv, depth = project(arrow_points(start, vector, pieces), camera)
    return arrow_from_projected(uv, depth, color, **kwargs)


def polyline_from_projected(
    uv, depth, color, *, width: float = 0.02, fade: bool = True
) -> Polygons:
    """Trail polygons from projected points (``uv (N, 2)``, ``depth (N,)``, oldest first).

    Each segment is a thin quad with its own depth; with ``fade`` the alpha rises from
    0.15 (oldest) to 1 (newest).
    """
    if len(uv) < 2:
        return Polygons.empty()
    quads = _ribbon(uv[:-1], uv[1:], width)
    n = len(quads)
    fc = _rgba(color, n, np.linspace(0.15, 1.0, n) if fade else None)
    return Polygons(quads, 0.5 * (depth[:-1] + depth[1:]), fc, fc.copy(), np.zeros(n))


def polyline_polygons(points, camera: Camera, color, **kwargs) -> Polygons:
    """A 3D polyline (a trail, ``points (N, 3)`` oldest first) as depth-tagged thin quads.

    Keyword options as :func:`polyline_from_projected` (``width``, ``fade``).

    Returns:
        :class:`Polygons` (unsorted).
    """
    uv, depth = project(np.asarray(points, float), camera)
    return polyline_from_projected(uv, depth, color, **kwargs)


def combine(*parts: Polygons) -> Polygons:
    """Concatenate polygon sets and sort them back to front (painter's algorithm)."""
    parts = [p for p in parts if len(p.depth)]
    if not parts:
        return Polygons.empty()
    cat = Polygons(*(np.concatenate(field) for field in zip(*parts, strict=True)))
    order = np.argsort(-cat.depth, kind="stable")
    return Polygons(*(field[order] for field in cat))


def draw_polygons(ax, polys: Polygons, collection: PolyCollection | None = None) -> PolyCollection:
    """Draw sorted polygons on ``ax`` as one ``PolyCollection`` (or update ``collection``).

    Returns:
        the collection.
    """
    if collection is None:
        collection = PolyCollection(
            list(polys.verts), closed=True, antialiaseds=True, joinstyle="round"
        )
        ax.add_collection(collection)
    else:
        collection.set_verts(list(polys.verts))
    collection.set_facecolor(polys.facecolors)
    collection.set_edgecolor(polys.edgecolors)
    collection.set_linewidth(polys.linewidths if len(polys.linewidths) else 0.0)
    return collection


def setup_axes(ax, extent: float, title: str = "") -> None:
    """Equal aspect, limits ``±extent``, no ticks or frame."""
    ax.set_xlim(-extent, extent)
    ax.set_ylim(-extent, extent)
    ax.set_aspect("equal")
    ax.set_axis_off()
    if title:
        ax.set_title(title, fontsize=10)
