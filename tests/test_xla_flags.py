"""Importing jrigid raises XLA:CPU's small-while-loop threshold and turns its MLIR fusion
emitters off (``jrigid._xla``).

The mechanism is checked where it acts: in a fresh interpreter, the compiled program of a
solve saving 101 times (the default solver and the eighth-order pairs) holds each of its
loops as one kernel (every ``while`` a call XLA marks ``xla_cpu_small_call``) when jrigid
was imported first, and not when the threshold is XLA's 1 kB default.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from jrigid import _xla

OPTION = _xla.OPTION
EXTRA = "--xla_backend_extra_options"


@pytest.mark.parametrize(
    "flags, expected",
    [
        ("", f"{EXTRA}={OPTION}=100000000"),
        ("--xla_force_host_platform_device_count=4",
         f"--xla_force_host_platform_device_count=4 {EXTRA}={OPTION}=100000000"),
        (f"{EXTRA}=xla_cpu_foo=1 --xla_dump_to=/tmp/x",
         f"{EXTRA}=xla_cpu_foo=1,{OPTION}=100000000 --xla_dump_to=/tmp/x"),
        (f"{EXTRA}=", f"{EXTRA}={OPTION}=100000000"),
        (f"{EXTRA}={OPTION}=1024", f"{EXTRA}={OPTION}=1024"),
    ],
    ids=["empty", "other_flag", "other_option", "empty_option", "user_threshold_kept"],
)
def test_with_threshold_adds_the_option_once(flags, expected):
    assert _xla.with_threshold(flags) == expected
    assert _xla.with_threshold(expected) == expected


@pytest.mark.parametrize(
    "flags, expected",
    [
        ("", _xla.EMITTERS),
        ("--xla_dump_to=/tmp/x", f"--xla_dump_to=/tmp/x {_xla.EMITTERS}"),
        ("--xla_cpu_use_fusion_emitters=true", "--xla_cpu_use_fusion_emitters=true"),
    ],
    ids=["empty", "other_flag", "user_setting_kept"],
)
def test_with_emitters_adds_the_flag_once(flags, expected):
    assert _xla.with_emitters(flags) == expected
    assert _xla.with_emitters(expected) == expected


def test_jaxlib_release_is_the_installed_version():
    from importlib import metadata

    major, minor = metadata.version("jaxlib").split(".")[:2]
    assert _xla._jaxlib_release() == (int(major), int(minor))


# What importing jrigid adds to empty XLA_FLAGS besides the threshold: the emitter flag
# where this jaxlib has it (XLA stops the process on an unknown flag).
_EMITTERS = f" {_xla.EMITTERS}" if _xla._jaxlib_release() in _xla.EMITTER_JAXLIB else ""


def _run(code: str, xla_flags: str | None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["JAX_PLATFORMS"] = "cpu"
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env,
                          capture_output=True, text=True, timeout=300)


_COMPILED_SOLVE = """
    import os
    import re
    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from jrigid import initial, simulate, solvers
    from jrigid.body import RigidBody
    from jrigid.scene import Scene

    scene = Scene(RigidBody((1.0, 2.0, 3.0)))
    state = initial.from_omega(jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.array([1.0, 0.3, 0.7]))
    ts = jnp.linspace(0.0, 10.0, 101)
    solver = {solver}
    solve = jax.jit(lambda s: simulate(scene, s, ts, solver=solver).q)
    text = solve.lower(state).compile().as_text()
    print(os.environ["XLA_FLAGS"])
    loops = len(re.findall(r"[ ]while[(]", text))
    kernels = text.count("xla_cpu_small_call")
    print("one kernel" if loops and kernels == loops else "dispatched")
"""


@pytest.mark.parametrize("solver", ["None", "solvers.FusedDopri8()", "solvers.FusedDop853()"])
def test_import_compiles_a_solve_loop_into_one_kernel(solver):
    # The default and the eighth-order pairs, saving 101 times (their dense output is
    # evaluated inside the loop: a matrix product there would keep it dispatched).
    out = _run(_COMPILED_SOLVE.replace("{solver}", solver), xla_flags=None)
    assert out.returncode == 0, out.stderr
    flags, verdict = out.stdout.split("\n")[:2]
    assert flags == f"--xla_backend_extra_options={OPTION}=100000000{_EMITTERS}"
    assert verdict == "one kernel"
    assert "RuntimeWarning" not in out.stderr


def test_a_threshold_set_by_the_user_is_kept():
    out = _run(_COMPILED_SOLVE.replace("{solver}", "None"),
               xla_flags=f"--xla_backend_extra_options={OPTION}=1024")
    assert out.returncode == 0, out.stderr
    flags, verdict = out.stdout.split("\n")[:2]
    assert flags == f"--xla_backend_extra_options={OPTION}=1024{_EMITTERS}"
    assert verdict == "dispatched"  # XLA's default: the loop's buffers are above 1 kB


def test_emitters_the_user_set_are_kept():
    user = "--xla_cpu_use_fusion_emitters=true"
    out = _run(_COMPILED_SOLVE.replace("{solver}", "None"), xla_flags=user)
    assert out.returncode == 0, out.stderr
    flags, verdict = out.stdout.split("\n")[:2]
    assert flags == f"{user} --xla_backend_extra_options={OPTION}=100000000"
    assert verdict == "one kernel"


def test_importing_after_jax_started_warns_how_to_get_the_fast_path():
    out = _run("""
        import warnings
        import jax.numpy as jnp
        jnp.ones(2).block_until_ready()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            import jrigid  # noqa: F401
        print(len(caught), caught[0].category.__name__, caught[0].message)
    """, xla_flags=None)
    assert out.returncode == 0, out.stderr
    count, category, message = out.stdout.split(" ", 2)
    assert (count, category) == ("1", "RuntimeWarning")
    assert "Import jrigid before running JAX" in message and OPTION in message
