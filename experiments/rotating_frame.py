"""A ball thrown on a rotating platform: the straight throw seen curving (Coriolis), Project 17.1.

The platform turns at ``Ω`` about the vertical ``z``. A thrower standing on its rim at
``r0 = (R, 0, 0)`` throws a ball toward the centre with velocity ``v' = (−u, 0, w)``
*relative to the platform*. In the inertial frame the ball leaves with ``v' + Ω ẑ × r0``
(the thrower moves with the rim) and flies a parabola: a :class:`~jrigid.scene.Scene` in
:class:`~jrigid.scene.FreeFlight` under :class:`~jrigid.scene.Gravity`, integrated by
:func:`jrigid.simulate`. The platform's orientation at time ``t`` is the quaternion
``q(t) = (cos ½Ωt, 0, 0, sin ½Ωt)`` (rotating frame → inertial), i.e. the rigid transform
``T(t) = affine.rotation_3d(q(t))``; the ball in platform coordinates is
``affine.apply_to_points(affine.inverse_rigid(T(t)), x(t))`` (checked against
``quaternion.rotate_inverse``).

*Exact rotating-frame path.* ``r'(t) = R_z(−Ωt) (r0 + (v' + Ω ẑ×r0) t + ½ g t²)``. The
ball lands at ``T = 2w/g`` (rotation about the vertical leaves the height alone). With
``θ = ΩT`` and horizontal vectors, ``R_z(−θ) a = a cos θ − sin θ ẑ×a``, so the landing
point minus the no-rotation landing point ``r0 + v'T`` is

    d = r0 (cos θ + θ sin θ − 1) + v'T (cos θ − 1) + ẑ×r0 (θ cos θ − sin θ) − T sin θ ẑ×v'.

For the throw toward the centre the sideways part, to the thrower's right, is
``R (θ cos θ − sin θ) + u T sin θ``.

*Small Ω.* To first order ``d ≈ −Ω T² ẑ × v'``: the Coriolis acceleration
``−2 Ω × v'`` integrated twice, ``Ω u T²`` to the right (a counter-clockwise platform
deflects moving things to the right), independent of where the throw starts. The next
term is relative ``−θ² (1/6 + R/(3uT))``. Independent check: the rotating-frame equation of
motion ``r̈' = g − 2Ω×ṙ' − Ω×(Ω×r')`` integrated by scipy's ``solve_ivp``.

Run it with ``jrigid run rotating_frame [--quick]``.
"""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp

from jrigid import affine, inertia, initial, viz
from jrigid import quaternion as quat
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.report import Report
from jrigid.scene import FreeFlight, Gravity, Scene

Z = np.array([0.0, 0.0, 1.0])


def platform_orientation(omega: float, ts) -> jax.Array:
    """``(T, 4)`` platform (rotating frame → inertial) quaternions ``q(t)`` about ``z``."""
    ts = jnp.asarray(ts)
    axis = jnp.broadcast_to(jnp.asarray(Z, ts.dtype), ts.shape + (3,))
    return quat.from_axis_angle(axis, omega * ts)


@jax.jit
def _to_rotating(omega, ts, x):
    q = platform_orientation(omega, ts)
    T_inv = affine.inverse_rigid(affine.rotation_3d(q))
    return affine.apply_to_points(T_inv, x), quat.rotate_inverse(q, x)


def to_rotating(omega: float, ts, x) -> tuple[np.ndarray, np.ndarray]:
    """Inertial points ``x (T, 3)`` in platform coordinates: by affine maps and by quaternions."""
    by_affine, by_quat = _to_rotating(jnp.asarray(omega, float), jnp.asarray(ts), jnp.asarray(x))
    return np.asarray(by_affine), np.asarray(by_quat)


def exact_rotating(omega, r0, v_rel, g, ts) -> np.ndarray:
    """Closed-form platform-frame path ``R_z(−Ωt)(r0 + (v' + Ω ẑ×r0) t + ½ g t²)``, ``(T, 3)``."""
    ts = np.asarray(ts)[:, None]
    v_in = v_rel + omega * np.cross(Z, r0)
    x = r0 + v_in * ts + 0.5 * np.array([0.0, 0.0, -g]) * ts**2
    c, s = np.cos(omega * ts[:, 0]), np.sin(omega * ts[:, 0])
    return np.stack([c * x[:, 0] + s * x[:, 1], -s * x[:, 0] + c * x[:, 1], x[:, 2]], axis=-1)


def rotating_eom(omega, r0, v_rel, g, ts) -> np.ndarray:
    """Platform-frame path from ``r̈' = g − 2Ω×ṙ' − Ω×(Ω×r')`` by scipy ``solve_ivp``."""
    W = omega * Z
    gv = np.array([0.0, 0.0, -g])

    def f(t, s):
        r, v = s[:3], s[3:]
        return np.concatenate([v, gv - 2 * np.cross(W, v) - np.cross(W, np.cross(W, r))])

    sol = solve_ivp(f, (ts[0], ts[-1]), np.concatenate([r0, v_rel]), t_eval=ts,
                    method="DOP853", rtol=1e-11, atol=1e-12)  # fmt: skip
    return sol.y[:3].T


def deflection_exact(omega, radius, u, T) -> float:
    """Sideways landing offset to the thrower's right, ``R (θ cos θ − sin θ) + u T sin θ``."""
    th = omega * T
    return radius * (th * math.cos(th) - math.sin(th)) + u * T * math.sin(th)


def throw(scene, omega, radius, u, w, g, n):
    """Simulate the throw in the inertial frame; return times, inertial and platform paths."""
    r0 = np.array([radius, 0.0, 0.0])
    v_rel = np.array([-u, 0.0, w])
    T = 2 * w / g
    ts = np.linspace(0.0, T, n)
    v_in = v_rel + omega * np.cross(Z, r0)
    state = initial.from_omega(None, (0.0, 0.0, 0.0), x=r0, v=v_in)
    traj = simulate(scene, state, ts, rtol=1e-10, atol=1e-12)
    x = np.asarray(traj.x)
    rot, rot_q = to_rotating(omega, ts, x)
    return dict(ts=ts, T=T, x=x, rot=rot, rot_q=rot_q, r0=r0, v_rel=v_rel)


def right_offset(path_end, r0, v_rel, T):
    """Landing point minus the no-rotation landing point, along the thrower's right."""
    right = -np.cross(Z, v_rel / np.linalg.norm(v_rel[:2]))
    return float(np.dot(path_end - (r0 + v_rel * T), right))


def main(
    out_dir,
    quick: bool = False,
    *,
    omega: float = 0.5,
    radius: float = 4.0,
    speed: float = 6.0,
    up: float = 4.0,
    g: float = 9.81,
    samples: int = 401,
    sweep: tuple = (0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0),
) -> dict:
    """Throw a ball on a rotating platform; compare the Coriolis deflection with theory.

    Args:
        out_dir: results folder.
        quick: fewer samples, a shorter sweep.
        omega: platform rate ``Ω`` (rad/s, counter-clockwise seen from above).
        radius: the thrower's distance ``R`` from the axis.
        speed: horizontal throwing speed ``u`` toward the centre (platform frame).
        up: vertical throwing speed ``w``.
        g: gravitational acceleration.
        samples: output samples per throw.
        sweep: platform rates of the deflection sweep.

    Returns:
        the numbers written to ``numbers.json``.
    """
    n = 101 if quick else samples
    rates = tuple(sweep)[::2] if quick else tuple(sweep)
    ball = RigidBody(inertia.sphere(0.145, 0.037), 0.145)  # a baseball
    scene = Scene(ball, FreeFlight(), Gravity(g))
    run = throw(scene, omega, radius, speed, up, g, n)
    ts, T, rot = run["ts"], run["T"], run["rot"]
    exact = exact_rotating(omega, run["r0"], run["v_rel"], g, ts)
    eom = rotating_eom(omega, run["r0"], run["v_rel"], g, ts)
    theta = omega * T
    d_sim = right_offset(rot[-1], run["r0"], run["v_rel"], T)
    d_exact = deflection_exact(omega, radius, speed, T)
    d_small = omega * speed * T**2
    second = theta**2 * (1 / 6 + radius / (3 * speed * T))

    rows = []
    for w_ in rates:
        r = throw(scene, w_, radius, speed, up, g, n)
        rows.append((w_, w_ * T, right_offset(r["rot"][-1], r["r0"], r["v_rel"], T),
                     deflection_exact(w_, radius, speed, T), w_ * speed * T**2))  # fmt: skip
    sweep_sim = np.array([r[2] for r in rows])
    sweep_exact = np.array([r[3] for r in rows])
    sweep_small = np.array([r[4] for r in rows])
    numbers = {
        "omega": omega, "radius": radius, "speed": speed, "up": up, "g": g,
        "flight_time": T, "theta": theta,
        "deflection_simulated": d_sim, "deflection_exact": d_exact,
        "deflection_small_omega": d_small,
        "small_omega_rel_error": d_small / d_exact - 1,
        "second_order_rel_prediction": second,
        "path_vs_exact_max": float(np.max(np.abs(rot - exact))),
        "path_vs_rotating_eom_max": float(np.max(np.abs(rot - eom))),
        "affine_vs_quaternion_max": float(np.max(np.abs(rot - run["rot_q"]))),
        "inertial_vs_parabola_max": float(np.max(np.abs(run["x"] - exact_rotating(
            0.0, run["r0"], run["v_rel"] + omega * np.cross(Z, run["r0"]), g, ts)))),
        "landing_height": float(rot[-1, 2]),
        "sweep_omega": list(rates), "sweep_deflection_simulated": sweep_sim,
        "sweep_deflection_exact": sweep_exact, "sweep_deflection_small_omega": sweep_small,
        "samples": n,
    }  # fmt: skip

    rep = Report(Path(out_dir), title="A ball thrown on a rotating platform (Coriolis)")
    rep.text(
        f"Platform Ω = {omega:g} rad/s (counter-clockwise); thrower at R = {radius:g} throws "
        f"toward the centre at u = {speed:g}, w = {up:g} (platform frame); flight time "
        f"T = 2w/g = {T:.5f}, ΩT = {theta:.4f}. Solved as a parabola in the inertial frame "
        "(`jrigid.simulate`), moved to the platform frame with `affine.inverse_rigid("
        "affine.rotation_3d(q(t)))`. The ball lands "
        f"**{d_sim:.6f}** to the thrower's right: exact {d_exact:.6f}, small-Ω Coriolis "
        f"Ω u T² = {d_small:.6f} ({100 * (d_small / d_exact - 1):+.2f} %, second-order "
        f"estimate θ²(1/6 + R/3uT) = {100 * second:+.2f} %). The transformed path follows the "
        f"closed form to {numbers['path_vs_exact_max']:.1e} and the rotating-frame equation "
        f"of motion with Coriolis and centrifugal terms (scipy) to "
        f"{numbers['path_vs_rotating_eom_max']:.1e}."
    )
    rep.table(rows, headers=("Ω", "ΩT", "deflection (simulated)", "exact", "Ω u T²"), digits=7)
    fig = viz.new_figure(figsize=(9, 4.2))
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    circ = np.linspace(0, 2 * np.pi, 200)
    for ax, path, title in ((ax1, run["x"], "inertial frame"), (ax2, rot, "platform frame")):
        ax.plot(radius * np.cos(circ), radius * np.sin(circ), color="#bbbbbb", lw=1)
        ax.plot(path[:, 0], path[:, 1], lw=2, label="ball")
        ax.plot(*path[-1, :2], "o", color="C0")
        ax.set_aspect("equal")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("x (m)")
    ax1.plot(*run["r0"][:2], "ks", label="thrower at t = 0")
    q_end = platform_orientation(omega, np.array([T]))[0]
    thrower_end = np.asarray(quat.rotate(q_end, jnp.asarray(run["r0"])))
    ax1.plot(*thrower_end[:2], "kD", mfc="none", label="thrower at landing")
    ax2.plot(*run["r0"][:2], "ks", label="thrower")
    straight = run["r0"] + run["v_rel"] * ts[:, None]
    ax2.plot(straight[:, 0], straight[:, 1], "k--", lw=0.8, label="aimed (no rotation)")
    ax2.plot(exact[::4, 0], exact[::4, 1], ".", color="C3", ms=3, label="closed form")
    ax1.set_ylabel("y (m)")
    for ax in (ax1, ax2):
        ax.legend(fontsize=7, loc="lower left")
    rep.figure("paths", fig, caption="top view of the throw in both frames", dpi=80)
    fig = viz.new_figure(figsize=(5, 3.4))
    ax = fig.add_subplot(1, 1, 1)
    ax.loglog(rates, sweep_sim, "o", label="simulated + transformed")
    ax.loglog(rates, sweep_exact, "k-", lw=0.8, label="exact")
    ax.loglog(rates, sweep_small, "C3--", lw=0.8, label="Ω u T² (small Ω)")
    ax.set_xlabel("Ω (rad/s)")
    ax.set_ylabel("deflection to the right")
    ax.legend(fontsize=8)
    rep.figure("deflection", fig, caption="landing deflection against the platform rate", dpi=80)
    rep.numbers(numbers)
    rep.write_summary()
    print(f"rotating_frame: deflection {d_sim:.6f} (exact {d_exact:.6f}, small-Ω {d_small:.6f})")
    return numbers


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "rotating_frame")
