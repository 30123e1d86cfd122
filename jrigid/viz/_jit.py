"""Shape bucketing for the jitted kernels of the drawing code.

Drawing calls the geometry layer on arrays whose lengths change from call to call (a
trail grows, meshes differ). Eager JAX compiles every operation anew for each shape,
which dominates the drawing time; instead the viz modules call a few jitted kernels
on inputs padded to a power of two, so each kernel compiles once per size class.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

__all__ = ["bucket", "pad", "float_dtype"]


def bucket(n: int, minimum: int = 64) -> int:
    """Smallest power of two ``≥ n`` and ``≥ minimum``."""
    return max(minimum, 1 << max(int(n) - 1, 0).bit_length())


def pad(x, n: int, fill=0.0) -> np.ndarray:
    """Pad ``x`` along its first axis to length ``n`` with rows equal to ``fill``."""
    x = np.asarray(x)
    if len(x) == n:
        return x
    rows = np.broadcast_to(np.asarray(fill, dtype=x.dtype), (n - len(x),) + x.shape[1:])
    return np.concatenate([x, rows])


def float_dtype():
    """JAX's default float (float64 when x64 is on)."""
    return jnp.result_type(float)
