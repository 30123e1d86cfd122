"""jrigid: differentiable rigid-body rotation in JAX.

Layers (imports point down the stack):

- geometry: :mod:`jrigid.quaternion`, :mod:`jrigid.affine`, :mod:`jrigid.inertia`
- dynamics: :class:`RigidBody`, :class:`Scene` with holders (:class:`FreeRotation`,
  :class:`Pivot`, :class:`FreeFlight`) and loads (:class:`Gravity`, :class:`Torque`),
  :mod:`jrigid.initial` for initial conditions, :mod:`jrigid.formulations`
- integration: :func:`simulate` (diffrax), :func:`leapfrog` (the chapter's stepper),
  :mod:`jrigid.exact` (closed-form torque-free motion), :mod:`jrigid.special`
- presentation: :mod:`jrigid.viz` (matplotlib; imported only on request), the ``jrigid``
  command line

``import jrigid`` does not import matplotlib.
"""

from jrigid import affine, inertia, initial, quaternion
from jrigid.body import RigidBody
from jrigid.formulations import (
    BodyOmega,
    EulerAngles,
    QuaternionAcceleration,
    QuaternionOmega,
)
from jrigid.leapfrog import leapfrog
from jrigid.scene import FreeFlight, FreeRotation, Gravity, Pivot, Scene, Torque
from jrigid.simulate import Result, SimulationError, simulate
from jrigid.state import Kinematics, State
from jrigid.trajectory import Trajectory

__version__ = "0.1.0"

__all__ = [
    "BodyOmega",
    "EulerAngles",
    "FreeFlight",
    "FreeRotation",
    "Gravity",
    "Kinematics",
    "Pivot",
    "QuaternionAcceleration",
    "QuaternionOmega",
    "Result",
    "RigidBody",
    "Scene",
    "SimulationError",
    "State",
    "Torque",
    "Trajectory",
    "affine",
    "inertia",
    "initial",
    "leapfrog",
    "quaternion",
    "simulate",
]
