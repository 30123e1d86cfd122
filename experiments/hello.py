"""Hello: a steady spin drawn, and ω recovered from q̇ = ½ q ⊗ (0, ω) (eq. 17.44).

The smallest experiment, and the template for new ones. A body turns at a constant rate
about a fixed axis, ``q(t) = exp(t ω/2)`` (eq. 17.25 with angle ``|ω| t``); its angular
velocity is recovered from central differences of ``q`` through
:func:`jrigid.quaternion.angular_velocity` (eq. 17.42) and compared with the exact ``ω``.
Writes a still of the body with its ``ω`` arrow, a plot of ``ω(t)``, ``numbers.json`` and
``report.md``.

Run it with ``jrigid run hello [--quick] [key=value ...]`` or ``python experiments/hello.py``.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import quaternion as quat
from jrigid import viz
from jrigid.report import Report

SHAPES = {
    "box": lambda: viz.box(1.0, 0.6, 0.3),
    "disk": lambda: viz.disk(0.6, 0.08),
    "ellipsoid": lambda: viz.ellipsoid(0.6, 0.4, 0.25),
    "rod": lambda: viz.rod(1.2),
    "t_handle": lambda: viz.t_handle(),
}


def main(
    out_dir,
    quick: bool = False,
    *,
    rate: float = 2.0,
    axis: tuple = (0.0, 0.3, 1.0),
    duration: float = 3.0,
    samples: int = 61,
    shape: str = "box",
) -> dict:
    """Spin a body steadily and check ω from finite differences of q.

    Args:
        out_dir: results folder.
        quick: fewer samples.
        rate: angular speed ``|ω|`` in rad/s.
        axis: spin axis (body = space at t = 0), need not be normalised.
        duration: time span.
        samples: number of samples.
        shape: one of box, disk, ellipsoid, rod, t_handle.

    Returns:
        the numbers written to ``numbers.json``.
    """
    if shape not in SHAPES:
        raise ValueError(f"shape must be one of {', '.join(SHAPES)}, got {shape!r}")
    if samples < 3:
        raise ValueError(
            f"samples must be >= 3 (central differences need neighbours), got {samples}")
    n = 21 if quick else samples
    axis = np.asarray(axis, dtype=float)
    if axis.shape != (3,) or not np.linalg.norm(axis) > 0:
        raise ValueError(f"axis must be three numbers, not all zero, got {axis.tolist()}")
    omega = rate * axis / np.linalg.norm(axis)
    ts = np.linspace(0.0, duration, n)
    h = 1e-4 * max(duration, 1.0)

    @jax.jit
    def motion(t):
        """Orientation at times t, and ω from central differences of q (17.42)."""
        q_of = lambda s: quat.from_rotvec(s[:, None] * jnp.asarray(omega)[None, :])
        q = q_of(t)
        qdot = (q_of(t + h) - q_of(t - h)) / (2 * h)
        return q, quat.angular_velocity(q, qdot)

    q, omega_fd = (np.asarray(x) for x in motion(jnp.asarray(ts)))
    # body frame = space frame at t = 0 and the axis is fixed: ω_body = ω
    err = float(np.max(np.abs(omega_fd - omega[None, :])))

    rep = Report(Path(out_dir), title="Hello: a steady spin")
    rep.text(
        f"A {shape} spins at |ω| = {rate:g} rad/s about {np.round(omega / rate, 4).tolist()} for "
        f"{duration:g} s ({n} samples). ω recovered from central differences of q agrees with "
        f"the exact value to {err:.2e} (the O(h²) error of the difference, h = {h:g})."
    )
    data = {"ts": ts, "q": q, "omega": omega_fd}
    mesh = SHAPES[shape]()
    rep.figure("body", viz.space_body_views(data, mesh, dpi=60), caption="space and body views")
    rep.figure("omega", viz.plot_omega(data), caption="ω from finite differences")
    numbers = {"max_abs_error_omega": err, "rate": rate, "samples": n, "shape": shape}
    rep.numbers(numbers)
    rep.write_summary()
    print(f"hello: ω recovered to {err:.2e} from {n} samples of q")
    return numbers


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "hello")
