"""Animations: GIF through matplotlib's Pillow writer, MP4 when ffmpeg is installed.

GIFs use :class:`PalettePillowWriter`, matplotlib's ``PillowWriter`` with one shared
64-colour palette, to keep files small.

The frame rate is decoupled from the solver: the trajectory is resampled at evenly
spaced frame times (quaternions by slerp, :func:`jrigid.viz.data.resample`), whatever
steps the integrator took. The chapter's aliasing remark (section 17.6: a gyroscope's
shaft "rotates many times between screen updates", like wagon-wheel spokes turning
backward in films) applies to the frames: when the body turns by more than
``max_turn`` between two frames the spin cannot be read from the pictures, and
:func:`animate` warns with an :class:`AliasingWarning` (use more frames or a shorter
time span). Ask the simulation for output at :func:`frame_times` directly when it is
cheap; resampling is exact at the sample times and smooth in between.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import animation as mpl_animation
from matplotlib.figure import Figure

from .data import Series, as_series, resample, turn_angles
from .render import Camera
from .shapes import Mesh
from .views import DualView

__all__ = [
    "AliasingWarning",
    "PalettePillowWriter",
    "animate",
    "ffmpeg_available",
    "frame_times",
    "max_turn_per_frame",
    "write_animation",
]


class AliasingWarning(UserWarning):
    """The body turns so far between frames that the animation misrepresents the spin."""


class PalettePillowWriter(mpl_animation.PillowWriter):
    """matplotlib's Pillow GIF writer with one shared adaptive palette and no dithering.

    The stock writer lets Pillow pick a 256-colour palette per frame; a single palette
    of ``colors`` colours taken from a few frames makes the GIF markedly smaller and
    stops colours flickering between frames.
    """

    def __init__(self, *args, colors: int = 64, **kwargs):
        super().__init__(*args, **kwargs)
        self.colors = colors

    def finish(self):
        from PIL import Image

        frames = [f.convert("RGB") for f in self._frames]
        sample = frames[:: max(1, len(frames) // 4)]
        w, h = sample[0].size
        mosaic = Image.new("RGB", (w, h * len(sample)))
        for k, f in enumerate(sample):
            mosaic.paste(f, (0, k * h))
        palette = mosaic.quantize(colors=self.colors, method=Image.Quantize.MEDIANCUT)
        quantized = [f.quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
        quantized[0].save(
            self.outfile,
            save_all=True,
            append_images=quantized[1:],
            duration=int(1000 / self.fps),
            loop=0,
        )


def ffmpeg_available() -> bool:
    """True if matplotlib finds an ``ffmpeg`` executable (needed for MP4)."""
    return mpl_animation.writers.is_available("ffmpeg")


def frame_times(t0: float, t1: float, n_frames: int) -> np.ndarray:
    """``n_frames`` evenly spaced times from ``t0`` to ``t1`` inclusive."""
    if n_frames < 2:
        raise ValueError(f"an animation needs at least 2 frames, got {n_frames}")
    if not t1 > t0:
        raise ValueError(f"need t1 > t0, got [{t0}, {t1}]")
    return np.linspace(t0, t1, int(n_frames))


def max_turn_per_frame(data: Any) -> float:
    """Largest rotation angle (radians) of the body between consecutive samples.

    ``|ω| Δt`` when the angular velocity is known (it can exceed π), else the quaternion
    distance (see :func:`jrigid.viz.data.turn_angles`).

    Args:
        data: trajectory-like or mapping with ``q`` (see :mod:`jrigid.viz.data`).
    """
    turns = turn_angles(data)
    return float(turns.max()) if len(turns) else 0.0


def write_animation(
    fig: Figure,
    update: Callable[[int], Any],
    n_frames: int,
    path: str | os.PathLike,
    *,
    fps: float = 20,
    dpi: float | None = None,
    mp4: bool = False,
    colors: int = 64,
) -> list[Path]:
    """Draw ``update(i)`` for each frame and save the frames of ``fig``.

    Args:
        fig: figure on an Agg canvas (see :func:`jrigid.viz.new_figure`).
        update: called with the frame index before each grab.
        n_frames: number of frames.
        path: ``.gif`` (Pillow) or ``.mp4`` (ffmpeg).
        fps: playback frames per second.
        dpi: resolution (default the figure's).
        mp4: with a ``.gif`` path, also write the ``.mp4`` next to it when ffmpeg exists.
        colors: size of the GIF's shared palette (:class:`PalettePillowWriter`).

    Returns:
        the paths written.

    Raises:
        ValueError: ``fps`` not a positive finite number, fewer than 2 frames, unknown
            extension, or ``.mp4`` requested without ffmpeg (before any frame is drawn).
    """
    if isinstance(fps, bool) or not np.isfinite(np.asarray(fps, float)) or not fps > 0:
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    if n_frames < 2:
        raise ValueError(f"an animation needs at least 2 frames, got {n_frames}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    dpi = fig.dpi if dpi is None else dpi
    targets = []
    if path.suffix.lower() == ".gif":
        targets.append((PalettePillowWriter(fps=fps, colors=colors), path))
        if mp4 and ffmpeg_available():
            targets.append((mpl_animation.FFMpegWriter(fps=fps), path.with_suffix(".mp4")))
    elif path.suffix.lower() == ".mp4":
        if not ffmpeg_available():
            raise ValueError("writing .mp4 needs ffmpeg on the PATH; save a .gif instead")
        targets.append((mpl_animation.FFMpegWriter(fps=fps), path))
    else:
        raise ValueError(f"animation path must end in .gif or .mp4, got {path.name!r}")
    with contextlib.ExitStack() as stack:
        for writer, target in targets:
            stack.enter_context(writer.saving(fig, str(target), dpi))
        for i in range(n_frames):
            update(i)
            for writer, _ in targets:
                writer.grab_frame()
    return [t for _, t in targets]


def animate(
    data: Any,
    mesh: Mesh,
    path: str | os.PathLike,
    *,
    n_frames: int = 90,
    fps: float = 20,
    t_span: tuple[float, float] | None = None,
    moments=None,
    camera: Camera | None = None,
    trail: int | None = 40,
    trails: tuple[str, ...] = ("axes", "omega", "L"),
    body_trails: tuple[str, ...] = ("omega", "L"),
    size_px: tuple[int, int] = (400, 200),
    dpi: int = 80,
    max_turn: float = np.pi / 2,
    mp4: bool = True,
    titles=("space frame", "body frame"),
) -> list[Path]:
    """Animate the space-frame and body-frame views (:class:`~jrigid.viz.views.DualView`).

    Args:
        data: trajectory-like or mapping (see :mod:`jrigid.viz.data`).
        mesh: body mesh.
        path: output ``.gif`` (or ``.mp4``).
        n_frames: number of frames; the trajectory is resampled at :func:`frame_times`.
        fps: playback rate; the animation lasts ``n_frames / fps`` seconds whatever the
            simulated time span.
        t_span: simulated time span to show (default the whole trajectory).
        moments: principal moments if the data lack them (for ``L``).
        camera: :class:`~jrigid.viz.render.Camera`.
        trail: trail length in frames (``None``: from the start).
        trails, body_trails: which trails each view draws (see :class:`DualView`).
        size_px: ``(width, height)`` in pixels.
        dpi: resolution used to convert ``size_px`` to inches.
        max_turn: warn (:class:`AliasingWarning`) if the body turns more than this many
            radians between frames.
        mp4: also write an MP4 next to a GIF when ffmpeg is available.
        titles: panel titles.

    Returns:
        the paths written.
    """
    s: Series = as_series(data, moments)
    t0, t1 = (s.ts[0], s.ts[-1]) if t_span is None else t_span
    frames = resample(s, frame_times(t0, t1, n_frames))
    turn = max_turn_per_frame(frames)
    if turn > max_turn:
        warnings.warn(
            f"the body turns up to {np.degrees(turn):.0f}° between frames (limit "
            f"{np.degrees(max_turn):.0f}°): the spin will look wrong (aliasing); use more "
            "frames or a shorter time span",
            AliasingWarning,
            stacklevel=2,
        )
    view = DualView(
        frames,
        mesh,
        camera=camera,
        trail=trail,
        trails=trails,
        body_trails=body_trails,
        figsize=(size_px[0] / dpi, size_px[1] / dpi),
        dpi=dpi,
        titles=titles,
    )
    view.painter.prepare(range(len(frames)))
    return write_animation(view.fig, view.draw, len(frames), path, fps=fps, dpi=dpi, mp4=mp4)
