"""Pictures of rigid bodies: meshes, projected views, time series and animations.

The only part of jrigid that imports matplotlib (``import jrigid`` stays light). Figures
are built with the object-oriented API on an Agg canvas (:func:`new_figure`): nothing
touches pyplot's global state, everything works headless whatever backend a user chose,
and every function returns its ``Figure`` so notebooks display it.

Modules:

* :mod:`~jrigid.viz.shapes` — body meshes (box, ellipsoid, disk, rod, T-handle).
* :mod:`~jrigid.viz.render` — projection through :mod:`jrigid.affine` and the painter's
  algorithm (and why not ``mplot3d``).
* :mod:`~jrigid.viz.views` — the space-frame and body-frame views side by side.
* :mod:`~jrigid.viz.plots` — time series: ω, energy and ``|L|`` drift, ``|q| − 1``,
  Euler angles, precession and nutation.
* :mod:`~jrigid.viz.animation` — GIF (Pillow) and MP4 (ffmpeg) at a frame rate of its own.
* :mod:`~jrigid.viz.data` — trajectory or plain arrays → numpy series; slerp resampling.
* :mod:`~jrigid.viz.angles` — precession, nutation and spin about ``L``.

Example::

    from jrigid import viz
    fig = viz.space_body_views(traj, viz.disk(1.0, 0.1))   # traj: q, omega, L ...
    fig.savefig("plate.png")
    viz.animate(traj, viz.disk(1.0, 0.1), "plate.gif")
"""

from . import angles, animation, data, plots, render, shapes, views
from ._figure import MIN_WIDTH_PX, new_figure, save
from .angles import euler_about, fit_rate
from .animation import (
    AliasingWarning,
    animate,
    ffmpeg_available,
    frame_times,
    write_animation,
)
from .data import Series, as_series, resample
from .plots import *  # noqa: F403 - every name of plots.__all__, added below
from .render import Camera
from .shapes import Mesh, box, cylinder, disk, ellipsoid, rod, t_handle
from .views import *  # noqa: F403 - every name of views.__all__, added below

__all__ = [
    "AliasingWarning",
    "Camera",
    "MIN_WIDTH_PX",
    "Mesh",
    "Series",
    "angles",
    "animate",
    "animation",
    "as_series",
    "box",
    "cylinder",
    "data",
    "disk",
    "ellipsoid",
    "euler_about",
    "ffmpeg_available",
    "fit_rate",
    "frame_times",
    "new_figure",
    "plots",
    "render",
    "resample",
    "rod",
    "save",
    "shapes",
    "t_handle",
    "views",
    "write_animation",
]
# Modules re-exported whole: their own ``__all__``.
__all__ += plots.__all__
__all__ += views.__all__
