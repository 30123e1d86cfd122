"""scipy's DOP853 coefficients (``scipy.integrate._ivp.dop853_coefficients``: Hairer's
tableau, error estimates and dense output), loaded from their file on their own.

Importing the module the usual way imports the whole ``scipy.integrate`` package first
(``scipy.optimize``, ``scipy.special``, ...): 0.2–0.5 s of a new script's first
``simulate``, for a file that needs only NumPy. When the package is already imported,
or the file is not where scipy keeps it, the module is imported the usual way.
"""

from __future__ import annotations

import importlib
import importlib.util
import pathlib
import sys

_NAME = "scipy.integrate._ivp.dop853_coefficients"


def load():
    """The coefficients module (``A``, ``B``, ``C``, ``E3``, ``E5``, ``D``, ``N_STAGES``,
    ``N_STAGES_EXTENDED``, ``INTERPOLATOR_POWER``)."""
    if _NAME in sys.modules:
        return sys.modules[_NAME]
    spec = importlib.util.find_spec("scipy")  # finds scipy without importing it
    origin = None if spec is None else spec.origin
    path = None if origin is None else (
        pathlib.Path(origin).parent / "integrate" / "_ivp" / "dop853_coefficients.py")
    if path is None or not path.is_file():
        return importlib.import_module(_NAME)
    file_spec = importlib.util.spec_from_file_location("jrigid.solvers._scipy_dop853", path)
    module = importlib.util.module_from_spec(file_spec)
    file_spec.loader.exec_module(module)
    return module


coefficients = load()
