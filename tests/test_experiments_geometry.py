"""The geometry experiments of chapter 17 (issue 8, experiments 1-6), run in quick mode.

Each experiment runs once per session through the command line (``jrigid run NAME --quick
--out DIR``); the tests read its ``numbers.json`` and check the chapter's claim against
analytic values or an independent implementation (scipy ``Rotation``, Table 17.1 moments
typed in here, the printed eq. 17.36). All quantities are O(1) and computed in float64 with
a handful of operations, so "exact" claims are checked to 1e-12 (a few thousand ulps):
tight enough to catch any wrong formula, loose enough for roundoff.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest
from _experiments import quick_suite
from scipy.spatial.transform import Rotation

from jrigid import registry

NAMES = ("affine_2d", "affine_3d", "methane", "euler_angles", "quaternion_rotation", "fixed_axle")
EXACT = 1e-12  # see the module docstring


results, test_listed_and_writes_outputs = quick_suite(NAMES)


# --------------------------------------------------------------------------- 1. affine_2d


def test_affine_2d(results):
    n, _ = results["affine_2d"]
    # Exercise 17.1a: R(-30°) S(2, 1) - S R = [[0, -s], [-s, 0]], s = sin 30°: norm √2/2
    assert n["commutator_norm"] == pytest.approx(math.sqrt(2) / 2, abs=EXACT)
    assert n["commutator_norm"] > 0.7
    # 17.2a: the rotation turns about the origin; 17.2b: about_point keeps the vertex fixed
    np.testing.assert_allclose(n["rotation_fixed_point"], [0.0, 0.0], atol=EXACT)
    np.testing.assert_allclose(n["vertex_rotation_fixed_point"], [1.0, 0.5], atol=EXACT)
    assert n["vertex_displacement"] < EXACT
    # the arrow (w = 0) is untouched by a translation and only turned by the rotation
    assert n["arrow_change_under_translation"] == 0.0 and n["arrow_w_after_translation"] == 0.0
    assert n["arrow_turn_error"] < EXACT
    # (17.6): y is kept, vertical lines tilt by atan(0.2), areas are kept
    assert n["skew_y_change"] == 0.0
    assert n["skew_tilt_deg"] == pytest.approx(math.degrees(math.atan(0.2)), abs=1e-9)
    assert n["skew_det"] == pytest.approx(1.0, abs=EXACT)
    # 17.2d: parallel stays parallel for affine maps, not for a projective bottom row
    assert n["parallel_sin_affine"] < 1e-12
    assert n["parallel_sin_projective"] > 0.05


# --------------------------------------------------------------------------- 2. affine_3d


def test_affine_3d_order_of_transforms(results):
    n, _ = results["affine_3d"]
    # independent: the same prism turned by scipy rotations in both orders
    ang = 2 * np.pi * np.arange(5) / 5
    upper = np.stack([np.cos(ang) + 0.3, np.sin(ang), np.full(5, 0.6)], axis=-1)
    rx, ry = Rotation.from_rotvec([np.pi / 2, 0, 0]), Rotation.from_rotvec([0, np.pi / 2, 0])
    diff = np.max(np.abs((rx * ry).apply(upper) - (ry * rx).apply(upper)))
    assert n["rotations_order_max_vertex_difference"] == pytest.approx(diff, abs=EXACT)
    assert diff > 0.5
    assert n["translations_order_max_difference"] <= 1e-15
    # T(d) R - R T(d) moves every point by d - R d; for d = (0.5, -0.2, 0.3), R = Rx(90°):
    # R d = (0.5, -0.3, -0.2), |d - R d| = |(0, 0.1, 0.5)| = √0.26
    assert n["rotation_translation_difference"] == pytest.approx(math.sqrt(0.26), abs=EXACT)
    assert n["segment_change_under_translation"] == 0.0
    assert n["upper_rebuilt_error"] < EXACT


def test_affine_3d_depth_order(results):
    n, _ = results["affine_3d"]
    assert n["wrong_pairs_naive_drawn"] > 0  # the tree order paints a far face over a near one
    assert n["wrong_pairs_sorted_drawn"] == 0
    assert n["orientations_naive_wrong"] > 0
    assert n["orientations_culled_wrong"] == 0  # sorting + culling is exact for a convex body


# --------------------------------------------------------------------------- 3. methane


def test_methane(results):
    n, _ = results["methane"]
    assert n["hint_correct"] is True
    assert n["h"] == pytest.approx(math.sqrt(2 / 3), abs=EXACT)  # unit tetrahedron height
    np.testing.assert_allclose(n["hh_distances"], 1.0, atol=EXACT)
    np.testing.assert_allclose(n["ch_distance"], math.sqrt(6) / 4, atol=EXACT)
    np.testing.assert_allclose(n["centroid_of_H"], 0.0, atol=EXACT)  # C at the centre
    # arccos is well conditioned at -1/3 (slope ≈ 1.06), so the angle is good to ~1e-12 rad
    np.testing.assert_allclose(n["hch_angles_deg"], math.degrees(math.acos(-1 / 3)), atol=1e-9)
    assert n["hch_angles_deg"][0] == pytest.approx(109.47, abs=0.01)
    # isotropic: (8/3) m_H d² with d² = 3/8 is m_H on every axis, no products of inertia
    tensor = np.asarray(n["inertia_tensor"])
    np.testing.assert_allclose(tensor, 1.008 * np.eye(3), atol=EXACT)
    assert n["inertia_turned_max_change"] < EXACT


# --------------------------------------------------------------------------- 4. euler_angles


def test_euler_angles_block_by_angles_equals_matrix(results):
    n, _ = results["euler_angles"]
    assert n["elements_vs_angles_max_diff"] < EXACT
    assert n["matrix_vs_angles_max_diff"] < EXACT
    assert n["quaternion_from_matrix_distance"] < EXACT


def test_euler_angles_rate_matrix_is_the_printed_17_36():
    rate_matrix = registry.get("euler_angles").load().rate_matrix
    angles = np.random.default_rng(3).uniform(-3, 3, size=(6, 3))
    _, th, ps = angles.T
    st, ct, sp, cp = np.sin(th), np.cos(th), np.sin(ps), np.cos(ps)
    z = np.zeros_like(th)
    printed = np.stack(
        [np.stack([st * sp, cp, z], -1), np.stack([st * cp, -sp, z], -1),
         np.stack([ct, z, z + 1], -1)], axis=-2,
    )  # fmt: skip
    np.testing.assert_allclose(rate_matrix(jnp.asarray(angles)), printed, atol=EXACT)


def test_euler_angles_singularity(results):
    n, _ = results["euler_angles"]
    th = np.radians(n["theta_deg"])
    np.testing.assert_allclose(n["rate_matrix_det"], -np.sin(th), atol=EXACT)
    np.testing.assert_allclose(n["rate_matrix_det_at_0_and_pi"], 0.0, atol=EXACT)
    g, phi, psi = n["gimbal_lock"], 40.0, 60.0
    assert all(case["gimbal_lock"] for case in g.values())
    # scipy's convention: third angle 0, the first carries φ + ψ (θ = 0) or φ - ψ (θ = π)
    np.testing.assert_allclose(g["theta_0"]["to_euler_deg"], [phi + psi, 0, 0], atol=1e-9)
    with pytest.warns(UserWarning, match="Gimbal lock"):
        ref = Rotation.from_euler("ZXZ", [phi, 0, psi], degrees=True).as_euler("ZXZ", True)
    np.testing.assert_allclose(g["theta_0"]["to_euler_deg"], ref, atol=1e-9)
    first, middle, third = g["theta_pi"]["to_euler_deg"]
    assert first == pytest.approx(phi - psi, abs=1e-9) and third == 0.0
    assert middle == pytest.approx(180.0, abs=1e-9)  # scipy: the middle angle is in [0, π]
    for case in ("theta_0", "theta_pi"):
        assert g[case]["round_trip_distance"] < EXACT  # the rotation itself is kept
    assert g["theta_1e-9"]["round_trip_distance"] < 2e-9  # O(θ) when θ is snapped to lock


# --------------------------------------------------------------------------- 5. quaternion_rotation


@pytest.mark.parametrize(
    "name, target, angle",
    [("45deg_in_xy", (1, 1, 0), 45.0), ("45deg_in_zy", (0, 1, 1), 90.0),
     ("along_121", (1, 2, 1), math.degrees(math.acos(1 / math.sqrt(6))))],
)  # fmt: skip
def test_quaternion_orientations(results, name, target, angle):
    n = results["quaternion_rotation"][0][name]
    t = np.asarray(target, float) / np.linalg.norm(target)
    assert n["long_side_error"] < EXACT
    # independent: scipy turns body x onto the target with the same quaternion
    r = Rotation.from_quat(n["q"], scalar_first=True)
    np.testing.assert_allclose(r.apply([1.0, 0.0, 0.0]), t, atol=EXACT)
    assert abs(n["norm_minus_1"]) < EXACT and n["length_change"] < EXACT  # Exercise 17.8
    # 17.27 back out: the angle built in, and the axis perpendicular to x and the target
    assert n["angle_deg"] == pytest.approx(angle, abs=1e-9)
    assert n["angle_deg_17_27"] == pytest.approx(angle, abs=1e-6)  # arccos: ~sqrt(eps) near 0
    np.testing.assert_allclose(n["axis"], n["axis_17_27"], atol=1e-9)
    np.testing.assert_allclose(np.cross([1.0, 0.0, 0.0], t), np.sin(np.radians(angle)) *
                               np.asarray(n["axis"]), atol=EXACT)  # fmt: skip


def test_quaternion_non_unit_and_zero(results):
    n, _ = results["quaternion_rotation"]
    nu, zero = n["non_unit"], n["zero"]
    assert nu["rotate_length_ratio"] == pytest.approx(nu["scale"] ** 2, abs=EXACT)
    assert nu["to_matrix_difference"] < EXACT
    assert "not unit length" in nu["check_quaternion_message"]
    assert zero["rotate"] == [0.0, 0.0, 0.0] and zero["to_matrix_all_nan"] is True
    assert "zero quaternion" in zero["check_quaternion_message"]


# --------------------------------------------------------------------------- 6. fixed_axle


def test_fixed_axle(results):
    n, _ = results["fixed_axle"]
    # defaults: box (1, 0.4, 0.2), m = 1, ω = 2, α = 30°; Table 17.1 moments
    a, b, c, w, al = 1.0, 0.4, 0.2, 2.0, math.radians(30.0)
    I1, I2, I3 = (b * b + c * c) / 12, (a * a + c * c) / 12, (a * a + b * b) / 12
    np.testing.assert_allclose(n["I_body_moments"], [I1, I2, I3], atol=EXACT)
    # (17.32) against scipy: R = Ry(α) at t = 0
    R = Rotation.from_rotvec([0.0, al, 0.0]).as_matrix()
    np.testing.assert_allclose(n["I_space_t0"], R @ np.diag([I1, I2, I3]) @ R.T, atol=EXACT)
    # Exercise 17.11: |L| and L itself agree between the frames
    assert n["L_norm_space_minus_body_max"] < EXACT
    assert n["L_body_to_space_max_error"] < EXACT
    # L_body = ω(-I1 sin α, 0, I3 cos α): not parallel to ω = ω e_z
    beta = math.atan2((I3 - I1) * math.sin(al) * math.cos(al),
                      I1 * math.sin(al) ** 2 + I3 * math.cos(al) ** 2)  # fmt: skip
    assert n["angle_L_omega_deg"] == pytest.approx(math.degrees(beta), abs=1e-9)
    assert n["angle_L_omega_deg"] > 10.0
    N = 0.5 * w * w * abs(I3 - I1) * math.sin(2 * al)
    assert n["torque_norm"] == pytest.approx(N, abs=EXACT)
    assert n["torque_norm_spread_over_revolution"] < EXACT and n["torque_z_max"] < EXACT
    # central difference with h = 5e-5: truncation h² ω³ |L⊥| / 6 ≈ 2e-10, roundoff
    # eps |L| / h ≈ 4e-13, so 1e-8 is a safe bound that a wrong torque would miss by far
    assert n["torque_vs_finite_difference_max_error"] < 1e-8
    assert n["tilt_sweep_max_error_vs_theory"] < EXACT
    np.testing.assert_allclose(n["torque_at_tilt_0_and_90"], 0.0, atol=EXACT)
    assert max(n["tilt_sweep_torque_norm"]) == pytest.approx(0.5 * w * w * (I3 - I1), rel=1e-2)


def test_float32_still_runs(float32, tmp_path):
    """The library's float32 path: the 2D experiment's claims hold to single precision."""
    mod = registry.get("affine_2d").load()
    n = mod.main(tmp_path, quick=True)
    assert jnp.zeros(1).dtype == jnp.float32
    assert n["commutator_norm"] == pytest.approx(math.sqrt(2) / 2, abs=1e-6)
    assert n["vertex_displacement"] < 1e-5
