"""Tests of jrigid.affine: homogeneous transforms (17.1-17.9) and cameras."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from jrigid import affine

BATCH_SHAPES = [(), (1,), (3, 1, 2)]
SETTINGS = settings(max_examples=25, deadline=None)
seeds = st.integers(0, 2**32 - 1)


def _random_affine(rng, n, batch=()):
    """Well-conditioned random affine matrix (numpy), shape batch + (n+1, n+1)."""
    A = rng.normal(size=batch + (n, n)) + 2.0 * np.eye(n)
    T = np.zeros(batch + (n + 1, n + 1))
    T[..., :n, :n] = A
    T[..., :n, n] = rng.normal(size=batch + (n,))
    T[..., n, n] = 1.0
    return T


def _random_rigid(rng, batch=()):
    T = np.zeros(batch + (4, 4))
    size = int(np.prod(batch)) if batch else None
    T[..., :3, :3] = Rotation.random(size, random_state=rng).as_matrix().reshape(batch + (3, 3))
    T[..., :3, 3] = rng.normal(size=batch + (3,))
    T[..., 3, 3] = 1.0
    return T


# --------------------------------------------------------------------------- 2D, 17.1-17.7


def test_rotation_2d_is_17_1():
    theta, x, y = 0.7, 1.3, -0.4
    out = affine.apply_to_points(affine.rotation_2d(theta), jnp.array([x, y]))
    c, s = np.cos(theta), np.sin(theta)
    np.testing.assert_allclose(out, [c * x - s * y, s * x + c * y], rtol=1e-14)
    # Exercise 17.1a: a 30° clockwise rotation takes (1, 0) to (cos 30°, -sin 30°).
    out = affine.apply_to_points(affine.rotation_2d(-np.pi / 6), jnp.array([1.0, 0.0]))
    np.testing.assert_allclose(out, [np.sqrt(3) / 2, -0.5], atol=1e-15)


def test_scaling_translation_and_skew_2d():
    p = jnp.array([2.0, 3.0])
    np.testing.assert_allclose(
        affine.apply_to_points(affine.scaling(jnp.array([2.0, 0.5])), p), [4.0, 1.5]
    )
    np.testing.assert_allclose(
        affine.translation(jnp.array([1.0, -2.0]))[:2, 2], [1.0, -2.0]
    )  # 17.5
    np.testing.assert_allclose(
        affine.apply_to_points(affine.translation(jnp.array([1.0, -2.0])), p), [3.0, 1.0]
    )
    # 17.6: [[1, 0.2, 0], [0, 1, 0], [0, 0, 1]] skews x by 0.2 y.
    np.testing.assert_allclose(affine.shear_2d(0.2), [[1, 0.2, 0], [0, 1, 0], [0, 0, 1]])
    np.testing.assert_allclose(affine.apply_to_points(affine.shear_2d(0.2), p), [2.6, 3.0])
    np.testing.assert_allclose(affine.apply_to_points(affine.shear_2d(0.0, 0.5), p), [2.0, 4.0])


def test_blocks_round_trip_17_7():
    rng = np.random.default_rng(0)
    A, d = rng.normal(size=(3, 3)), rng.normal(size=3)
    T = affine.from_blocks(A, d)
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])
    A2, d2 = affine.to_blocks(T)
    np.testing.assert_array_equal(A2, A)
    np.testing.assert_array_equal(d2, d)


def test_scaling_and_rotation_do_not_commute_2d():
    # Exercise 17.1a: a rotation and a non-uniform scaling do not commute.
    R, S = affine.rotation_2d(-np.pi / 6), affine.scaling(jnp.array([2.0, 1.0]))
    assert not np.allclose(affine.compose(R, S), affine.compose(S, R))
    # Two rotations about the same point in the plane do commute.
    R2 = affine.rotation_2d(1.1)
    np.testing.assert_allclose(affine.compose(R, R2), affine.compose(R2, R), atol=1e-15)
    np.testing.assert_allclose(
        affine.compose(R, R2), affine.rotation_2d(1.1 - np.pi / 6), atol=1e-15
    )


# --------------------------------------------------------------------------- composition


def test_3d_rotations_do_not_commute_and_match_scipy_composition():
    rx = Rotation.from_rotvec([np.pi / 2, 0, 0])
    ry = Rotation.from_rotvec([0, np.pi / 2, 0])
    Rx = affine.rotation_3d_axis_angle(jnp.array([1.0, 0, 0]), np.pi / 2)
    Ry = affine.rotation_3d_axis_angle(jnp.array([0, 1.0, 0]), np.pi / 2)
    xy, yx = affine.compose(Rx, Ry), affine.compose(Ry, Rx)
    assert np.abs(np.asarray(xy) - np.asarray(yx)).max() > 0.5
    # compose(A, B) applies B first, like scipy's A * B.
    np.testing.assert_allclose(xy[:3, :3], (rx * ry).as_matrix(), atol=1e-15)
    np.testing.assert_allclose(yx[:3, :3], (ry * rx).as_matrix(), atol=1e-15)
    p = jnp.array([0.3, -1.2, 0.5])
    np.testing.assert_allclose(
        affine.apply_to_points(xy, p), affine.apply_to_points(Rx, affine.apply_to_points(Ry, p))
    )


def test_translations_commute_and_add():
    a, b = jnp.array([1.0, 2.0, -3.0]), jnp.array([-0.5, 4.0, 0.25])
    Ta, Tb = affine.translation(a), affine.translation(b)
    np.testing.assert_array_equal(affine.compose(Ta, Tb), affine.compose(Tb, Ta))
    np.testing.assert_allclose(affine.compose(Ta, Tb), affine.translation(a + b))
    # A translation and a rotation do not commute.
    R = affine.rotation_3d_axis_angle(jnp.array([0, 0, 1.0]), 0.4)
    assert not np.allclose(affine.compose(R, Ta), affine.compose(Ta, R))


def test_compose_three_and_batches():
    rng = np.random.default_rng(1)
    Ts = [_random_affine(rng, 3, (2, 1)), _random_affine(rng, 3), _random_affine(rng, 3, (5,))]
    out = affine.compose(*Ts)
    assert out.shape == (2, 5, 4, 4)
    np.testing.assert_allclose(out, Ts[0] @ Ts[1] @ Ts[2], rtol=1e-12)
    np.testing.assert_array_equal(affine.compose(Ts[1]), Ts[1])


# --------------------------------------------------------------------------- points vs vectors


@SETTINGS
@given(seed=seeds, n=st.sampled_from([2, 3]))
def test_points_translate_vectors_do_not(seed, n):
    rng = np.random.default_rng(seed)
    T = _random_affine(rng, n)
    p, q = rng.normal(size=(2, n))
    d = rng.normal(size=n)
    v = rng.normal(size=n)
    # Vectors are invariant under translation, points move.
    np.testing.assert_allclose(affine.apply_to_vectors(affine.translation(d), v), v, rtol=1e-14)
    np.testing.assert_allclose(affine.apply_to_points(affine.translation(d), p), p + d, rtol=1e-14)
    # The difference of two transformed points is the transformed difference vector (w = 0).
    diff = affine.apply_to_points(T, p) - affine.apply_to_points(T, q)
    np.testing.assert_allclose(diff, affine.apply_to_vectors(T, p - q), rtol=1e-10, atol=1e-12)
    # Homogeneous form: w = 1 for points, 0 for vectors, and T keeps it.
    P = affine.apply(T, affine.to_homogeneous(p, 1.0))
    V = affine.apply(T, affine.to_homogeneous(v, 0.0))
    assert float(P[-1]) == 1.0 and float(V[-1]) == 0.0
    np.testing.assert_allclose(affine.from_homogeneous(P), T[:n, :n] @ p + T[:n, n], rtol=1e-12)
    np.testing.assert_allclose(V[:n], T[:n, :n] @ v, rtol=1e-12)


def test_homogeneous_points_are_equivalent_up_to_scale():
    X = jnp.array([2.0, 4.0, -6.0, 2.0])
    np.testing.assert_allclose(affine.from_homogeneous(X), [1.0, 2.0, -3.0])


@SETTINGS
@given(seed=seeds, n=st.sampled_from([2, 3]))
def test_parallel_lines_stay_parallel(seed, n):
    rng = np.random.default_rng(seed)
    T = _random_affine(rng, n)
    direction = rng.normal(size=n)
    a, b = rng.normal(size=(2, n))
    t = np.array([-1.3, 0.0, 2.1])[:, None]
    line1 = affine.apply_to_points(T, a + t * direction)
    line2 = affine.apply_to_points(T, b + t * direction)
    d1 = np.asarray(line1[2] - line1[0])
    d2 = np.asarray(line2[2] - line2[0])
    # Each image is still a straight line ...
    mid = np.asarray(line1[1] - line1[0])
    cos_mid = mid @ d1 / np.linalg.norm(mid) / np.linalg.norm(d1)
    np.testing.assert_allclose(abs(cos_mid), 1.0, rtol=1e-10)
    # ... and the images are parallel with equal length ratios.
    np.testing.assert_allclose(d1, d2, rtol=1e-9, atol=1e-10)


# --------------------------------------------------------------------------- inverse


@SETTINGS
@given(seed=seeds, n=st.sampled_from([2, 3]))
def test_inverse_round_trip(seed, n):
    rng = np.random.default_rng(seed)
    T = _random_affine(rng, n)
    Ti = affine.inverse(T)
    np.testing.assert_allclose(Ti, np.linalg.inv(T), rtol=1e-9, atol=1e-11)
    p = rng.normal(size=(4, n))
    back = affine.apply_to_points(Ti, affine.apply_to_points(T, p))
    np.testing.assert_allclose(back, p, rtol=1e-9, atol=1e-11)


@SETTINGS
@given(seed=seeds)
def test_inverse_rigid_closed_form(seed):
    rng = np.random.default_rng(seed)
    T = _random_rigid(rng, (3,))
    Ti = affine.inverse_rigid(T)
    np.testing.assert_allclose(Ti, np.linalg.inv(T), atol=1e-12)
    np.testing.assert_allclose(
        affine.compose(T, Ti), np.broadcast_to(np.eye(4), (3, 4, 4)), atol=1e-12
    )
    # 2D rigid transforms too.
    T2 = affine.compose(affine.translation(jnp.array([1.0, 2.0])), affine.rotation_2d(0.8))
    np.testing.assert_allclose(affine.inverse_rigid(T2), np.linalg.inv(T2), atol=1e-14)


def test_inverse_rigid_refuses_what_is_not_rigid():
    """A scaling, a shear or a projective matrix has no transpose inverse: refused, where
    the closed form would return diag(2, 2, 1) for the inverse of diag(2, 2, 1)."""
    with pytest.raises(ValueError, match="not orthogonal"):
        affine.inverse_rigid(affine.scaling(jnp.array([2.0, 2.0])))
    with pytest.raises(ValueError, match="not orthogonal"):
        affine.inverse_rigid(affine.shear_2d(0.3))
    projective = jnp.array([[1.0, 0, 0], [0, 1, 0], [1, 0, 1]])
    with pytest.raises(ValueError, match="last row"):
        affine.inverse_rigid(projective)
    with pytest.raises(ValueError, match="non-finite"):
        affine.inverse_rigid(jnp.full((4, 4), jnp.nan))
    with pytest.raises(Exception, match="not orthogonal"):
        jax.jit(affine.inverse_rigid)(affine.scaling(jnp.array([2.0, 2.0]))).block_until_ready()


def test_rotations_refuse_a_zero_quaternion_or_axis():
    with pytest.raises(ValueError, match="zero quaternion"):
        affine.rotation_3d(jnp.zeros(4))
    with pytest.raises(ValueError, match="non-finite"):
        affine.rotation_3d(jnp.array([jnp.nan, 0.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match="axis must be finite and not zero"):
        affine.rotation_3d_axis_angle(jnp.zeros(3), 0.3)
    # any other scale is the rotation of q/|q| (scipy)
    q = jnp.array([2.0, 0.4, -0.2, 1.0])
    expected = Rotation.from_quat(np.roll(np.asarray(q), -1)).as_matrix()
    np.testing.assert_allclose(affine.rotation_3d(q)[:3, :3], expected, atol=1e-14)


def test_inverse_of_projective_matrix():
    T = np.eye(4)
    T[3, 2] = -1.0  # w' = -z: a perspective division
    T[2, 3] = 0.5
    np.testing.assert_allclose(affine.inverse(T), np.linalg.inv(T), atol=1e-14)


def test_inverse_of_singular_matrix_raises():
    singular = affine.scaling(jnp.array([1.0, 0.0, 2.0]))
    with pytest.raises(ValueError, match="singular"):
        affine.inverse(singular)
    rank_deficient = np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="singular"):
        affine.inverse(rank_deficient)
    with pytest.raises(ValueError, match="singular"):
        affine.inverse(jnp.full((3, 3), jnp.nan))
    with pytest.raises(Exception, match="singular"):
        jax.block_until_ready(jax.jit(affine.inverse)(singular))
    # A batch with one singular member is refused, naming its singular values.
    batch = jnp.stack([jnp.eye(4), singular])
    with pytest.raises(ValueError, match="singular values"):
        affine.inverse(batch)


# --------------------------------------------------------------------------- pivots


def test_rotation_about_a_vertex_leaves_it_fixed():
    # Exercise 17.2b: rotate a polygon about one of its vertices.
    polygon = np.array([[0.0, 0.0], [2.0, 0.0], [2.5, 1.5], [0.5, 2.0]]) + np.array([3.0, 1.0])
    vertex = polygon[2]
    T = affine.rotation_2d(-np.pi / 6, pivot=vertex)
    out = np.asarray(affine.apply_to_points(T, polygon))
    np.testing.assert_allclose(out[2], vertex, atol=1e-14)
    # Distances to the vertex are kept and the rotation angle is -30°.
    np.testing.assert_allclose(
        np.linalg.norm(out - out[2], axis=-1), np.linalg.norm(polygon - vertex, axis=-1), rtol=1e-14
    )
    before, after = polygon[0] - vertex, out[0] - out[2]
    angle = np.arctan2(before[0] * after[1] - before[1] * after[0], before @ after)
    np.testing.assert_allclose(angle, -np.pi / 6, rtol=1e-13)
    # The same transform moves the arrow (a vector) only by the rotation.
    arrow = jnp.array([1.0, 0.0])
    np.testing.assert_allclose(
        affine.apply_to_vectors(T, arrow), [np.sqrt(3) / 2, -0.5], atol=1e-15
    )


def test_rotation_3d_about_pivot_fixes_the_axis_line():
    pivot = np.array([1.0, -2.0, 0.5])
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    T = affine.rotation_3d_axis_angle(axis, 1.3, pivot=pivot)
    on_axis = pivot + np.array([-1.0, 0.0, 2.5])[:, None] * axis
    np.testing.assert_allclose(affine.apply_to_points(T, on_axis), on_axis, atol=1e-14)
    off = np.zeros(3)
    expected = Rotation.from_rotvec(1.3 * np.asarray(axis)).apply(off - pivot) + pivot
    np.testing.assert_allclose(affine.apply_to_points(T, off), expected, atol=1e-14)
    np.testing.assert_allclose(
        affine.about_point(affine.scaling(jnp.array([2.0, 2.0, 2.0])), pivot)
        @ jnp.append(pivot, 1.0),
        jnp.append(pivot, 1.0),
    )


# --------------------------------------------------------------------------- 3D rotations


@SETTINGS
@given(seed=seeds)
def test_rotation_3d_block_equals_scipy(seed):
    rng = np.random.default_rng(seed)
    rot = Rotation.random(random_state=rng)
    T = affine.rotation_3d(jnp.asarray(rot.as_quat(scalar_first=True)))
    np.testing.assert_allclose(T[:3, :3], rot.as_matrix(), atol=1e-14)
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])
    np.testing.assert_array_equal(T[:3, 3], 0)
    rotvec = rot.as_rotvec()
    angle = np.linalg.norm(rotvec)
    T = affine.rotation_3d_axis_angle(jnp.asarray(rotvec / angle * 2.5), angle)  # unnormalised axis
    np.testing.assert_allclose(T[:3, :3], rot.as_matrix(), atol=1e-13)
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-14)


@pytest.mark.parametrize("seq", ["ZXZ", "XYZ", "xyz", "zyx", "yxy"])
def test_rotation_3d_euler_equals_scipy(seq):
    rng = np.random.default_rng(2)
    angles = rng.uniform(-np.pi, np.pi, size=(4, 3))
    angles[:, 1] = rng.uniform(0.1, 1.4, size=4)
    T = affine.rotation_3d_euler(seq, jnp.asarray(angles))
    assert T.shape == (4, 4, 4)
    np.testing.assert_allclose(
        T[:, :3, :3], Rotation.from_euler(seq, angles).as_matrix(), atol=1e-13
    )


def test_rotation_about_z_agrees_with_2d_rotation():
    # Exercise 17.5: a rotation about z is the 2D rotation in the x-y plane.
    T3 = affine.rotation_3d_axis_angle(jnp.array([0.0, 0.0, 1.0]), 0.9)
    T2 = affine.rotation_2d(0.9)
    np.testing.assert_allclose(T3[:2, :2], T2[:2, :2], atol=1e-15)


# --------------------------------------------------------------------------- projections


def test_orthographic_projection_and_depth_order():
    pts = jnp.array([[1.0, 2.0, 3.0], [1.0, 2.0, -1.0], [0.5, -2.0, 0.0]])
    uv, depth = affine.orthographic(pts, axis=2)
    np.testing.assert_array_equal(uv, pts[:, :2])  # drop z (section 17.2)
    # The viewer is on +z: the highest point is nearest, drawn last.
    order = np.argsort(-np.asarray(depth))  # back to front
    np.testing.assert_array_equal(order, [1, 2, 0])
    # Along x the image axes are (y, z) and u × v points toward the viewer.
    uv_x, depth_x = affine.orthographic(pts, axis=0)
    np.testing.assert_array_equal(uv_x, pts[:, 1:])
    np.testing.assert_array_equal(depth_x, -pts[:, 0])
    uv_y, _ = affine.orthographic(pts, axis=1)
    np.testing.assert_array_equal(uv_y, pts[:, [2, 0]])
    for axis in range(3):
        e = np.eye(3)
        (u,), _ = affine.orthographic(jnp.asarray(e[(axis + 1) % 3])[None], axis=axis)
        assert u[0] == 1.0 and u[1] == 0.0


def test_look_at_is_rigid_and_maps_eye_and_target():
    eye, target = jnp.array([4.0, -3.0, 2.0]), jnp.array([0.5, 1.0, -0.5])
    V = np.asarray(affine.look_at(eye, target))
    R = V[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, rtol=1e-14)
    np.testing.assert_allclose(V[:3] @ np.append(eye, 1), 0.0, atol=1e-14)
    dist = np.linalg.norm(target - eye)
    np.testing.assert_allclose(V[:3] @ np.append(target, 1), [0, 0, -dist], atol=1e-14)
    # The camera's up axis is the world z direction made orthogonal to the view.
    f = np.asarray(target - eye) / dist
    up = np.array([0.0, 0.0, 1.0]) - f[2] * f
    np.testing.assert_allclose(R[1], up / np.linalg.norm(up), atol=1e-14)


def test_perspective_maps_target_to_centre_and_orders_depth():
    eye, target = jnp.array([5.0, 2.0, 3.0]), jnp.array([0.0, 0.5, 0.0])
    fov = np.deg2rad(50.0)
    uv, depth = affine.perspective(target, eye, target, fov)
    np.testing.assert_allclose(uv, [0.0, 0.0], atol=1e-14)
    np.testing.assert_allclose(depth, np.linalg.norm(target - eye), rtol=1e-14)
    # Points on the line of sight project to the centre at increasing depth.
    t = np.array([0.3, 1.0, 2.5])
    line = np.asarray(eye) + t[:, None] * np.asarray(target - eye)
    uv, depth = affine.perspective(line, eye, target, fov)
    np.testing.assert_allclose(uv, 0.0, atol=1e-13)
    np.testing.assert_allclose(depth, t * np.linalg.norm(target - eye), rtol=1e-13)
    assert np.all(np.diff(np.asarray(depth)) > 0)


def test_perspective_field_of_view_and_orientation():
    # Camera on the +x axis looking at the origin, world z up: right is +y, up is +z.
    eye, target = jnp.array([10.0, 0.0, 0.0]), jnp.zeros(3)
    fov, aspect = np.deg2rad(60.0), 2.0
    half = np.tan(fov / 2) * 10.0
    pts = jnp.array([[0.0, 0.0, half], [0.0, half * aspect, 0.0], [0.0, 1.0, 0.0], [5.0, 0.0, 1.0]])
    uv, depth = affine.perspective(pts, eye, target, fov, aspect=aspect)
    np.testing.assert_allclose(uv[0], [0.0, 1.0], atol=1e-14)  # top edge of the image
    np.testing.assert_allclose(uv[1], [1.0, 0.0], atol=1e-14)  # right edge
    assert uv[2, 0] > 0
    # Nearer objects look bigger: the same offset at depth 5 appears twice as high as at 10.
    np.testing.assert_allclose(uv[3, 1], 2 * (1.0 / half), rtol=1e-14)
    np.testing.assert_allclose(depth, [10.0, 10.0, 10.0, 5.0], rtol=1e-14)


def test_perspective_behind_the_eye_is_nan_and_culled_by_depth():
    eye, target = jnp.array([0.0, 0.0, 5.0]), jnp.zeros(3)
    uv, depth = affine.perspective(
        jnp.array([[0.0, 0.0, 7.0], [0.1, 0.0, 0.0]]),
        eye,
        target,
        1.0,
        up=jnp.array([0.0, 1.0, 0.0]),
    )
    assert depth[0] < 0 and np.all(np.isnan(uv[0]))
    assert depth[1] > 0 and np.all(np.isfinite(uv[1]))


def test_perspective_depth_sorts_cube_faces_back_to_front():
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    faces = [corners[corners[:, k] == s] for k in range(3) for s in (-1, 1)]
    centres = jnp.asarray([f.mean(0) for f in faces])
    eye = jnp.array([6.0, 4.0, 3.0])
    _, depth = affine.perspective(centres, eye, jnp.zeros(3), 0.8)
    order = np.argsort(-np.asarray(depth))
    dist = np.linalg.norm(np.asarray(centres) - np.asarray(eye), axis=-1)
    # Back to front by depth agrees with decreasing distance from the eye here.
    np.testing.assert_array_equal(order, np.argsort(-dist))
    # The three visible faces (+x, +y, +z) are drawn last.
    assert set(order[3:].tolist()) == {1, 3, 5}


# --------------------------------------------------------------------------- transformations


@pytest.mark.parametrize("batch", BATCH_SHAPES)
def test_batch_shapes_broadcast(batch):
    rng = np.random.default_rng(3)
    angles = rng.uniform(-3, 3, batch)
    p = rng.normal(size=(7,) + batch + (2,))  # a leading extra dim broadcasts against T
    d = rng.normal(size=batch + (3,))
    q = Rotation.random(int(np.prod(batch)), random_state=rng).as_quat(scalar_first=True)
    q = q.reshape(batch + (4,))
    eye = rng.normal(size=batch + (3,)) + 5.0

    @jax.jit
    def run(angles, p, d, q, eye):
        T = affine.rotation_2d(angles)
        T3 = affine.compose(affine.translation(d), affine.rotation_3d(q))
        return dict(
            T=T,
            out=affine.apply_to_points(T, p),
            T3=T3,
            inv=affine.inverse(T3),
            inv_rigid=affine.inverse_rigid(T3),
            shear=affine.shear_3d(xy=angles),
            view=affine.look_at(eye, jnp.zeros(3)),
            proj=affine.perspective(jnp.zeros(batch + (3,)), eye, jnp.ones(3), 1.0),
        )

    r = run(angles, p, d, q, eye)
    assert r["T"].shape == batch + (3, 3)
    assert r["out"].shape == p.shape
    c, s = np.cos(angles), np.sin(angles)
    np.testing.assert_allclose(
        r["out"][..., 0], c * p[..., 0] - s * p[..., 1], rtol=1e-12, atol=1e-14
    )
    for key in ("T3", "inv", "inv_rigid", "shear", "view"):
        assert r[key].shape == batch + (4, 4), key
    np.testing.assert_allclose(r["inv"], np.linalg.inv(r["T3"]), atol=1e-12)
    np.testing.assert_allclose(r["inv_rigid"], np.linalg.inv(r["T3"]), atol=1e-12)
    uv, depth = r["proj"]
    assert uv.shape == batch + (2,) and depth.shape == batch
    assert np.all(np.asarray(depth) > 0)


def test_vmap_matches_batch():
    angles = jnp.linspace(-2.0, 2.0, 5)
    p = jnp.array([0.3, -0.8])
    batched = affine.apply_to_points(affine.rotation_2d(angles), p)
    mapped = jax.vmap(lambda a: affine.apply_to_points(affine.rotation_2d(a), p))(angles)
    np.testing.assert_allclose(mapped, batched, rtol=1e-14)


def test_gradients_through_camera_match_finite_differences():
    point = jnp.array([0.4, -0.3, 0.7])
    target = jnp.zeros(3)

    def f(eye):
        uv, depth = affine.perspective(point, eye, target, 0.9)
        return uv[0] + 2.0 * uv[1] + 0.1 * depth

    eye = jnp.array([4.0, 1.0, 2.0])
    g = jax.jit(jax.grad(f))(eye)
    assert np.all(np.isfinite(g))
    eps = 1e-6
    fd = [(f(eye + eps * e) - f(eye - eps * e)) / (2 * eps) for e in jnp.eye(3)]
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)


def test_gradient_of_inverse_and_rotation():
    def f(theta):
        T = affine.compose(affine.translation(jnp.array([1.0, 2.0])), affine.rotation_2d(theta))
        return affine.apply_to_points(affine.inverse(T), jnp.array([0.0, 0.0]))[0]

    # inverse maps the origin to R(-θ)(-d): x = -cos θ - 2 sin θ.
    theta = 0.6
    np.testing.assert_allclose(f(theta), -np.cos(theta) - 2 * np.sin(theta), rtol=1e-14)
    np.testing.assert_allclose(jax.grad(f)(theta), np.sin(theta) - 2 * np.cos(theta), rtol=1e-12)


def test_float32_path(float32):
    T = affine.compose(
        affine.translation(jnp.array([1.0, 2.0, 3.0])),
        affine.rotation_3d_euler("ZXZ", jnp.array([0.3, 0.7, -1.1])),
    )
    assert T.dtype == jnp.float32
    p = jnp.array([[0.5, -1.0, 2.0]], dtype=jnp.float32)
    back = affine.apply_to_points(affine.inverse(T), affine.apply_to_points(T, p))
    assert back.dtype == jnp.float32
    np.testing.assert_allclose(back, p, atol=1e-5)
    np.testing.assert_allclose(
        affine.inverse_rigid(T), np.linalg.inv(np.asarray(T, np.float64)), atol=1e-5
    )
    uv, depth = affine.perspective(p, jnp.array([5.0, 5.0, 5.0]), p[0], 0.8)
    assert uv.dtype == jnp.float32 and depth.dtype == jnp.float32
    np.testing.assert_allclose(uv, 0.0, atol=1e-6)


# --------------------------------------------------------------------------- bad input


def test_wrong_shapes_raise():
    with pytest.raises(ValueError, match=r"d must have shape"):
        affine.translation(jnp.ones(4))
    with pytest.raises(ValueError, match=r"T must have shape"):
        affine.apply_to_points(jnp.eye(5), jnp.ones(4))
    with pytest.raises(ValueError, match=r"p must have shape \(\.\.\., 3\)"):
        affine.apply_to_points(jnp.eye(4), jnp.ones(2))
    with pytest.raises(ValueError, match=r"v must have shape"):
        affine.apply_to_vectors(jnp.eye(3), jnp.ones(3))
    with pytest.raises(ValueError, match="A must have shape"):
        affine.from_blocks(jnp.eye(2), jnp.ones(3))
    with pytest.raises(ValueError, match="2D and 3D"):
        affine.compose(jnp.eye(3), jnp.eye(4))
    with pytest.raises(ValueError, match="q must"):
        affine.rotation_3d(jnp.ones(3))
    with pytest.raises(ValueError, match="axis must"):
        affine.orthographic(jnp.ones(3), axis=3)
    with pytest.raises(ValueError, match="pivot"):
        affine.rotation_2d(0.3, pivot=jnp.ones(3))
    # Shape errors are raised while tracing, so also under jit.
    with pytest.raises(ValueError, match="p must"):
        jax.jit(affine.apply_to_points)(jnp.eye(4), jnp.ones(2))


def test_zero_length_look_direction_raises():
    eye = jnp.array([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="zero-length look direction"):
        affine.look_at(eye, eye)
    with pytest.raises(ValueError, match="zero-length look direction"):
        affine.perspective(jnp.zeros(3), eye, eye, 1.0)
    with pytest.raises(Exception, match="zero-length look direction"):
        jax.block_until_ready(jax.jit(affine.look_at)(eye, eye, jnp.array([0.0, 0.0, 1.0])))
    with pytest.raises(ValueError, match="parallel"):
        affine.look_at(jnp.array([0.0, 0.0, 5.0]), jnp.zeros(3))  # looking along the default up
    with pytest.raises(ValueError, match="fov"):
        affine.perspective(jnp.zeros(3), eye, jnp.zeros(3), 3.5)


@pytest.mark.parametrize("aspect", [0.0, -1.5, np.nan, np.inf])
def test_perspective_refuses_non_physical_aspect(aspect):
    eye, target = jnp.array([5.0, 4.0, 3.0]), jnp.zeros(3)
    with pytest.raises(ValueError, match="aspect"):
        affine.perspective(jnp.zeros(3), eye, target, 0.8, aspect=aspect)
    # A batch names the problem too; under jit the same check is a runtime error.
    with pytest.raises(ValueError, match="aspect"):
        affine.perspective(jnp.zeros(3), eye, target, 0.8, aspect=jnp.array([1.0, aspect]))
    run = jax.jit(lambda a: affine.perspective(jnp.zeros(3), eye, target, 0.8, aspect=a))
    with pytest.raises(Exception, match="aspect"):
        jax.block_until_ready(run(aspect))
    np.testing.assert_allclose(run(1.5)[0], 0.0, atol=1e-15)


@pytest.mark.parametrize("fov", [0.0, -0.3, np.pi, np.nan])
def test_perspective_refuses_non_physical_fov(fov):
    with pytest.raises(ValueError, match="fov"):
        affine.perspective(jnp.zeros(3), jnp.array([5.0, 4.0, 3.0]), jnp.zeros(3), fov)


@pytest.mark.parametrize("bad", ["eye", "target", "up"])
def test_look_at_refuses_non_finite_positions(bad):
    args = {"eye": jnp.array([5.0, 4.0, 3.0]), "target": jnp.zeros(3),
            "up": jnp.array([0.0, 0.0, 1.0])}
    args[bad] = args[bad].at[1].set(jnp.nan)
    # Before, a NaN eye was reported as a zero-length look direction.
    with pytest.raises(ValueError, match="must be finite"):
        affine.look_at(**args)
    with pytest.raises(ValueError, match="must be finite"):
        affine.perspective(jnp.zeros(3), args["eye"], args["target"], 0.8, up=args["up"])


@pytest.mark.parametrize("axis", [True, 1.0, "z", -1])
def test_orthographic_axis_must_be_an_integer_index(axis):
    with pytest.raises(ValueError, match="axis must be the integer 0, 1 or 2"):
        affine.orthographic(jnp.ones(3), axis=axis)
    uv, _ = affine.orthographic(jnp.array([1.0, 2.0, 3.0]), axis=np.int64(2))
    np.testing.assert_array_equal(uv, [1.0, 2.0])


@pytest.mark.parametrize(
    "call, expected",
    [
        (lambda: affine.rotation_3d(jnp.ones(5)), r"\(\.\.\., 4\)"),
        (lambda: affine.translation(jnp.ones(4)), r"\(\.\.\., 2\) or \(\.\.\., 3\)"),
        (lambda: affine.inverse(jnp.eye(5)), r"\(\.\.\., 3, 3\) or \(\.\.\., 4, 4\)"),
        (lambda: affine.apply(jnp.eye(4), jnp.ones(3)), r"\(\.\.\., 4\) to match T"),
        (lambda: affine.from_homogeneous(jnp.ones(2)), r"\(\.\.\., 3\) or \(\.\.\., 4\)"),
        (lambda: affine.look_at(jnp.ones(2), jnp.zeros(3)), r"eye must have shape \(\.\.\., 3\)"),
        (lambda: affine.rotation_3d_axis_angle(jnp.ones(4), 0.1), r"\(\.\.\., 3\)"),
        (lambda: affine.to_homogeneous(jnp.ones(4), 1.0), r"\(\.\.\., 2\) or \(\.\.\., 3\)"),
    ],
)
def test_shape_errors_name_the_expected_trailing_shape(call, expected):
    with pytest.raises(ValueError, match=expected):
        call()


def test_inverse_of_a_far_translation_or_pivot_is_exact(float32):
    """An affine matrix is singular only through its linear part: a translation (or a
    pivot) far from the origin, whose homogeneous matrix has a smallest singular value
    of about 1/|d|², is inverted exactly, in float32 too (it was refused above ~1.4e3)."""
    for T in (affine.translation(jnp.array([2000.0, 0.0, 0.0])),
              affine.rotation_2d(jnp.pi / 2, pivot=jnp.array([1500.0, 0.0])),
              affine.scaling(jnp.full(3, 1e-7))):
        inv = affine.inverse(T)
        assert inv.dtype == jnp.float32
        np.testing.assert_allclose(np.asarray(inv @ T), np.eye(T.shape[-1]), atol=1e-4)


def test_inverse_derivative_is_the_general_inverses_in_every_entry():
    """The affine matrix is inverted by blocks (Schur complement), which keeps the
    derivative along the last row: d(T⁻¹) = −T⁻¹ dT T⁻¹ for any dT, as for a projective T."""
    rng = np.random.default_rng(3)
    for T in (np.asarray(affine.from_blocks(rng.normal(size=(3, 3)), rng.normal(size=3))),
              rng.normal(size=(4, 4))):
        dT = rng.normal(size=(4, 4))
        _, tangent = jax.jvp(affine.inverse, (jnp.asarray(T),), (jnp.asarray(dT),))
        inv = np.linalg.inv(T)
        np.testing.assert_allclose(np.asarray(affine.inverse(T)), inv, atol=1e-13)
        np.testing.assert_allclose(np.asarray(tangent), -inv @ dT @ inv, atol=1e-12)


def test_python_scalars_take_the_arrays_dtype():
    f32 = jnp.float32
    assert affine.shear_2d(f32(0.2)).dtype == jnp.float32
    assert affine.shear_3d(f32(0.2)).dtype == jnp.float32
    assert affine.rotation_3d_axis_angle(jnp.ones(3, f32), 0.5).dtype == jnp.float32
    assert affine.shear_3d(0.2).dtype == jnp.float64


def test_to_homogeneous_names_a_w_of_the_wrong_shape():
    with pytest.raises(ValueError, match="w must be a scalar or of x's batch shape"):
        affine.to_homogeneous(jnp.ones(3), jnp.ones(2))
    np.testing.assert_array_equal(affine.to_homogeneous(jnp.ones((2, 3)), jnp.zeros(2)),
                                  [[1, 1, 1, 0], [1, 1, 1, 0]])


@pytest.mark.parametrize("eye, target", [
    ([5e-8, 0.0, 0.0], [0.0, 0.0, 0.0]),  # close, and near the origin
    ([1e-20, 0.0, 0.0], [0.0, 0.0, 0.0]),
    ([1e308, 0.0, 0.0], [0.0, 0.0, 0.0]),  # far: |eye|² overflows
    ([1e308, 0.0, 0.0], [-1e308, 0.0, 0.0]),  # target - eye overflows
    ([1.0, 2.0, 3.0], [1.0 + 1e-12, 2.0, 3.0]),
])
def test_look_at_any_two_distinct_points(eye, target):
    """Cameras 5e-8 (float32) or 1e-20 (float64) from their target were refused as
    "eye == target", and one at 1e308 as "`up` is parallel to the look direction"."""
    V = np.asarray(affine.look_at(jnp.asarray(eye), jnp.asarray(target)))
    d = np.asarray(target) / 2 - np.asarray(eye) / 2  # (no overflow)
    f = d / np.max(np.abs(d))
    assert np.allclose(V[2, :3], -f / np.linalg.norm(f), atol=1e-15)  # looks along -z
    R = V[:3, :3]
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-15) and np.linalg.det(R) > 0


def test_look_at_refuses_equal_points_and_perspective_names_unmatched_batches():
    with pytest.raises(ValueError, match="eye == target"):
        affine.look_at(jnp.ones(3), jnp.ones(3))
    with pytest.raises(ValueError, match=r"batch shapes of points \(5,\) and of the camera"):
        affine.perspective(jnp.zeros((5, 3)), jnp.ones((2, 3)), jnp.zeros(3), 1.0)
