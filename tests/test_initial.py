"""Batches of initial states: every field of a helper's State carries one batch shape.

``initial.from_omega`` with a batch of ω used to return ``q (4,)`` beside ``q̇ (N, 4)``;
these tests keep the helpers' batch shapes consistent (q, q̇, x, v), each member equal
to the single-state result and to an independent computation (scipy), under ``jit`` and
``vmap`` too, and usable as a batch by :func:`jrigid.ensemble.simulate_many`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from jrigid import initial
from jrigid.body import RigidBody
from jrigid.ensemble import simulate_many
from jrigid.scene import Scene


def _rotations(shape, rng):
    """Unit quaternions (scalar first) of batch ``shape`` from scipy."""
    n = int(np.prod(shape, dtype=int))
    return Rotation.random(n, random_state=rng).as_quat(scalar_first=True).reshape(*shape, 4)


def _expected_qdot(q, omega_body):
    """``½ q ⊗ (0, ω)`` written out with numpy (eq. 17.44), any batch shape."""
    w, v = q[..., :1], q[..., 1:]
    return 0.5 * np.concatenate(
        [-np.sum(v * omega_body, axis=-1, keepdims=True), w * omega_body + np.cross(v, omega_body)],
        axis=-1,
    )


# Batch shapes that broadcast: a target shape, and for each argument a suffix of it with
# some axes replaced by 1.
@st.composite
def _broadcastable(draw):
    target = draw(st.lists(st.integers(1, 3), min_size=0, max_size=3))
    shapes = []
    for _ in range(2):
        keep = draw(st.integers(0, len(target)))
        suffix = target[len(target) - keep :]
        shapes.append(tuple(draw(st.sampled_from([n, 1])) for n in suffix))
    return tuple(target), shapes


@settings(max_examples=20, deadline=None)
@given(
    shapes=_broadcastable(),
    seed=st.integers(0, 2**31 - 1),
    frame=st.sampled_from(["body", "space"]),
)
def test_from_omega_batch_shapes_and_members(shapes, seed, frame):
    """q, q̇ share the broadcast batch shape; each member matches scipy's rotation."""
    _, (q_shape, w_shape) = shapes
    rng = np.random.default_rng(seed)
    q = _rotations(q_shape, rng)
    omega = rng.normal(size=(*w_shape, 3))
    s = initial.from_omega(q, omega, frame=frame)
    batch = np.broadcast_shapes(q_shape, w_shape)
    assert s.q.shape == s.qdot.shape == (*batch, 4)
    assert s.x is None and s.v is None
    q_b = np.broadcast_to(q, (*batch, 4)).copy()
    w_b = np.broadcast_to(omega, (*batch, 3)).copy()
    np.testing.assert_allclose(s.q, q_b, atol=1e-15)
    body = w_b
    if frame == "space":  # ω_body = Rᵀ ω_space with scipy's matrix of each member
        rot = Rotation.from_quat(q_b.reshape(-1, 4), scalar_first=True)
        body = rot.inv().apply(w_b.reshape(-1, 3)).reshape(w_b.shape)
    np.testing.assert_allclose(s.qdot, _expected_qdot(q_b, body), atol=1e-14)
    np.testing.assert_allclose(s.omega, body, atol=1e-14)


def test_batch_of_omega_with_the_default_orientation():
    omegas = np.random.default_rng(0).normal(size=(5, 3))
    for frame in ("body", "space"):  # the identity: both frames agree
        s = initial.from_omega(omega=omegas, frame=frame)
        assert s.q.shape == s.qdot.shape == (5, 4)
        np.testing.assert_array_equal(s.q, np.broadcast_to([1.0, 0.0, 0.0, 0.0], (5, 4)))
        np.testing.assert_allclose(s.qdot[:, 1:], 0.5 * omegas, atol=1e-16)
        np.testing.assert_array_equal(s.qdot[:, 0], 0.0)


def test_translation_broadcasts_with_the_rotation():
    rng = np.random.default_rng(1)
    omegas = rng.normal(size=(4, 3))
    s = initial.from_omega(omega=omegas, x=np.zeros(3), v=np.ones((1, 3)))
    assert s.x.shape == s.v.shape == (4, 3) and s.q.shape == (4, 4)
    s = initial.from_omega(_rotations((2, 1), rng), omegas[:3], x=rng.normal(size=(3,)),
                           v=rng.normal(size=(1, 1, 3)))
    assert s.q.shape == s.qdot.shape == (2, 3, 4) and s.x.shape == s.v.shape == (2, 3, 3)
    with pytest.raises(ValueError, match=r"batch shapes do not broadcast: .*x \(2,\)"):
        initial.from_omega(omega=omegas, x=np.zeros((2, 3)), v=np.zeros(3))
    with pytest.raises(ValueError, match=r"batch shapes do not broadcast: q0 \(3,\), omega \(4,\)"):
        initial.from_omega(_rotations((3,), rng), omegas)


def test_batched_call_equals_vmap_and_jit():
    rng = np.random.default_rng(2)
    qs, omegas = 3.0 * _rotations((6,), rng), rng.normal(size=(6, 3))  # non-unit q: normalised
    batched = initial.from_omega(qs, omegas, frame="space")
    mapped = jax.vmap(lambda q, w: initial.from_omega(q, w, frame="space"))(qs, omegas)
    jitted = jax.jit(lambda q, w: initial.from_omega(q, w, frame="space"))(qs, omegas)
    for other in (mapped, jitted):
        np.testing.assert_allclose(other.q, batched.q, atol=1e-15)
        np.testing.assert_allclose(other.qdot, batched.qdot, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(batched.q, axis=-1), 1.0, rtol=1e-15)


def test_a_bad_member_is_named_under_jit():
    qs = _rotations((3,), np.random.default_rng(3))
    qs[1] = 0.0
    f = eqx.filter_jit(lambda q: initial.from_omega(q, jnp.ones(3)).q)
    with pytest.raises(eqx.EquinoxRuntimeError, match="zero quaternion"):
        jax.block_until_ready(f(qs))
    with pytest.raises(ValueError, match="zero quaternion"):  # concrete: a ValueError
        initial.from_omega(qs, jnp.ones(3))


def test_dtypes_agree_across_fields(float32):
    s = initial.from_omega(omega=np.ones((3, 3), np.float32))
    assert s.q.dtype == s.qdot.dtype == jnp.float32 and s.q.shape == s.qdot.shape == (3, 4)
    s = initial.tilted(2, jnp.zeros(2, jnp.float32), 1.0)
    assert s.q.dtype == s.qdot.dtype == jnp.float32 and s.q.shape == (2, 4)
    s = initial.from_omega(np.array([1.0, 0, 0, 0], np.float32))  # default ω: q0's dtype
    assert s.q.dtype == s.qdot.dtype == jnp.float32


def test_other_helpers_broadcast_consistently():
    rng = np.random.default_rng(3)
    angles, rates = rng.normal(size=(6, 3)), rng.normal(size=3)
    s = initial.from_euler_rates(angles, rates, x=np.zeros(3), v=np.ones((6, 3)))
    assert s.q.shape == s.qdot.shape == (6, 4) and s.x.shape == (6, 3)
    np.testing.assert_allclose(s.qdot[2], initial.from_euler_rates(angles[2], rates).qdot,
                               atol=1e-15)
    np.testing.assert_allclose(
        Rotation.from_quat(np.asarray(s.q), scalar_first=True).as_matrix(),
        Rotation.from_euler("ZXZ", angles).as_matrix(), atol=1e-12,
    )
    qs = _rotations((3,), rng)
    s = initial.tilted(1, jnp.array([0.0, 0.1, 0.2]), 2.0, q0=qs)
    assert s.q.shape == s.qdot.shape == (3, 4)
    np.testing.assert_allclose(s.q, qs, atol=1e-15)
    np.testing.assert_allclose(s.omega[2], [0.0, 2 * np.cos(0.2), 2 * np.sin(0.2)], atol=1e-15)
    with pytest.raises(ValueError, match="tilted: batch shapes"):
        initial.tilted(1, jnp.zeros(3), jnp.ones(2))
    with pytest.raises(ValueError, match="axis must be the integer"):
        initial.tilted(1.0, 0.1, 1.0)
    scene = Scene(RigidBody(jnp.array([1.0, 2.0, 2.5])))
    with pytest.raises(ValueError, match="one state"):
        initial.from_momentum_energy(scene, jnp.ones((2, 3)), 1.0)


def test_from_omega_batch_runs_as_an_ensemble():
    """The batch goes straight into simulate_many; each member keeps its own ω and energy."""
    moments = np.array([1.0, 2.0, 2.5])
    rng = np.random.default_rng(4)
    qs, omegas = _rotations((4,), rng), rng.normal(size=(4, 3))
    states = initial.from_omega(qs, omegas)
    out = simulate_many(Scene(RigidBody(jnp.asarray(moments))), states,
                        np.linspace(0.0, 2.0, 3), rtol=1e-10, atol=1e-12, progress=False)
    np.testing.assert_array_equal(out["result"], 0)
    np.testing.assert_allclose(out["omega"][:, 0], omegas, atol=1e-12)
    q0 = out["q"][:, 0] * np.sign(np.sum(out["q"][:, 0] * qs, axis=-1, keepdims=True))
    np.testing.assert_allclose(q0, qs, atol=1e-12)
    energy = 0.5 * np.sum(moments * out["omega"] ** 2, axis=-1)
    np.testing.assert_allclose(energy, energy[:, :1] * np.ones(3), rtol=1e-9)
