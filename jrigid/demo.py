"""Feynman's wobbling plate and Dzhanibekov's T-handle, measured against theory.

``jrigid demo`` (or ``jrigid run demo``) simulates two torque-free bodies with
:func:`jrigid.simulate`, measures one number on each, compares it with theory, draws both
(stills and GIFs) and writes a one-page ``report.md``.

**The wobbling plate** (Feynman, *Surely You're Joking*, pp. 157–158; chapter Problem
17.4). A disk of radius ``r`` and thickness ``h`` (:func:`jrigid.inertia.disk`) is tossed
spinning about its symmetry axis with a small tilt ``θ`` from ``L``. In Euler angles about
``L`` the axis precesses ("wobbles") at ``φ̇ = |L|/I1`` and the plate turns about its own
axis at ``ψ̇ = ω3 (I1 − I3)/I1``, so the wobble-to-spin ratio is
``|φ̇/ψ̇| = 2/((1 − h²/(3r²)) cos θ)``, ``2/cos θ`` for a thin plate
(:func:`jrigid.theory.plate_theory`). The demo fits straight lines to the unwrapped
angles (:func:`jrigid.theory.wobble_to_spin`) and compares.

**The T-handle** (Dzhanibekov effect; the unstable intermediate axis, Problem 17.6). A
T-shaped body of two solid cylinders (:func:`jrigid.inertia.t_handle_moments`) spins
about its intermediate principal axis with a small tilt; it flips over and back
periodically, every ``2K(m)/λ`` (:func:`jrigid.theory.flip_theory`; the full period is
``4K(m)/λ``). The demo measures the times the intermediate component of ``ω`` crosses
zero (:func:`jrigid.theory.zero_crossings`) and averages their spacing; if
:mod:`jrigid.exact` is present it also compares ``ω(t)`` with the exact solution.

The theory functions and ``t_handle_moments`` are re-exported here from
:mod:`jrigid.theory` and :mod:`jrigid.inertia`.

Both simulations use the same number of output samples, so :func:`jrigid.simulate`
compiles once. Frames for the GIFs are resampled at their own times (slerp), decoupled
from the solver's steps.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Annotated

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import inertia, initial, viz
from jrigid import quaternion as quat
from jrigid.body import RigidBody
from jrigid.experiment_parameters import POSITIVE, ParameterError
from jrigid.inertia import t_handle_moments
from jrigid.integrate import simulate
from jrigid.report import Report, format_number
from jrigid.scene import Scene
from jrigid.theory import flip_theory, plate_theory, wobble_to_spin, zero_crossings

__all__ = [
    "MOMENT_RANGE",
    "TOLERANCE",
    "flip_theory",
    "main",
    "plate_moments",
    "plate_theory",
    "run_plate",
    "run_t_handle",
    "t_handle_moments",
    "wobble_to_spin",
    "zero_crossings",
]


# --------------------------------------------------------------------------- bodies


#: The relative tolerance of the demo's solves in float64 and in float32 (with JAX's
#: 64-bit mode off; float32 cannot step to 1e-10).
TOLERANCE = (1e-10, 1e-5)

#: The plate's moments of inertia :func:`run_plate` accepts (its numbers square them).
MOMENT_RANGE = (1e-50, 1e50)


def plate_moments(mass: float, radius: float, thickness: float) -> np.ndarray:
    """Principal moments ``(I1, I1, I3)`` of the plate (:func:`jrigid.inertia.disk`)."""
    return np.asarray(inertia.disk(mass, radius, thickness), dtype=float)


# --------------------------------------------------------------------------- simulation


def _align(v) -> jax.Array:
    """Quaternion turning the direction of ``v`` (body) onto space ``z`` (L drawn upright)."""
    v = np.asarray(v, float)
    v = v / np.max(np.abs(v))  # (no overflow or underflow in the norm)
    v = v / np.linalg.norm(v)
    axis = np.cross(v, [0.0, 0.0, 1.0])
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return quat.identity()
    return quat.from_axis_angle(jnp.asarray(axis / s), jnp.asarray(math.atan2(s, v[2])))


def _simulate(moments, omega0, t_end, n_samples):
    scene = Scene(RigidBody(jnp.asarray(moments)))
    L_body = np.asarray(moments) * np.asarray(omega0)
    state = initial.from_omega(_align(L_body), jnp.asarray(omega0))
    ts = jnp.linspace(0.0, t_end, n_samples)
    rtol = TOLERANCE[ts.dtype == jnp.float32]  # float64, or JAX's float32 (x64 off)
    return simulate(scene, state, ts, rtol=rtol, atol=1e-2 * rtol)


@jax.jit
def _compare_exact(moments, q, omega, ts):
    """Largest ``|ω − ω_exact|``, largest rotation angle to the exact orientation, and the
    exact period of ω, for a trajectory ``q (T, 4)``, ``omega (T, 3)`` at ``ts (T,)``.
    One jitted function for the module, so that every comparison of the same shapes
    reuses one compiled program."""
    from jrigid import exact

    q_exact, w_exact = exact.solve(moments, q[0], omega[0], ts)
    omega_error = jnp.max(jnp.linalg.norm(omega - w_exact, axis=-1))
    q_error = jnp.max(quat.distance(q, q_exact))
    return omega_error, q_error, exact.omega_period(exact.prepare(moments, q[0], omega[0]))


def _exact_check(moments, traj) -> dict:
    """Compare with :mod:`jrigid.exact` (closed form).

    Returns:
        dict with ``omega_error`` (largest ``|ω − ω_exact|`` over ``max |ω|``), ``q_error``
        (largest rotation angle between the simulated and exact orientations, radians) and
        ``period`` (the exact period of ω).
    """
    omega_error, q_error, period = _compare_exact(jnp.asarray(moments), traj.q, traj.omega,
                                                  traj.ts)
    w = np.asarray(traj.omega)
    return dict(
        omega_error=float(omega_error / np.max(np.linalg.norm(w, axis=-1))),
        q_error=float(q_error),
        period=float(period),
    )


# --------------------------------------------------------------------------- main


def _floats(values: dict) -> dict:
    """The ``()`` arrays of a :mod:`jrigid.theory` result as Python numbers."""
    return {k: v if isinstance(v, int) else float(v) for k, v in values.items()}


def _row(name, measured, theory):
    rel = abs(measured - theory) / abs(theory) if theory else float("nan")
    return (name, measured, theory, f"{rel:.1e}")


def _print_rows(rows) -> None:
    for name, meas, theo, rel in rows:
        print(f"  {name:<32} measured {meas:12.8f}   theory {theo:12.8f}   rel. diff {rel}")


def run_plate(radius, thickness, tilt_deg, spin_hz, n_samples, wobbles) -> dict:
    """Simulate the plate for ``wobbles`` precession periods and measure its rates.

    Returns:
        dict with the trajectory ``traj``, ``moments``, ``omega0``, ``theory``
        (:func:`plate_theory`), ``measured`` (:func:`wobble_to_spin`) and table ``rows``.
    """
    moments = plate_moments(1.0, radius, thickness)
    if not (MOMENT_RANGE[0] <= moments.min() and moments.max() <= MOMENT_RANGE[1]):
        raise ParameterError(
            f"radius={radius:g}, thickness={thickness:g} give the plate (mass 1) moments of "
            f"inertia {moments.min():.3g}…{moments.max():.3g}, outside "
            f"{MOMENT_RANGE[0]:g}…{MOMENT_RANGE[1]:g}")
    w3 = 2 * math.pi * spin_hz
    # tilt θ between the symmetry axis and L: tan θ = I1 ω⊥ / (I3 ω3)
    w_perp = w3 * math.tan(math.radians(tilt_deg)) * moments[2] / moments[0]
    omega0 = np.array([w_perp, 0.0, w3])
    theory = _floats(plate_theory(moments, omega0))
    period = 2 * math.pi / theory["precession_rate"] if theory["precession_rate"] else math.inf
    if not 0 < period < math.inf:
        raise ParameterError(f"spin_hz={spin_hz:g} with this plate gives no finite wobble "
                             f"period (precession rate {theory['precession_rate']:g} rad/s)")
    traj = _simulate(moments, omega0, wobbles * period, n_samples)
    measured = _floats(wobble_to_spin(traj.ts, traj.q, traj.L_space, axis=2))
    rows = [
        _row("wobble/spin |φ̇/ψ̇|", measured["ratio"], theory["ratio"]),
        _row("precession φ̇ (rad/s)", measured["precession_rate"], theory["precession_rate"]),
        _row("spin ψ̇ (rad/s)", measured["spin_rate"], theory["spin_rate"]),
    ]
    return dict(traj=traj, moments=moments, omega0=omega0, theory=theory, measured=measured,
                rows=rows, wobble_period=period)  # fmt: skip


def run_t_handle(tilt_deg, spin_hz, n_samples, intervals, compare_exact) -> dict:
    """Simulate the T-handle for ``intervals`` flip intervals and time its flips.

    Returns:
        dict with ``traj``, ``moments``, ``omega0``, the intermediate axis ``mid``,
        ``theory`` (:func:`flip_theory`), ``crossings``, ``flip_interval`` (measured),
        ``exact`` (:func:`_exact_check` or ``None``) and table ``rows``.
    """
    moments = np.asarray(t_handle_moments(1.0), dtype=float)
    _, mid, top = (int(k) for k in np.argsort(moments))
    eps, rate = math.radians(tilt_deg), 2 * math.pi * spin_hz
    omega0 = np.zeros(3)
    omega0[mid], omega0[top] = rate * math.cos(eps), rate * math.sin(eps)
    theory = _floats(flip_theory(moments, omega0))
    traj = _simulate(moments, omega0, intervals * theory["flip_interval"], n_samples)
    crossings = np.asarray(zero_crossings(traj.ts, traj.omega[:, mid]))
    measured = float(np.mean(np.diff(crossings))) if len(crossings) >= 2 else float("nan")
    exact = _exact_check(moments, traj) if compare_exact else None
    rows = [_row("flip interval 2K/λ (s)", measured, theory["flip_interval"])]
    if exact is not None:
        rows.append(_row("flip interval, jrigid.exact (s)", measured, exact["period"] / 2))
    return dict(traj=traj, moments=moments, omega0=omega0, mid=mid, theory=theory,
                crossings=crossings, flip_interval=measured, exact=exact, rows=rows,
                turn=2 * math.pi / rate)  # fmt: skip


def _plate_section(rep: Report, p: dict, radius, thickness, spin_hz, frames, fps, gif) -> None:
    th, traj = p["theory"], p["traj"]
    rep.text("## Feynman's wobbling plate")
    rep.text(
        f"A plate of radius {radius:g} and thickness {thickness:g} spins at {spin_hz:g} Hz "
        f"about its symmetry axis, which is tilted by θ = {math.degrees(th['theta']):.2f}° "
        "from the angular momentum L. The axis wobbles (precesses about L) at φ̇ = |L|/I1 "
        "while the plate turns about its own axis at ψ̇ = ω3 (I1 − I3)/I1, so "
        "|φ̇/ψ̇| = I3/((I3 − I1) cos θ) = 2/((1 − h²/3r²) cos θ): "
        f"{th['ratio']:.6f} here, {th['ratio_thin']:.6f} for a thin plate."
    )
    rep.table(p["rows"], headers=("quantity", "measured", "theory", "rel. diff"), digits=9)
    mesh = viz.disk(radius, thickness)
    dt = float(traj.ts[1] - traj.ts[0])
    fig = viz.space_body_views(traj, mesh, trail=int(p["wobble_period"] / dt), dpi=80)
    rep.figure("plate", fig, caption="plate: space frame (left) and body frame (right)", dpi=80)
    fig = viz.plot_precession_nutation(traj, axis=2)
    rep.figure("plate_angles", fig, caption="precession φ, spin ψ and nutation θ about L", dpi=80)
    if gif:
        turn = 2 * math.pi / float(np.linalg.norm(p["omega0"]))
        # three wobbles, at most 45° of turning per frame (no aliasing)
        span = min(float(traj.ts[-1]), 3 * p["wobble_period"], frames * turn / 8)
        paths = viz.animate(traj, mesh, rep.path("plate.gif"), n_frames=frames, fps=fps,
                            t_span=(0.0, span), trail=frames // 3, size_px=(400, 200))  # fmt: skip
        rep.image(paths[0], "the wobbling plate")


def _t_handle_section(rep: Report, h: dict, tilt_deg, spin_hz, frames, fps, gif) -> None:
    th, traj, mid = h["theory"], h["traj"], h["mid"]
    rep.text("## Dzhanibekov's T-handle")
    rep.text(
        f"A T-handle with moments {', '.join(format_number(x, 5) for x in h['moments'])} spins "
        f"at {spin_hz:g} Hz about its intermediate axis {mid + 1}, tilted by {tilt_deg:g}°. "
        f"It flips over every 2K(m)/λ (Jacobi elliptic functions; 1 − m = {th['m1']:.3e}); "
        f"the measured interval is the mean spacing of the zero crossings of ω{mid + 1}."
    )
    rep.table(h["rows"], headers=("quantity", "measured", "theory", "rel. diff"), digits=9)
    if h["exact"] is not None:
        rep.text(
            "Against the closed-form solution `jrigid.exact.solve`: largest relative "
            f"difference in ω {h['exact']['omega_error']:.2e}, largest orientation "
            f"difference {h['exact']['q_error']:.2e} rad."
        )
    fig = viz.plot_omega(traj)
    for t in h["crossings"]:
        fig.axes[0].axvline(t, color="#999999", lw=0.8, ls="--")
    rep.figure("t_handle_omega", fig, caption="body angular velocity; dashed: flips", dpi=80)
    mesh = viz.t_handle()
    dt = float(traj.ts[1] - traj.ts[0])
    fig = viz.space_body_views(traj, mesh, trail=int(1.5 * h["turn"] / dt), dpi=80)
    rep.figure("t_handle", fig, caption="T-handle: space frame and body frame", dpi=80)
    if gif:
        # two flips, at most 45° of turning per frame (no aliasing)
        span = min(float(traj.ts[-1]), 1.8 * th["flip_interval"], frames * h["turn"] / 8)
        paths = viz.animate(traj, mesh, rep.path("t_handle.gif"), n_frames=frames, fps=fps,
                            t_span=(0.0, span), trail=max(2, int(1.5 * h["turn"] * frames / span)),
                            size_px=(400, 200))  # fmt: skip
        rep.image(paths[0], "the T-handle flipping")


def main(
    out_dir,
    quick: bool = False,
    *,
    radius: Annotated[float, POSITIVE] = 1.0,
    thickness: Annotated[float, POSITIVE] = 0.1,
    tilt_deg: float = 10.0,
    spin_hz: Annotated[float, POSITIVE] = 1.0,
    handle_tilt_deg: float = 1.0,
    handle_spin_hz: Annotated[float, POSITIVE] = 1.5,
    frames: Annotated[int, POSITIVE] = 90,
    fps: Annotated[int, POSITIVE] = 20,
    gif: bool = True,
    compare_exact: bool = True,
) -> dict:
    """Run the demo and write ``report.md``, figures, GIFs and ``numbers.json`` to ``out_dir``.

    Args:
        out_dir: results folder.
        quick: shorter runs and fewer frames (for tests).
        radius, thickness: the plate's size (mass 1).
        tilt_deg: angle between the plate's symmetry axis and ``L``, in ``(0, 90)``: at 0
            the wobble is not defined (only the sum of the two rates is).
        spin_hz: the plate's spin ``ω3 / 2π``.
        handle_tilt_deg: tilt of the T-handle's initial ω from its intermediate axis, in
            ``(0, 90)``.
        handle_spin_hz: the T-handle's ``|ω| / 2π``.
        frames, fps: frames per GIF (at least 2) and playback rate (frames per second).
        gif: write the animations.
        compare_exact: compare the T-handle with :mod:`jrigid.exact` when present (its
            compilation takes several seconds; skipped with ``quick``).

    Returns:
        the measured and theoretical numbers (also in ``numbers.json``, written before
        the figures and animations are drawn).

    Raises:
        ParameterError: (a ``ValueError``) a tilt outside ``(0, 90)`` degrees, fewer than 2
            frames or a non-positive ``fps``, a plate whose moments are outside
            ``MOMENT_RANGE``, or one with no finite wobble period (before anything is
            written).
    """
    for name, value in (("tilt_deg", tilt_deg), ("handle_tilt_deg", handle_tilt_deg)):
        if not 0 < value < 90:
            raise ParameterError(f"{name} must be in (0, 90) degrees, got {value:g}")
    if frames < 2 or fps <= 0:
        raise ParameterError(f"an animation needs frames >= 2 and fps > 0, got "
                             f"frames={frames}, fps={fps}")
    start = time.perf_counter()
    n_samples = 401 if quick else 1201  # both runs alike: one compilation
    frames = min(frames, 24) if quick else frames
    p = run_plate(radius, thickness, tilt_deg, spin_hz, n_samples, 2.5 if quick else 6.0)
    t_first = time.perf_counter() - start
    h = run_t_handle(handle_tilt_deg, handle_spin_hz, n_samples, 2.6 if quick else 4.6,
                     compare_exact and not quick)  # fmt: skip
    drift = max(
        float(np.max(np.abs(np.asarray(tr.energy) / float(tr.energy[0]) - 1)))
        for tr in (p["traj"], h["traj"])
    )
    dtype = str(jnp.result_type(float))

    print(f"Feynman's wobbling plate: r = {radius:g}, h = {thickness:g}, "
          f"tilt θ = {math.degrees(p['theory']['theta']):.2f}°")  # fmt: skip
    _print_rows(p["rows"])
    print(f"  (thin-plate value 2/cos θ = {p['theory']['ratio_thin']:.6f}: "
          "the plate wobbles about twice as fast as it spins)")  # fmt: skip
    print(f"Dzhanibekov T-handle: moments {np.array2string(h['moments'], precision=5)}, "
          f"spin about axis {h['mid'] + 1} (intermediate) tilted {handle_tilt_deg:g}°")  # fmt: skip
    _print_rows(h["rows"])
    print(f"  (1 − m = {h['theory']['m1']:.3e}; full period 4K/λ = {h['theory']['period']:.6f} s; "
          f"{len(h['crossings'])} flips seen)")  # fmt: skip
    if h["exact"] is not None:
        print(f"  against jrigid.exact: ω max relative error {h['exact']['omega_error']:.2e}, "
              f"orientation max error {h['exact']['q_error']:.2e} rad")  # fmt: skip

    rep = Report(Path(out_dir), title="jrigid demo: a wobbling plate and a flipping T-handle")
    rep.text(
        f"Made by `jrigid demo{' --quick' if quick else ''}`. Both bodies are torque free, "
        "integrated by `jrigid.simulate` (quaternion acceleration, DOP853, rtol 1e-10) in "
        f"{dtype}; largest relative energy drift {drift:.1e}."
    )
    th, meas = p["theory"], p["measured"]
    numbers = {
        "plate": {
            "moments": p["moments"],
            "tilt_theta_deg": math.degrees(th["theta"]),
            "wobble_to_spin_measured": meas["ratio"],
            "wobble_to_spin_theory": th["ratio"],
            "wobble_to_spin_thin_plate": th["ratio_thin"],
            "precession_rate_measured": meas["precession_rate"],
            "precession_rate_theory": th["precession_rate"],
            "spin_rate_measured": meas["spin_rate"],
            "spin_rate_theory": th["spin_rate"],
        },
        "t_handle": {
            "moments": h["moments"],
            "intermediate_axis_index": h["mid"],  # 0-based, as theory.flip_theory's axis
            "flip_interval_measured": h["flip_interval"],
            "flip_interval_theory": h["theory"]["flip_interval"],
            "period_theory": h["theory"]["period"],
            "elliptic_m1": h["theory"]["m1"],
            "flips_seen": len(h["crossings"]),
            "exact_solution": h["exact"],
        },
        "max_relative_energy_drift": drift,
        "dtype": dtype,
        "quick": quick,
    }
    rep.numbers(numbers)  # the numbers first: drawing is the slow part
    _plate_section(rep, p, radius, thickness, spin_hz, frames, fps, gif)
    _t_handle_section(rep, h, handle_tilt_deg, handle_spin_hz, frames, fps, gif)
    seconds = time.perf_counter() - start
    numbers["seconds"] = {"total": seconds, "first_simulation_incl_compile": t_first}
    rep.numbers(numbers)
    rep.text(f"Total time {seconds:.1f} s (first simulation, with compilation, {t_first:.1f} s).")
    path = rep.write_summary()
    print(f"wrote {path}")
    return numbers
