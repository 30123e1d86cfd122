"""Figures without pyplot: ``matplotlib.figure.Figure`` on an Agg canvas.

No global pyplot state is touched, so the library works headless (CI, servers) whatever
backend a user chose, and the returned figures still display in Jupyter (a ``Figure``
renders itself as PNG in a notebook cell).
"""

from __future__ import annotations

import os
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["new_figure", "save"]


def new_figure(figsize=(6.4, 4.8), dpi: int = 100, **kwargs) -> Figure:
    """A ``Figure`` attached to an Agg canvas (``constrained_layout`` on by default)."""
    kwargs.setdefault("layout", "constrained")
    fig = Figure(figsize=figsize, dpi=dpi, **kwargs)
    FigureCanvasAgg(fig)
    return fig


def save(fig: Figure, path: str | os.PathLike, dpi: int | None = None) -> Path:
    """Save ``fig`` to ``path`` (format from the extension), creating folders; return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi if dpi is not None else fig.dpi)
    return path
