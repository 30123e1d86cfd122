"""Elliptic integrals and Jacobi elliptic functions in JAX (``jax.scipy`` has none).

Conventions are scipy's and mpmath's: the parameter is ``m = k²``; ``Π(n; φ|m)`` has the
characteristic first, as ``mpmath.ellippi(n, φ, m)``. Every function that takes ``m`` also
accepts the complement ``m1 = 1 - m`` as a keyword, which keeps full relative accuracy
when ``m`` is within a few ulps of 1 (``ellipk(m1=1e-12)``, ``ellipj(u, m1=1e-12)``).

* Carlson's symmetric integrals: :func:`elliprf`, :func:`elliprd`, :func:`elliprj`,
  :func:`elliprc` (duplication with a fixed number of steps; DLMF 19.36).
* Legendre's integrals: :func:`ellipk`, :func:`ellipe`, :func:`ellippi` (complete),
  :func:`ellipkinc`, :func:`ellipeinc`, :func:`ellippiinc` (incomplete, any amplitude).
* Jacobi functions: :func:`ellipj` (``sn, cn, dn, am`` like ``scipy.special.ellipj``),
  :func:`sn`, :func:`cn`, :func:`dn`, :func:`am`, for ``0 ≤ m ≤ 1`` and any real ``u``.

All functions are jitted, broadcast their arguments, work under ``vmap``, in float32 and
float64, and are differentiable (forward and reverse mode) in all arguments. In float64
they agree with 30-digit mpmath to 1e-14 relative, or, for large arguments, to within a
few times the change caused by rounding the argument itself (``eps |u f'(u)|``); see
``tests/test_special.py``. Arguments outside the documented domain give NaN rather than
raising, so that the functions can run under ``jit``.
"""

from ._carlson import elliprc, elliprd, elliprf, elliprj
from ._jacobi import am, cn, dn, ellipj, sn
from ._legendre import ellipe, ellipeinc, ellipk, ellipkinc, ellippi, ellippiinc

__all__ = [
    "am",
    "cn",
    "dn",
    "ellipe",
    "ellipeinc",
    "ellipj",
    "ellipk",
    "ellipkinc",
    "ellippi",
    "ellippiinc",
    "elliprc",
    "elliprd",
    "elliprf",
    "elliprj",
    "sn",
]
