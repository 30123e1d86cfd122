"""The top level of the package: every public submodule and name loads on first use."""

from __future__ import annotations

import pathlib
import subprocess
import sys

import jrigid

PACKAGE = pathlib.Path(jrigid.__file__).parent


def _public_modules() -> set[str]:
    """Public modules and subpackages, read from the folder itself."""
    names = {p.stem for p in PACKAGE.glob("*.py")}
    names |= {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}
    return {n for n in names if not n.startswith("_")}


def test_every_public_submodule_is_an_attribute():
    modules = _public_modules()
    assert {"stability", "contact", "lagrange_top", "ensemble", "viz"} <= modules
    assert modules <= set(jrigid.__all__) and modules <= set(dir(jrigid))
    for name in sorted(modules):
        assert getattr(jrigid, name).__name__ == f"jrigid.{name}"


def test_every_exported_name_resolves_and_unknown_names_fail():
    for name in jrigid.__all__:
        assert getattr(jrigid, name) is not None
    assert jrigid.simulate.__module__ == "jrigid.integrate"
    try:
        jrigid.no_such_name  # noqa: B018
    except AttributeError as exc:
        assert "no_such_name" in str(exc)
    else:
        raise AssertionError("an unknown attribute must raise AttributeError")


def test_import_stays_light():
    """``import jrigid`` and its module list import neither JAX nor matplotlib."""
    code = ("import sys, jrigid; jrigid.__all__; dir(jrigid); "
            "assert 'jax' not in sys.modules and 'matplotlib' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)
