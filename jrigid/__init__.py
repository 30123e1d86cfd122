"""jrigid: differentiable rigid-body rotation in JAX."""

__version__ = "0.1.0"
