"""jrigid: differentiable rigid-body rotation in JAX.

Layers (imports point down the stack):

- geometry: :mod:`jrigid.quaternion`, :mod:`jrigid.affine`, :mod:`jrigid.inertia`
- dynamics: :class:`RigidBody`, :class:`Scene` with holders (:class:`FreeRotation`,
  :class:`Pivot`, :class:`FreeFlight`) and loads (:class:`Gravity`, :class:`Torque`),
  :mod:`jrigid.initial` for initial conditions, :mod:`jrigid.formulations`
- integration: :func:`simulate` (diffrax, in :mod:`jrigid.integrate`),
  :func:`simulate_bounces` with a :class:`Floor` (impulsive contact, :mod:`jrigid.contact`),
  :mod:`jrigid.leapfrog` (the chapter's stepper), :mod:`jrigid.exact` (closed-form
  torque-free motion) on :mod:`jrigid.special` (elliptic functions),
  :class:`Splitting` (exact-flow splitting under a torque, :mod:`jrigid.splitting`)
- the chapter's theory: :mod:`jrigid.theory` (closed-form results and rate measurements),
  :mod:`jrigid.polhode`, :mod:`jrigid.ftle`
- applications: :mod:`jrigid.stability`, :mod:`jrigid.fit`, :mod:`jrigid.ensemble`
- presentation: :mod:`jrigid.viz` (matplotlib), the ``jrigid`` command line

``ARCHITECTURE.md`` describes the layout. Names and submodules load on first use, so
``import jrigid`` imports neither JAX nor matplotlib until something needs them
(``jrigid list`` stays instant).

Importing jrigid raises XLA:CPU's small-while-loop threshold in ``XLA_FLAGS`` (unless
already set), so that a solve's loop compiles into one kernel: 4–6× faster solves, 13×
faster gradients, and turns XLA:CPU's MLIR fusion emitters off, for shorter compiles
(``jrigid._xla`` says why and how to opt out); it also turns JAX's
asynchronous CPU dispatch off when JAX is imported, so that a solve runs on the calling
thread: with the default solve compiled into one kernel, a 2-step call took about 40 µs
instead of 145 µs on an Intel Xeon (``jrigid._dispatch``; the README has later numbers).
And it points JAX's persistent compilation cache at ``~/.cache/jrigid/xla``, so that a
script run again loads its compiled solves instead of compiling them (``jrigid._cache``;
``JRIGID_CACHE_DIR`` chooses the directory, ``JRIGID_CACHE_DIR=off`` turns it off, a
directory set for JAX is kept).
"""

from __future__ import annotations

import importlib
import pkgutil
from typing import TYPE_CHECKING

from jrigid import _cache, _dispatch, _xla

_xla.configure()
_dispatch.configure()
_cache.configure()

__version__ = "0.1.0"

_EXPORTS = {
    "RigidBody": "jrigid.body",
    "BodyOmega": "jrigid.formulations",
    "EulerAngles": "jrigid.formulations",
    "QuaternionAcceleration": "jrigid.formulations",
    "QuaternionOmega": "jrigid.formulations",
    "FreeFlight": "jrigid.scene",
    "FreeRotation": "jrigid.scene",
    "Gravity": "jrigid.scene",
    "Pivot": "jrigid.scene",
    "Scene": "jrigid.scene",
    "Torque": "jrigid.scene",
    "Kinematics": "jrigid.state",
    "State": "jrigid.state",
    "Trajectory": "jrigid.trajectory",
    "Result": "jrigid.trajectory",
    "SimulationError": "jrigid.trajectory",
    "PrecisionWarning": "jrigid.solve",
    "simulate": "jrigid.integrate",
    "Splitting": "jrigid.splitting",
    "Floor": "jrigid.contact",
    "simulate_bounces": "jrigid.contact",
}
# Every public submodule (the package folder's modules and subpackages without a leading
# underscore), read from the folder without importing any of them.
_SUBMODULES = tuple(sorted(m.name for m in pkgutil.iter_modules(__path__)
                           if not m.name.startswith("_")))

__all__ = sorted([*_EXPORTS, *_SUBMODULES])


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
    elif name in _SUBMODULES:
        value = importlib.import_module(f"jrigid.{name}")
    else:
        raise AttributeError(f"module 'jrigid' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS, *_SUBMODULES])


if TYPE_CHECKING:
    from jrigid import (  # noqa: F401
        affine,
        batching,
        body,
        camera,
        cli,
        closed_form,
        contact,
        demo,
        ensemble,
        exact,
        experiment_parameters,
        fit,
        formulations,
        ftle,
        impacts,
        inertia,
        initial,
        integrate,
        invariants,
        lagrange_top,
        leapfrog,
        linalg,
        polhode,
        quaternion,
        registry,
        report,
        scene,
        solve,
        solvers,
        special,
        splitting,
        stability,
        state,
        theory,
        trajectory,
        viz,
    )
    from jrigid.body import RigidBody  # noqa: F401
    from jrigid.contact import Floor, simulate_bounces  # noqa: F401
    from jrigid.formulations import (  # noqa: F401
        BodyOmega,
        EulerAngles,
        QuaternionAcceleration,
        QuaternionOmega,
    )
    from jrigid.integrate import simulate  # noqa: F401
    from jrigid.scene import FreeFlight, FreeRotation, Gravity, Pivot, Scene, Torque  # noqa: F401
    from jrigid.solve import PrecisionWarning  # noqa: F401
    from jrigid.splitting import Splitting  # noqa: F401
    from jrigid.state import Kinematics, State  # noqa: F401
    from jrigid.trajectory import Result, SimulationError, Trajectory  # noqa: F401
