"""Quaternion rotation: orienting a block (17.25-17.28), axis-angle back, non-unit and zero q.

Exercises 17.8-17.10 with :mod:`jrigid.quaternion`. The block's long side is body x.
Quaternions ``(cos θ/2, u sin θ/2)`` (17.25) turn it to 45° in the x-y plane, to 45° in the
z-y plane and along ``(1, 2, 1)``; the rotated long side ``q ⊗ (0, x̂) ⊗ q*`` (17.26) is
checked against the target, the norm of (17.25) is 1 and lengths are kept (Exercise 17.8),
and the axis and angle come back out through ``to_axis_angle`` and the chapter's
``θ = 2 arccos q0, e = q/|q|`` (17.27).

Exercise 17.9c, what a non-unit or zero quaternion does, with the library's documented
behaviour: ``quaternion.rotate`` evaluates (17.26) as written, so ``c q`` scales every
vector by ``c²`` (the body grows); ``quaternion.to_matrix`` divides by ``|q|²`` (as scipy),
so ``c q`` gives the same rotation; a zero quaternion collapses every vector to 0 under
``rotate`` and gives NaN from ``to_matrix``; ``quaternion.check_quaternion`` rejects both
with a ``ValueError`` naming the problem (messages stored in ``numbers.json``).

Run it with ``jrigid run quaternion_rotation [--quick]`` or
``python experiments/quaternion_rotation.py``.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import affine, viz
from jrigid import quaternion as quat
from jrigid.report import Report

EX = jnp.array([1.0, 0.0, 0.0])
TARGETS = {
    "45deg_in_xy": (1.0, 1.0, 0.0),
    "45deg_in_zy": (0.0, 1.0, 1.0),
    "along_121": (1.0, 2.0, 1.0),
}


def orient_long_side(target) -> jax.Array:
    """Quaternion (17.25) turning body x onto ``target`` about ``x̂ × target``."""
    t = jnp.asarray(target) / jnp.linalg.norm(jnp.asarray(target))
    return quat.from_axis_angle(jnp.cross(EX, t), jnp.arccos(jnp.dot(EX, t)))


def _error_message(q) -> str:
    try:
        quat.check_quaternion(q)
    except ValueError as e:
        return str(e)
    return "(accepted)"


def main(out_dir, quick: bool = False, *, scale: float = 2.0, seed: int = 0) -> dict:
    """Orient the block, recover axis and angle, and show non-unit and zero quaternions.

    Args:
        out_dir: results folder.
        quick: no effect (the experiment is instantaneous); kept for the test runner.
        scale: factor ``c`` of the non-unit quaternion ``c q``.
        seed: random seed of the vectors used for the length check.

    Returns:
        the numbers written to ``numbers.json``.
    """
    v = jnp.asarray(np.random.default_rng(seed).normal(size=(16, 3)))
    numbers: dict = {}
    qs = {}
    for name, target in TARGETS.items():
        q = orient_long_side(target)
        qs[name] = q
        t = np.asarray(target) / np.linalg.norm(target)
        axis, angle = quat.to_axis_angle(q)
        q0, qv = float(q[0]), np.asarray(q[1:])
        numbers[name] = {
            "q": q,
            "norm_minus_1": float(quat.norm(q) - 1.0),
            "long_side": quat.rotate(q, EX),
            "long_side_error": float(np.max(np.abs(np.asarray(quat.rotate(q, EX)) - t))),
            "length_change": float(
                jnp.max(
                    jnp.abs(
                        jnp.linalg.norm(quat.rotate(q[None], v), axis=-1)
                        - jnp.linalg.norm(v, axis=-1)
                    )
                )
            ),  # fmt: skip
            "axis": axis,
            "angle_deg": float(np.degrees(angle)),
            "angle_deg_theory": float(np.degrees(np.arccos(t[0]))),
            "axis_17_27": qv / np.linalg.norm(qv),
            "angle_deg_17_27": float(np.degrees(2 * np.arccos(q0))),
        }
    q = qs["along_121"]
    cq, zero = scale * q, jnp.zeros(4)
    numbers["non_unit"] = {
        "scale": scale,
        "rotate_length_ratio": float(jnp.linalg.norm(quat.rotate(cq, EX))),
        "rotate_length_ratio_theory": scale**2,
        "to_matrix_difference": float(jnp.max(jnp.abs(quat.to_matrix(cq) - quat.to_matrix(q)))),
        "check_quaternion_message": _error_message(cq),
    }
    numbers["zero"] = {
        "rotate": quat.rotate(zero, EX),
        "to_matrix_all_nan": bool(jnp.all(jnp.isnan(quat.to_matrix(zero)))),
        "check_quaternion_message": _error_message(zero),
    }

    rep = Report(Path(out_dir), title="Quaternion rotation")
    rows = [(k, *np.round(np.asarray(numbers[k]["q"]), 6), numbers[k]["angle_deg"],
             numbers[k]["long_side_error"]) for k in TARGETS]  # fmt: skip
    rep.table(rows, ("orientation", "q0", "q1", "q2", "q3", "angle (°)", "long-side error"))
    rep.text(
        f"Non-unit q (×{scale:g}): rotate scales vectors by "
        f"{numbers['non_unit']['rotate_length_ratio']:.6g} = c², to_matrix is unchanged "
        f"({numbers['non_unit']['to_matrix_difference']:.1e}); check_quaternion says: "
        f"“{numbers['non_unit']['check_quaternion_message']}”. Zero q: rotate gives "
        f"{np.asarray(numbers['zero']['rotate']).tolist()}, to_matrix NaN; check_quaternion "
        f"says: “{numbers['zero']['check_quaternion_message']}”."
    )
    rep.figure(
        "orientations",
        _figure(qs, cq),
        caption="long side (accent face +x) turned onto the red target; purple: rotation "
        "axis (17.27); right: a non-unit q",
        dpi=70,
    )
    rep.numbers(numbers)
    rep.write_summary()
    worst = max(numbers[k]["long_side_error"] for k in TARGETS)
    print(f"quaternion_rotation: largest long-side error {worst:.1e}")
    return numbers


def _panel(ax, A, arrows, title, camera):
    """Block placed by the linear map ``A (3, 3)``, with arrows, painter's algorithm."""
    mesh = viz.box(1.0, 0.4, 0.2)
    T = np.asarray(affine.from_blocks(jnp.asarray(A), jnp.zeros(3)))
    parts = [viz.render.mesh_polygons(mesh, T, camera)]
    for vec, color in arrows:
        parts.append(
            viz.render.arrow_polygons(
                np.zeros(3), vec, camera, color, width=0.02, head_length=0.1, head_width=0.07
            )
        )
    viz.render.draw_polygons(ax, viz.render.combine(*parts))
    viz.render.setup_axes(ax, 1.25, title)


def _figure(qs, cq):
    cam = viz.Camera(elev=20, azim=-50)
    axes_arrows = [(0.9 * e, "#999999") for e in np.eye(3)]
    fig = viz.new_figure(figsize=(13, 3.0), layout=None)
    axs = [fig.add_axes((k / 5, 0.0, 0.2, 0.85)) for k in range(5)]
    titles = {
        "45deg_in_xy": "45° in x-y",
        "45deg_in_zy": "45° in z-y",
        "along_121": "along (1, 2, 1)",
    }
    for ax, (name, q) in zip(axs, qs.items(), strict=False):
        axis, _ = quat.to_axis_angle(q)
        t = np.asarray(TARGETS[name]) / np.linalg.norm(TARGETS[name])
        arrows = [*axes_arrows, (1.1 * t, "#d62728"), (0.8 * np.asarray(axis), "#9467bd")]
        _panel(ax, quat.to_matrix(q), arrows, titles[name], cam)
    _panel(axs[3], quat.to_matrix(cq), axes_arrows, "2q, to_matrix: normalised", cam)
    A = np.asarray(quat.rotate(cq[None], jnp.eye(3))).T  # columns: images of x, y, z
    _panel(axs[4], A / 2.0, axes_arrows, "2q, rotate: ×4 (half scale)", cam)
    return fig


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "quaternion_rotation")
