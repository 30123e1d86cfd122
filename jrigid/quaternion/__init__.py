"""Quaternions and rotation conversions (chapter eqs. 17.8, 17.10, 17.16-17.28, 17.37-17.44).

Quaternions are ``(..., 4)`` arrays, scalar first ``(w, x, y, z)``. A unit
quaternion ``q`` maps body to space: ``v_space = q ⊗ (0, v_body) ⊗ q*``. Rotation
matrices are active (``v_space = R @ v_body``) and match scipy's ``Rotation``; the
chapter's passive matrices (17.8, 17.10, 17.28) are reproduced by the ``passive_*``
functions. Angular velocity is body frame unless a name says ``space``.

Modules: ``core`` (algebra, axis-angle, rotation vectors, slerp), ``kinematics``
(``q̇`` and ω), ``matrix`` (matrices, Rodrigues), ``euler`` (Euler angles), ``validate``
(input checks).

Bad input:

* wrong trailing shapes always raise ``ValueError`` naming the expected shape (a static
  check, free under ``jit``), as do invalid Euler sequences;
* conversions do not raise on bad values: a zero or non-finite quaternion gives NaN.
  Any finite non-zero norm is fine (``1e-300`` to ``1e300``): functions that do not
  depend on the scale rescale by the largest component before squaring;
* :func:`from_matrix` refuses a reflection or a matrix far from orthogonal: ``ValueError``
  for concrete input, NaN under ``jit``/``vmap``/``grad`` (see its docstring);
* :func:`check_quaternion` and :func:`check_rotation_matrix` raise ``ValueError`` on
  concrete input and use ``equinox.error_if`` under ``jit``.
"""

from .core import (
    canonicalize,
    conjugate,
    distance,
    from_axis_angle,
    from_rotvec,
    from_xyzw,
    identity,
    inverse,
    multiply,
    norm,
    normalize,
    rotate,
    rotate_inverse,
    slerp,
    to_axis_angle,
    to_rotvec,
    to_xyzw,
)
from .euler import EULER_SEQUENCES, from_euler, gimbal_lock, to_euler
from .kinematics import (
    angular_velocity,
    angular_velocity_space,
    derivative,
    derivative_space,
    w_matrix,
    w_matrix_space,
)
from .matrix import (
    from_matrix,
    passive_axis_matrix,
    passive_matrix,
    passive_zxz_matrix,
    project_to_rotation,
    rodrigues_matrix,
    to_matrix,
)
from .validate import check_quaternion, check_rotation_matrix, default_atol

__all__ = [
    "EULER_SEQUENCES",
    "angular_velocity",
    "angular_velocity_space",
    "canonicalize",
    "check_quaternion",
    "check_rotation_matrix",
    "conjugate",
    "default_atol",
    "derivative",
    "derivative_space",
    "distance",
    "from_axis_angle",
    "from_euler",
    "from_matrix",
    "from_rotvec",
    "from_xyzw",
    "gimbal_lock",
    "identity",
    "inverse",
    "multiply",
    "norm",
    "normalize",
    "passive_axis_matrix",
    "passive_matrix",
    "passive_zxz_matrix",
    "project_to_rotation",
    "rodrigues_matrix",
    "rotate",
    "rotate_inverse",
    "slerp",
    "to_axis_angle",
    "to_euler",
    "to_matrix",
    "to_rotvec",
    "to_xyzw",
    "w_matrix",
    "w_matrix_space",
]
