"""Run a setting once JAX is imported, without importing it (``import jrigid`` stays
free of JAX until something needs it)."""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys
from collections.abc import Callable

__all__ = ["after_jax_import"]

_PENDING: list[Callable[[], None]] = []


class _AfterJaxImport(importlib.abc.MetaPathFinder):
    """Run the pending settings once ``jax`` has been imported."""

    def find_spec(self, name, path=None, target=None):
        if name != "jax":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        exec_module = spec.loader.exec_module

        def exec_then_configure(module):
            exec_module(module)
            pending = list(_PENDING)
            _PENDING.clear()
            for fn in pending:
                fn()

        spec.loader.exec_module = exec_then_configure
        return spec


def after_jax_import(fn: Callable[[], None]) -> None:
    """Call ``fn()`` now if JAX is imported, else right after ``import jax`` (once)."""
    if "jax" in sys.modules:
        fn()
        return
    if fn not in _PENDING:
        _PENDING.append(fn)
    if not any(isinstance(f, _AfterJaxImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterJaxImport())
