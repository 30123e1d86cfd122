"""Test configuration: float64 by default, rank promotion forbidden.

Tests that exercise the float32 path request the ``float32`` fixture, which
switches ``jax_enable_x64`` off for the duration of the test.
"""

import jax
import pytest

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


@pytest.fixture
def float32():
    """Run the test with 64-bit mode off, so arrays default to float32."""
    jax.config.update("jax_enable_x64", False)
    try:
        yield
    finally:
        jax.config.update("jax_enable_x64", True)
