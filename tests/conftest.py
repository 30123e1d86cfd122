"""Test configuration: float64 by default, rank promotion forbidden.

Tests that exercise the float32 path request the ``float32`` fixture, which
switches ``jax_enable_x64`` off for the duration of the test.

The run compiles into a persistent compilation cache of its own (``jrigid._cache``), a
fresh directory shared by the xdist workers (they inherit this process's environment)
and by the scripts the tests start, removed at the end; not the user's cache. Set
``JRIGID_CACHE_DIR`` to choose another (``off`` for none).
"""

import gc
import os
import shutil
import tempfile

# before jrigid is imported (the test modules import it)
_RUN_CACHE = None
if "JRIGID_CACHE_DIR" not in os.environ:
    _RUN_CACHE = tempfile.mkdtemp(prefix="jrigid-test-xla-")
    os.environ["JRIGID_CACHE_DIR"] = _RUN_CACHE

import jax  # noqa: E402
import pytest  # noqa: E402

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


def _mapped_regions() -> int:
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:  # not Linux
        return 0


# Clear between test files once this many regions are mapped (a file's tests reuse each
# other's programs, so clearing inside a file recompiles them); inside a file only past the
# hard limit, which leaves room for the ~2000 regions a single heavy test can add.
_CLEAR_BETWEEN_FILES = 20_000
_CLEAR_ALWAYS = 45_000


def _release() -> None:
    jax.clear_caches()
    gc.collect()


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs_between_files():
    """Free JAX's compiled programs when they pile up, at the start of a test file.

    Every compiled XLA:CPU program holds memory mappings of its own; a test process that
    compiles thousands of them reaches the kernel's ``vm.max_map_count`` (65530) and then
    crashes inside the compiler. Clearing the caches releases them (they are recompiled on
    demand).
    """
    if _mapped_regions() > _CLEAR_BETWEEN_FILES:
        _release()
    yield


@pytest.fixture(autouse=True)
def _release_compiled_programs():
    """The same inside a file, past the hard limit only."""
    yield
    if _mapped_regions() > _CLEAR_ALWAYS:
        _release()


# The test files that take the longest (worker time, measured on 2 cores), run first: with
# ``--dist loadfile`` a long file handed out last leaves the other worker idle at the end.
_LONGEST_FIRST = (
    "test_docs.py",
    "test_experiments_fit.py",
    "test_integrate.py",
    "test_fit.py",
    "test_invariants.py",
    "test_lockstep.py",
    "test_simulate_exact.py",
    "test_experiments_dynamics.py",
    "test_splitting.py",
    "test_exact_gradients.py",
    "test_lagrange_top.py",
    "test_stability.py",
    "test_dispatch.py",
    "test_experiments_motion.py",
    "test_experiments_geometry.py",
    "test_sweep_members.py",
)


def pytest_collection_modifyitems(items):
    rank = {name: i for i, name in enumerate(_LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


def pytest_sessionfinish(session):
    """Remove the compilation cache this process made (the xdist controller's, once its
    workers are done; a worker makes none, it inherits the controller's)."""
    if _RUN_CACHE is not None:
        shutil.rmtree(_RUN_CACHE, ignore_errors=True)
