"""Whether a :class:`~jrigid.scene.Scene` is a heavy symmetric top, and its constants."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid._checks import is_traced
from jrigid.scene import Gravity, Pivot, Scene

from ._constants import TopConstants, prepare

__all__ = ["applies", "check_scene", "prepare_scene", "scene_gravity", "value_checks"]


def _problems(scene: Scene) -> list[str]:
    """Why ``scene`` is not a Lagrange top (empty if it is)."""
    problems = []
    if not isinstance(scene, Scene):
        return [f"expected a Scene, got {type(scene).__name__}"]
    if not isinstance(scene.holder, Pivot):
        problems.append(f"it needs a Pivot holder, the scene has {type(scene.holder).__name__}")
    others = [type(load).__name__ for load in scene.loads if not isinstance(load, Gravity)]
    if others:
        problems.append(f"its only loads may be Gravity, the scene has {', '.join(others)}")
    body = scene.body
    if not is_traced(body.moments, body.com, body.mass):
        moments, com = np.asarray(body.moments), np.asarray(body.com)
        if moments.shape != (3,) or com.shape != (3,):
            problems.append("it needs one body (moments (3,), com (3,)); vmap for batches")
        else:
            if moments[0] != moments[1]:
                problems.append(
                    f"the body must be symmetric about axis 3 (I1 == I2 exactly), got {moments}"
                )
            if com[0] != 0 or com[1] != 0:
                problems.append(
                    f"the centre of mass must lie on the symmetry axis (0, 0, l), got {com}"
                )
    return problems


def applies(scene: Scene) -> bool:
    """Whether the closed form describes ``scene`` (a static, trace-time decision).

    True for a :class:`~jrigid.scene.Pivot` scene whose loads are only
    :class:`~jrigid.scene.Gravity` (any number, summed; none is a torque-free symmetric
    body) and whose body is symmetric, ``I1 == I2`` **exactly**, with its centre of mass
    exactly on the symmetry axis, ``com = (0, 0, l)``. A body that is symmetric only to
    rounding (e.g. built from a tensor) is not: the closed form would silently be the
    motion of a slightly different body. When the body's values are traced (the scene is
    a ``jit`` argument) only the structure is decided here; :func:`prepare` checks the
    values at run time.

    Args:
        scene: a :class:`~jrigid.scene.Scene`.

    Returns:
        ``bool``.
    """
    return not _problems(scene)


def check_scene(scene: Scene) -> None:
    """Raise ``ValueError`` saying why ``scene`` is not a Lagrange top (see :func:`applies`).

    Args:
        scene: a :class:`~jrigid.scene.Scene`.
    """
    problems = _problems(scene)
    if problems:
        raise ValueError(
            "the closed-form heavy symmetric top does not apply: " + "; ".join(problems)
        )


def value_checks(scene: Scene) -> list[tuple[jax.Array, str]]:
    """``[(bad, message), ...]``: the body's values that :func:`applies` cannot decide
    when they are traced (``jit``/``vmap``), as flags for a solve's input checks (an
    invalid member then gets a result code, not an error).

    Args:
        scene: a scene with a :class:`~jrigid.scene.Pivot` holder and Gravity loads.

    Returns:
        ``()`` boolean flags and their messages: ``I1 != I2``, ``com`` off the axis.
    """
    moments, com = scene.body.moments, scene.body.com
    return [
        (moments[..., 0] != moments[..., 1],
         "solver='exact' (the heavy symmetric top) needs I1 == I2 exactly"),
        ((com[..., 0] != 0) | (com[..., 1] != 0),
         "solver='exact' (the heavy symmetric top) needs the centre of mass on the "
         "symmetry axis, com = (0, 0, l)"),
    ]


def scene_gravity(scene: Scene) -> jax.Array:
    """``(3,)`` total gravitational field of a scene's :class:`~jrigid.scene.Gravity` loads."""
    total = jnp.zeros(3, dtype=scene.body.moments.dtype)
    for load in scene.loads:
        if isinstance(load, Gravity):
            total = total + load.g
    return total


def prepare_scene(scene: Scene, q0: ArrayLike, omega0: ArrayLike) -> TopConstants:
    """:func:`prepare` for a :class:`~jrigid.scene.Scene` (checked with :func:`check_scene`).

    Args:
        scene: a Lagrange-top scene (one body; its Gravity loads are summed).
        q0: ``(4,)`` initial orientation; omega0: ``(3,)`` initial body angular velocity
            (e.g. ``state.q``, ``state.omega`` of a :class:`~jrigid.state.State`).

    Returns:
        :class:`TopConstants` (batch shape ``()``).
    """
    check_scene(scene)
    body = scene.body
    return prepare(body.moments, body.mass, body.com, scene_gravity(scene), q0, omega0)
