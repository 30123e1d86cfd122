"""solve: the shared solve kit — float32 precision warnings and their threshold."""


import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _simulate import (
    OMEGA0,
    Q0,
    free_scene,
)

from jrigid import initial
from jrigid.integrate import simulate
from jrigid.solve import PrecisionWarning, precision_problem

# --------------------------------------------------------------------------- precision


def test_float32_warns_once_when_the_horizon_defeats_the_tolerance(float32):
    """|ω| t_end eps32 = 1.54 · 1e3 · 1.2e-7 = 1.8e-4 > rtol = 1e-5: one warning, at the
    caller's line, and the solve still runs."""
    state = initial.from_omega(Q0.astype(jnp.float32), OMEGA0.astype(jnp.float32))
    with pytest.warns(PrecisionWarning, match=r"float32 resolves times near t = 1000") as got:
        traj = simulate(free_scene(), state, jnp.linspace(0.0, 1000.0, 21))
    assert len(got) == 1 and got[0].filename == __file__
    assert int(traj.result) == 0


def test_precision_problem_threshold():
    """The floor |ω| max|t| eps against rtol; float64 and traced inputs are never examined."""
    omega = np.array([0.0, 0.0, 2.0])
    eps32 = float(np.finfo(np.float32).eps)
    state = initial.from_omega(omega=jnp.asarray(omega, jnp.float32))
    rtol = jnp.asarray(1e-5, jnp.float32)
    t_edge = 1e-5 / (2.0 * eps32)  # floor = rtol here
    for t_end, warns in ((0.9 * t_edge, False), (1.1 * t_edge, True)):
        ts = jnp.asarray([-1.0, t_end], jnp.float32)
        assert (precision_problem(state, ts, rtol) is not None) == warns
    ts = jnp.asarray([-1.1 * t_edge, 0.0], jnp.float32)  # |t0| counts as well
    assert "coarser than rtol = 1e-05 asks" in precision_problem(state, ts, rtol)
    tiny_rtol = jnp.asarray(1e-7, jnp.float32)  # below 10 eps: refused by the checks instead
    assert precision_problem(state, ts, tiny_rtol) is None
    state64 = initial.from_omega(omega=jnp.asarray(omega))
    assert precision_problem(state64, jnp.asarray([0.0, 1e12]), jnp.asarray(1e-10)) is None
    traced = jax.jit(lambda s: precision_problem(s, ts, rtol) is None)
    assert traced(state)
