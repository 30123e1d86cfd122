"""Inertia: moments of simple shapes and a T-handle, tensors of point masses, principal axes,
checks.

Implements chapter 17.29–17.32 and Table 17.1.

An inertia is given either as principal moments ``(..., 3)`` about the body ``x, y, z``
axes, or as a symmetric tensor ``(..., 3, 3)``. The shape functions return principal
moments about the centre of mass for a uniform density; each docstring states how the
shape sits along the body axes. Arguments broadcast over leading batch dimensions.

Errors: :func:`validate` raises ``ValueError`` naming the violated condition and the
offending values (it needs concrete values; under a JAX transformation it falls back to
:func:`check`). :func:`check` is jit-safe: it raises at run time through
``equinox.error_if``. Wrong shapes raise ``ValueError`` naming the expected trailing shape
while tracing. The shape functions and :func:`from_point_masses` / :func:`parallel_axis`
refuse a mass that is not finite and positive (point masses: not negative) and sizes or
positions that are negative or not finite (``ValueError`` for concrete values,
``equinox.error_if`` under ``jit``).
"""

from jrigid.inertia import _checks, _shapes, _tensors  # noqa: I001
from jrigid.inertia._checks import *  # noqa: F403
from jrigid.inertia._shapes import *  # noqa: F403
from jrigid.inertia._tensors import *  # noqa: F403

# The package's names: each listed once, in the ``__all__`` of the module defining it.
__all__: list[str] = []
__all__ += _checks.__all__
__all__ += _shapes.__all__
__all__ += _tensors.__all__
