"""The gyroscope in Euler angles: agrees with quaternions and the fast-top solution, fails at θ → 0.

Project 17.2. The chapter's top (:func:`gyroscope.top`: ellipsoid ``R, R/5``, pivot, ``g = 1``)
is integrated with the ``euler_angles`` formulation of :func:`jrigid.simulate` (ZXZ angles,
rates from inverting 17.36, which divides by ``sin θ``) and with quaternions (the default,
17.50). Checks that

* released with ``φ̇ = θ̇ = 0`` at ``θ0``, both give the same motion, and both follow the
  fast-top solution ``θ = θ0 + ½Δ (1 − cos ω_n t)``, ``φ = Ω_s (t − sin(ω_n t)/ω_n)``
  with ``ω_n = I3 ω3/I1``, ``Ω_s = M g l/(I3 ω3)`` and ``Δ = 2 M g l I1 sin θ0/(I3 ω3)²``
  (valid to first order in ``ε = M g l I1/(I3 ω3)²``);
* thrown through the vertical (``L_z = L·e3``, which lets the axle pass ``θ = 0``), the
  quaternion run goes through smoothly, while the Euler-angle run stops at gimbal lock:
  ``throw=False`` returns ``Result.gimbal_lock`` and the time reached; ``throw=True`` raises
  :class:`jrigid.integrate.SimulationError` naming the cause.

Run it with ``jrigid run euler_angle_gyroscope [--quick]``.
"""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import initial, viz
from jrigid import quaternion as quat
from jrigid.integrate import Result, SimulationError, simulate
from jrigid.report import Report

try:
    from .gyroscope import run, steady_roots, top
except ImportError:  # run as a script
    from gyroscope import run, steady_roots, top


def main(
    out_dir,
    quick: bool = False,
    *,
    radius: float = 1.0,
    z0: float = 1.0,
    omega3: float = 20.0,
    theta_deg: float = 60.0,
    nutations: float = 6.0,
    flip_theta_deg: float = 20.0,
    flip_theta_rate: float = -2.0,
    samples: int = 1201,
) -> dict:
    """Compare Euler angles with quaternions and the fast top; show the gimbal-lock failure.

    Args:
        out_dir: results folder.
        quick: fewer samples.
        radius, z0, omega3: the top and its spin (see ``gyroscope``).
        theta_deg: release angle ``θ0`` from the vertical.
        nutations: simulated nutation periods.
        flip_theta_deg, flip_theta_rate: start of the run thrown through the vertical.
        samples: output samples.

    Returns:
        the numbers written to ``numbers.json``.
    """
    n = 401 if quick else samples
    scene, th0 = top(radius, z0), math.radians(theta_deg)
    r = steady_roots(scene, th0, omega3)
    w_n, slow = r["I3"] * omega3 / r["I1"], r["mgl"] / (r["I3"] * omega3)
    dip = 2 * r["mgl"] * r["I1"] * math.sin(th0) / (r["I3"] * omega3) ** 2
    span = nutations * 2 * math.pi / w_n
    tq, th_q, phi_q = run(scene, th0, omega3, 0.0, span, n)
    te, th_e, phi_e = run(scene, th0, omega3, 0.0, span, n, formulation="euler_angles")
    t = np.asarray(tq.ts)
    th_fast = th0 + 0.5 * dip * (1 - np.cos(w_n * t))
    phi_fast = slow * (t - np.sin(w_n * t) / w_n)
    first = t <= 2 * math.pi / w_n  # the first-order phase error grows ~ 2π ε per nutation

    # thrown through the vertical: L_z = L_3 when I1 φ̇ sin²θ = I3 ω3 (1 − cos θ)
    thf = math.radians(flip_theta_deg)
    phid = r["I3"] * omega3 * (1 - math.cos(thf)) / (r["I1"] * math.sin(thf) ** 2)
    state = initial.from_euler_rates(
        (0.0, thf, 0.0), (phid, flip_theta_rate, omega3 - phid * math.cos(thf))
    )
    ts = jnp.linspace(0.0, 4 * thf / abs(flip_theta_rate), n)
    fq = simulate(scene, state, ts)
    fe = simulate(scene, state, ts, formulation="euler_angles", throw=False)
    try:
        simulate(scene, state, ts, formulation="euler_angles")
        message = ""
    except SimulationError as e:
        message = str(e)
    th_flip = np.degrees(np.arccos(np.clip(np.asarray(fq.axes[:, 2, 2]), -1.0, 1.0)))
    valid = np.isfinite(np.asarray(fe.q[:, 0]))
    numbers = {
        "q_euler_vs_quaternion_max_angle": float(np.max(np.asarray(quat.distance(te.q, tq.q)))),
        "theta_euler_vs_quaternion_max": float(np.max(np.abs(th_e - th_q))),
        "dip_fast_top": dip,
        "theta_vs_fast_top_max_over_dip": float(np.max(np.abs(th_q - th_fast)[first]) / dip),
        "phi_vs_fast_top_max_over_advance": float(
            np.max(np.abs(phi_q - phi_q[0] - phi_fast)[first]) / (slow * 2 * math.pi / w_n)
        ),  # fmt: skip
        "epsilon": r["mgl"] * r["I1"] / (r["I3"] * omega3) ** 2,
        "flip_quaternion_min_theta_deg": float(th_flip.min()),
        "flip_quaternion_success": bool(fq.succeeded),
        "flip_quaternion_time_of_min": float(ts[np.argmin(th_flip)]),
        "flip_euler_result": int(fe.result),
        "flip_euler_result_name": Result(int(fe.result)).name,
        "flip_euler_t_stop": float(fe.t_stop),
        "flip_euler_t_end": float(ts[-1]),
        "flip_euler_outputs_after_stop_nan": bool(not valid[~(np.asarray(ts) <= fe.t_stop)].any()),
        "flip_euler_error_message": message,
        "samples": n,
    }

    rep = Report(Path(out_dir), title="The gyroscope in Euler angles (Project 17.2)")
    rep.text(
        f"Released at θ0 = {theta_deg:g}° with ω3 = {omega3:g}: Euler angles and quaternions "
        f"agree to {numbers['q_euler_vs_quaternion_max_angle']:.1e} rad; the fast-top solution "
        f"matches θ over the first nutation to {numbers['theta_vs_fast_top_max_over_dip']:.1%} "
        f"of the dip ({math.degrees(dip):.3f}°) and φ to "
        f"{numbers['phi_vs_fast_top_max_over_advance']:.1%} of its advance (first order in "
        f"ε = {numbers['epsilon']:.3f}). Thrown through the vertical "
        f"(θ0 = {flip_theta_deg:g}°, θ̇0 = {flip_theta_rate:g}), the quaternion run reaches "
        f"θ = {numbers['flip_quaternion_min_theta_deg']:.2e}° and goes on; the Euler-angle run "
        f"stops at t = {numbers['flip_euler_t_stop']:.4f} with `Result."
        f"{numbers['flip_euler_result_name']}`. With throw=True: \n\n> {message}"
    )
    fig = viz.new_figure(figsize=(9, 3.2))
    ax = fig.add_subplot(1, 2, 1)
    ax.plot(t, np.degrees(th_q), lw=1.5, label="quaternions")
    ax.plot(t, np.degrees(th_e), "--", lw=1, label="Euler angles")
    ax.plot(t, np.degrees(th_fast), ":", color="k", lw=1, label="fast top")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("θ (°)")
    ax.legend(fontsize=7)
    ax = fig.add_subplot(1, 2, 2)
    ax.plot(np.asarray(ts), th_flip, lw=1.5, label="quaternions")
    th_fe = np.degrees(np.arccos(np.clip(np.asarray(fe.axes[:, 2, 2]), -1.0, 1.0)))
    ax.plot(np.asarray(ts), th_fe, "--", lw=1, label="Euler angles (stops)")
    ax.axvline(float(fe.t_stop), color="#d62728", lw=0.8)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("θ (°)")
    ax.legend(fontsize=7)
    rep.figure("theta", fig, caption="left: nutation, three ways; right: through the vertical "
               "(red line: the Euler-angle run stops at gimbal lock)", dpi=70)  # fmt: skip
    rep.numbers(numbers)
    rep.write_summary()
    print(f"euler_angle_gyroscope: Euler angles vs quaternions "
          f"{numbers['q_euler_vs_quaternion_max_angle']:.1e} rad; "
          f"gimbal lock at t = {numbers['flip_euler_t_stop']:.4f}")  # fmt: skip
    return numbers


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "euler_angle_gyroscope")
