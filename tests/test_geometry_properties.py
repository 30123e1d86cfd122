"""Property-based checks of every public function of jrigid.quaternion, .affine and .inertia.

Each case draws a batch shape and, per argument, a kind of input: valid values (random
floats, integers, tiny and huge norms, exact 180° turns), zero, NaN/inf, or a wrong
trailing shape. The function must then either return the right result, checked against
scipy's ``Rotation`` where it applies and otherwise against an independent numpy formula
or an invariant (unit norm, orthogonality, round trip, scaling law), or raise the
``ValueError`` its docstring promises. Non-finite input must give a non-finite output in
every affected element (or a ``ValueError``), never a plausible number.

No jit here: every new shape would compile, and eager calls already run the same code.
"""

import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from scipy.spatial.transform import Rotation, Slerp

import jrigid.quaternion as jq
from jrigid import affine, inertia

SETTINGS = settings(
    max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
SEEDS = st.integers(0, 2**32 - 1)
BATCHES = st.sampled_from([(), (1,), (3, 1, 2)])  # as in the other geometry tests
Q_VALID = ("unit", "scaled", "int", "half_turn")
Q_KINDS = (*Q_VALID, "zero", "nonfinite", "wrong_shape")
SEQS = jq.EULER_SEQUENCES


# --------------------------------------------------------------------------- drawing inputs


def _rng(data, label):
    return np.random.default_rng(data.draw(SEEDS, label=f"{label} seed"))


def _unit_rows(rng, shape):
    x = rng.normal(size=shape)
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _poison(rng, x):
    """Put NaN, inf or -inf into one entry of every element (last axis) of ``x``."""
    x = np.array(x, dtype=float)
    flat = x.reshape(-1, x.shape[-1])
    for row in flat:
        row[rng.integers(row.size)] = rng.choice([np.nan, np.inf, -np.inf])
    return flat.reshape(x.shape)


def draw_quat(data, batch, kinds=Q_KINDS, label="q", max_exp=300):
    """``(q, kind)``: a ``batch + (4,)`` quaternion of the drawn kind."""
    kind = data.draw(st.sampled_from(kinds), label=f"{label} kind")
    rng = _rng(data, label)
    if kind == "wrong_shape":
        n = data.draw(st.sampled_from([1, 2, 3, 5, 8]), label=f"{label} trailing")
        return rng.normal(size=batch + (n,)), kind
    u = _unit_rows(rng, batch + (4,))
    if kind == "scaled":
        return u * 10.0 ** rng.uniform(-max_exp, max_exp, size=batch + (1,)), kind
    if kind == "int":
        q = rng.integers(-3, 4, size=batch + (4,))
        q[..., 0] = np.where(np.all(q == 0, axis=-1), 1, q[..., 0])
        return q, kind
    if kind == "half_turn":
        u[..., 0] = rng.choice([0.0, -0.0])
        return u / np.linalg.norm(u, axis=-1, keepdims=True), kind
    if kind == "zero":
        return np.zeros(batch + (4,)), kind
    if kind == "nonfinite":
        return _poison(rng, u), kind
    return u, kind


def draw_vec(data, batch, n=3, label="v", kinds=("float", "int"), max_exp=0, wrong=None):
    """``(v, kind)`` of shape ``batch + (n,)``; kinds as for quaternions."""
    kind = data.draw(st.sampled_from(kinds), label=f"{label} kind")
    rng = _rng(data, label)
    if kind == "wrong_shape":
        wrong = [k for k in (1, 2, 3, 4, 5) if k != n] if wrong is None else wrong
        m = data.draw(st.sampled_from(wrong), label=f"{label} trailing")
        return rng.normal(size=batch + (m,)), kind
    if kind == "int":
        v = rng.integers(-3, 4, size=batch + (n,))
        v[..., 0] = np.where(np.all(v == 0, axis=-1), 1, v[..., 0])
        return v, kind
    if kind == "zero":
        return np.zeros(batch + (n,)), kind
    v = rng.normal(size=batch + (n,))
    if kind == "scaled":
        v = v * 10.0 ** rng.uniform(-max_exp, max_exp, size=batch + (1,))
    if kind == "nonfinite":
        v = _poison(rng, v)
    return v, kind


def unit_np(q):
    """Independent, overflow-free normalisation in numpy."""
    q = np.asarray(q, dtype=float)
    m = np.max(np.abs(q), axis=-1, keepdims=True)
    q = q / m
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def norm_np(q):
    q = np.asarray(q, dtype=float)
    m = np.max(np.abs(q), axis=-1)
    return m * np.linalg.norm(q / m[..., None], axis=-1)


def rot(q):
    return Rotation.from_quat(unit_np(q).reshape(-1, 4), scalar_first=True)


def hamilton_np(p, q):
    """``p ⊗ q`` as the left-multiplication matrix of ``p`` applied to ``q``."""
    w, x, y, z = np.moveaxis(np.asarray(p, dtype=float), -1, 0)
    left = np.stack(
        [np.stack(r, axis=-1) for r in (
            (w, -x, -y, -z), (x, w, -z, y), (y, z, w, -x), (z, -y, x, w))],
        axis=-2,
    )
    return (left @ np.asarray(q, dtype=float)[..., None])[..., 0]


def same_rotation(a, b, atol=1e-12):
    a, b = np.reshape(a, (-1, 4)), np.reshape(b, (-1, 4))
    d = np.minimum(np.abs(a - b).max(-1), np.abs(a + b).max(-1))
    assert np.all(d <= atol), d.max()


def each_element_non_finite(out, batch):
    """Every batch element of every output has a non-finite entry."""
    size = int(np.prod(batch, dtype=int))
    leaves = out if isinstance(out, tuple) else (out,)
    bad = np.zeros(size, dtype=bool)
    for leaf in leaves:
        leaf = np.asarray(leaf)
        bad |= ~np.all(np.isfinite(leaf.reshape(size, -1)), axis=1)
    assert bad.all(), "a non-finite input gave a finite output"


def raises_shape_error(call, expected):
    with pytest.raises(ValueError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        call()


CASES = {}  # "module.function" -> check(name, data, batch)


def case(module, *names):
    def register(f):
        for name in names:
            CASES[f"{module.__name__.rsplit('.', 1)[-1]}.{name}"] = f
        return f

    return register


# --------------------------------------------------------------------------- quaternion: one q


@case(jq, "normalize", "norm", "inverse", "conjugate", "canonicalize", "to_xyzw", "from_xyzw")
def _algebra_one(name, data, batch):
    q, kind = draw_quat(data, batch)
    f = getattr(jq, name)
    if kind == "wrong_shape":
        return raises_shape_error(lambda: f(q), "(..., 4)")
    out = np.asarray(f(q))
    if kind == "nonfinite":
        return each_element_non_finite(out, batch)
    qf = np.asarray(q, dtype=float)
    if name == "conjugate":
        np.testing.assert_array_equal(out, qf * [1, -1, -1, -1])
    elif name == "to_xyzw":
        np.testing.assert_array_equal(out, qf[..., [1, 2, 3, 0]])
    elif name == "from_xyzw":
        np.testing.assert_array_equal(out, qf[..., [3, 0, 1, 2]])
    elif kind == "zero":
        expected = {"norm": 0.0, "canonicalize": 0.0}.get(name, np.nan)
        np.testing.assert_array_equal(out, np.full(out.shape, expected))
    elif name == "normalize":
        np.testing.assert_allclose(out, unit_np(q), rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, rtol=1e-14)
    elif name == "norm":
        np.testing.assert_allclose(out, norm_np(q), rtol=1e-14)
    elif name == "inverse":
        # Parallel to the conjugate, reciprocal norm (valid at 1e±300 too).
        np.testing.assert_allclose(unit_np(out), unit_np(qf * [1, -1, -1, -1]), atol=1e-14)
        np.testing.assert_allclose(norm_np(out) * norm_np(q), 1.0, rtol=1e-13)
    elif name == "canonicalize":
        flipped = np.all(out == -qf, axis=-1) & ~np.all(out == qf, axis=-1)
        assert np.all(np.all(out == qf, axis=-1) | flipped)
        expected = rot(q).as_quat(canonical=True, scalar_first=True).reshape(out.shape)
        np.testing.assert_allclose(unit_np(out), expected, atol=1e-15)


@case(jq, "to_matrix", "passive_matrix", "to_rotvec", "to_axis_angle")
def _conversions(name, data, batch):
    q, kind = draw_quat(data, batch)
    f = getattr(jq, name)
    if kind == "wrong_shape":
        return raises_shape_error(lambda: f(q), "(..., 4)")
    out = f(q)
    if kind in ("nonfinite", "zero"):
        return each_element_non_finite(out, batch)
    r = rot(q)
    if name == "to_matrix":
        np.testing.assert_allclose(out, r.as_matrix().reshape(batch + (3, 3)), atol=1e-14)
    elif name == "passive_matrix":
        np.testing.assert_allclose(out, r.inv().as_matrix().reshape(batch + (3, 3)), atol=1e-14)
    else:
        rv = out if name == "to_rotvec" else out[0] * np.asarray(out[1])[..., None]
        # q and -q give the same result, bit for bit, 180° turns included.
        minus = f(-np.asarray(q))
        for a, b in zip(jax.tree.leaves(out), jax.tree.leaves(minus), strict=True):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(np.reshape(rv, (-1, 3)), r.as_rotvec(), atol=1e-12)
        if name == "to_axis_angle":
            angle = np.asarray(out[1])
            assert np.all((angle >= 0) & (angle <= np.pi))
            np.testing.assert_allclose(np.linalg.norm(out[0], axis=-1), 1.0, rtol=1e-14)


def _wrap(a):
    return np.angle(np.exp(1j * np.asarray(a)))


@case(jq, "to_euler", "gimbal_lock")
def _euler_out(name, data, batch):
    seq = data.draw(st.sampled_from(SEQS + ("XXY", "xyZ", "ZXZX", "abc")), label="seq")
    q, kind = draw_quat(data, batch, kinds=(*Q_KINDS, "locked"))
    if kind == "locked":
        rng = _rng(data, "angles")
        angles = rng.uniform(-3, 3, size=batch + (3,))
        singular = 0.0 if seq[0].lower() == seq[2].lower() else np.pi / 2
        angles[..., 1] = rng.choice([singular, np.pi - singular if singular == 0 else -singular])
        q = Rotation.from_euler(seq if seq in SEQS else "ZXZ", angles.reshape(-1, 3))
        q = q.as_quat(scalar_first=True).reshape(batch + (4,))
    f = getattr(jq, name)
    if seq not in SEQS:  # (a wrong shape may be named first: both are ValueErrors)
        with pytest.raises(ValueError, match="invalid Euler sequence|must have shape"):
            f(seq, q)
        return
    if kind == "wrong_shape":
        return raises_shape_error(lambda: f(seq, q), "(..., 4)")
    out = np.asarray(f(seq, q))
    if name == "gimbal_lock":
        assert out.dtype == bool and out.shape == batch
        if kind == "locked":
            assert out.all()
        return
    if kind in ("nonfinite", "zero"):
        return each_element_non_finite(out, batch)
    assert out.shape == batch + (3,)
    # The angles reproduce the rotation (also at gimbal lock) and equal scipy's elsewhere.
    same_rotation(Rotation.from_euler(seq, out.reshape(-1, 3)).as_quat(scalar_first=True),
                  unit_np(q), atol=1e-12)
    free = ~np.asarray(jq.gimbal_lock(seq, q, eps=1e-4)).reshape(-1)
    if free.any():
        ref = rot(q)[free].as_euler(seq)
        np.testing.assert_allclose(_wrap(out.reshape(-1, 3)[free] - ref), 0.0, atol=1e-10)


@case(jq, "w_matrix", "w_matrix_space")
def _w(name, data, batch):
    q, kind = draw_quat(data, batch)
    f = getattr(jq, name)
    if kind == "wrong_shape":
        return raises_shape_error(lambda: f(q), "(..., 4)")
    out = np.asarray(f(q))
    if kind == "nonfinite":
        return each_element_non_finite(out, batch)
    q0, q1, q2, q3 = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    s = 1.0 if name == "w_matrix" else -1.0  # (17.43); the space form flips the cross part
    rows = [(-q1, q0, s * q3, -s * q2), (-q2, -s * q3, q0, s * q1), (-q3, s * q2, -s * q1, q0)]
    expected = np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)
    np.testing.assert_array_equal(out, expected)
    if kind == "unit":  # orthonormal rows, orthogonal to q
        np.testing.assert_allclose(out @ np.swapaxes(out, -1, -2),
                                   np.broadcast_to(np.eye(3), batch + (3, 3)), atol=1e-14)
        np.testing.assert_allclose((out @ np.asarray(q)[..., None])[..., 0], 0.0, atol=1e-15)


# --------------------------------------------------------------------------- quaternion: two args


@case(jq, "multiply", "distance", "squared_distance")
def _two_quats(name, data, batch):
    p, kind_p = draw_quat(data, batch, label="p", max_exp=150)
    q, kind_q = draw_quat(data, batch, kinds=Q_VALID if kind_p not in Q_VALID else Q_KINDS,
                          max_exp=150)
    f = getattr(jq, name)
    if "wrong_shape" in (kind_p, kind_q):
        return raises_shape_error(lambda: f(p, q), "(..., 4)")
    out = np.asarray(f(p, q))
    if "nonfinite" in (kind_p, kind_q):
        return each_element_non_finite(out, batch)
    if name == "multiply":
        scale = (norm_np(p) * norm_np(q))[..., None]
        np.testing.assert_allclose(out / scale, hamilton_np(p, q) / scale, atol=1e-14)
    elif "zero" in (kind_p, kind_q):
        each_element_non_finite(out, batch)
    else:
        expected = (rot(q).inv() * rot(p)).magnitude().reshape(batch)
        if name == "squared_distance":  # (an angle's rounding, times up to 2π)
            np.testing.assert_allclose(out, expected**2, atol=1e-11)
        else:
            np.testing.assert_allclose(out, expected, atol=1e-12)
        np.testing.assert_allclose(f(p, p), 0.0, atol=1e-12)


@case(jq, "rotate", "rotate_inverse")
def _rotate(name, data, batch):
    q, kind_q = draw_quat(data, batch, max_exp=100)
    v, kind_v = draw_vec(data, batch, kinds=("float", "int", "zero", "nonfinite", "wrong_shape")
                         if kind_q in Q_VALID else ("float", "int"))
    f = getattr(jq, name)
    if kind_q == "wrong_shape":
        return raises_shape_error(lambda: f(q, v), "(..., 4)")
    if kind_v == "wrong_shape":
        return raises_shape_error(lambda: f(q, v), "(..., 3)")
    out = np.asarray(f(q, v))
    if "nonfinite" in (kind_q, kind_v):
        return each_element_non_finite(out, batch)
    r = rot(q) if kind_q != "zero" else None
    if r is None:  # the zero quaternion scales by |q|² = 0
        np.testing.assert_array_equal(out, 0.0)
        return
    r = r.inv() if name == "rotate_inverse" else r
    # Documented: for a non-unit q the rotated vector is scaled by |q|².
    expected = r.apply(np.reshape(v, (-1, 3))).reshape(batch + (3,))
    np.testing.assert_allclose(out / norm_np(q)[..., None] ** 2, expected, atol=1e-13)


@case(jq, "derivative", "derivative_space", "angular_velocity", "angular_velocity_space")
def _kinematics(name, data, batch):
    q, kind_q = draw_quat(data, batch, kinds=("unit", "half_turn", "zero", "nonfinite",
                                              "wrong_shape"))
    n = 3 if name.startswith("derivative") else 4
    x, kind_x = draw_vec(data, batch, n=n, label="rate",
                         kinds=("float", "int", "nonfinite", "wrong_shape")
                         if kind_q in Q_VALID else ("float",))
    f = getattr(jq, name)
    if "wrong_shape" in (kind_q, kind_x):
        shape = "(..., 4)" if kind_q == "wrong_shape" else f"(..., {n})"
        return raises_shape_error(lambda: f(q, x), shape)
    out = np.asarray(f(q, x))
    if "nonfinite" in (kind_q, kind_x):
        return each_element_non_finite(out, batch)
    if kind_q == "zero":
        np.testing.assert_array_equal(out, 0.0)
        return
    w = np.asarray(jq.w_matrix(q) if "space" not in name else jq.w_matrix_space(q))
    if name.startswith("derivative"):
        # ω = 2 W q̇ (17.42) and q·q̇ = 0 on the constraint.
        np.testing.assert_allclose(2 * (w @ out[..., None])[..., 0], x, atol=1e-14)
        np.testing.assert_allclose(np.sum(out * q, axis=-1), 0.0, atol=1e-15)
    else:
        np.testing.assert_allclose(out, 2 * (w @ np.asarray(x, float)[..., None])[..., 0],
                                   atol=1e-14)


@case(jq, "slerp")
def _slerp(name, data, batch):
    p, kind_p = draw_quat(data, batch, kinds=("unit", "half_turn", "zero", "nonfinite",
                                              "wrong_shape"), label="p")
    q, kind_q = draw_quat(data, batch, kinds=("unit", "half_turn"))
    t = data.draw(st.floats(0.0, 1.0), label="t")
    if kind_p == "wrong_shape":
        return raises_shape_error(lambda: jq.slerp(p, q, t), "(..., 4)")
    out = np.asarray(jq.slerp(p, q, t))
    if kind_p in ("zero", "nonfinite"):
        return each_element_non_finite(out, batch)
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, rtol=1e-13)
    total = np.asarray(jq.distance(p, q))
    np.testing.assert_allclose(jq.distance(p, out), t * total, atol=1e-12)
    np.testing.assert_allclose(jq.distance(out, q), (1 - t) * total, atol=1e-12)
    if batch == () and total < np.pi - 1e-6:
        ref = Slerp([0.0, 1.0], rot(np.stack([p, q])))([t]).as_quat(scalar_first=True)
        same_rotation(out, ref, atol=1e-12)


# --------------------------------------------------------------------------- quaternion: builders


@case(jq, "from_rotvec")
def _from_rotvec(name, data, batch):
    kind = data.draw(st.sampled_from(["float", "int", "zero", "tiny", "huge", "large",
                                      "nonfinite", "wrong_shape"]), label="rotvec kind")
    rng = _rng(data, "rotvec")
    r = rng.normal(size=batch + (3,))
    if kind == "wrong_shape":
        r = r[..., :2]
        return raises_shape_error(lambda: jq.from_rotvec(r), "(..., 3)")
    r = {"int": rng.integers(-4, 5, size=batch + (3,)), "zero": 0 * r, "tiny": 1e-300 * r,
         "huge": 1e300 * r, "large": 300 * r, "nonfinite": _poison(rng, r)}.get(kind, r)
    out = np.asarray(jq.from_rotvec(r))
    if kind == "nonfinite":
        return each_element_non_finite(out, batch)
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, rtol=1e-13)
    if kind == "huge":  # the angle mod 2π is lost to rounding; a unit quaternion remains
        return
    ref = Rotation.from_rotvec(np.reshape(r, (-1, 3)).astype(float)).as_quat(scalar_first=True)
    np.testing.assert_allclose(out.reshape(-1, 4), ref, atol=1e-12 if kind == "large" else 1e-15)


@case(jq, "from_axis_angle", "rodrigues_matrix")
def _axis_angle_in(name, data, batch):
    axis, kind = draw_vec(data, batch, label="axis", max_exp=300,
                          kinds=("float", "int", "scaled", "zero", "nonfinite", "wrong_shape"))
    angle = _rng(data, "angle").uniform(-10, 10, size=batch)
    f = getattr(jq, name)
    if kind == "wrong_shape":
        return raises_shape_error(lambda: f(axis, angle), "(..., 3)")
    out = np.asarray(f(axis, angle))
    if kind in ("zero", "nonfinite"):  # a zero axis has no direction: NaN (documented)
        return each_element_non_finite(out, batch)
    rv = unit_np(axis) * angle[..., None]
    r = Rotation.from_rotvec(rv.reshape(-1, 3))
    if name == "from_axis_angle":
        np.testing.assert_allclose(out.reshape(-1, 4), r.as_quat(scalar_first=True), atol=1e-14)
    else:
        np.testing.assert_allclose(out.reshape(-1, 3, 3), r.as_matrix(), atol=1e-14)


@case(jq, "from_euler")
def _from_euler(name, data, batch):
    seq = data.draw(st.sampled_from(SEQS + ("XYX ", "xyx_", "zz")), label="seq")
    angles, kind = draw_vec(data, batch, label="angles",
                            kinds=("float", "int", "zero", "nonfinite", "wrong_shape"))
    if seq not in SEQS:
        with pytest.raises(ValueError, match="invalid Euler sequence"):
            jq.from_euler(seq, angles)
        return
    if kind == "wrong_shape":
        return raises_shape_error(lambda: jq.from_euler(seq, angles), "(..., 3)")
    out = np.asarray(jq.from_euler(seq, angles))
    if kind == "nonfinite":
        return each_element_non_finite(out, batch)
    ref = Rotation.from_euler(seq, np.reshape(angles, (-1, 3)).astype(float))
    np.testing.assert_allclose(out.reshape(-1, 4), ref.as_quat(scalar_first=True), atol=1e-14)


def draw_matrix(data, batch, label="matrix"):
    """``(m, kind)``: rotations, integer rotations, reflections, non-orthogonal, ..."""
    kinds = ("rotation", "int", "near", "reflection", "scaled", "zero", "nonfinite",
             "wrong_shape")
    kind = data.draw(st.sampled_from(kinds), label=f"{label} kind")
    rng = _rng(data, label)
    m = Rotation.random(int(np.prod(batch, dtype=int)), random_state=rng).as_matrix()
    m = m.reshape(batch + (3, 3))
    if kind == "int":
        group = Rotation.create_group("O").as_matrix().round().astype(int)
        m = group[rng.integers(len(group), size=batch)]
    elif kind == "near":
        m = m + 1e-8 * rng.normal(size=m.shape)
    elif kind == "reflection":
        m = m @ np.diag([1.0, -1.0, 1.0])
    elif kind == "scaled":
        m = m * rng.choice([2.0, 1e-3, 1e300])
    elif kind == "zero":
        m = 0 * m
    elif kind == "nonfinite":
        m = _poison(rng, m.reshape(batch + (9,))).reshape(batch + (3, 3))
    elif kind == "wrong_shape":
        shape = data.draw(st.sampled_from([(2, 2), (3, 4), (4, 4), (3,)]), label="shape")
        m = rng.normal(size=batch + shape)
    return m, kind


@case(jq, "from_matrix", "check_rotation_matrix")
def _from_matrix(name, data, batch):
    m, kind = draw_matrix(data, batch)
    f = getattr(jq, name)
    if kind == "wrong_shape":
        return raises_shape_error(lambda: f(m), "(..., 3, 3)")
    if kind in ("reflection", "scaled", "zero"):
        with pytest.raises(ValueError, match="reflection|not orthogonal|proper rotation"):
            f(m)
        return
    if kind == "nonfinite":
        try:
            out = f(m)
        except ValueError:
            return
        assert name == "from_matrix"
        return each_element_non_finite(out, batch)
    out = np.asarray(f(m))
    if name == "check_rotation_matrix":
        np.testing.assert_array_equal(out, m)
        return
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, rtol=1e-14)
    ref = Rotation.from_matrix(np.reshape(m, (-1, 3, 3)).astype(float))
    same_rotation(out, ref.as_quat(scalar_first=True), atol=1e-7 if kind == "near" else 1e-14)


@case(jq, "project_to_rotation")
def _project(name, data, batch):
    m, kind = draw_matrix(data, batch)
    if kind == "wrong_shape":
        return raises_shape_error(lambda: jq.project_to_rotation(m), "(..., 3, 3)")
    out = np.asarray(jq.project_to_rotation(m))
    if kind == "nonfinite":
        return each_element_non_finite(out, batch)
    eye = np.broadcast_to(np.eye(3), batch + (3, 3))
    np.testing.assert_allclose(np.swapaxes(out, -1, -2) @ out, eye, atol=1e-13)
    np.testing.assert_allclose(np.linalg.det(out), 1.0, rtol=1e-13)
    if kind in ("rotation", "int", "near") or (kind == "scaled"):
        # The nearest rotation of a (scaled, noisy) rotation is that rotation.
        ref = Rotation.from_matrix(np.reshape(m, (-1, 3, 3)).astype(float)).as_matrix()
        np.testing.assert_allclose(out.reshape(-1, 3, 3), ref, atol=1e-7)


@case(jq, "passive_axis_matrix")
def _passive_axis(name, data, batch):
    axis = data.draw(st.sampled_from([0, 1, 2, "x", "Y", "z", np.int64(1), 3, -1, "w", True,
                                      1.0, None]), label="axis")
    angle, kind = draw_vec(data, batch, n=1, label="angle",
                           kinds=("float", "int", "zero", "nonfinite"))
    angle = angle[..., 0]
    valid = {0: 0, 1: 1, 2: 2, "x": 0, "Y": 1, "z": 2}
    key = axis if isinstance(axis, str) or type(axis) is int else None
    if isinstance(axis, np.integer):
        key = int(axis)
    if key not in valid:
        with pytest.raises(ValueError, match="axis must be one of"):
            jq.passive_axis_matrix(axis, angle)
        return
    out = np.asarray(jq.passive_axis_matrix(axis, angle))
    if kind == "nonfinite":
        return each_element_non_finite(out, batch)
    e = np.eye(3)[valid[key]]
    ref = Rotation.from_rotvec(np.reshape(angle, (-1, 1)) * e).inv().as_matrix()
    np.testing.assert_allclose(out.reshape(-1, 3, 3), ref, atol=1e-14)


@case(jq, "passive_zxz_matrix")
def _passive_zxz(name, data, batch):
    angles, kind = draw_vec(data, batch, label="angles", kinds=("float", "int", "nonfinite"))
    out = np.asarray(jq.passive_zxz_matrix(angles[..., 0], angles[..., 1], angles[..., 2]))
    if kind == "nonfinite":
        return each_element_non_finite(out, batch)
    ref = Rotation.from_euler("ZXZ", np.reshape(angles, (-1, 3)).astype(float)).inv()
    np.testing.assert_allclose(out.reshape(-1, 3, 3), ref.as_matrix(), atol=1e-14)


@case(jq, "identity", "default_atol")
def _constants(name, data, batch):
    if name == "default_atol":
        assert jq.default_atol(jnp.float64) == 1e-6 and jq.default_atol(jnp.float32) == 1e-4
        return
    bad = data.draw(st.sampled_from([None, (-1,), (2.5,), "ab"]), label="bad batch")
    out = np.asarray(jq.identity(batch))
    np.testing.assert_array_equal(out, np.broadcast_to([1.0, 0, 0, 0], batch + (4,)))
    if bad is not None:
        with pytest.raises(ValueError, match="batch_shape"):
            jq.identity(bad)


@case(jq, "check_quaternion")
def _check_quaternion(name, data, batch):
    q, kind = draw_quat(data, batch)
    unit = data.draw(st.booleans(), label="unit")
    if kind == "wrong_shape":
        return raises_shape_error(lambda: jq.check_quaternion(q, unit=unit), "(..., 4)")
    n = norm_np(q) if kind in Q_VALID else np.zeros(batch)
    invalid = kind in ("zero", "nonfinite") or (unit and np.any(np.abs(n - 1) > 1e-6))
    if invalid:
        with pytest.raises(ValueError, match="non-finite|zero quaternion|not unit"):
            jq.check_quaternion(q, unit=unit)
    else:
        np.testing.assert_array_equal(jq.check_quaternion(q, unit=unit), q)


# --------------------------------------------------------------------------- affine


def _vec_or_wrong(data, batch, n, label, kinds=("float", "int", "zero", "nonfinite",
                                                "wrong_shape", "scaled")):
    return draw_vec(data, batch, n=n, label=label, kinds=kinds, max_exp=300, wrong=(1, 4, 5))


@case(affine, "translation", "scaling")
def _translation_scaling(name, data, batch):
    n = data.draw(st.sampled_from([2, 3]), label="dim")
    d, kind = _vec_or_wrong(data, batch, n, "d")
    f = getattr(affine, name)
    if kind == "wrong_shape":
        return raises_shape_error(lambda: f(d), "(..., 2) or (..., 3)")
    T = np.asarray(f(d))
    assert T.shape == batch + (n + 1, n + 1)
    if kind == "nonfinite":
        return each_element_non_finite(T, batch)
    p = _rng(data, "points").normal(size=batch + (n,))
    moved = np.asarray(affine.apply_to_points(T, p))
    d = np.asarray(d, float)
    np.testing.assert_allclose(moved, p + d if name == "translation" else p * d,
                               rtol=1e-14, atol=1e-14)
    np.testing.assert_array_equal(T[..., n, :], np.eye(n + 1)[n] + 0 * T[..., n, :])


@case(affine, "shear_2d", "shear_3d", "rotation_2d")
def _planar(name, data, batch):
    rng = _rng(data, "k")
    k = rng.normal(size=batch + (6,))
    kind = data.draw(st.sampled_from(["float", "nonfinite", "bad_batch"]), label="kind")
    if kind == "nonfinite":  # poison a parameter (not the probe point) of every element
        used = {"shear_2d": [0, 1], "shear_3d": [0, 1, 2], "rotation_2d": [0, 4, 5]}[name]
        k[..., used] = _poison(rng, k[..., used])
    if kind == "bad_batch":
        if name == "shear_2d":
            call = lambda: affine.shear_2d(np.ones(3), np.ones(2))  # noqa: E731
        elif name == "shear_3d":
            call = lambda: affine.shear_3d(np.ones(3), np.ones(2))  # noqa: E731
        else:
            call = lambda: affine.rotation_2d(0.3, pivot=np.ones(3))  # noqa: E731
        with pytest.raises(ValueError):
            call()
        return
    if name == "shear_2d":
        T = np.asarray(affine.shear_2d(k[..., 0], k[..., 1]))
        p = np.stack([k[..., 2], k[..., 3]], axis=-1)
        expected = np.stack([p[..., 0] + k[..., 0] * p[..., 1], p[..., 1] + k[..., 1] * p[..., 0]],
                            axis=-1)
    elif name == "shear_3d":
        T = np.asarray(affine.shear_3d(xy=k[..., 0], yz=k[..., 1], zx=k[..., 2]))
        p = k[..., 3:]
        expected = p + np.stack([k[..., 0] * p[..., 1], k[..., 1] * p[..., 2],
                                 k[..., 2] * p[..., 0]], axis=-1)
    else:
        pivot = k[..., 4:]
        T = np.asarray(affine.rotation_2d(k[..., 0], pivot=pivot))
        p = k[..., 2:4]
        c, s = np.cos(k[..., 0]), np.sin(k[..., 0])
        rel = p - pivot
        expected = pivot + np.stack([c * rel[..., 0] - s * rel[..., 1],
                                     s * rel[..., 0] + c * rel[..., 1]], axis=-1)
    if kind == "nonfinite":
        return each_element_non_finite(T, batch)
    np.testing.assert_allclose(affine.apply_to_points(T, p), expected, atol=1e-13)


@case(affine, "rotation_3d", "rotation_3d_axis_angle", "rotation_3d_euler", "about_point")
def _rotations_3d(name, data, batch):
    rng = _rng(data, "pivot")
    pivot = rng.normal(size=batch + (3,))
    if name in ("rotation_3d", "about_point"):
        q, kind = draw_quat(data, batch)
        shape = "(..., 4)"
        if name == "rotation_3d":
            call = lambda: affine.rotation_3d(q, pivot)  # noqa: E731
        else:
            call = lambda: affine.about_point(affine.rotation_3d(q), pivot)  # noqa: E731
        r = rot(q) if kind in Q_VALID else None
    elif name == "rotation_3d_axis_angle":
        axis, kind = draw_vec(data, batch, label="axis", max_exp=300,
                              kinds=("float", "int", "scaled", "zero", "nonfinite",
                                     "wrong_shape"))
        angle = rng.uniform(-4, 4, size=batch)
        shape = "(..., 3)"
        call = lambda: affine.rotation_3d_axis_angle(axis, angle, pivot)  # noqa: E731
        r = Rotation.from_rotvec((unit_np(axis) * angle[..., None]).reshape(-1, 3)) \
            if kind in ("float", "int", "scaled") else None
    else:
        seq = data.draw(st.sampled_from(SEQS), label="seq")
        angles, kind = draw_vec(data, batch, label="angles",
                                kinds=("float", "int", "nonfinite", "wrong_shape"))
        shape = "(..., 3)"
        call = lambda: affine.rotation_3d_euler(seq, angles, pivot)  # noqa: E731
        r = Rotation.from_euler(seq, np.reshape(angles, (-1, 3)).astype(float)) \
            if kind in ("float", "int") else None
    if kind == "wrong_shape":
        return raises_shape_error(call, shape)
    if r is None and name != "rotation_3d_euler":  # a zero or non-finite quaternion / axis
        match = ("axis must be finite and not zero" if name == "rotation_3d_axis_angle"
                 else "zero quaternion|non-finite")
        with pytest.raises(ValueError, match=match):
            call()
        return None
    T = np.asarray(call())
    if r is None:  # non-finite angles
        return each_element_non_finite(T, batch)
    np.testing.assert_allclose(T[..., :3, :3].reshape(-1, 3, 3), r.as_matrix(), atol=1e-14)
    # The pivot is a fixed point.
    np.testing.assert_allclose(affine.apply_to_points(T, pivot), pivot, atol=1e-13)


def _random_affine(rng, batch, n=3):
    A = rng.normal(size=batch + (n, n)) + 3 * np.eye(n)
    return np.asarray(affine.from_blocks(A, rng.normal(size=batch + (n,))))


@case(affine, "compose", "inverse", "inverse_rigid", "from_blocks", "to_blocks")
def _algebra(name, data, batch):
    rng = _rng(data, "T")
    n = data.draw(st.sampled_from([2, 3]), label="dim")
    kind = data.draw(st.sampled_from(["float", "singular", "nonfinite", "huge", "wrong_shape"]),
                     label="kind")
    T = _random_affine(rng, batch, n)
    if kind == "singular":
        T = T.copy()
        T[..., :n, 0] = 0.0
    elif kind == "nonfinite":
        T = _poison(rng, T.reshape(batch + (-1,))).reshape(T.shape)
    elif kind == "huge":
        T = T * 1e300
    elif kind == "wrong_shape":
        T = rng.normal(size=batch + data.draw(st.sampled_from([(2, 2), (3, 4), (5, 5), (3,)])))
    if kind == "wrong_shape":
        calls = {"compose": lambda: affine.compose(T, T), "inverse": lambda: affine.inverse(T),
                 "inverse_rigid": lambda: affine.inverse_rigid(T),
                 "to_blocks": lambda: affine.to_blocks(T),
                 "from_blocks": lambda: affine.from_blocks(T, np.ones(T.shape[-1]))}
        if name == "from_blocks" and T.shape[-2:] in ((2, 2),):
            return  # a valid 2D linear part
        with pytest.raises(ValueError, match="must have shape"):
            calls[name]()
        return
    if name == "compose":
        U = _random_affine(rng, batch, n)
        out = np.asarray(affine.compose(T, U, U))
        if kind == "nonfinite":
            return each_element_non_finite(out, batch)
        np.testing.assert_allclose(out, T @ U @ U, rtol=1e-12, atol=1e-12 * np.abs(T).max())
        with pytest.raises(ValueError, match="2D and 3D"):
            affine.compose(T, np.eye(6 - n))
    elif name == "inverse":
        if kind in ("singular", "nonfinite"):
            with pytest.raises(ValueError, match="singular"):
                affine.inverse(T)
            return
        out = np.asarray(affine.inverse(T))  # at 1e300 too: the inverse is 1e-300 of it
        np.testing.assert_allclose(out @ T, np.broadcast_to(np.eye(n + 1), T.shape), atol=1e-12)
    elif name == "inverse_rigid":
        R = Rotation.random(int(np.prod(batch, dtype=int)), random_state=rng).as_matrix()
        R = R.reshape(batch + (3, 3)) if n == 3 else \
            np.asarray(affine.rotation_2d(rng.normal(size=batch)))[..., :2, :2]
        rigid = np.asarray(affine.from_blocks(R, rng.normal(size=batch + (n,))))
        out = np.asarray(affine.inverse_rigid(rigid))
        np.testing.assert_allclose(out, np.linalg.inv(rigid), atol=1e-12)
    else:
        A, d = affine.to_blocks(T)
        back = np.asarray(affine.from_blocks(A, d))
        # The top rows round-trip; the bottom row is rebuilt as (0, ..., 0, 1).
        np.testing.assert_array_equal(back[..., :n, :], T[..., :n, :])
        np.testing.assert_array_equal(back[..., n, :], np.broadcast_to(np.eye(n + 1)[n],
                                                                       batch + (n + 1,)))
        with pytest.raises(ValueError, match="A must have shape"):
            affine.from_blocks(A, np.ones(5 - n))


@case(affine, "to_homogeneous", "from_homogeneous", "apply", "apply_to_points", "apply_to_vectors")
def _application(name, data, batch):
    rng = _rng(data, "x")
    n = data.draw(st.sampled_from([2, 3]), label="dim")
    kind = data.draw(st.sampled_from(["float", "int", "nonfinite", "wrong_shape"]), label="kind")
    x = rng.normal(size=batch + (n,))
    if kind == "int":
        x = rng.integers(-5, 6, size=batch + (n,))
    elif kind == "nonfinite":
        x = _poison(rng, x)
    T = _random_affine(rng, batch, n)
    if kind == "wrong_shape":
        x = rng.normal(size=batch + (n + 2,))
        calls = {"to_homogeneous": lambda: affine.to_homogeneous(x, 1.0),
                 "from_homogeneous": lambda: affine.from_homogeneous(x[..., :1]),
                 "apply": lambda: affine.apply(T, x),
                 "apply_to_points": lambda: affine.apply_to_points(T, x),
                 "apply_to_vectors": lambda: affine.apply_to_vectors(T, x)}
        with pytest.raises(ValueError, match="must have shape"):
            calls[name]()
        return
    xf = np.asarray(x, float)
    X = np.concatenate([xf, np.ones(batch + (1,))], axis=-1)
    expected = {
        "to_homogeneous": X,
        "from_homogeneous": xf[..., :-1] / xf[..., -1:] if n == 3 else None,
        "apply": (T @ X[..., None])[..., 0],
        "apply_to_points": (T @ X[..., None])[..., 0][..., :n],
        "apply_to_vectors": (T[..., :n, :n] @ xf[..., None])[..., 0],
    }[name]
    if name == "from_homogeneous" and n == 2:
        return raises_shape_error(lambda: affine.from_homogeneous(x), "(..., 3) or (..., 4)")
    args = {"to_homogeneous": (x, 1.0), "from_homogeneous": (x,)}.get(
        name, (T, X if name == "apply" else x))
    out = np.asarray(getattr(affine, name)(*args))
    if kind == "nonfinite" and name != "from_homogeneous":
        return each_element_non_finite(out, batch)
    # (from_homogeneous divides as numpy does: w = ±inf is the limit point, NaN stays NaN)
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12)


@case(affine, "orthographic")
def _orthographic(name, data, batch):
    points, kind = draw_vec(data, batch, label="points",
                            kinds=("float", "int", "nonfinite", "wrong_shape"))
    axis = data.draw(st.sampled_from([0, 1, 2, np.int64(2), 3, -1, 1.0, True]), label="axis")
    if kind == "wrong_shape":
        return raises_shape_error(lambda: affine.orthographic(points, 0), "(..., 3)")
    if isinstance(axis, bool) or not isinstance(axis, int | np.integer) or axis not in (0, 1, 2):
        with pytest.raises(ValueError, match="axis must be"):
            affine.orthographic(points, axis)
        return
    uv, depth = affine.orthographic(points, axis)
    if kind == "nonfinite":
        return each_element_non_finite((uv, depth), batch)
    p = np.asarray(points, float)
    np.testing.assert_array_equal(uv, p[..., [(axis + 1) % 3, (axis + 2) % 3]])
    np.testing.assert_array_equal(depth, -p[..., axis])


def _camera_np(points, eye, target, up, fov, aspect):
    """Independent pinhole camera: orthonormal basis from the look direction."""
    f = target - eye
    f = f / np.linalg.norm(f, axis=-1, keepdims=True)
    r = np.cross(f, up)
    r = r / np.linalg.norm(r, axis=-1, keepdims=True)
    u = np.cross(r, f)
    rel = points - eye
    x, y, depth = (np.sum(rel * a, axis=-1) for a in (r, u, f))
    scale = 1.0 / np.tan(fov / 2)
    return np.stack([scale * x / (aspect * depth), scale * y / depth], axis=-1), depth


@case(affine, "look_at", "perspective")
def _cameras(name, data, batch):
    rng = _rng(data, "camera")
    eye = rng.normal(size=batch + (3,)) + np.array([6.0, 5.0, 4.0])
    target = rng.normal(size=batch + (3,))
    up = np.array([0.0, 0.0, 1.0])
    points = rng.normal(size=batch + (3,))
    fov, aspect = rng.uniform(0.2, 2.5), rng.uniform(0.3, 3.0)
    kind = data.draw(st.sampled_from(["valid", "eye_is_target", "parallel_up", "nonfinite",
                                      "bad_fov", "bad_aspect", "wrong_shape"]), label="kind")
    if kind == "eye_is_target":
        target = eye.copy()
    elif kind == "parallel_up":
        up = target - eye
    elif kind == "nonfinite":
        eye = _poison(rng, eye)
    elif kind == "bad_fov":
        fov = data.draw(st.sampled_from([0.0, -0.5, np.pi, 4.0, np.nan, np.inf]))
    elif kind == "bad_aspect":
        aspect = data.draw(st.sampled_from([0.0, -1.0, np.nan, np.inf, -np.inf]))
    elif kind == "wrong_shape":
        eye = eye[..., :2]

    def call():
        if name == "look_at":
            return affine.look_at(eye, target, up)
        return affine.perspective(points, eye, target, fov, up=up, aspect=aspect)

    if kind == "wrong_shape":
        return raises_shape_error(call, "(..., 3)")
    if kind != "valid" and not (name == "look_at" and kind in ("bad_fov", "bad_aspect")):
        message = {"eye_is_target": "zero-length", "parallel_up": "parallel",
                   "nonfinite": "finite", "bad_fov": "fov", "bad_aspect": "aspect"}[kind]
        with pytest.raises(ValueError, match=message):
            call()
        return
    out = call()
    if name == "look_at":
        V = np.asarray(out)
        R = V[..., :3, :3]
        np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2),
                                   np.broadcast_to(np.eye(3), R.shape), atol=1e-14)
        np.testing.assert_allclose(np.linalg.det(R), 1.0, rtol=1e-14)
        np.testing.assert_allclose(affine.apply_to_points(V, eye), 0.0, atol=1e-13)
        dist = np.linalg.norm(target - eye, axis=-1)
        np.testing.assert_allclose(affine.apply_to_points(V, target),
                                   np.stack([0 * dist, 0 * dist, -dist], axis=-1), atol=1e-13)
    else:
        uv_ref, depth_ref = _camera_np(points, eye, target, up, fov, aspect)
        np.testing.assert_allclose(out[1], depth_ref, rtol=1e-13)
        front = depth_ref > 0
        np.testing.assert_allclose(np.asarray(out[0])[front], uv_ref[front], rtol=1e-11,
                                   atol=1e-13)
        assert np.all(np.isnan(np.asarray(out[0])[~front]))


# --------------------------------------------------------------------------- inertia


SHAPES = {  # name -> (number of size arguments, principal moments per unit mass of sizes 1)
    "ellipsoid": 3, "box": 3, "sphere": 1, "thin_rod": 1, "thin_disk": 1,
    "thin_plate": 2, "solid_cylinder": 2, "disk": 2,
}


@case(inertia, *SHAPES)
def _shapes(name, data, batch):
    rng = _rng(data, "sizes")
    f = getattr(inertia, name)
    k = SHAPES[name]
    m = 10.0 ** rng.uniform(-100, 100, size=batch)
    sizes = [10.0 ** rng.uniform(-50, 50, size=batch) for _ in range(k)]
    kind = data.draw(st.sampled_from(["valid", "int", "zero_size", "bad_mass", "bad_size"]),
                     label="kind")
    if kind == "int":
        m = rng.integers(1, 5, size=batch)
        sizes = [rng.integers(1, 5, size=batch) for _ in range(k)]
    if kind == "zero_size":
        sizes[0] = 0 * sizes[0]
    if kind in ("bad_mass", "bad_size"):
        bad = data.draw(st.sampled_from([0.0, -1.0, np.nan, np.inf]), label="bad value")
        if kind == "bad_mass":
            m = np.where(np.arange(m.size).reshape(batch) == 0, bad, m)
        elif bad != 0.0:
            sizes[-1] = np.where(np.arange(m.size).reshape(batch) == 0, bad, sizes[-1])
        else:
            sizes[-1] = -sizes[-1]
        with pytest.raises(ValueError, match="must be finite and"):
            f(m, *sizes)
        return
    out = np.asarray(f(m, *sizes))
    assert out.shape == batch + (3,)
    assert np.all(np.isfinite(out)) and np.all(out >= 0)
    # The scaling law I(m, λ·sizes) = m λ² I(1, sizes) (Table 17.1 is quadratic in size).
    lam = 10.0 ** rng.uniform(-3, 3)
    unit = np.asarray(f(1.0, *[np.asarray(s, float) * lam for s in sizes]))
    np.testing.assert_allclose(unit * np.asarray(m, float)[..., None], out * lam**2, rtol=1e-12)
    # Every real body satisfies the triangle inequality; all but the ideal rod are positive.
    lo_mid_hi = np.sort(out, axis=-1)
    assert np.all(lo_mid_hi[..., 0] + lo_mid_hi[..., 1] >= lo_mid_hi[..., 2] * (1 - 1e-12))
    if name != "thin_rod" and kind != "zero_size":
        inertia.validate(out, kind="moments")


T_HANDLE_SIZES = ("bar_length", "bar_radius", "stem_length", "stem_radius")


def _t_handle_numpy(mass, bl, br, sl, sr):
    """The T-handle's moments from Table 17.1's cylinder and the parallel-axis shift."""
    v_bar, v_stem = np.pi * br**2 * bl, np.pi * sr**2 * sl
    m_bar, m_stem = mass * v_bar / (v_bar + v_stem), mass * v_stem / (v_bar + v_stem)
    y_stem = br + sl / 2
    y_cm = v_stem * y_stem / (v_bar + v_stem)
    d_bar, d_stem = y_cm, y_stem - y_cm  # both offsets along y
    across_bar = m_bar * (3 * br**2 + bl**2) / 12
    across_stem = m_stem * (3 * sr**2 + sl**2) / 12
    ixx = m_bar * br**2 / 2 + m_bar * d_bar**2 + across_stem + m_stem * d_stem**2
    iyy = across_bar + m_stem * sr**2 / 2
    izz = across_bar + m_bar * d_bar**2 + across_stem + m_stem * d_stem**2
    return np.stack([ixx, iyy, izz], axis=-1)


@case(inertia, "t_handle_parts", "t_handle_moments")
def _t_handle(name, data, batch):
    rng = _rng(data, "sizes")
    mass = 10.0 ** rng.uniform(-50, 50, size=batch)
    scale = 10.0 ** rng.uniform(-20, 20, size=batch)
    sizes = {k: scale * 10.0 ** rng.uniform(-1, 1, size=batch) for k in T_HANDLE_SIZES}
    kind = data.draw(st.sampled_from(["valid", "int", "bad"]), label="kind")
    if kind == "int":
        sizes = {k: rng.integers(1, 5, size=batch) for k in T_HANDLE_SIZES}
    if kind == "bad":
        bad = data.draw(st.sampled_from([0.0, -1.0, np.nan, np.inf]), label="bad value")
        names = T_HANDLE_SIZES if name == "t_handle_parts" else ("mass",) + T_HANDLE_SIZES
        which = data.draw(st.sampled_from(names), label="bad argument")
        first = np.arange(mass.size).reshape(batch) == 0
        if which == "mass":
            mass = np.where(first, bad, mass)
        else:
            sizes[which] = np.where(first, bad, sizes[which])
        with pytest.raises(ValueError, match=f"{which} must be finite and > 0"):
            if name == "t_handle_parts":
                inertia.t_handle_parts(**sizes)
            else:
                inertia.t_handle_moments(mass, **sizes)
        return
    if name == "t_handle_parts":
        parts = inertia.t_handle_parts(**sizes)
        frac = np.stack([np.asarray(p["mass_fraction"]) for p in parts])
        centers = np.stack([np.asarray(p["center"]) for p in parts])
        assert centers.shape == (2,) + batch + (3,)
        np.testing.assert_allclose(frac.sum(0), 1.0, rtol=1e-12)
        # the origin is the centre of mass; the stem starts on the bar's surface
        com = (frac[..., None] * centers).sum(0)
        assert np.all(np.abs(com) <= 1e-12 * np.abs(centers).max(0))
        gap = centers[1, ..., 1] - centers[0, ..., 1] - np.asarray(sizes["stem_length"]) / 2
        np.testing.assert_allclose(gap, np.asarray(sizes["bar_radius"], float), rtol=1e-12)
        # each orientation turns the cylinder's z onto the part's axis (bar x, stem y)
        for part, axis in zip(parts, np.eye(3)[:2], strict=True):
            q = np.asarray(part["orientation"]).reshape(-1, 4)
            z = Rotation.from_quat(q[:, [1, 2, 3, 0]]).apply([0.0, 0.0, 1.0])
            np.testing.assert_allclose(z, np.broadcast_to(axis, z.shape), atol=1e-12)
        return
    out = np.asarray(inertia.t_handle_moments(mass, **sizes))
    assert out.shape == batch + (3,)
    args = [np.asarray(sizes[k], float) for k in T_HANDLE_SIZES]
    expected = _t_handle_numpy(np.asarray(mass, float), *args)
    np.testing.assert_allclose(out, expected, rtol=1e-10)
    lo_mid_hi = np.sort(out, axis=-1)
    assert np.all(lo_mid_hi[..., 0] + lo_mid_hi[..., 1] >= lo_mid_hi[..., 2] * (1 - 1e-12))


@case(inertia, "to_tensor", "rotate_tensor", "rotate_tensor_by_matrix", "principal_axes")
def _tensors(name, data, batch):
    rng = _rng(data, "tensor")
    moments = np.asarray(inertia.box(1.0, *rng.uniform(0.1, 3.0, size=(3,) + batch)))
    moments = moments * 10.0 ** rng.uniform(-100, 100, size=batch + (1,))
    q, kind = draw_quat(data, batch)
    tensor = np.asarray(inertia.to_tensor(moments))
    if name == "to_tensor":
        if kind == "wrong_shape":
            return raises_shape_error(lambda: inertia.to_tensor(q[..., :1]), "(..., 3)")
        np.testing.assert_array_equal(tensor, moments[..., :, None] * np.eye(3))
        return
    if name == "rotate_tensor_by_matrix":
        if kind == "wrong_shape":
            return raises_shape_error(lambda: inertia.rotate_tensor_by_matrix(tensor, q),
                                      "(..., 3, 3)")
        R = rot(q).as_matrix().reshape(batch + (3, 3)) if kind in Q_VALID else np.full(
            batch + (3, 3), np.nan)
        out = np.asarray(inertia.rotate_tensor_by_matrix(tensor, R))
        if kind not in Q_VALID:
            return each_element_non_finite(out, batch)
        np.testing.assert_allclose(out, R @ tensor @ np.swapaxes(R, -1, -2),
                                   rtol=1e-13, atol=1e-14 * moments.max())
        return
    if name == "rotate_tensor":
        if kind == "wrong_shape":
            return raises_shape_error(lambda: inertia.rotate_tensor(tensor, q), "(..., 4)")
        out = np.asarray(inertia.rotate_tensor(tensor, q))
        if kind not in Q_VALID:
            return each_element_non_finite(out, batch)
        R = rot(q).as_matrix().reshape(batch + (3, 3))
        scale = moments.max(axis=-1)[..., None, None]
        np.testing.assert_allclose(out / scale, R @ tensor @ np.swapaxes(R, -1, -2) / scale,
                                   atol=1e-13)
        return
    # principal_axes of a rotated tensor
    if kind == "wrong_shape":
        return raises_shape_error(lambda: inertia.principal_axes(q), "(..., 3, 3)")
    R = rot(q if kind in Q_VALID else np.ones(batch + (4,))).as_matrix().reshape(batch + (3, 3))
    rotated = R @ tensor @ np.swapaxes(R, -1, -2)
    if kind == "nonfinite":
        rotated = _poison(rng, rotated.reshape(batch + (9,))).reshape(batch + (3, 3))
    w, frame = inertia.principal_axes(rotated)
    if kind == "nonfinite":
        return each_element_non_finite((w, frame), batch)
    scale = moments.max(axis=-1)[..., None]
    np.testing.assert_allclose(np.asarray(w) / scale, np.sort(moments, axis=-1) / scale,
                               atol=1e-13)
    V = np.asarray(jq.to_matrix(frame))
    back = V @ (np.asarray(w)[..., :, None] * np.eye(3)) @ np.swapaxes(V, -1, -2)
    np.testing.assert_allclose(back / scale[..., None], rotated / scale[..., None], atol=1e-12)


@case(inertia, "from_point_masses", "parallel_axis")
def _point_masses(name, data, batch):
    rng = _rng(data, "points")
    n = data.draw(st.sampled_from([1, 4]), label="n points")  # few shapes: few compiles
    masses = rng.uniform(0.1, 3.0, size=batch + (n,))
    positions = rng.normal(size=batch + (n, 3))
    origin = rng.normal(size=batch + (3,))
    kind = data.draw(st.sampled_from(["valid", "int", "negative", "nonfinite", "zero_total",
                                      "wrong_shape"]), label="kind")
    if kind == "int":
        masses = rng.integers(1, 4, size=batch + (n,))
        positions = rng.integers(-3, 4, size=batch + (n, 3))
    elif kind == "negative":
        masses = -masses
    elif kind == "nonfinite":
        positions = _poison(rng, positions)
    elif kind == "zero_total":
        masses = 0 * masses
    if name == "from_point_masses":
        if kind == "wrong_shape":
            with pytest.raises(ValueError, match="must have shape"):
                inertia.from_point_masses(masses[..., :1] if n > 1 else masses[..., :0],
                                          positions)
            return
        if kind in ("negative", "nonfinite", "zero_total"):
            with pytest.raises(ValueError, match="masses|positions"):
                inertia.from_point_masses(masses, positions)
            return
        out = np.asarray(inertia.from_point_masses(masses, positions, origin))
        r = np.asarray(positions, float) - origin[..., None, :]
        mf = np.asarray(masses, float)
        expected = np.einsum("...k,...kij->...ij", mf,
                             np.einsum("...ki,...ki->...k", r, r)[..., None, None] * np.eye(3)
                             - r[..., :, None] * r[..., None, :])
        np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12)
        return
    # parallel_axis: shifting the centre-of-mass tensor to origin = point-mass sum there.
    total = np.sum(np.abs(masses), axis=-1) if kind != "zero_total" else np.zeros(batch)
    if kind == "wrong_shape":
        return raises_shape_error(lambda: inertia.parallel_axis(np.eye(3), 1.0, origin[..., :2]),
                                  "(..., 3)")
    if kind in ("negative", "zero_total"):
        with pytest.raises(ValueError, match="mass must be finite and > 0"):
            inertia.parallel_axis(np.eye(3), -total if kind == "negative" else total, origin)
        return
    if kind == "nonfinite":  # refused, as non-finite positions are (jrigid.inertia)
        with pytest.raises(ValueError, match="d must be finite"):
            inertia.parallel_axis(np.eye(3), 1.0, _poison(rng, origin))
        return
    I_cm = np.asarray(inertia.from_point_masses(masses, positions))
    com = np.einsum("...k,...ki->...i", np.asarray(masses, float),
                    np.asarray(positions, float)) / total[..., None]
    out = np.asarray(inertia.parallel_axis(I_cm, total, com - origin))
    expected = np.asarray(inertia.from_point_masses(masses, positions, origin))
    np.testing.assert_allclose(out, expected, rtol=1e-11, atol=1e-11)


@case(inertia, "validate", "check", "conditions")
def _validate(name, data, batch):
    rng = _rng(data, "moments")
    sides = rng.uniform(0.1, 3.0, size=(3,) + batch)
    moments = np.asarray(inertia.box(1.0, *sides))
    kind = data.draw(st.sampled_from(["valid", "scaled", "needle", "tensor", "triangle",
                                      "negative", "nonfinite", "asymmetric", "wrong_shape"]),
                     label="kind")
    value = moments
    if kind == "scaled":
        value = moments * 10.0 ** rng.uniform(-200, 200, size=batch + (1,))
    elif kind == "needle":
        value = np.broadcast_to([1e-12, 1e12, 1e12], batch + (3,))
    elif kind == "tensor":
        R = Rotation.random(int(np.prod(batch, dtype=int)), random_state=rng).as_matrix()
        value = R.reshape(batch + (3, 3)) @ (moments[..., :, None] * np.eye(3)) \
            @ np.swapaxes(R.reshape(batch + (3, 3)), -1, -2)
    elif kind == "triangle":
        value = np.broadcast_to([1.0, 1.0, 2.5], batch + (3,))
    elif kind == "negative":
        value = moments * [1.0, -1.0, 1.0]
    elif kind == "nonfinite":
        value = _poison(rng, moments)
    elif kind == "asymmetric":
        value = moments[..., :, None] * np.eye(3) + np.triu(np.ones((3, 3)), 1)
    elif kind == "wrong_shape":
        value = rng.uniform(1, 2, size=batch + (4,))
    f = getattr(inertia, name)
    kw = {"kind": "tensor" if kind in ("tensor", "asymmetric") else "moments"}
    if kind == "wrong_shape":
        return raises_shape_error(lambda: f(value, **kw), "(..., 3)")
    expected = {"triangle": "triangle", "negative": "positive definite",
                "nonfinite": "finite", "asymmetric": "symmetric"}.get(kind)
    if name == "conditions":  # every element flagged under exactly its first failed condition
        flags = {c: np.asarray(bad) for c, bad, _, _ in f(value, **kw)}
        assert all(bad.shape == batch for bad in flags.values())
        first = {"triangle": "triangle inequality Ia + Ib >= Ic violated",
                 "negative": "not positive definite", "nonfinite": "values not finite",
                 "asymmetric": "tensor not symmetric"}.get(kind)
        assert first is None or first in flags
        for c, bad in flags.items():
            np.testing.assert_array_equal(bad, c == first)
        return
    if expected is None:
        np.testing.assert_array_equal(f(value, **kw), value)
    else:
        with pytest.raises(ValueError if name == "validate" else Exception, match=expected):
            f(value, **kw)


@case(inertia, "checked_moments")
def _checked_moments(name, data, batch):
    """Principal moments only: returned unchanged when physical; a wrong trailing shape,
    a negative, non-finite or triangle-breaking moment is a ValueError naming the problem
    (the triangle inequality is skipped with allow_nonphysical)."""
    rng = _rng(data, "moments")
    moments = np.asarray(inertia.box(1.0, *rng.uniform(0.1, 3.0, size=(3,) + batch)))
    kind = data.draw(st.sampled_from(["valid", "scaled", "triangle", "negative",
                                      "nonfinite", "wrong_shape"]), label="kind")
    if kind == "wrong_shape":
        return raises_shape_error(lambda: inertia.checked_moments(moments[..., :2]),
                                  "moments (principal moments)")
    value = {"valid": moments,
             "scaled": moments * 10.0 ** rng.uniform(-200, 200, size=batch + (1,)),
             "triangle": np.broadcast_to([1.0, 1.0, 2.5], batch + (3,)),
             "negative": moments * [1.0, -1.0, 1.0],
             "nonfinite": _poison(rng, moments)}[kind]
    if kind in ("valid", "scaled"):
        np.testing.assert_array_equal(inertia.checked_moments(value), value)
        return
    if kind == "triangle":
        np.testing.assert_array_equal(
            inertia.checked_moments(value, allow_nonphysical=True), value)
    expected = {"triangle": "triangle", "negative": "positive definite",
                "nonfinite": "finite"}[kind]
    with pytest.raises(ValueError, match=expected):
        inertia.checked_moments(value)


# --------------------------------------------------------------------------- the suite


PUBLIC = {
    f"{module.__name__.rsplit('.', 1)[-1]}.{name}"
    for module in (jq, affine, inertia)
    for name in module.__all__
    if callable(getattr(module, name))
}


def test_every_public_geometry_function_has_a_case():
    missing = PUBLIC - set(CASES)
    assert not missing, f"public functions without a property case: {sorted(missing)}"


@pytest.mark.parametrize("qualified", sorted(CASES))
@SETTINGS
@given(data=st.data(), batch=BATCHES)
def test_result_is_right_or_a_value_error(qualified, data, batch):
    with np.errstate(all="ignore"):  # numpy references meet the same NaN/inf inputs
        CASES[qualified](qualified.rsplit(".", 1)[-1], data, batch)
