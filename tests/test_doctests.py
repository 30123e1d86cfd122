"""The ``>>>`` examples in jrigid's docstrings run and print what they say.

Every module of the package is imported (``pkgutil.walk_packages``) and searched with
:class:`doctest.DocTestFinder`; each module with examples is one test, named by the
module, run with ``ELLIPSIS`` and ``NORMALIZE_WHITESPACE``. A failure shows doctest's
own report. The JAX configuration an example changes (``jax_enable_x64``, ...) is
restored afterwards, so an example cannot leak into the tests that follow.
"""

import doctest
import importlib
import pkgutil

import jax
import pytest

import jrigid

OPTIONFLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE

# Modules whose examples are the documentation of a whole workflow: at least this many
# examples must run, so that a trimmed docstring is noticed.
MIN_EXAMPLES = {"jrigid.fit": 10}

# JAX options an example may switch; each is put back after the module's examples ran.
JAX_OPTIONS = ("jax_enable_x64", "jax_numpy_rank_promotion", "jax_debug_nans")


def _modules():
    """jrigid and every module below it, imported, in name order."""
    failed = []
    names = {"jrigid"}
    for info in pkgutil.walk_packages(jrigid.__path__, "jrigid.", onerror=failed.append):
        names.add(info.name)
    if failed:
        raise ImportError(f"walking jrigid failed in {failed}")
    return [importlib.import_module(name) for name in sorted(names)]


def _doctests(module):
    """The module's doctests that hold examples (its own objects only, not re-exports)."""
    tests = doctest.DocTestFinder(exclude_empty=True).find(module, module.__name__)
    return sorted((t for t in tests if t.examples), key=lambda t: t.name)


MODULES_WITH_EXAMPLES = [m.__name__ for m in _modules() if _doctests(m)]


def test_some_modules_have_examples():
    """Guard: the finder sees the package's examples (an empty list would test nothing)."""
    assert MODULES_WITH_EXAMPLES, "no jrigid module has >>> examples: the finder is broken"
    assert set(MIN_EXAMPLES) <= set(MODULES_WITH_EXAMPLES)


@pytest.mark.parametrize("name", MODULES_WITH_EXAMPLES)
def test_examples(name):
    module = importlib.import_module(name)
    tests = _doctests(module)
    report = []
    runner = doctest.DocTestRunner(optionflags=OPTIONFLAGS, verbose=False)
    saved = {option: getattr(jax.config, option) for option in JAX_OPTIONS}
    failed = attempted = 0
    try:
        for test in tests:
            result = runner.run(test, out=report.append)
            failed += result.failed
            attempted += result.attempted
    finally:
        for option, value in saved.items():
            jax.config.update(option, value)
    if failed:
        pytest.fail(f"{failed} of {attempted} examples of {name} failed:\n" + "".join(report),
                    pytrace=False)
    assert attempted >= MIN_EXAMPLES.get(name, 1)
