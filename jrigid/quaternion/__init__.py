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
  depend on the scale rescale by the largest component before squaring. (Components
  below the smallest normal float, about ``2.2e-308`` in float64 and ``1.2e-38`` in
  float32, are subnormal, and XLA on a CPU flushes them to zero: such a quaternion
  counts as zero);
* :func:`from_matrix` refuses a reflection or a matrix far from orthogonal: ``ValueError``
  for concrete input, NaN under ``jit``/``vmap``/``grad`` (see its docstring);
* :func:`check_quaternion` and :func:`check_rotation_matrix` raise ``ValueError`` on
  concrete input and use ``equinox.error_if`` under ``jit``.
"""

from jrigid.quaternion import core, euler, kinematics, matrix, validate  # noqa: I001
from jrigid.quaternion.core import *  # noqa: F403
from jrigid.quaternion.euler import *  # noqa: F403
from jrigid.quaternion.kinematics import *  # noqa: F403
from jrigid.quaternion.matrix import *  # noqa: F403
from jrigid.quaternion.validate import *  # noqa: F403

# The package's names: each listed once, in the ``__all__`` of the module defining it.
__all__: list[str] = []
__all__ += core.__all__
__all__ += euler.__all__
__all__ += kinematics.__all__
__all__ += matrix.__all__
__all__ += validate.__all__
