"""The chapter's two windows: the body seen from space and the world seen from the body.

Left, the **space frame**: the body at its orientation, the body axes ``1, 2, 3`` (red,
green, blue), the angular velocity ``ω`` (orange) and the angular momentum ``L``
(purple, fixed for a free body), with trails of the body axes' tips, of ``ω``'s tip (for
a free body it stays in the plane ``ω·L = 2E`` normal to ``L``: the herpolhode) and of
``L``'s tip (a dot unless ``L`` drifts).

Right, the **body frame** (section 17.6, "a second window displays the body frame view
with space frame xyz-axes orbiting the block"): the body fixed, ``ω`` and ``L`` moving,
with trails of ``ω``'s tip (the polhode) and ``L``'s tip (and, on request, of the space
axes' tips).

Arrow lengths are scaled per quantity so that the largest value over the trajectory is
``1.6`` body radii: directions and relative sizes are exact, units are not.
Drawing goes through :mod:`jrigid.viz.render` (own projection, painter's algorithm).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure

from jrigid import quaternion as quat

from ._figure import new_figure
from .data import Series, as_series
from .render import (
    Camera,
    MeshView,
    arrow_from_projected,
    arrow_points,
    body_transform,
    combine,
    draw_polygons,
    polyline_from_projected,
    project,
    setup_axes,
    shade_mesh,
    view_mesh,
)
from .shapes import Mesh

__all__ = ["DualView", "space_body_views", "body_still"]

AXIS_COLORS = ("#d62728", "#2ca02c", "#1f77b4")
SPACE_AXIS_COLORS = ("#555555", "#888888", "#222222")
OMEGA_COLOR = "#ff7f0e"
L_COLOR = "#9467bd"


def _scale(x: np.ndarray | None, length: float) -> float:
    if x is None:
        return 0.0
    m = float(np.max(np.linalg.norm(x, axis=-1)))
    return length / m if m > 0 else 0.0


class _Painter:
    """Depth-sorted polygons and tip labels of both views at any sample.

    Everything that does not depend on the frame being drawn is projected once for the
    whole series (trails, arrows); body placements are projected in batches on demand.
    """

    def __init__(
        self, s: Series, mesh: Mesh, camera: Camera, trail, trails, body_trails=(), show_axes=True
    ):
        self.s, self.mesh, self.camera = s, mesh, camera
        self.trail, self.show_axes = trail, show_axes
        self.trails = {"space": tuple(trails), "body": tuple(body_trails)}
        size = mesh.radius
        self.axis_len = 1.35 * size
        self.w_scale = _scale(s.omega, 1.6 * size)
        self.L_scale = _scale(s.L, 1.6 * size)
        self.extent = 1.85 * size
        self.width = 0.012 * self.extent
        self._mesh_views: dict[int, MeshView] = {}
        self._body_mesh = view_mesh(mesh, np.eye(4), camera)
        Rt = np.swapaxes(s.R, -1, -2)  # columns: space axes in body coordinates
        self._vectors = {"space": {}, "body": {}}
        for k in range(3):
            self._add("space", str(k + 1), s.R[:, :, k] * self.axis_len, AXIS_COLORS[k], "axes")
            self._add("body", "xyz"[k], Rt[:, :, k] * self.axis_len, SPACE_AXIS_COLORS[k], "axes")
        for frame, w, L in (("space", s.omega_space, s.L_space), ("body", s.omega, s.L)):
            if w is not None and self.w_scale > 0:
                self._add(frame, "ω", w * self.w_scale, OMEGA_COLOR, "omega")
            if L is not None and self.L_scale > 0:
                self._add(frame, "L", L * self.L_scale, L_COLOR, "L")

    def _add(self, frame, name, vecs, color, kind):
        """Project the arrows (all samples) and their tips' trail once."""
        if kind == "axes" and not self.show_axes:
            return
        uv, depth = project(arrow_points(np.zeros(3), vecs), self.camera)
        self._vectors[frame][name] = (uv, depth, color, kind)

    def prepare(self, indices) -> None:
        """Project the body at the samples ``indices`` in one batch (for animations)."""
        idx = [int(i) for i in np.atleast_1d(indices) if int(i) not in self._mesh_views]
        if not idx:
            return
        mv = view_mesh(self.mesh, body_transform(self.s.q[idx]), self.camera)
        for j, i in enumerate(idx):
            self._mesh_views[i] = MeshView(*(a[j] for a in mv))

    def _scene(self, frame: str, i: int, mesh_view: MeshView):
        labels: dict = {}
        parts = [shade_mesh(self.mesh, mesh_view, self.camera)]
        win = slice(0 if self.trail is None else max(0, i - self.trail), i + 1)
        for name, (uv, depth, color, kind) in self._vectors[frame].items():
            thin = kind == "axes"
            parts.append(
                arrow_from_projected(
                    uv[i], depth[i], color,
                    width=self.width * (1.0 if thin else 1.6),
                    head_length=0.09 * self.extent, head_width=0.07 * self.extent,
                )
            )  # fmt: skip
            tip, tail = uv[i, -1], uv[i, 0]
            labels[name] = (tip + 0.1 * (tip - tail), color)
            if kind in self.trails[frame]:
                parts.append(
                    polyline_from_projected(uv[win, -1], depth[win, -1], color, width=self.width)
                )
        return combine(*parts), labels

    def space(self, i: int):
        """The body from space: body axes 1, 2, 3, ω and L in space coordinates."""
        self.prepare([i])
        return self._scene("space", i, self._mesh_views[i])

    def body(self, i: int):
        """The world from the body: space axes x, y, z, ω and L in body coordinates."""
        return self._scene("body", i, self._body_mesh)


class _Panel:
    """One axes holding a single PolyCollection and the tip labels, updated in place."""

    def __init__(self, ax, camera: Camera, extent: float, title: str):
        self.ax, self.camera = ax, camera
        self.collection = None
        self.texts: dict = {}
        setup_axes(ax, extent, title)

    def draw(self, polys, labels) -> None:
        self.collection = draw_polygons(self.ax, polys, self.collection)
        for name, (uv, color) in labels.items():
            if name not in self.texts:
                self.texts[name] = self.ax.text(
                    0, 0, name, color=color, fontsize=9, fontweight="bold",
                    ha="center", va="center", zorder=5,
                )  # fmt: skip
            self.texts[name].set_position((float(uv[0]), float(uv[1])))
            self.texts[name].set_visible(True)
        for name, t in self.texts.items():
            if name not in labels:
                t.set_visible(False)


class DualView:
    """Space-frame and body-frame views side by side, redrawable frame by frame.

    Args:
        data: trajectory-like object or mapping of arrays (see :mod:`jrigid.viz.data`);
            needs ``q``; ``ω``/``L`` arrows appear when known (or derivable from ``moments``).
        mesh: the body (:mod:`jrigid.viz.shapes`).
        moments: principal moments, if ``data`` has none and ``L`` is wanted.
        camera: :class:`~jrigid.viz.render.Camera` for both panels.
        trail: number of past samples in the trails (``None``: all since the start).
        trails: trails in the space view, any of ``"axes"`` (body-axis tips), ``"omega"``
            (ω's tip), ``"L"`` (L's tip).
        body_trails: trails in the body view, any of ``"axes"`` (space-axis tips),
            ``"omega"`` (the polhode), ``"L"``.
        figsize, dpi: figure size (inches) and resolution.
        titles: panel titles.
        fig: draw into this figure instead of a new one (its content is cleared).

    Attributes:
        fig: the ``Figure``; ``draw(i)`` redraws it at sample ``i``.
    """

    def __init__(
        self,
        data: Any,
        mesh: Mesh,
        *,
        moments=None,
        camera: Camera | None = None,
        trail: int | None = None,
        trails: tuple[str, ...] = ("axes", "omega", "L"),
        body_trails: tuple[str, ...] = ("omega", "L"),
        figsize=(8.0, 4.0),
        dpi: int = 100,
        titles=("space frame", "body frame"),
        fig: Figure | None = None,
    ):
        camera = Camera() if camera is None else camera
        self.s: Series = as_series(data, moments)
        self.painter = _Painter(self.s, mesh, camera, trail, trails, body_trails)
        if fig is None:
            fig = new_figure(figsize=figsize, dpi=dpi, layout=None)
        else:
            fig.clear()
        fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=0.9, wspace=0.02)
        self.fig = fig
        axes = fig.subplots(1, 2)
        self.panels = [
            _Panel(ax, camera, self.painter.extent, title)
            for ax, title in zip(axes, titles, strict=True)
        ]
        self.time_text = axes[0].text(
            0.02, 0.02, "", transform=axes[0].transAxes, fontsize=9, color="#333333"
        )

    def draw(self, i: int) -> Figure:
        """Redraw both panels at sample ``i`` (negative counts from the end); return the figure."""
        i = range(len(self.s))[i]
        self.panels[0].draw(*self.painter.space(i))
        self.panels[1].draw(*self.painter.body(i))
        self.time_text.set_text(f"t = {self.s.ts[i]:.3g}")
        return self.fig


def space_body_views(data: Any, mesh: Mesh, index: int = -1, **kwargs) -> Figure:
    """Still of the two views at sample ``index`` with trails up to it.

    Args:
        data: trajectory-like or mapping (needs ``q``; ``omega``/``L``/``moments`` for arrows).
        mesh: body mesh.
        index: sample to draw (default the last).
        **kwargs: passed to :class:`DualView` (``moments``, ``camera``, ``trail``, ...).

    Returns:
        ``Figure``.
    """
    return DualView(data, mesh, **kwargs).draw(index)


def body_still(
    mesh: Mesh,
    q=None,
    *,
    omega=None,
    L=None,
    camera: Camera | None = None,
    ax=None,
    title: str = "",
    axes: bool = True,
) -> Figure:
    """One body at orientation ``q`` with optional space-frame ``ω`` and ``L`` arrows.

    Args:
        mesh: body mesh.
        q: ``(4,)`` body → space quaternion (default identity).
        omega, L: ``(3,)`` space-frame vectors, drawn scaled to 1.6 body radii.
        camera: :class:`~jrigid.viz.render.Camera`.
        ax: axes to draw on (default a new figure).
        title: panel title.
        axes: draw the body axes ``1, 2, 3``.

    Returns:
        the ``Figure``.
    """
    camera = Camera() if camera is None else camera
    q = np.array([1.0, 0.0, 0.0, 0.0]) if q is None else np.asarray(
        quat.check_quaternion(np.asarray(q, float), unit=False), float)
    data = {"q": q[None], "ts": np.zeros(1)}
    if omega is not None:
        data["omega_space"] = np.asarray(omega, float)[None]
    if L is not None:
        data["L_space"] = np.asarray(L, float)[None]
    if ax is None:
        fig = new_figure(figsize=(4, 4), layout=None)
        ax = fig.add_axes((0, 0, 1, 0.92))
    painter = _Painter(as_series(data), mesh, camera, None, (), (), show_axes=axes)
    _Panel(ax, camera, painter.extent, title).draw(*painter.space(0))
    return ax.figure
