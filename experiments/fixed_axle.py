"""Fixed axle: a tilted block on a shaft at constant ω; L not parallel to ω; the shaft torque.

Section 17.4 and Exercise 17.11. A box (sides ``a, b, c`` along body x, y, z) is tilted by
``α`` about body y and turns with the shaft at constant ``ω`` about space z:
``q(t) = q_z(ω t) ⊗ q_y(α)``. In the space frame ``I_space = R I_body Rᵀ`` (17.32,
:func:`jrigid.inertia.rotate_tensor`) and ``L = I_space ω``; in the body frame
``L_body = I_body ω_body`` with ``ω_body = q* ω q``. Checks that

* ``|L|`` is the same in both frames and ``q L_body q* = L_space`` (Exercise 17.11a-b);
* ``L`` is not parallel to ``ω`` unless ``α`` is 0 or 90° (a principal axis on the shaft);
* the torque the shaft must supply, ``N = dL/dt = ω × L`` (L is fixed in the body and ω is
  constant), matches a central finite difference of ``L(t)``;
* ``|N| = ½ ω² |I3 − I1| sin 2α``: zero at tilt 0 and 90°, largest at 45°.

Run it with ``jrigid run fixed_axle [--quick]`` or ``python experiments/fixed_axle.py``.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import affine, inertia, viz
from jrigid import quaternion as quat
from jrigid.report import Report

EZ, EY = jnp.array([0.0, 0.0, 1.0]), jnp.array([0.0, 1.0, 0.0])


def orientation(t, omega, tilt):
    """``q(t) = q_z(ω t) ⊗ q_y(α)``, ``t (n,)`` → ``(n, 4)``."""
    t = jnp.asarray(t)
    q_shaft = quat.from_axis_angle(jnp.broadcast_to(EZ, t.shape + (3,)), omega * t)
    return quat.multiply(q_shaft, quat.from_axis_angle(EY, jnp.asarray(tilt))[None])


@jax.jit
def momenta(t, omega, tilt, I_body):
    """Space-frame ``L`` by (17.32), body-frame ``L``, its image in space, and ``ω × L``."""
    q = orientation(t, omega, tilt)
    w_space = jnp.broadcast_to(omega * EZ, q.shape[:-1] + (3,))
    I_space = inertia.rotate_tensor(I_body[None], q)
    L_space = (I_space @ w_space[..., None])[..., 0]
    L_body = (I_body[None] @ quat.rotate_inverse(q, w_space)[..., None])[..., 0]
    return L_space, L_body, quat.rotate(q, L_body), jnp.cross(w_space, L_space), I_space


def main(
    out_dir,
    quick: bool = False,
    *,
    sides: tuple = (1.0, 0.4, 0.2),
    mass: float = 1.0,
    omega: float = 2.0,
    tilt_deg: float = 30.0,
    samples: int = 73,
) -> dict:
    """Turn the tilted block through one revolution; compare L and N computed several ways.

    Args:
        out_dir: results folder.
        quick: fewer samples.
        sides: box sides ``(a, b, c)`` along body x, y, z.
        mass: box mass.
        omega: shaft angular speed (rad/s).
        tilt_deg: tilt ``α`` about body y, degrees.
        samples: samples over one revolution (and tilt angles in the sweep).

    Returns:
        the numbers written to ``numbers.json``.
    """
    n = 25 if quick else samples
    I_body = inertia.to_tensor(inertia.box(mass, *sides))
    I1, _, I3 = np.diag(np.asarray(I_body))
    tilt = np.radians(tilt_deg)
    ts = jnp.linspace(0.0, 2 * np.pi / omega, n)
    L, L_body, L_body_in_space, N, I_space = (
        np.asarray(x) for x in momenta(ts, omega, tilt, I_body)
    )
    h = 1e-4 / omega
    dL = (np.asarray(momenta(ts + h, omega, tilt, I_body)[0])
          - np.asarray(momenta(ts - h, omega, tilt, I_body)[0])) / (2 * h)  # fmt: skip
    w = np.array([0.0, 0.0, omega])
    cos_Lw = L @ w / (np.linalg.norm(L, axis=-1) * omega)
    tilts = np.linspace(0.0, np.pi / 2, n)
    N_sweep = np.asarray(
        jax.vmap(lambda a: momenta(ts[:1], omega, a, I_body)[3][0])(jnp.asarray(tilts))
    )
    N_theory = 0.5 * omega**2 * abs(I3 - I1) * np.sin(2 * tilts)
    numbers = {
        "I_body_moments": np.diag(np.asarray(I_body)),
        "I_space_t0": I_space[0],
        "L_space_t0": L[0],
        "L_norm_space_minus_body_max": float(
            np.max(np.abs(np.linalg.norm(L, axis=-1) - np.linalg.norm(L_body, axis=-1)))
        ),  # fmt: skip
        "L_body_to_space_max_error": float(np.max(np.abs(L_body_in_space - L))),
        "angle_L_omega_deg": float(np.degrees(np.arccos(np.clip(cos_Lw[0], -1, 1)))),
        "torque_norm": float(np.linalg.norm(N[0])),
        "torque_norm_theory": float(0.5 * omega**2 * abs(I3 - I1) * np.sin(2 * tilt)),
        "torque_norm_spread_over_revolution": float(np.ptp(np.linalg.norm(N, axis=-1))),
        "torque_vs_finite_difference_max_error": float(np.max(np.abs(dL - N))),
        "finite_difference_step": h,
        "torque_z_max": float(np.max(np.abs(N[:, 2]))),
        "tilt_sweep_deg": np.degrees(tilts),
        "tilt_sweep_torque_norm": np.linalg.norm(N_sweep, axis=-1),
        "tilt_sweep_max_error_vs_theory": float(
            np.max(np.abs(np.linalg.norm(N_sweep, axis=-1) - N_theory))
        ),
        "torque_at_tilt_0_and_90": [
            float(np.linalg.norm(N_sweep[0])),
            float(np.linalg.norm(N_sweep[-1])),
        ],
    }

    rep = Report(Path(out_dir), title="Rotation about a fixed axle")
    rep.text(
        f"Box {tuple(sides)} tilted {tilt_deg:g}° on a shaft at ω = {omega:g} rad/s: L makes "
        f"{numbers['angle_L_omega_deg']:.3f}° with ω. |L| in space and body frames agree to "
        f"{numbers['L_norm_space_minus_body_max']:.1e}; q L_body q* matches I_space ω to "
        f"{numbers['L_body_to_space_max_error']:.1e}. The shaft torque ω × L has |N| = "
        f"{numbers['torque_norm']:.6f} "
        f"(theory ½ω²|I3−I1| sin 2α = {numbers['torque_norm_theory']:.6f}), "
        f"horizontal, and matches dL/dt by finite differences to "
        f"{numbers['torque_vs_finite_difference_max_error']:.1e}."
    )
    rep.table([("I_space (t = 0)", *np.round(row, 6)) for row in I_space[0]], ("", "x", "y", "z"))
    fig = _figure(ts, omega, tilt, sides, L, N, tilts, N_sweep, N_theory)
    rep.figure(
        "axle", fig, caption="L (purple) and N (red) over one revolution; |N| against tilt", dpi=70
    )
    rep.numbers(numbers)
    rep.write_summary()
    print(
        f"fixed_axle: |N| {numbers['torque_norm']:.6f} (theory {numbers['torque_norm_theory']:.6f})"
    )
    return numbers


def _figure(ts, omega, tilt, sides, L, N, tilts, N_sweep, N_theory):
    cam = viz.Camera(elev=20, azim=35)
    mesh = viz.box(*sides)
    k = [0, len(ts) // 4, len(ts) // 2, 3 * len(ts) // 4]
    qs = np.asarray(orientation(ts[np.asarray(k)], omega, tilt))
    sL, sN = 0.9 / np.linalg.norm(L[0]), 0.7 / max(np.linalg.norm(N[0]), 1e-12)
    fig = viz.new_figure(figsize=(13, 3.2), layout=None)
    for j, (i, q) in enumerate(zip(k, qs, strict=True)):
        ax = fig.add_axes((0.19 * j, 0.0, 0.19, 0.88))
        T = np.asarray(affine.rotation_3d(jnp.asarray(q)))
        parts = [
            viz.render.mesh_polygons(mesh, T, cam, alpha=0.85),
            viz.render.arrow_polygons(
                np.array([0, 0, -1.0]), np.array([0, 0, 2.0]), cam, "#555555", width=0.02
            ),
            viz.render.arrow_polygons(np.zeros(3), sL * L[i], cam, "#9467bd", width=0.03),
            viz.render.arrow_polygons(np.zeros(3), sN * N[i], cam, "#d62728", width=0.03),
            viz.render.polyline_polygons(sL * L[: i + 1], cam, "#9467bd", width=0.01),
            viz.render.polyline_polygons(sN * N[: i + 1], cam, "#d62728", width=0.01),
        ]
        viz.render.draw_polygons(ax, viz.render.combine(*parts))
        viz.render.setup_axes(ax, 1.1, f"t = {float(ts[i]):.2f} s")
    ax = fig.add_axes((0.8, 0.2, 0.19, 0.65))
    ax.plot(np.degrees(tilts), np.linalg.norm(N_sweep, axis=-1), "o", ms=3, label="|ω × L|")
    ax.plot(np.degrees(tilts), N_theory, "k-", lw=0.8, label="½ω²|I3−I1| sin 2α")
    ax.set_xlabel("tilt α (degrees)")
    ax.legend(fontsize=7)
    ax.set_title("shaft torque against tilt", fontsize=9)
    return fig


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "fixed_axle")
