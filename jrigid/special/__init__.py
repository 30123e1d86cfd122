"""Elliptic integrals and Jacobi elliptic functions in JAX (``jax.scipy`` has none).

Conventions are scipy's and mpmath's: the parameter is ``m = k²``; ``Π(n; φ|m)`` has the
characteristic first, as ``mpmath.ellippi(n, φ, m)``. Every function that takes ``m`` also
accepts the complement ``m1 = 1 - m`` as a keyword, which keeps full relative accuracy
when ``m`` is within a few ulps of 1 (``ellipk(m1=1e-12)``, ``ellipj(u, m1=1e-12)``).

* Carlson's symmetric integrals: :func:`elliprf`, :func:`elliprd`, :func:`elliprj`,
  :func:`elliprc` (duplication with a fixed number of steps; DLMF 19.36), and
  :func:`elliprf_sqrt`, :func:`elliprj_sqrt`, which take the square roots of the
  arguments (finite derivatives where an argument is zero).
* Legendre's integrals: :func:`ellipk`, :func:`ellipe`, :func:`ellippi` (complete),
  :func:`ellipkinc`, :func:`ellipeinc`, :func:`ellippiinc` (incomplete, any amplitude).
* Jacobi functions: :func:`ellipj` (``sn, cn, dn, am`` like ``scipy.special.ellipj``),
  :func:`sn`, :func:`cn`, :func:`dn`, :func:`am`, for ``0 ≤ m ≤ 1`` and any real ``u``;
  :func:`jacobi_with_index` also returns the half-period index ``j`` of ``u = 2jK + r``
  (for unwrapping quasi-periodic integrals), with :func:`complete_k` the ``K`` it needs.

All functions are jitted, broadcast their arguments, work under ``vmap``, in float32 and
float64, and are differentiable (forward and reverse mode) in all arguments. In float64
they agree with 30-digit mpmath to 1e-14 relative, or, for large arguments, to within a
few times the change caused by rounding the argument itself (``eps |u f'(u)|``); see
``tests/test_special.py``. Arguments outside the documented domain give NaN rather than
raising, so that the functions can run under ``jit``: a NaN argument, ``m`` and ``m1``
that do not agree, a negative Carlson argument; where an integral diverges (``K(1)``,
``R_F`` or ``R_J`` with two zero arguments, ``R_D(0, 0, z)``) the value is ``inf``.
"""

from jrigid.special import _carlson, _jacobi, _legendre  # noqa: I001
from jrigid.special._carlson import *  # noqa: F403
from jrigid.special._jacobi import *  # noqa: F403
from jrigid.special._legendre import *  # noqa: F403

# The package's names: each listed once, in the ``__all__`` of the module defining it.
__all__: list[str] = []
__all__ += _carlson.__all__
__all__ += _jacobi.__all__
__all__ += _legendre.__all__
