"""Stability maps on the sphere of spin directions: a globe and an equal-area map.

Values computed per direction (by :mod:`jrigid.stability`: the angle the nearest axis
moves, the flip count, the FTLE ...) are drawn in colour, each pixel taking the value of
the nearest direction (a k-d tree, ``scipy.spatial.cKDTree``),

* on a **globe**: an orthographic view of the unit sphere from a chosen direction (front
  hemisphere only; drawn here with numpy, no ``mplot3d``), and
* on a **Mollweide map** (matplotlib's equal-area ``"mollweide"`` projection), which shows
  the whole sphere at once with areas in proportion, so the share of the map a region
  takes is its share of directions.

The map's coordinates follow the body: latitude ``asin(d_hi)`` (the axis of largest
moment at the poles), longitude ``atan2(d_mid, d_lo)`` (the smallest axis at the centre,
its negative at the left and right edges, the intermediate axis at ``±90°``). Polhodes (from
:func:`jrigid.stability.polhode_family`) are drawn over both as thin lines: the directions
of ω move along them, and the separatrix through the intermediate axis bounds the regions.

Example::

    from jrigid import stability
    from jrigid.viz import stability as vs
    fig = vs.stability_figure(directions, {"max axis angle (deg)": angles}, moments,
                              polhodes=stability.polhode_family(moments))
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ._figure import new_figure

__all__ = ["draw_globe", "draw_map", "map_coordinates", "stability_figure"]

_AXIS_NAMES = ("smallest", "intermediate", "largest")


def _order(moments) -> np.ndarray:
    return np.argsort(np.asarray(moments, dtype=float))


def map_coordinates(directions, moments) -> tuple[np.ndarray, np.ndarray]:
    """Longitude and latitude (radians) of body directions on the map.

    Args:
        directions: ``(..., 3)`` body-frame vectors (need not be unit).
        moments: ``(3,)`` principal moments (sets which axis goes where).

    Returns:
        ``(lon, lat)``, each of shape ``(...)``: ``lat = asin(d_hi)``,
        ``lon = atan2(d_mid, d_lo)``.
    """
    d = np.asarray(directions, dtype=float)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    lo, mid, hi = _order(moments)
    lat = np.arcsin(np.clip(d[..., hi], -1.0, 1.0))
    lon = np.arctan2(d[..., mid], d[..., lo])
    return lon, lat


def _values(values, directions) -> np.ndarray:
    """``values`` as a float array of shape ``(N,)``, one per direction, or ``ValueError``."""
    vals = np.asarray(values, dtype=float)
    n = np.shape(directions)[0]
    if vals.shape != (n,):
        raise ValueError(f"values must have shape (N,) = ({n},), one per direction; got "
                         f"shape {vals.shape}")
    return vals


def _nearest(directions, query) -> np.ndarray:
    """Index of the nearest of ``directions (N, 3)`` to each of ``query (..., 3)``."""
    from scipy.spatial import cKDTree

    d = np.asarray(directions, dtype=float)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    q = np.asarray(query, dtype=float)
    _, idx = cKDTree(d).query(q.reshape(-1, 3))
    return idx.reshape(q.shape[:-1])


def _split_at_seam(lon, lat):
    """Insert NaNs where a curve jumps across the map's ±180° seam."""
    jump = np.abs(np.diff(lon)) > np.pi
    idx = np.nonzero(jump)[0] + 1
    return np.insert(lon, idx, np.nan), np.insert(lat, idx, np.nan)


def draw_map(
    ax,
    directions,
    values,
    moments,
    *,
    polhodes=None,
    cmap: str = "viridis",
    vmin=None,
    vmax=None,
    resolution: int = 180,
):
    """Draw values per direction on a Mollweide axes (``projection="mollweide"``).

    Each cell of a ``resolution × 2 resolution`` longitude-latitude grid takes the value
    of the nearest direction (non-finite values are left blank).

    Args:
        ax: a matplotlib axes created with ``projection="mollweide"``.
        directions: ``(N, 3)`` body-frame directions.
        values: ``(N,)`` values (colour).
        moments: ``(3,)`` principal moments.
        polhodes: ``(C, n, 3)`` curves of body ω (optional), drawn in white.
        cmap, vmin, vmax: colour map and limits.
        resolution: cells in latitude.

    Returns:
        the mesh artist (for a colour bar).
    """
    vals = _values(values, directions)
    lo, mid, hi = _order(moments)
    lon_e = np.linspace(-np.pi, np.pi, 2 * resolution + 1)
    lat_e = np.linspace(-np.pi / 2, np.pi / 2, resolution + 1)
    lon_c, lat_c = np.meshgrid(0.5 * (lon_e[1:] + lon_e[:-1]), 0.5 * (lat_e[1:] + lat_e[:-1]))
    query = np.zeros(lon_c.shape + (3,))
    query[..., lo] = np.cos(lat_c) * np.cos(lon_c)
    query[..., mid] = np.cos(lat_c) * np.sin(lon_c)
    query[..., hi] = np.sin(lat_c)
    grid = vals[_nearest(directions, query)]
    art = _paint(ax, lon_e, lat_e, grid, cmap, vmin, vmax)
    if polhodes is not None:
        for curve in np.asarray(polhodes, dtype=float):
            cl, ca = _split_at_seam(*map_coordinates(curve, moments))
            ax.plot(cl, ca, color="white", lw=0.6, alpha=0.85)
    marks = [
        (0.0, 0.0, f"{lo + 1}"),
        (np.pi / 2, 0.0, f"{mid + 1}"),
        (-np.pi / 2, 0.0, f"−{mid + 1}"),
        (0.0, np.pi / 2 * 0.93, f"{hi + 1}"),
        (0.0, -np.pi / 2 * 0.93, f"−{hi + 1}"),
    ]
    for x, y, text in marks:
        ax.text(
            x,
            y,
            text,
            color="black",
            fontsize=7,
            ha="center",
            va="center",
            bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.7),
        )
    ax.set_xticklabels([])
    ax.set_yticklabels([])
    ax.grid(True, lw=0.3, alpha=0.4)
    return art


def _paint(ax, x_edges, y_edges, grid, cmap, vmin, vmax):
    """Colour the cells of ``grid`` (NaN cells left blank); the mesh artist."""
    return ax.pcolormesh(
        x_edges,
        y_edges,
        np.ma.masked_invalid(grid),
        cmap=cmap,
        vmin=vmin,
        vmax=vmax,
        shading="flat",
        rasterized=True,
    )


def _view_basis(view):
    v = np.asarray(view, dtype=float)
    v = v / np.linalg.norm(v)
    up0 = np.array([0.0, 0.0, 1.0]) if abs(v[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    right = np.cross(up0, v)
    right /= np.linalg.norm(right)
    return v, right, np.cross(v, right)


def draw_globe(
    ax,
    directions,
    values,
    moments,
    *,
    view=(1.0, 0.8, 0.6),
    polhodes=None,
    cmap: str = "viridis",
    vmin=None,
    vmax=None,
    resolution: int = 200,
):
    """Draw values per direction on the unit sphere seen from ``view`` (orthographic).

    Body axis ``k`` is the body-frame unit vector ``e_k``; only the hemisphere facing the
    viewer is drawn. Each pixel of a ``resolution²`` image takes the value of the nearest
    direction.

    Args:
        ax: a plain matplotlib axes.
        directions: ``(N, 3)`` body-frame directions.
        values: ``(N,)`` values (colour).
        moments: ``(3,)`` principal moments (for axis labels).
        view: ``(3,)`` direction from the centre to the viewer, body frame.
        polhodes: ``(C, n, 3)`` curves of body ω (optional).
        cmap, vmin, vmax: colour map and limits.
        resolution: pixels across.

    Returns:
        the mesh artist.
    """
    v, right, up = _view_basis(view)
    vals = _values(values, directions)
    edges = np.linspace(-1.0, 1.0, resolution + 1)
    xc, yc = np.meshgrid(0.5 * (edges[1:] + edges[:-1]), 0.5 * (edges[1:] + edges[:-1]))
    r2 = xc * xc + yc * yc
    inside = r2 < 1.0
    zc = np.sqrt(np.where(inside, 1.0 - r2, 0.0))
    query = xc[..., None] * right + yc[..., None] * up + zc[..., None] * v
    grid = np.where(inside, vals[_nearest(directions, query)], np.nan)
    art = _paint(ax, edges, edges, grid, cmap, vmin, vmax)
    if polhodes is not None:
        for curve in np.asarray(polhodes, dtype=float):
            c = curve / np.linalg.norm(curve, axis=-1, keepdims=True)
            px, py = c @ right, c @ up
            hidden = c @ v <= 0
            px, py = np.where(hidden, np.nan, px), np.where(hidden, np.nan, py)
            ax.plot(px, py, color="white", lw=0.6, alpha=0.85)
    t = np.linspace(0, 2 * np.pi, 200)
    ax.plot(np.cos(t), np.sin(t), color="0.3", lw=0.8)
    names = dict(zip(_order(moments), _AXIS_NAMES, strict=True))
    for k in range(3):
        for sign in (1.0, -1.0):
            e = np.zeros(3)
            e[k] = sign
            if e @ v > 0.05:
                ax.annotate(
                    f"{'−' if sign < 0 else ''}{k + 1} ({names[k]})",
                    (e @ right, e @ up),
                    fontsize=7,
                    ha="center",
                    va="center",
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.7),
                )
    ax.set_aspect("equal")
    ax.set_xlim(-1.05, 1.05)
    ax.set_ylim(-1.05, 1.05)
    ax.axis("off")
    return art


def stability_figure(
    directions,
    fields: Mapping[str, object],
    moments,
    *,
    polhodes=None,
    view=(1.0, 0.8, 0.6),
    title: str = "",
    cmaps: Mapping[str, str] | None = None,
    limits: Mapping[str, tuple] | None = None,
    width: float = 9.0,
):
    """One row per field: the globe and the Mollweide map, with a shared colour bar.

    Args:
        directions: ``(N, 3)`` body-frame directions.
        fields: label → ``(N,)`` values, one row each.
        moments: ``(3,)`` principal moments.
        polhodes: ``(C, n, 3)`` curves of body ω drawn over every panel (optional).
        view: globe viewing direction (body frame).
        title: figure title.
        cmaps: label → colour map name (default ``viridis``).
        limits: label → ``(vmin, vmax)``.
        width: figure width in inches.

    Returns:
        ``matplotlib.figure.Figure``.
    """
    cmaps, limits = dict(cmaps or {}), dict(limits or {})
    rows = len(fields)
    fig = new_figure(figsize=(width, 2.9 * rows), layout=None)
    fig.subplots_adjust(
        left=0.02, right=0.9, top=0.93 if title else 0.97, bottom=0.03, wspace=0.05, hspace=0.15
    )
    for r, (label, vals) in enumerate(fields.items()):
        vmin, vmax = limits.get(label, (None, None))
        cmap = cmaps.get(label, "viridis")
        ax_g = fig.add_subplot(rows, 3, 3 * r + 1)
        ax_m = fig.add_subplot(rows, 3, (3 * r + 2, 3 * r + 3), projection="mollweide")
        draw_globe(
            ax_g,
            directions,
            vals,
            moments,
            view=view,
            polhodes=polhodes,
            cmap=cmap,
            vmin=vmin,
            vmax=vmax,
        )
        art = draw_map(
            ax_m, directions, vals, moments, polhodes=polhodes, cmap=cmap, vmin=vmin, vmax=vmax
        )
        bar = fig.colorbar(art, ax=[ax_g, ax_m], fraction=0.025, pad=0.01)
        bar.set_label(label, fontsize=8)
        bar.ax.tick_params(labelsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig
