"""Shared helper for the ensemble tests: a Python subprocess with its own JAX devices.

JAX fixes its devices when it starts, so a test that needs several host devices (or a
process it can kill) runs its code in a fresh interpreter: :func:`python`.
"""

import os
import pathlib
import subprocess
import sys
import textwrap

ROOT = pathlib.Path(__file__).resolve().parents[1]

PRELUDE = f"""
import sys, time, numpy as np, jax
jax.config.update("jax_enable_x64", True)
sys.path.insert(0, {str(ROOT / "tests")!r})
from test_ensemble import rotor, rotor_inputs
from jrigid import ensemble
"""


def python(code: str, **env) -> subprocess.Popen:
    """Start ``code`` (dedented, after :data:`PRELUDE`: float64, numpy as ``np``, ``jax``,
    ``ensemble`` and the ``rotor`` model of test_ensemble) in a new interpreter on the CPU,
    with ``env`` added to the environment (e.g. ``XLA_FLAGS``); stdout/stderr are piped."""
    full = {**os.environ, "JAX_PLATFORMS": "cpu", **env}
    return subprocess.Popen(
        [sys.executable, "-c", PRELUDE + textwrap.dedent(code)],
        env=full, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
