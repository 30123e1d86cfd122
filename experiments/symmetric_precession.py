"""Torque-free symmetric body: ω1, ω2 are out-of-phase sinusoids; ω precesses at Ω = (I3/I1 − 1) ω3.

Problem 17.5 and eq. (17.47). For ``I1 = I2`` Euler's equations (17.35) with no torque give
``ω̇1 = −Ω ω2``, ``ω̇2 = Ω ω1``, ``ω3`` constant, with ``Ω = (I3/I1 − 1) ω3`` and
``ω3 = |ω| cos α`` (α the angle between ω and the symmetry axis 3): ``ω`` turns about body
axis 3 at the rate Ω, so ``ω1 = A cos(Ωt + δ)``, ``ω2 = A sin(Ωt + δ)``. The chapter's
``Is`` is ``I1 = I2``. Checks, on a plate (:func:`jrigid.inertia.disk`) simulated with
:func:`jrigid.simulate`, that

* ``ω3`` and ``ω1² + ω2²`` are constant, and ``ω1``, ``ω2`` are 90° apart (the angle
  ``atan2(ω2, ω1)`` advances uniformly);
* the measured rate (slope of that angle, :func:`jrigid.theory.omega_phase_rate`) equals (17.47)
  (:func:`jrigid.theory.body_precession_rate`),
  for the plate and for a sweep of ``I3/I1`` from rod-like (``Ω < 0``) to plate-like.

Run it with ``jrigid run symmetric_precession [--quick]``.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import inertia, initial, viz
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.report import Report
from jrigid.scene import Scene
from jrigid.theory import body_precession_rate, omega_phase_rate


def precession(moments, rate, alpha, periods, n):
    """Simulate; return ``ω (n, 3)``, times, and measured / theoretical Ω (17.47)."""
    moments = np.asarray(moments, float)
    omega0 = rate * np.array([np.sin(alpha), 0.0, np.cos(alpha)])
    theory = float(body_precession_rate(moments, omega0))
    ts = jnp.linspace(0.0, periods * 2 * np.pi / abs(theory), n)
    traj = simulate(Scene(RigidBody(jnp.asarray(moments))), initial.from_omega(None, omega0), ts)
    w = np.asarray(traj.omega)
    measured = float(omega_phase_rate(ts, w, axis=2))
    return traj, w, np.asarray(ts), measured, float(theory)


def main(
    out_dir,
    quick: bool = False,
    *,
    radius: float = 1.0,
    thickness: float = 0.1,
    rate: float = 6.0,
    alpha_deg: float = 20.0,
    periods: float = 3.0,
    ratios: tuple = (0.1, 0.3, 0.6, 0.9, 1.2, 1.5, 1.8),
    samples: int = 1201,
) -> dict:
    """Measure the precession of ω about the symmetry axis and compare with (17.47).

    Args:
        out_dir: results folder.
        quick: fewer samples and sweep points.
        radius, thickness: the plate (mass 1).
        rate: ``|ω|`` (rad/s).
        alpha_deg: angle α between ω and the symmetry axis (degrees).
        periods: simulated precession periods.
        ratios: values of ``I3/I1`` for the sweep (``I1 = I2 = 1``; at most 2).
        samples: output samples.

    Returns:
        the numbers written to ``numbers.json``.
    """
    n = 401 if quick else samples
    ratios = tuple(ratios)[::2] if quick else tuple(ratios)
    alpha = np.radians(alpha_deg)
    moments = np.asarray(inertia.disk(1.0, radius, thickness), dtype=float)
    traj, w, ts, measured, theory = precession(moments, rate, alpha, periods, n)
    perp = np.hypot(w[:, 0], w[:, 1])
    phase = np.unwrap(np.arctan2(w[:, 1], w[:, 0]))
    resid = phase - (phase[0] + theory * ts)
    sweep = [precession((1.0, 1.0, r), rate, alpha, periods, n)[3:] for r in ratios]
    sweep_meas = np.array([s[0] for s in sweep])
    sweep_theory = np.array([s[1] for s in sweep])
    numbers = {
        "moments": moments,
        "alpha_deg": alpha_deg,
        "omega3_spread": float(np.ptp(w[:, 2])),
        "omega_perp_rel_spread": float(np.ptp(perp) / perp.mean()),
        "phase_residual_max": float(np.max(np.abs(resid))),
        "precession_rate_measured": measured,
        "precession_rate_theory": theory,
        "sweep_I3_over_I1": list(ratios),
        "sweep_rate_measured": sweep_meas,
        "sweep_rate_theory": sweep_theory,
        "sweep_max_rel_error": float(np.max(np.abs(sweep_meas / sweep_theory - 1))),
        "samples": n,
    }

    rep = Report(Path(out_dir), title="Torque-free rotation of a symmetric body (Problem 17.5)")
    rep.text(
        f"A plate (moments {np.round(moments, 5).tolist()}) spins at |ω| = {rate:g} rad/s with ω "
        f"at α = {alpha_deg:g}° from its symmetry axis. ω3 stays constant (spread "
        f"{numbers['omega3_spread']:.1e}); ω1 and ω2 are sinusoids 90° apart whose phase "
        f"advances at Ω = {measured:.8f} rad/s against (17.47) (I3/I1 − 1) ω cos α = "
        f"{theory:.8f} (largest phase departure from uniform {numbers['phase_residual_max']:.1e} "
        "rad)."
    )
    rep.table(list(zip(ratios, sweep_meas, sweep_theory, strict=True)),
              headers=("I3/I1", "Ω measured", "Ω (17.47)"), digits=8)  # fmt: skip
    rep.figure("omega", viz.plot_omega(traj), caption="ω1, ω2 out of phase; ω3 constant", dpi=70)
    fig = viz.new_figure(figsize=(5, 3.2))
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(ratios, sweep_meas, "o", label="measured")
    ax.plot(ratios, sweep_theory, "k-", lw=0.8, label="(I3/I1 − 1) ω cos α")
    ax.axhline(0.0, color="#999999", lw=0.5)
    ax.set_xlabel("I3 / I1")
    ax.set_ylabel("Ω (rad/s)")
    ax.legend(fontsize=8)
    rep.figure("rate_vs_ratio", fig, caption="precession rate of ω about axis 3", dpi=70)
    rep.numbers(numbers)
    rep.write_summary()
    print(f"symmetric_precession: Ω {measured:.8f}, theory {theory:.8f}")
    return numbers


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "symmetric_precession")
