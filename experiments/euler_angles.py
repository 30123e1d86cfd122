"""Euler angles: the ZXZ block by angles equals the block by matrix (17.10); singular at sin θ = 0.

Exercise 17.4. A block is oriented three ways: by the chapter's rotation elements (turn
``φ`` about z, then ``θ`` about the new x, then ``ψ`` about the new z, composed with
:mod:`jrigid.affine`), by the quaternion ``quaternion.from_euler("ZXZ", (φ, θ, ψ))``, and by
the chapter's matrix (17.10), which is passive: the active body → space matrix is its
transpose, ``passive_zxz_matrix(φ, θ, ψ)ᵀ``. All three agree.

The singularity: the Euler-angle rate matrix ``M`` of (17.36), ``ω_body = M (φ̇, θ̇, ψ̇)``, is
derived here from quaternion kinematics (column ``i`` is
``quaternion.angular_velocity(q, ∂q/∂angle_i)``, eq. 17.42); its determinant is
``−sin θ`` and goes to zero at ``θ = 0, π``, where only ``φ ± ψ`` is defined.
``quaternion.to_euler`` then follows scipy's convention: the third angle is set to 0 and
the first carries ``φ + ψ`` (``θ = 0``) or ``φ − ψ`` (``θ = π``); ``gimbal_lock`` flags it.

Run it with ``jrigid run euler_angles [--quick]`` or ``python experiments/euler_angles.py``.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import affine, viz
from jrigid import quaternion as quat
from jrigid.report import Report


@jax.jit
def rate_matrix(angles):
    """``M (..., 3, 3)`` with ``ω_body = M (φ̇, θ̇, ψ̇)`` (17.36), from ``q(φ, θ, ψ)`` and 17.42."""

    def one(a):
        q = quat.from_euler("ZXZ", a)
        dq = jax.jacfwd(lambda x: quat.from_euler("ZXZ", x))(a)  # (4, 3)
        return quat.angular_velocity(jnp.broadcast_to(q, (3, 4)), dq.T).T

    return jax.vmap(one)(angles.reshape(-1, 3)).reshape(angles.shape + (3,))


def main(
    out_dir,
    quick: bool = False,
    *,
    phi_deg: float = 40.0,
    theta_deg: float = 30.0,
    psi_deg: float = 60.0,
    samples: int = 181,
) -> dict:
    """Compare the three ways of orienting the block; show the singularity at sin θ = 0.

    Args:
        out_dir: results folder.
        quick: fewer samples of θ.
        phi_deg, theta_deg, psi_deg: precession, nutation and spin, degrees.
        samples: values of θ in ``[0, π]`` for the determinant sweep.

    Returns:
        the numbers written to ``numbers.json``.
    """
    angles = jnp.radians(jnp.asarray([phi_deg, theta_deg, psi_deg]))
    phi, theta, psi = angles
    ez, ex = jnp.array([0.0, 0.0, 1.0]), jnp.array([1.0, 0.0, 0.0])
    # rotation elements: each turn is about the body axis produced by the previous ones,
    # i.e. a right-multiplication of the placement
    T = affine.compose(
        affine.rotation_3d_axis_angle(ez, phi),
        affine.rotation_3d_axis_angle(ex, theta),
        affine.rotation_3d_axis_angle(ez, psi),
    )
    R_elements = np.asarray(affine.to_blocks(T)[0])
    q = quat.from_euler("ZXZ", angles)
    R_angles = np.asarray(quat.to_matrix(q))
    R_matrix = np.asarray(quat.passive_zxz_matrix(phi, theta, psi)).T
    q_matrix = quat.from_matrix(jnp.asarray(R_matrix))

    n = 37 if quick else samples
    th = np.linspace(0.0, np.pi, n)
    sweep = jnp.stack([jnp.full(n, phi), jnp.asarray(th), jnp.full(n, psi)], axis=-1)
    det = np.asarray(jnp.linalg.det(rate_matrix(sweep)))
    cond = np.asarray(jnp.linalg.cond(rate_matrix(sweep[1:-1])))

    locked = {}
    for name, t in (("theta_0", 0.0), ("theta_pi", np.pi), ("theta_1e-9", 1e-9)):
        ql = quat.from_euler("ZXZ", jnp.asarray([phi, t, psi]))
        back = quat.to_euler("ZXZ", ql)
        locked[name] = {
            "to_euler_deg": np.degrees(np.asarray(back)),
            "gimbal_lock": bool(quat.gimbal_lock("ZXZ", ql)),
            "round_trip_distance": float(quat.distance(quat.from_euler("ZXZ", back), ql)),
        }
    numbers = {
        "angles_deg": [phi_deg, theta_deg, psi_deg],
        "elements_vs_angles_max_diff": float(np.max(np.abs(R_elements - R_angles))),
        "matrix_vs_angles_max_diff": float(np.max(np.abs(R_matrix - R_angles))),
        "quaternion_from_matrix_distance": float(quat.distance(q_matrix, q)),
        "theta_deg": np.degrees(th),
        "rate_matrix_det": det,
        "rate_matrix_det_max_error_vs_minus_sin": float(np.max(np.abs(det + np.sin(th)))),
        "rate_matrix_det_at_0_and_pi": [float(det[0]), float(det[-1])],
        "rate_matrix_cond_near_0": float(cond[0]),
        "gimbal_lock": locked,
        "expected_first_angle_deg": {"theta_0": phi_deg + psi_deg, "theta_pi": phi_deg - psi_deg},
    }

    rep = Report(Path(out_dir), title="Euler angles")
    rep.text(
        f"Block at (φ, θ, ψ) = ({phi_deg:g}°, {theta_deg:g}°, {psi_deg:g}°): rotation elements "
        f"and angles agree to {numbers['elements_vs_angles_max_diff']:.1e}, the transposed "
        f"chapter matrix (17.10) to {numbers['matrix_vs_angles_max_diff']:.1e}. The rate "
        f"matrix (17.36) has det = −sin θ "
        f"(error {numbers['rate_matrix_det_max_error_vs_minus_sin']:.1e}), "
        f"zero at θ = 0 and π. At θ = 0, to_euler gives "
        f"{np.round(locked['theta_0']['to_euler_deg'], 6).tolist()}° (third angle 0, first φ + ψ); "
        f"at θ = π, {np.round(locked['theta_pi']['to_euler_deg'], 6).tolist()}° (first φ − ψ)."
    )
    fig = viz.new_figure(figsize=(11, 3.8), layout=None)
    axes = [fig.add_axes((0.0 + 0.3 * k, 0.05, 0.3, 0.82)) for k in range(2)]
    mesh = viz.box(1.0, 0.6, 0.3)
    viz.body_still(mesh, np.asarray(q), ax=axes[0], title="from_euler('ZXZ', angles)")
    viz.body_still(mesh, np.asarray(q_matrix), ax=axes[1], title="passive_zxz_matrix(...)ᵀ")
    ax = fig.add_axes((0.67, 0.17, 0.31, 0.7))
    ax.plot(np.degrees(th), det, label="det M (17.36)")
    ax.plot(np.degrees(th), -np.sin(th), "k--", lw=0.8, label="−sin θ")
    ax.set_xlabel("θ (degrees)")
    ax.legend(fontsize=8)
    ax.set_title("the rate matrix is singular at sin θ = 0", fontsize=9)
    rep.figure(
        "euler_block", fig, caption="the block by angles and by matrix; det of (17.36)", dpi=70
    )
    rep.numbers(numbers)
    rep.write_summary()
    print(
        f"euler_angles: matrix vs angles {numbers['matrix_vs_angles_max_diff']:.1e}, "
        f"det at 0 and pi {numbers['rate_matrix_det_at_0_and_pi']}"
    )
    return numbers


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "euler_angles")
