"""Shared helpers for the quaternion tests: random rotations, scipy, sign-invariant checks."""

import numpy as np
from scipy.spatial.transform import Rotation


def random_quaternions(rng, shape, scale=1.0):
    """Unit quaternions (w, x, y, z), uniformly random, in either sign, with shape (*shape, 4)."""
    q = rng.normal(size=tuple(shape) + (4,))
    return scale * q / np.linalg.norm(q, axis=-1, keepdims=True)


def scipy_rot(q):
    """A scipy ``Rotation`` stack (always batched) from scalar-first quaternions."""
    return Rotation.from_quat(np.reshape(q, (-1, 4)), scalar_first=True)


def assert_same_rotation(q1, q2, atol=1e-12):
    """q1 and q2 represent the same rotation: equal up to sign."""
    q1, q2 = np.asarray(q1), np.asarray(q2)
    assert q1.shape == q2.shape
    d = np.minimum(np.abs(q1 - q2).max(axis=-1), np.abs(q1 + q2).max(axis=-1))
    assert np.all(d <= atol), d.max()
