"""Feynman's plate: infer a plate's thickness from its wobble-to-spin ratio — and where it can't.

A plate of radius ``r`` and thickness ``h`` (:func:`jrigid.inertia.disk`) tossed with its
axis tilted by ``θ`` from ``L`` wobbles ``|φ̇/ψ̇| = 2/((1 − x²/3) cos θ)`` times as fast as
it spins, ``x = h/r`` (:func:`jrigid.theory.plate_theory`). An observer measures the ratio
(± ``σ_R``) and the tilt (± ``σ_θ``); the fit recovers ``x`` (a positive parameter,
:func:`jrigid.fit.positive`) and ``θ`` through the closed-form features
:class:`jrigid.fit.WobbleRatio` and :class:`jrigid.fit.Tilt` (forward model
:class:`jrigid.fit.Invariants`: the constants of the torque-free motion, no
trajectory), with Gauss–Newton (Laplace) standard deviations.

Where the ratio stops constraining the thickness: ``∂R/∂x = (4x/3) cos θ ⁻¹ (1 − x²/3)⁻²``
vanishes as ``x → 0`` — every thin plate has ``R → 2/cos θ`` — so ``σ_x ≈ 3 σ_eff /(4x)``
grows like ``1/x``, with ``σ_eff² = (cos θ σ_R)² + (R sin θ σ_θ)²`` (the ratio's noise
and the tilt's, seen through ``R cos θ``). The thickness is constrained (``σ_x < x``) only
above ``x* ≈ √(3 σ_eff/4)``. The sweep fits noise-free data for plates from very thin to
thick and compares the Laplace ``σ_x`` with this delta-method formula; seeded noisy fits
show the estimates ± σ against the truth. A cross-check fits the same data with the
features measured from a sampled trajectory (``method="trajectory"``: line fits of the
unwrapped Euler angles about ``L``) instead of the closed form.

Run with ``jrigid run fit_plate [--quick]`` or ``python experiments/fit_plate.py``.
"""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import fit, inertia, initial, theory, viz
from jrigid.body import RigidBody
from jrigid.report import Report
from jrigid.scene import Scene

SPIN = 2 * math.pi  # ω3 (rad/s); the ratio does not depend on it


def build(theta):
    """Plate of radius 1, thickness ``positive(theta['x'])``, axis tilted by ``theta['tilt']``
    from ``L`` (``tan θ = I1 ω⊥ / (I3 ω3)``)."""
    x = fit.positive(theta["x"])
    m = inertia.disk(1.0, 1.0, x)
    w_perp = SPIN * jnp.tan(theta["tilt"]) * m[2] / m[0]
    w = jnp.stack([w_perp, jnp.zeros_like(w_perp), SPIN * jnp.ones_like(w_perp)])
    return Scene(RigidBody(m)), initial.from_omega(None, w)


def ratio_theory(x: float, tilt: float) -> float:
    """``|φ̇/ψ̇|`` of the plate from :func:`jrigid.theory.plate_theory` (independent of fit)."""
    m = np.asarray(inertia.disk(1.0, 1.0, x), dtype=float)
    w = np.array([SPIN * math.tan(tilt) * m[2] / m[0], 0.0, SPIN])
    return float(theory.plate_theory(m, w)["ratio"])


def sigma_theory(x: float, tilt: float, s_ratio: float, s_tilt: float) -> float:
    """Delta-method ``σ_x`` of ``x = √(3 (1 − 2/(R cos θ)))``."""
    r = ratio_theory(x, tilt)
    dx_dr = 3.0 / (x * r * r * math.cos(tilt))
    dx_dt = -3.0 * math.tan(tilt) / (x * r * math.cos(tilt))
    return math.hypot(dx_dr * s_ratio, dx_dt * s_tilt)


def _problem(ratio, tilt, s_ratio, s_tilt, ts=(0.0, 1.0), method="closed"):
    obs = [
        fit.WobbleRatio(ts, ratio, s_ratio, method=method),
        fit.Tilt(ts, tilt, s_tilt, method=method),
    ]
    return fit.Problem(fit.Invariants(build) if method == "closed" else fit.Exact(build), obs)


def _fit(problem, tilt_guess):
    start = {"x": fit.positive_raw(0.5), "tilt": jnp.asarray(tilt_guess)}
    res = fit.fit(problem, start, max_iter=200, gtol=1e-12, ftol=1e-15)
    lap = fit.laplace(problem, res.params)
    x, sx = fit.propagate(lambda p: fit.positive(p["x"]), lap)
    return res, lap, float(x), float(sx)


def main(
    out_dir,
    quick: bool = False,
    *,
    thickness: float = 0.2,
    tilt_deg: float = 10.0,
    sigma_ratio: float = 1e-3,
    sigma_tilt_deg: float = 0.05,
    thicknesses: tuple = (0.003, 0.01, 0.03, 0.1, 0.2, 0.4, 0.8),
    seeds: int = 8,
) -> dict:
    """Recover the thickness-to-radius ratio of a plate from its wobble-to-spin ratio.

    Args:
        out_dir: results folder.
        quick: fewer sweep points and seeds.
        thickness: true ``h/r`` of the headline fit.
        tilt_deg: true tilt ``θ`` of the axis from ``L`` (degrees).
        sigma_ratio: noise of the measured ratio.
        sigma_tilt_deg: noise of the measured tilt (degrees).
        thicknesses: true ``h/r`` of the sweep.
        seeds: noisy fits per sweep point.

    Returns:
        the numbers written to ``numbers.json``.
    """
    tilt = math.radians(tilt_deg)
    s_t = math.radians(sigma_tilt_deg)
    s_r = sigma_ratio
    xs = tuple(thicknesses)[::2] if quick else tuple(thicknesses)
    n_seeds = 3 if quick else seeds

    # 1. noise-free recovery: the fit inverts the ratio exactly
    r_true = ratio_theory(thickness, tilt)
    res, lap, x_hat, x_sig = _fit(_problem(r_true, tilt, s_r, s_t), tilt)
    noise_free_error = abs(x_hat - thickness)

    # 2. the sweep: Laplace σ against the delta-method formula, seeded noisy fits
    rng = np.random.default_rng(0)
    sweep = []
    for x in xs:
        r = ratio_theory(x, tilt)
        _, _, xf, sf = _fit(_problem(r, tilt, s_r, s_t), tilt)
        noisy = []
        for _ in range(n_seeds):
            r_obs, t_obs = r + s_r * rng.standard_normal(), tilt + s_t * rng.standard_normal()
            rr, _, xe, se = _fit(_problem(r_obs, t_obs, s_r, s_t), t_obs)
            noisy.append({"estimate": xe, "sigma": se, "converged": rr.converged})
        sweep.append(
            {
                "thickness": x,
                "ratio": r,
                "noise_free_estimate": xf,
                "sigma_laplace": sf,
                "sigma_theory": sigma_theory(x, tilt, s_r, s_t),
                "dratio_dthickness": 4 * x / (3 * math.cos(tilt) * (1 - x * x / 3) ** 2),
                "noisy": noisy,
            }
        )
    s_eff = math.hypot(math.cos(tilt) * s_r, r_true * math.sin(tilt) * s_t)
    x_star = math.sqrt(3 * s_eff / 4)
    # seeded runs where the truth is resolvable (σ < truth) must lie within 3σ of it
    resolvable = [
        (n["estimate"], n["sigma"], s["thickness"])
        for s in sweep
        for n in s["noisy"]
        if s["sigma_theory"] < 0.5 * s["thickness"]
    ]
    within = [abs(e - x) < 3 * s for e, s, x in resolvable]

    # 3. cross-check (full mode): the same features measured from a sampled trajectory
    # (line fits of the Euler angles about L, through the closed-form solution)
    x_traj = x_traj_sig = float("nan")
    if not quick:
        ts = np.linspace(0.0, 4 * 2 * math.pi / SPIN, 161)
        traj_problem = _problem(r_true, tilt, s_r, s_t, ts=ts, method="trajectory")
        _, _, x_traj, x_traj_sig = _fit(traj_problem, tilt)

    numbers = {
        "thickness": thickness,
        "tilt_deg": tilt_deg,
        "ratio_true": r_true,
        "ratio_thin_2_over_cos": 2 / math.cos(tilt),
        "noise_free_estimate": x_hat,
        "noise_free_error": noise_free_error,
        "noise_free_sigma": x_sig,
        "noise_free_sigma_theory": sigma_theory(thickness, tilt, s_r, s_t),
        "trajectory_estimate": x_traj,
        "trajectory_sigma": x_traj_sig,
        "iterations": res.n_iter,
        "reason": res.reason,
        "sigma_effective": s_eff,
        "thickness_floor": x_star,
        "sweep": sweep,
        "resolvable_runs": len(within),
        "resolvable_within_3_sigma": int(sum(within)),
    }

    rep = Report(Path(out_dir), title="Feynman's plate: thickness from the wobble-to-spin ratio")
    rep.text(
        f"A plate (radius 1) of thickness x = {thickness:g} tilted by θ = {tilt_deg:g}° from L "
        f"wobbles {r_true:.6f}× as fast as it spins (thin-plate limit 2/cos θ = "
        f"{2 / math.cos(tilt):.6f}). Observed ratio ± {s_r:g} and tilt ± {sigma_tilt_deg:g}°: "
        f"the closed-form fit (`fit.WobbleRatio`, `fit.Tilt`, `fit.Invariants`) recovers "
        f"x = {x_hat:.9f} from noise-free data (error {noise_free_error:.1e}) with Laplace "
        f"σ_x = {x_sig:.3g} (delta method {numbers['noise_free_sigma_theory']:.3g})."
        + (
            ""
            if quick
            else " The same fit with the features measured from a sampled trajectory (line "
            f"fits of the Euler angles about L, `method='trajectory'`) gives x = {x_traj:.9f}."
        )
    )
    rep.text(
        f"The ratio's sensitivity ∂R/∂x = 4x/(3 cos θ (1 − x²/3)²) vanishes for thin plates, so "
        f"σ_x ≈ 3σ_eff/(4x) with σ_eff = {s_eff:.2g}: the ratio stops constraining the "
        f"thickness below x* ≈ √(3σ_eff/4) = {x_star:.3g} (σ_x > x). Of the {len(within)} seeded "
        f"noisy fits where the thickness is resolvable (σ < x/2), {sum(within)} lie within "
        "3σ of the truth."
    )
    rep.table(
        [
            [
                s["thickness"],
                s["ratio"],
                s["dratio_dthickness"],
                s["sigma_laplace"],
                s["sigma_theory"],
                s["sigma_laplace"] / s["thickness"],
            ]
            for s in sweep
        ],
        ["true x", "ratio", "∂R/∂x", "σ_x (Laplace)", "σ_x (delta method)", "σ_x / x"],
        digits=4,
    )
    fig = viz.new_figure(figsize=(10, 3.4))
    ax = fig.add_subplot(1, 2, 1)
    grid = np.linspace(0.0, 1.0, 200)
    for deg in (0.0, tilt_deg, 2 * tilt_deg):
        c = math.cos(math.radians(deg))
        line = ax.plot(grid, 2 / ((1 - grid**2 / 3) * c), lw=1, label=f"θ = {deg:g}°")
        ax.axhline(2 / c, color=line[0].get_color(), ls=":", lw=0.8)
    ax.plot([s["thickness"] for s in sweep], [s["ratio"] for s in sweep], "ko", ms=3,
            label="sweep points")  # fmt: skip
    ax.set_xlabel("thickness / radius x")
    ax.set_ylabel("wobble / spin")
    ax.set_title("ratio flattens to 2/cos θ (dotted) as x → 0", fontsize=9)
    ax.legend(fontsize=7)
    ax = fig.add_subplot(1, 2, 2)
    sx = np.array([s["thickness"] for s in sweep])
    fine = np.geomspace(sx.min(), sx.max(), 100)
    ax.loglog(fine, [sigma_theory(v, tilt, s_r, s_t) for v in fine], "k-", lw=1,
              label="σ_x, delta method")  # fmt: skip
    ax.loglog(sx, [s["sigma_laplace"] for s in sweep], "o", label="σ_x, Laplace at the fit")
    ax.loglog(fine, fine, "k:", lw=0.8, label="σ_x = x")
    for s in sweep:
        err = [abs(n["estimate"] - s["thickness"]) for n in s["noisy"]]
        ax.loglog([s["thickness"]] * len(err), np.maximum(err, 1e-12), "r.", ms=4, alpha=0.6)
    ax.plot([], [], "r.", label="|estimate − truth|, seeded")
    ax.axvline(x_star, color="0.5", ls="--", lw=0.8)
    ax.set_xlabel("true thickness / radius x")
    ax.set_ylabel("σ_x")
    ax.set_title("where the ratio stops constraining x (dashed: x*)", fontsize=9)
    ax.legend(fontsize=7)
    rep.figure("plate_thickness", fig, caption="ratio against thickness; σ against true thickness",
               dpi=80)  # fmt: skip
    rep.numbers(numbers)
    rep.write_summary()
    print(
        f"fit_plate: x = {x_hat:.9f} ± {x_sig:.2g} (truth {thickness}); floor x* ≈ {x_star:.3g}; "
        f"{sum(within)}/{len(within)} resolvable noisy fits within 3σ"
    )
    return numbers


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "fit_plate")
