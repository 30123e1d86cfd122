"""Time-series plots of a rotation: ω, conserved quantities, ``|q| − 1``, Euler angles.

Every function takes ``data`` (a trajectory-like object or a mapping of arrays, see
:mod:`jrigid.viz.data`), draws on ``ax`` if given (else on a new figure) and returns the
``Figure``.

* :func:`plot_omega` — ``ω1, ω2, ω3`` (body or space frame), Problem 17.5a.
* :func:`plot_invariants` — relative drift of the energy and of ``|L|``, Problem 17.4b.
* :func:`plot_q_norm` — ``|q| − 1``, the quaternion's drift off the unit sphere.
* :func:`plot_euler_angles` — any of the 12 sequences (scipy's meaning; ``"ZXZ"`` the
  chapter's precession, nutation, spin about the space ``z`` axis).
* :func:`plot_precession_nutation` — precession, nutation and spin of a body axis about
  ``L`` (:mod:`jrigid.viz.angles`), with the measured mean rates in the legend.
* :func:`plot_overview` — all of the above on one page.

Axes are labelled in SI units (time in s, ω in rad/s), the units of jrigid's defaults
(``Gravity`` is 9.81 m/s²); a scene built in other consistent units reads them in those.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib.figure import Figure

from jrigid import quaternion as quat

from ._figure import new_figure
from ._jit import bucket, float_dtype, pad
from .angles import euler_about, fit_rate
from .data import Series, as_series

__all__ = [
    "plot_estimates",
    "plot_euler_angles",
    "plot_invariants",
    "plot_omega",
    "plot_overview",
    "plot_precession_nutation",
    "plot_q_norm",
]

COMPONENT_COLORS = ("#d62728", "#2ca02c", "#1f77b4")


def _axes(ax, figsize=(6.0, 3.2)):
    if ax is not None:
        return ax.figure, ax
    fig = new_figure(figsize=figsize)
    return fig, fig.add_subplot(1, 1, 1)


def _finish(ax, ylabel: str, title: str = "") -> None:
    ax.set_xlabel("t [s]")
    short = len(ylabel) <= 2  # a lone symbol reads better upright (a turned ω looks like 3)
    ax.set_ylabel(ylabel, rotation=0 if short else 90, labelpad=12 if short else 4)
    if title:
        ax.set_title(title, fontsize=10)
    ax.grid(True, alpha=0.3)


def plot_omega(data: Any, *, frame: str = "body", ax=None, moments=None) -> Figure:
    """Angular velocity components against time.

    Args:
        data: trajectory-like or mapping (``omega``, ``omega_space``, or ``L`` + ``moments``).
        frame: ``"body"`` (ω1, ω2, ω3) or ``"space"`` (ωx, ωy, ωz).
        ax: axes to draw on.
        moments: principal moments if the data lack them and ω must come from ``L``.

    Returns:
        ``Figure``.
    """
    if frame not in ("body", "space"):
        raise ValueError(f"frame must be 'body' or 'space', got {frame!r}")
    s = as_series(data, moments)
    name = "omega" if frame == "body" else "omega_space"
    s.require(name)
    w = getattr(s, name)
    labels = ("ω1", "ω2", "ω3") if frame == "body" else ("ωx", "ωy", "ωz")
    fig, ax = _axes(ax)
    for k in range(3):
        ax.plot(s.ts, w[:, k], color=COMPONENT_COLORS[k], label=labels[k], lw=1.2)
    ax.legend(loc="best", fontsize=8, ncols=3, framealpha=0.8)
    _finish(ax, "ω [rad/s]", f"angular velocity ({frame} frame)")
    return fig


def plot_invariants(data: Any, *, ax=None, moments=None) -> Figure:
    """Relative drift ``E/E0 − 1`` of the energy and ``|L|/|L0| − 1`` of the momentum.

    Both are zero for exact torque-free motion; the curves show the integrator's error.

    Args:
        data: trajectory-like or mapping (``energy`` or ω and ``L``/moments).
        ax: axes to draw on.
        moments: principal moments if needed to derive ``L``.

    Returns:
        ``Figure``.
    """
    s = as_series(data, moments)
    fig, ax = _axes(ax)
    drawn = False
    if s.energy is not None and s.energy[0] != 0:
        ax.plot(s.ts, s.energy / s.energy[0] - 1.0, label="E/E₀ − 1", color="#1f77b4", lw=1.2)
        drawn = True
    if s.L_space is not None:
        n = np.linalg.norm(s.L_space, axis=-1)
        if n[0] > 0:
            ax.plot(s.ts, n / n[0] - 1.0, label="|L|/|L₀| − 1", color="#9467bd", lw=1.2)
            drawn = True
    if not drawn:
        raise ValueError("the data have neither an energy nor L (pass moments=)")
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    ax.legend(loc="best", fontsize=8)
    _finish(ax, "relative drift", "conserved quantities")
    return fig


def plot_q_norm(data: Any, *, ax=None) -> Figure:
    """``|q| − 1`` against time: how far the integrated quaternion left the unit sphere.

    Args:
        data: trajectory-like or mapping (``q`` or ``q_norm_error``).
        ax: axes to draw on.

    Returns:
        ``Figure``.
    """
    s = as_series(data)
    fig, ax = _axes(ax)
    ax.plot(s.ts, s.q_norm_error, color="#444444", lw=1.2)
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    _finish(ax, "|q| − 1", "quaternion norm")
    return fig


_to_euler = jax.jit(quat.to_euler, static_argnums=0)


def plot_euler_angles(data: Any, *, seq: str = "ZXZ", ax=None, unwrap: bool = True) -> Figure:
    """Euler angles of the orientation in degrees (scipy's meaning of ``seq``).

    Args:
        data: trajectory-like or mapping (``q``).
        seq: one of the 24 sequence strings, e.g. ``"ZXZ"`` (the chapter's φ, θ, ψ).
        ax: axes to draw on.
        unwrap: remove the 360° jumps of the first and third angles.

    Returns:
        ``Figure``.
    """
    s = as_series(data)
    n = bucket(len(s))
    ang = _to_euler(seq, jnp.asarray(pad(s.q, n, s.q[-1]), dtype=float_dtype()))
    ang = np.array(ang, dtype=float)[: len(s)]
    if unwrap:
        ang[:, 0] = np.unwrap(ang[:, 0])
        ang[:, 2] = np.unwrap(ang[:, 2])
    fig, ax = _axes(ax)
    names = ("φ", "θ", "ψ") if seq.upper() in ("ZXZ", "ZYZ") else ("1st", "2nd", "3rd")
    for k in range(3):
        ax.plot(s.ts, np.degrees(ang[:, k]), color=COMPONENT_COLORS[k], label=names[k], lw=1.2)
    ax.legend(loc="best", fontsize=8, ncols=3)
    _finish(ax, "degrees", f"Euler angles {seq}")
    return fig


def plot_precession_nutation(
    data: Any, *, axis: int = 2, axes=None, moments=None, L_space=None
) -> Figure:
    """Precession ``φ``, spin ``ψ`` (top) and nutation ``θ`` (bottom) of a body axis about ``L``.

    The legend gives the mean rates ``φ̇``, ``ψ̇`` in radians per unit time (least-squares
    slopes); the curves are in degrees.

    Args:
        data: trajectory-like or mapping (``q`` and ``L_space``, or ω/L and moments).
        axis: body axis (0, 1, 2) followed; 2 is the symmetry axis of a plate.
        axes: two axes to draw on (top, bottom); default a new figure.
        moments: principal moments if needed to derive ``L``.
        L_space: the fixed angular momentum, if the data lack it.

    Returns:
        ``Figure``.
    """
    s = as_series(data, moments)
    L = s.L_space if L_space is None else np.asarray(L_space, float)
    if L is None:
        raise ValueError("precession about L needs L_space (or ω with moments)")
    ang = euler_about(s.q, L, axis=axis)
    if axes is None:
        fig = new_figure(figsize=(6.0, 4.4))
        axes = fig.subplots(2, 1, sharex=True)
    fig = axes[0].figure
    top, bottom = axes
    rate_phi, rate_psi = fit_rate(s.ts, ang[:, 0]), fit_rate(s.ts, ang[:, 2])
    top.plot(
        s.ts,
        np.degrees(ang[:, 0]),
        color="#9467bd",
        label=f"precession φ (dφ/dt = {rate_phi:.4g} rad/time)",
    )
    top.plot(
        s.ts,
        np.degrees(ang[:, 2]),
        color="#ff7f0e",
        label=f"spin ψ (dψ/dt = {rate_psi:.4g} rad/time)",
    )
    top.legend(loc="best", fontsize=8)
    _finish(top, "degrees", f"body axis {axis + 1} about L")
    top.set_xlabel("")
    bottom.plot(s.ts, np.degrees(ang[:, 1]), color="#2ca02c", label="nutation θ")
    bottom.legend(loc="best", fontsize=8)
    _finish(bottom, "degrees")
    return fig


def plot_overview(data: Any, *, moments=None, axis: int = 2, seq: str = "ZXZ") -> Figure:
    """All time series on one page (2 × 3 panels).

    ω (body), energy and ``|L|`` drift, ``|q| − 1``, Euler angles, precession/spin and
    nutation of body axis ``axis`` about ``L``. Panels whose data are missing say so.

    Returns:
        ``Figure``.
    """
    s: Series = as_series(data, moments)
    fig = new_figure(figsize=(13.0, 6.5))
    ax = fig.subplots(2, 3)

    def attempt(panel, fn):
        try:
            fn()
        except ValueError as e:
            panel.text(0.5, 0.5, str(e), ha="center", va="center", wrap=True, fontsize=8)
            panel.set_axis_off()

    attempt(ax[0, 0], lambda: plot_omega(s, ax=ax[0, 0]))
    attempt(ax[0, 1], lambda: plot_invariants(s, ax=ax[0, 1]))
    attempt(ax[0, 2], lambda: plot_q_norm(s, ax=ax[0, 2]))
    attempt(ax[1, 0], lambda: plot_euler_angles(s, seq=seq, ax=ax[1, 0]))
    attempt(ax[1, 1], lambda: plot_precession_nutation(s, axis=axis, axes=(ax[1, 1], ax[1, 2])))
    return fig


def plot_estimates(names, estimate, truth, sigma, *, ax=None) -> Figure:
    """Fitted parameters against the truth, in units of their standard deviation.

    Args:
        names: ``K`` parameter labels.
        estimate, truth, sigma: ``(K,)`` estimates, true values and standard deviations
            (e.g. from :func:`jrigid.fit.laplace`).
        ax: draw into these axes (default: a new figure).

    Returns:
        The figure: ``(estimate − truth)/σ ± 1`` per parameter over a ±3σ band.
    """
    fig, ax = _axes(ax)
    z = (np.asarray(estimate) - np.asarray(truth)) / np.asarray(sigma)
    ticks = np.arange(len(names))
    ax.axhspan(-3, 3, color="0.9", label="±3σ")
    ax.errorbar(ticks, z, yerr=np.ones_like(z), fmt="o", capsize=3,
                label="(estimate − truth)/σ ± 1")  # fmt: skip
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xticks(ticks, list(names))
    ax.set_ylabel("(estimate − truth) / σ")
    ax.set_title("estimates ± σ against the truth", fontsize=9)
    ax.legend(fontsize=7)
    return fig
