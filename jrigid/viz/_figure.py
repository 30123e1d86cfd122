"""Figures without pyplot: ``matplotlib.figure.Figure`` on an Agg canvas.

No global pyplot state is touched, so the library works headless (CI, servers) whatever
backend a user chose, and the returned figures still display in Jupyter (a ``Figure``
renders itself as PNG in a notebook cell).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["MIN_WIDTH_PX", "new_figure", "save"]

MIN_WIDTH_PX = 1000  # raster images at least this wide: readable at page width
RASTER = (".png", ".jpg", ".jpeg", ".webp", ".tif", ".tiff")


def new_figure(figsize=(6.4, 4.8), dpi: int = 100, **kwargs) -> Figure:
    """A ``Figure`` attached to an Agg canvas (``constrained_layout`` on by default)."""
    kwargs.setdefault("layout", "constrained")
    fig = Figure(figsize=figsize, dpi=dpi, **kwargs)
    FigureCanvasAgg(fig)
    return fig


def save(fig, path: str | os.PathLike, dpi: int | None = None, *,
         min_width: int = MIN_WIDTH_PX) -> Path:
    """Save ``fig`` to ``path`` (format from the extension), creating folders; return the path.

    Args:
        fig: a ``Figure`` (or anything with ``savefig(path, dpi=...)``).
        path: output file; its extension picks the format.
        dpi: resolution; default the figure's own. A raster image (PNG, JPEG, …) is raised
            to at least ``min_width`` pixels wide, so that it stays readable at page width.
        min_width: smallest raster width in pixels (``0``: keep ``dpi`` as given).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    dpi = getattr(fig, "dpi", 100) if dpi is None else dpi
    width = getattr(fig, "get_figwidth", None)
    if path.suffix.lower() in RASTER and width is not None and min_width > 0:
        dpi = max(dpi, math.ceil(min_width / width()))
    fig.savefig(path, dpi=dpi)
    return path
