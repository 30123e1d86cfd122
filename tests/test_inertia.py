"""Tests of jrigid.inertia: Table 17.1 against quadrature of 17.31, tensors, checks."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jrigid import inertia
from jrigid import quaternion as quat

BATCH_SHAPES = [(), (1,), (3, 1, 2)]


# --------------------------------------------------------------------------- quadrature


def _gauss(n, lo, hi):
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (hi - lo) * x + 0.5 * (hi + lo), 0.5 * (hi - lo) * w


def _periodic(n):
    phi = 2 * np.pi * (np.arange(n) + 0.5) / n
    return phi, np.full(n, 2 * np.pi / n)


def _grid(*rules):
    """Tensor-product rule: nodes (K, d) and weights (K,)."""
    nodes = np.meshgrid(*[r[0] for r in rules], indexing="ij")
    weights = np.meshgrid(*[r[1] for r in rules], indexing="ij")
    return np.stack([x.ravel() for x in nodes], axis=-1), np.prod([w.ravel() for w in weights], 0)


def _tensor_by_quadrature(points, weights, mass):
    """The integrals 17.31 (and the products of inertia) for a uniform density.

    ``weights`` are volume (area, length) elements; the density is mass / total measure.
    """
    rho = mass / weights.sum()
    r2 = np.sum(points**2, axis=-1)
    second = np.einsum("k,ki,kj->ij", weights, points, points)
    return rho * (np.sum(weights * r2) * np.eye(3) - second)


def _solid_ellipsoid(a, b, c):
    (r, wr), (t, wt), (p, wp) = _gauss(12, 0, 1), _gauss(24, 0, np.pi), _periodic(24)
    nodes, w = _grid((r, wr), (t, wt), (p, wp))
    r, t, p = nodes.T
    pts = np.stack(
        [a * r * np.sin(t) * np.cos(p), b * r * np.sin(t) * np.sin(p), c * r * np.cos(t)]
    )
    return pts.T, w * a * b * c * r**2 * np.sin(t)


def _solid_box(a, b, c):
    return _grid(_gauss(6, -a / 2, a / 2), _gauss(6, -b / 2, b / 2), _gauss(6, -c / 2, c / 2))


def _solid_cylinder(r, h):
    nodes, w = _grid(_gauss(12, 0, r), _periodic(24), _gauss(6, -h / 2, h / 2))
    s, p, z = nodes.T
    return np.stack([s * np.cos(p), s * np.sin(p), z], -1), w * s


def _flat_disk(r):
    nodes, w = _grid(_gauss(12, 0, r), _periodic(24))
    s, p = nodes.T
    return np.stack([s * np.cos(p), s * np.sin(p), 0 * s], -1), w * s


def _flat_plate(a, b):
    nodes, w = _grid(_gauss(6, -a / 2, a / 2), _gauss(6, -b / 2, b / 2))
    return np.concatenate([nodes, np.zeros((len(w), 1))], -1), w


def _line_z(length):
    z, w = _gauss(6, -length / 2, length / 2)
    return np.stack([0 * z, 0 * z, z], -1), w


def _midpoint_box(a, b, c, n=60):
    """Independent second rule for the box: a plain Cartesian midpoint grid."""
    axes = [(np.arange(n) + 0.5) / n * s - s / 2 for s in (a, b, c)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    return pts, np.full(len(pts), a * b * c / n**3)


M = 2.3
SHAPES = [
    ("ellipsoid", lambda: inertia.ellipsoid(M, 0.7, 1.3, 0.4), _solid_ellipsoid(0.7, 1.3, 0.4)),
    ("sphere", lambda: inertia.sphere(M, 0.9), _solid_ellipsoid(0.9, 0.9, 0.9)),
    ("box", lambda: inertia.box(M, 0.5, 1.7, 1.1), _solid_box(0.5, 1.7, 1.1)),
    ("box-midpoint", lambda: inertia.box(M, 0.5, 1.7, 1.1), _midpoint_box(0.5, 1.7, 1.1)),
    ("solid_cylinder", lambda: inertia.solid_cylinder(M, 0.6, 1.9), _solid_cylinder(0.6, 1.9)),
    ("disk", lambda: inertia.disk(M, 1.2, 0.15), _solid_cylinder(1.2, 0.15)),
    ("thin_disk", lambda: inertia.thin_disk(M, 0.8), _flat_disk(0.8)),
    ("thin_plate", lambda: inertia.thin_plate(M, 0.9, 2.1), _flat_plate(0.9, 2.1)),
    ("thin_rod", lambda: inertia.thin_rod(M, 1.7), _line_z(1.7)),
]


@pytest.mark.parametrize("name,formula,rule", SHAPES, ids=[s[0] for s in SHAPES])
def test_table_17_1_against_quadrature_of_17_31(name, formula, rule):
    points, weights = rule
    expected = _tensor_by_quadrature(points, weights, M)
    moments = np.asarray(formula())
    assert moments.shape == (3,)
    # The body axes are principal: products of inertia vanish.
    scale = np.abs(expected).max()
    np.testing.assert_allclose(expected - np.diag(np.diag(expected)), 0, atol=1e-10 * scale)
    rtol = 1e-3 if name == "box-midpoint" else 1e-9
    np.testing.assert_allclose(moments, np.diag(expected), rtol=rtol, atol=1e-12)


def test_thin_plate_normal_moment_is_a2_plus_b2_over_12():
    # Table 17.1 prints m(a²+b²)/2; the perpendicular-axis theorem says I3 = I1 + I2.
    a, b = 0.9, 2.1
    i = np.asarray(inertia.thin_plate(M, a, b))
    np.testing.assert_allclose(i[2], M * (a * a + b * b) / 12, rtol=1e-14)
    np.testing.assert_allclose(i[2], i[0] + i[1], rtol=1e-14)


def test_disk_equals_cylinder_and_tends_to_thin_disk():
    np.testing.assert_array_equal(
        inertia.disk(1.5, 0.7, 0.2), inertia.solid_cylinder(1.5, 0.7, 0.2)
    )
    np.testing.assert_allclose(
        inertia.disk(1.5, 0.7, 1e-6), inertia.thin_disk(1.5, 0.7), rtol=1e-10
    )


@pytest.mark.parametrize("batch", BATCH_SHAPES)
def test_shape_functions_broadcast(batch):
    rng = np.random.default_rng(0)
    m = rng.uniform(1, 2, batch)
    a = rng.uniform(0.5, 1.0, batch[-1:])  # lower rank: broadcasts against m
    for out in (
        inertia.ellipsoid(m, a, 1.0, 2.0),
        inertia.box(m, a, 1.0, 2.0),
        inertia.sphere(m, a),
        inertia.thin_rod(m, a),
        inertia.thin_disk(m, a),
        inertia.thin_plate(m, a, 1.0),
        inertia.solid_cylinder(m, a, 1.0),
        inertia.disk(m, a, 0.1),
    ):
        assert out.shape == batch + (3,)
    np.testing.assert_allclose(
        inertia.sphere(m, a)[..., 1], 0.4 * m * np.broadcast_to(a, batch) ** 2, rtol=1e-14
    )


# --------------------------------------------------------------------------- point masses


def test_from_point_masses_matches_explicit_sum():
    rng = np.random.default_rng(1)
    m = rng.uniform(0.5, 2, 7)
    r = rng.normal(size=(7, 3))
    o = rng.normal(size=3)
    expected = np.zeros((3, 3))
    for mk, rk in zip(m, r - o, strict=True):
        expected += mk * (rk @ rk * np.eye(3) - np.outer(rk, rk))
    np.testing.assert_allclose(inertia.from_point_masses(m, r, o), expected, rtol=1e-13)
    # Diagonal entries are the sums of 17.31a-c.
    d = r - o
    np.testing.assert_allclose(
        np.diag(inertia.from_point_masses(m, r, o))[0], np.sum(m * (d[:, 1] ** 2 + d[:, 2] ** 2))
    )


def test_from_point_masses_default_origin_is_centre_of_mass():
    rng = np.random.default_rng(2)
    m = rng.uniform(0.5, 2, 6)
    r = rng.normal(size=(6, 3))
    cm = (m[:, None] * r).sum(0) / m.sum()
    np.testing.assert_allclose(
        inertia.from_point_masses(m, r), inertia.from_point_masses(m, r, cm), rtol=1e-13
    )
    # Translating the body does not change its centre-of-mass tensor.
    np.testing.assert_allclose(
        inertia.from_point_masses(m, r + np.array([3.0, -1.0, 2.0])),
        inertia.from_point_masses(m, r),
        atol=1e-12,
    )


def _methane():
    """CH4 after Problem 17.1: C at the origin, unit H-H distance."""
    h = np.sqrt(1 - 4 * np.cos(np.pi / 6) ** 2 / 9)
    rho = np.sqrt(1 / 3)  # circumradius of the unit equilateral base
    base = [(rho * np.cos(t), rho * np.sin(t), -0.25 * h) for t in 2 * np.pi * np.arange(3) / 3]
    return np.array([(0, 0, 0), (0, 0, 0.75 * h), *base])


def test_methane_is_isotropic_with_tetrahedral_angle():
    pos = _methane()
    hyd = pos[1:]
    dists = [np.linalg.norm(hyd[i] - hyd[j]) for i in range(4) for j in range(i)]
    np.testing.assert_allclose(dists, 1.0, rtol=1e-14)
    m_c, m_h = 12.011, 1.008
    masses = np.array([m_c, m_h, m_h, m_h, m_h])
    tensor = np.asarray(inertia.from_point_masses(masses, pos))
    # Four atoms at distance R from the centre: I = (8/3) m_H R² = m_H for R² = 3/8.
    np.testing.assert_allclose(tensor, m_h * np.eye(3), atol=1e-13)
    moments, _ = inertia.principal_axes(tensor)
    np.testing.assert_allclose(moments, m_h, rtol=1e-13)
    u = hyd / np.linalg.norm(hyd, axis=-1, keepdims=True)
    angles = [np.arccos(u[i] @ u[j]) for i in range(4) for j in range(i)]
    np.testing.assert_allclose(angles, np.arccos(-1 / 3), rtol=1e-13)
    np.testing.assert_allclose(np.degrees(angles[0]), 109.4712206, rtol=1e-9)


def test_parallel_axis_against_point_masses():
    rng = np.random.default_rng(3)
    m = rng.uniform(0.5, 2, 9)
    r = rng.normal(size=(9, 3))
    cm = (m[:, None] * r).sum(0) / m.sum()
    d = np.array([0.4, -1.3, 2.2])
    shifted = inertia.parallel_axis(inertia.from_point_masses(m, r), m.sum(), d)
    np.testing.assert_allclose(shifted, inertia.from_point_masses(m, r, cm + d), rtol=1e-12)
    np.testing.assert_allclose(shifted, inertia.from_point_masses(m, r, cm - d), rtol=1e-12)


def test_parallel_axis_rod_about_its_end():
    # A rod about an end: m l² / 3 (independent textbook value).
    rod = inertia.to_tensor(inertia.thin_rod(2.0, 3.0))
    shifted = inertia.parallel_axis(rod, 2.0, jnp.array([0.0, 0.0, 1.5]))
    np.testing.assert_allclose(np.diag(shifted), [6.0, 6.0, 0.0], atol=1e-14)


@pytest.mark.parametrize("batch", BATCH_SHAPES)
def test_point_masses_and_parallel_axis_batch(batch):
    rng = np.random.default_rng(4)
    m = rng.uniform(0.5, 2, batch + (5,))
    r = rng.normal(size=(5, 3))  # shared positions broadcast against the mass batch
    out = inertia.from_point_masses(m, r)
    assert out.shape == batch + (3, 3)
    d = rng.normal(size=(3,))
    assert inertia.parallel_axis(out, m.sum(-1), d).shape == batch + (3, 3)
    # One tensor shifted to several points: the displacement batch broadcasts.
    ds = rng.normal(size=batch + (3,))
    shifted = inertia.parallel_axis(inertia.from_point_masses(m[(0,) * len(batch)], r), 2.0, ds)
    assert shifted.shape == batch + (3, 3)
    for idx in np.ndindex(*batch):
        np.testing.assert_allclose(out[idx], inertia.from_point_masses(m[idx], r), rtol=1e-12)


# --------------------------------------------------------------------------- frames


def _random_tensor(rng, moments=None):
    moments = rng.uniform(1, 3, 3) if moments is None else np.asarray(moments, float)
    R = Rotation.random(random_state=rng).as_matrix()
    return R @ np.diag(moments) @ R.T


@pytest.mark.parametrize("seed", range(5))
def test_principal_axes_matches_numpy_eigh(seed):
    rng = np.random.default_rng(seed)
    tensor = _random_tensor(rng)
    moments, q = inertia.principal_axes(tensor)
    R = np.asarray(quat.to_matrix(q))
    w, V = np.linalg.eigh(tensor)
    np.testing.assert_allclose(moments, w, rtol=1e-12)
    assert np.all(np.diff(moments) >= 0)
    np.testing.assert_allclose(np.abs(np.sum(R * V, axis=0)), 1.0, rtol=1e-10)  # up to sign
    np.testing.assert_allclose(np.linalg.det(R), 1.0, rtol=1e-12)  # right-handed
    np.testing.assert_allclose(R @ np.diag(moments) @ R.T, tensor, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(q), 1.0, rtol=1e-12)


@pytest.mark.parametrize(
    "moments", [(1.0, 1.0, 2.0), (1.0, 2.0, 2.0), (1.5, 1.5, 1.5)], ids=["oblate", "prolate", "iso"]
)
def test_principal_axes_degenerate(moments):
    rng = np.random.default_rng(7)
    tensor = _random_tensor(rng, moments)
    w, q = inertia.principal_axes(tensor)
    R = np.asarray(quat.to_matrix(q))
    np.testing.assert_allclose(w, sorted(moments), rtol=1e-12)
    np.testing.assert_allclose(R @ np.diag(w) @ R.T, tensor, atol=1e-12)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, rtol=1e-12)
    # Moments stay differentiable at the degeneracy: dλ summed = trace derivative = 1.
    g = jax.grad(lambda t: jnp.sum(inertia.principal_axes(t)[0]))(jnp.asarray(tensor))
    np.testing.assert_allclose(g, np.eye(3), atol=1e-12)


def test_principal_axes_gradients_match_finite_differences():
    rng = np.random.default_rng(8)
    tensor = _random_tensor(rng, (1.0, 1.7, 2.9))
    sym = rng.normal(size=(3, 3))
    direction = sym + sym.T
    c = rng.normal(size=3)

    def f(t):
        w, q = inertia.principal_axes(t)
        axis3 = quat.to_matrix(q)[:, 2]
        return jnp.dot(w, jnp.array([0.3, -1.1, 0.7])) + jnp.dot(axis3, jnp.asarray(c)) ** 2

    g = jax.grad(f)(jnp.asarray(tensor))
    eps = 1e-6
    fd = (f(tensor + eps * direction) - f(tensor - eps * direction)) / (2 * eps)
    np.testing.assert_allclose(np.sum(g * direction), fd, rtol=1e-6)


@pytest.mark.parametrize("moments", [(1.0, 1.0, 2.0), (1.0, 2.0, 2.0)], ids=["oblate", "prolate"])
def test_principal_axes_frame_gradient_at_repeated_moments(moments):
    """The distinct axis is a smooth function of the tensor even where the other two tie:
    its gradient is finite and matches finite differences (eigh's own rule divides by the
    rounding-level gap of the tied pair: NaN or noise)."""
    rng = np.random.default_rng(11)
    tensor = _random_tensor(rng, moments)
    distinct = 2 if moments[0] == moments[1] else 0
    sym = rng.normal(size=(3, 3))
    direction = sym + sym.T
    c = rng.normal(size=3)

    def f(t):
        _, q = inertia.principal_axes(t)
        return jnp.dot(quat.to_matrix(q)[:, distinct], jnp.asarray(c)) ** 2

    g = jax.grad(f)(jnp.asarray(tensor))
    assert np.all(np.isfinite(g))
    eps = 1e-6
    fd = (f(tensor + eps * direction) - f(tensor - eps * direction)) / (2 * eps)
    np.testing.assert_allclose(np.sum(g * direction), fd, rtol=1e-6)


@pytest.mark.parametrize("batch", BATCH_SHAPES)
def test_principal_axes_batch(batch):
    rng = np.random.default_rng(9)
    tensors = np.stack([_random_tensor(rng) for _ in range(int(np.prod(batch)))])
    tensors = tensors.reshape(batch + (3, 3))
    w, q = jax.jit(inertia.principal_axes)(tensors)
    assert w.shape == batch + (3,) and q.shape == batch + (4,)
    R = np.asarray(quat.to_matrix(q))
    rebuilt = np.einsum("...ij,...j,...kj->...ik", R, w, R)
    np.testing.assert_allclose(rebuilt, tensors, atol=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_rotate_tensor_preserves_spectrum_and_angular_momentum(seed):
    rng = np.random.default_rng(seed)
    moments = inertia.box(1.3, 0.4, 1.0, 2.2)
    body = inertia.to_tensor(moments)
    rot = Rotation.random(random_state=rng)
    q = jnp.asarray(rot.as_quat(scalar_first=True))
    space = inertia.rotate_tensor(body, q)
    R = rot.as_matrix()
    np.testing.assert_allclose(space, R @ np.diag(moments) @ R.T, atol=1e-14)
    np.testing.assert_allclose(np.linalg.eigvalsh(space), np.sort(moments), rtol=1e-12)
    np.testing.assert_allclose(inertia.rotate_tensor_by_matrix(body, R), space, atol=1e-14)
    # L = I ω: same magnitude in both frames, and L_space = R L_body (17.30b, Exercise 17.11).
    omega_body = rng.normal(size=3)
    L_body = np.asarray(body) @ omega_body
    L_space = np.asarray(space) @ (R @ omega_body)
    np.testing.assert_allclose(np.linalg.norm(L_space), np.linalg.norm(L_body), rtol=1e-13)
    np.testing.assert_allclose(L_space, R @ L_body, atol=1e-13)
    # Back to the body frame with the conjugate.
    np.testing.assert_allclose(inertia.rotate_tensor(space, quat.conjugate(q)), body, atol=1e-14)


def test_rotate_tensor_batch_and_vmap():
    rng = np.random.default_rng(11)
    q = Rotation.random(6, random_state=rng).as_quat(scalar_first=True).reshape(2, 3, 4)
    body = inertia.to_tensor(inertia.ellipsoid(1.0, 1.0, 2.0, 3.0))
    out = inertia.rotate_tensor(body, q)
    assert out.shape == (2, 3, 3, 3)
    via_vmap = jax.vmap(jax.vmap(inertia.rotate_tensor, (None, 0)), (None, 0))(body, q)
    np.testing.assert_allclose(out, via_vmap, atol=1e-14)


def test_to_tensor():
    np.testing.assert_array_equal(inertia.to_tensor(jnp.array([1.0, 2.0, 3.0])), np.diag([1, 2, 3]))
    assert inertia.to_tensor(jnp.ones((4, 2, 3))).shape == (4, 2, 3, 3)


# --------------------------------------------------------------------------- validation


HLW = (2.0, 1.0, 2.0 / 3.0)


def test_validate_accepts_physical_bodies():
    for moments in (inertia.box(1, 1, 2, 3), inertia.thin_plate(1, 1, 2), inertia.thin_disk(1, 1)):
        np.testing.assert_array_equal(inertia.validate(moments), moments)
    # A flat body meets the triangle inequality with equality, also after rotation.
    q = Rotation.from_euler("xyz", [0.3, 1.1, -0.4]).as_quat(scalar_first=True)
    plate = inertia.rotate_tensor(inertia.to_tensor(inertia.thin_plate(1.0, 1.0, 3.0)), q)
    inertia.validate(plate)


def test_validate_hairer_lubich_wanner_body_needs_flag():
    with pytest.raises(ValueError, match=r"triangle inequality.*0\.66"):
        inertia.validate(jnp.array(HLW))
    inertia.validate(jnp.array(HLW), allow_nonphysical=True)


@pytest.mark.parametrize(
    "value,match",
    [
        (jnp.array([1.0, jnp.nan, 1.0]), "finite"),
        (jnp.array([1.0, jnp.inf, 1.0]), "finite"),
        (jnp.array([[2.0, 0.1, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]]), "symmetric"),
        (jnp.array([1.0, 2.0, -0.5]), "positive definite"),
        (jnp.array([1.0, 1.0, 0.0]), "positive definite"),  # the thin rod
        (jnp.diag(jnp.array([1.0, 1.0, 2.5])), "triangle"),
    ],
    ids=["nan", "inf", "asymmetric", "negative", "rod", "triangle-tensor"],
)
def test_validate_names_the_condition(value, match):
    with pytest.raises(ValueError, match=match):
        inertia.validate(value)
    with pytest.raises(Exception, match=match):
        jax.block_until_ready(jax.jit(inertia.check)(value))


def test_validate_nonphysical_flag_does_not_skip_other_checks():
    with pytest.raises(ValueError, match="positive definite"):
        inertia.validate(jnp.array([2.0, 1.0, -1.0]), allow_nonphysical=True)


def test_validate_reports_batch_index_and_values():
    batch = jnp.stack([jnp.array([1.0, 1.0, 1.0]), jnp.array(HLW), jnp.array([1.0, 2.0, 2.5])])
    with pytest.raises(ValueError, match=r"batch index \(1,\).*2\.") as info:
        inertia.validate(batch, kind="moments")
    assert "triangle" in str(info.value)


def test_validate_kind_and_shapes():
    three = jnp.array([[1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [3.0, 3.0, 3.0]])
    with pytest.raises(ValueError, match="symmetric"):
        inertia.validate(three)  # read as a (non-symmetric) tensor
    inertia.validate(three, kind="moments")  # three isotropic bodies
    with pytest.raises(ValueError, match="shape"):
        inertia.validate(jnp.ones(4))
    with pytest.raises(ValueError, match="kind"):
        inertia.validate(jnp.ones(3), kind="vector")


def test_check_is_jit_safe():
    good = jnp.array([1.0, 1.5, 2.0])
    f = jax.jit(lambda i: inertia.check(i) * 2.0)
    np.testing.assert_allclose(f(good), 2 * good)
    with pytest.raises(Exception, match="triangle"):
        jax.block_until_ready(f(jnp.array(HLW)))
    g = jax.jit(lambda i: inertia.check(i, allow_nonphysical=True))
    np.testing.assert_allclose(g(jnp.array(HLW)), HLW)
    # validate under jit defers to check
    with pytest.raises(Exception, match="positive definite"):
        jax.block_until_ready(eqx.filter_jit(inertia.validate)(jnp.array([1.0, 1.0, -1.0])))
    # vmap: a batch with one bad member fails
    with pytest.raises(Exception, match="triangle"):
        jax.block_until_ready(jax.vmap(inertia.check)(jnp.stack([good, jnp.array(HLW)])))


def test_bad_shapes_raise():
    with pytest.raises(ValueError, match="to_tensor"):
        inertia.rotate_tensor(jnp.ones(3), quat.identity())
    with pytest.raises(ValueError, match="q must"):
        inertia.rotate_tensor(jnp.eye(3), jnp.ones(3))
    with pytest.raises(ValueError, match="masses"):
        inertia.from_point_masses(jnp.ones(4), jnp.ones((5, 3)))
    with pytest.raises(ValueError, match="positions"):
        inertia.from_point_masses(jnp.ones(4), jnp.ones((4, 2)))
    with pytest.raises(ValueError, match="d must"):
        inertia.parallel_axis(jnp.eye(3), 1.0, jnp.ones(2))
    with pytest.raises(ValueError, match="shape"):
        inertia.principal_axes(jnp.ones((2, 3)))


# --------------------------------------------------------------------------- float32


def test_float32_path(float32):
    moments = inertia.thin_plate(1.0, 1.0, 3.0)
    assert moments.dtype == jnp.float32
    q = jnp.asarray(Rotation.from_euler("xyz", [0.3, 1.1, -0.4]).as_quat(scalar_first=True))
    plate = inertia.rotate_tensor(inertia.to_tensor(moments), q.astype(jnp.float32))
    assert plate.dtype == jnp.float32
    inertia.validate(plate)  # equality case survives float32 rounding
    w, q2 = inertia.principal_axes(plate)
    assert w.dtype == jnp.float32 and q2.dtype == jnp.float32
    np.testing.assert_allclose(w, np.sort(np.asarray(moments)), rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="triangle"):
        inertia.validate(jnp.array(HLW, dtype=jnp.float32))


# --------------------------------------------------------------------------- scale-free checks


@pytest.mark.parametrize(
    "moments",
    [(1e-12, 1e12, 1e12), (1e12, 1e-12, 1e12), (3e-9, 2.0, 2.0), (1e-200, 1e200, 1e200)],
)
def test_needles_of_any_aspect_ratio_are_physical(moments):
    """Positive definiteness does not compare the smallest moment with the largest.

    A needle of length L and radius r has moments (m r²/2, m L²/12, m L²/12): its ratio
    is unbounded, and the old test ``lo > 3 eps hi`` refused it below r/L ≈ 1e-8.
    """
    m = jnp.array(moments)
    np.testing.assert_array_equal(inertia.validate(m), m)
    inertia.validate(inertia.to_tensor(m))  # diagonal tensor: exact eigenvalues
    jax.block_until_ready(jax.jit(inertia.check)(m))
    # A solid cylinder that thin, built from its dimensions, passes too.
    inertia.validate(inertia.solid_cylinder(1.0, 1e-9, 1.0))


def test_positive_definiteness_of_a_tensor_ignores_the_units_of_each_axis():
    """diag(s) I diag(s) is positive definite exactly when I is: the verdict is unchanged."""
    rng = np.random.default_rng(4)
    q = Rotation.random(random_state=rng).as_quat(scalar_first=True)
    tensor = inertia.rotate_tensor(inertia.to_tensor(jnp.array([1.0, 1.5, 2.0])), q)
    for s in ([1e-6, 1.0, 1e6], [1e5, 1e5, 1e-5]):
        scaled = jnp.diag(jnp.array(s)) @ tensor @ jnp.diag(jnp.array(s))
        inertia.validate(scaled, allow_nonphysical=True)
    # Still refused: a semi-definite (rod) tensor after a rotation, and negative moments.
    rod = inertia.rotate_tensor(inertia.to_tensor(inertia.thin_rod(1.0, 2.0)), q)
    with pytest.raises(ValueError, match="positive definite"):
        inertia.validate(rod)
    with pytest.raises(ValueError, match="positive definite"):
        inertia.validate(jnp.diag(jnp.array([1.0, -1e-30, 1.0])), allow_nonphysical=True)


def test_non_symmetric_tensor_is_reported_as_non_symmetric_only():
    """Each element is reported under its first failed condition (its symmetric part here
    is also indefinite), in validate, under jit and in a batch."""
    bad = jnp.array([[1.0, 0.0, 0.0], [3.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    assert np.linalg.eigvalsh(0.5 * (bad + bad.T))[0] < 0
    with pytest.raises(ValueError, match="not symmetric"):
        inertia.validate(bad)
    with pytest.raises(Exception, match="not symmetric") as info:
        jax.block_until_ready(eqx.filter_jit(inertia.check)(bad))
    assert "positive definite" not in str(info.value)
    batch = jnp.stack([jnp.eye(3), bad])
    with pytest.raises(ValueError, match=r"not symmetric at batch index \(1,\)"):
        inertia.validate(batch)
    with pytest.raises(Exception, match="not symmetric"):
        jax.block_until_ready(jax.vmap(inertia.check)(batch))


# --------------------------------------------------------------------------- shape functions


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: inertia.box(-1.0, 1.0, 1.0, 1.0), "mass must be finite and > 0"),
        (lambda: inertia.box(0.0, 1.0, 1.0, 1.0), "mass must be finite and > 0"),
        (lambda: inertia.box(1.0, 1.0, -2.0, 1.0), "b must be finite and >= 0"),
        (lambda: inertia.sphere(jnp.nan, 1.0), "mass must be finite"),
        (lambda: inertia.sphere(1.0, jnp.inf), "r must be finite"),
        (lambda: inertia.ellipsoid(1.0, 1.0, 1.0, -1.0), "c must be"),
        (lambda: inertia.thin_rod(1.0, -2.0), "length must be"),
        (lambda: inertia.thin_disk(jnp.array([1.0, -1.0]), 1.0), "mass must be"),
        (lambda: inertia.thin_plate(1.0, -1.0, 1.0), "a must be"),
        (lambda: inertia.solid_cylinder(1.0, 1.0, -1.0), "h must be"),
        (lambda: inertia.disk(-1.0, 1.0, 0.1), "mass must be"),
        (lambda: inertia.parallel_axis(jnp.eye(3), -2.0, jnp.ones(3)), "mass must be"),
        (lambda: inertia.from_point_masses(jnp.array([1.0, -1.0]), jnp.ones((2, 3))), "masses"),
        (lambda: inertia.from_point_masses(jnp.zeros(2), jnp.ones((2, 3))), "all be zero"),
        (lambda: inertia.from_point_masses(jnp.ones(2), jnp.full((2, 3), jnp.nan)), "positions"),
    ],
)
def test_shapes_refuse_non_physical_mass_and_sizes(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_shape_function_checks_run_under_jit():
    f = jax.jit(inertia.box)
    np.testing.assert_allclose(f(12.0, 1.0, 2.0, 3.0), [13.0, 10.0, 5.0])
    with pytest.raises(Exception, match="mass must be finite and > 0"):
        jax.block_until_ready(f(-12.0, 1.0, 2.0, 3.0))


@pytest.mark.parametrize(
    "call, expected",
    [
        (lambda: inertia.to_tensor(jnp.ones(4)), r"moments must have shape \(\.\.\., 3\)"),
        (lambda: inertia.validate(jnp.ones((3, 4))), r"\(\.\.\., 3\)"),
        (lambda: inertia.rotate_tensor_by_matrix(jnp.eye(3), jnp.eye(4)),
         r"R must have shape \(\.\.\., 3, 3\)"),
        (lambda: inertia.principal_axes(jnp.ones((2, 3))), r"\(\.\.\., 3, 3\).*to_tensor"),
        (lambda: inertia.rotate_tensor(jnp.eye(3), jnp.ones(5)), r"\(\.\.\., 4\)"),
        (lambda: inertia.parallel_axis(jnp.ones(3), 1.0, jnp.ones(3)), r"I_cm must have shape"),
        (lambda: inertia.from_point_masses(jnp.ones(3), jnp.ones(3)), r"\(\.\.\., N, 3\)"),
        (lambda: inertia.from_point_masses(jnp.ones(3), jnp.ones((3, 3)), jnp.ones(2)),
         r"origin must have shape \(\.\.\., 3\)"),
    ],
)
def test_shape_errors_name_the_expected_trailing_shape(call, expected):
    with pytest.raises(ValueError, match=expected):
        call()


def test_python_scalars_take_the_arrays_dtype():
    f32 = jnp.float32
    assert inertia.sphere(f32(1.0), 2.0).dtype == jnp.float32
    assert inertia.t_handle_moments(f32(1.0)).dtype == jnp.float32
    assert inertia.parallel_axis(inertia.to_tensor(jnp.ones(3, f32)), 1.0,
                                 jnp.ones(3, f32)).dtype == jnp.float32
    assert inertia.t_handle_moments(1.0).dtype == jnp.float64


def test_tensor_helpers_refuse_a_non_finite_origin_and_a_matrix_that_is_no_rotation():
    masses, positions = jnp.ones(2), jnp.eye(3)[:2]
    with pytest.raises(ValueError, match="origin must be finite"):
        inertia.from_point_masses(masses, positions, origin=jnp.array([jnp.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="R must be a rotation matrix"):
        inertia.rotate_tensor_by_matrix(jnp.eye(3), 2.0 * jnp.eye(3))
    # a rotation passes, and agrees with the quaternion form
    q = quat.normalize(jnp.array([1.0, 2.0, 3.0, 4.0]))
    tensor = jnp.diag(jnp.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(inertia.rotate_tensor_by_matrix(tensor, quat.to_matrix(q)),
                               inertia.rotate_tensor(tensor, q), atol=1e-14)
