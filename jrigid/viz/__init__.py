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

from jrigid.viz import _figure, angles, animation, data, plots, render, shapes, views  # noqa: I001
from jrigid.viz._figure import *  # noqa: F403
from jrigid.viz.angles import *  # noqa: F403
from jrigid.viz.animation import *  # noqa: F403
from jrigid.viz.data import *  # noqa: F403
from jrigid.viz.plots import *  # noqa: F403
from jrigid.viz.render import *  # noqa: F403
from jrigid.viz.shapes import *  # noqa: F403
from jrigid.viz.views import *  # noqa: F403

# The package's names: each listed once, in the ``__all__`` of the module defining it.
__all__: list[str] = []
__all__ += _figure.__all__
__all__ += angles.__all__
__all__ += animation.__all__
__all__ += data.__all__
__all__ += plots.__all__
__all__ += render.__all__
__all__ += shapes.__all__
__all__ += views.__all__
__all__ += ["angles", "animation", "data", "plots", "render", "shapes", "views"]
