"""Hard cases for rigid-body integrators: the cases as data, their references and checks.

Each :class:`Case` is a scene, an initial state and a horizon (in periods of the motion),
at a full size (for ``benchmarks/work_precision.py``) and a small size (for
``tests/test_hard_cases.py``):

1. ``general`` — asymmetric body (1, 2, 3), ω0 = (1, 0.3, 0.7), 100 periods of ω;
2. ``separatrix_1e-2``, ``_1e-4``, ``_1e-6`` — near the intermediate-axis separatrix
   (Dzhanibekov): ω0 = (ε, 1, ε), 4 periods (8 flips); the time between flips of ω2
   against its exact value ``2K(m)/λ``;
3. ``nearly_symmetric`` — ``I1 = I2 (1 − 1e-10)``, 20 periods;
4. ``thin_rod`` — moments (1, 1.00005, 1e-4) (the transverse asymmetry is bounded by
   ``I3`` for a real body), tumbling while spinning fast about its axis, 20 periods;
5. ``top_fast_20``, ``top_fast_100`` — heavy symmetric top released at rest at tilt 0.5
   with spin ω3 = 20× and 100× the slow precession rate ``Mgl/(I3 ω3)``, 20 nutation
   periods; the nutation period and amplitude against the analytic values;
6. ``long_horizon`` — case 1 over 10⁴ periods: drift of energy, ``|L|`` and ``|q|``;
   ``top_long_horizon`` — the fast top of case 5 (20×) over 10⁴ nutation periods: drift
   of energy and of the vertical momentum (where fixed-step splitting competes with
   adaptive methods);
7. ``*_f32`` — float32 versions of 1, 2 (ε = 1e-2) and 6;
8. ``gimbal_lock`` — a sleeping top at θ0 = 1e-3: the Euler-angle formulation must
   report gimbal lock, the quaternion formulations must not;

plus two published checks, mapped to Euler's equations by ``ω = d ⊙ y`` (a diagonal
scaling, see :func:`diagonal_map`) of a physical body:

- ``detest_b5`` — DETEST B5 ``y' = (y2 y3, −y1 y3, −0.51 y1 y2)``, ``y(0) = (0, 1, 1)``,
  ``t ≤ 20``, exact ``y = (sn, cn, dn)(t | 0.51)``;
- ``hairer_rigid_body`` — Hairer–Nørsett–Wanner ``y' = (−2 y2 y3, 1.25 y1 y3, −0.5 y1 y2)``,
  ``y(0) = (1, 0, 0.9)``, ``t ≤ 20``, with quadratic invariants ``Σ I_k y_k²`` and
  ``Σ I_k² y_k²`` for ``I = (0.5, 2, 3)``.

References (never a method under test): torque-free cases use ``jrigid.exact`` (closed
form), cross-checked with scipy DOP853 at rtol 1e-13 up to 2000 time units; the tops use
``jrigid.lagrange_top`` (the heavy symmetric top in closed form), cross-checked with scipy
DOP853 at rtol 1e-13 on the (q, ω) equations (also up to 2000 time units) and with the
analytic ``cos θ(t)`` of :func:`top_analytic`. Periods (:func:`free_period`) and the top's
nutation (:func:`top_analytic`) come from the classical formulae with scipy's elliptic
functions, independent of ``jrigid.special``.

Every orientation is chosen so that the angular momentum points along space z (then turned
by 0.7 rad about z), so that the ZXZ Euler angles stay away from gimbal lock (except in
case 8). Functions take the case and ``size`` (``"full"`` or ``"small"``).
"""

from __future__ import annotations

import math
import pathlib
import sys
import time
import warnings
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from scipy import special as sps
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import harness  # noqa: E402

__all__ = [
    "CASES",
    "Case",
    "diagonal_map",
    "flip_times",
    "flips_from_samples",
    "free_period",
    "horizon",
    "initial_state",
    "problem",
    "reference",
    "scene",
    "time_scale",
    "top_analytic",
    "top_final",
    "top_u",
    "nutation_from_samples",
    "turning_points",
]

SIZES = ("full", "small")


@dataclass(frozen=True)
class Case:
    """One hard case. Torque free unless ``tilt`` is set (then a heavy top on a pivot).

    Attributes:
        key: identifier; number: the case number in the suite ("1" … "8", "B5", "HNW").
        title: one line for tables.
        moments: central principal moments.
        omega0: body ω0 (torque free).
        tilt: θ0 of a top (released with φ̇ = θ̇ = 0); spin_ratio: ω3 / (Mgl/(I3 ω3));
            spin: ω3 directly (used when spin_ratio is None).
        mass, height, g: top mass, centre of mass height above the pivot, gravity.
        periods, small_periods: horizon in periods of ω (tops: nutation periods).
        dtype: "float64" or "float32".
        eps: the separatrix perturbation (case 2).
        published: "B5" or "HNW" for the published checks (``ω = d ⊙ y``).
        checks: what the case checks, in words.
    """

    key: str
    number: str
    title: str
    moments: tuple[float, float, float]
    omega0: tuple[float, float, float] | None = None
    tilt: float | None = None
    spin_ratio: float | None = None
    spin: float | None = None
    mass: float = 1.0
    height: float = 1.0
    g: float = 1.0
    periods: float = 20.0
    small_periods: float = 2.0
    dtype: str = "float64"
    eps: float | None = None
    published: str | None = None
    checks: str = ""

    @property
    def torque_free(self) -> bool:
        return self.tilt is None

    @property
    def top_spin(self) -> float:
        """ω3 of a top."""
        if self.spin_ratio is None:
            return float(self.spin)
        return math.sqrt(self.spin_ratio * self.mass * self.g * self.height / self.moments[2])


# ------------------------------------------------------------------ published problems

B5_COEFFS = (1.0, -1.0, -0.51)  # y' = c ⊙ (y2 y3, y3 y1, y1 y2)
B5_Y0 = (0.0, 1.0, 1.0)
B5_BODY = (2.0, 3.0, 1.0)  # I3 < I1 < I2 gives the signs of B5's coefficients
HNW_COEFFS = (-2.0, 1.25, -0.5)
HNW_Y0 = (1.0, 0.0, 0.9)
HNW_BODY = (1.0, 2.0, 2.5)  # I1 < I2 < I3 gives the signs of HNW's coefficients
HNW_MOMENTS = (0.5, 2.0, 3.0)  # the (non-physical) body HNW's equations are Euler's for


def euler_coeffs(moments) -> np.ndarray:
    """``a`` of Euler's equations ``ω̇ = a ⊙ (ω2 ω3, ω3 ω1, ω1 ω2)``."""
    i1, i2, i3 = moments
    return np.array([(i2 - i3) / i1, (i3 - i1) / i2, (i1 - i2) / i3])


def diagonal_map(moments, coeffs) -> np.ndarray:
    """``d`` with ``ω = d ⊙ y`` solving Euler's equations iff ``y' = c ⊙ (y2 y3, y3 y1, y1 y2)``.

    With ``a`` = :func:`euler_coeffs`: ``c1 = a1 d2 d3 / d1`` etc., so
    ``d1 = √(r2 r3)``, ``d2 = √(r1 r3)``, ``d3 = √(r1 r2)`` with ``r = c / a`` (all > 0:
    the signs of ``c`` must be those of ``a``).
    """
    r = np.asarray(coeffs, float) / euler_coeffs(moments)
    if np.any(r <= 0):
        raise ValueError(f"coefficients {coeffs} have other signs than Euler's for {moments}")
    return np.sqrt(np.array([r[1] * r[2], r[0] * r[2], r[0] * r[1]]))


def published_rhs(coeffs):
    """The published right-hand side ``f(t, y)`` (numpy), literally."""
    c1, c2, c3 = coeffs

    def rhs(t, y):
        return np.array([c1 * y[1] * y[2], c2 * y[2] * y[0], c3 * y[0] * y[1]])

    return rhs


def published(name: str) -> tuple[tuple, tuple, tuple]:
    """A published check as printed: ``(body, coeffs, y0)``.

    ``name`` is ``"B5"`` (DETEST B5) or ``"HNW"`` (Hairer–Nørsett–Wanner's rigid body);
    ``coeffs`` are the published ``c`` of ``y' = c ⊙ (y2 y3, y3 y1, y1 y2)`` and ``y0``
    the published initial value; ``body`` is a physical body whose Euler coefficients
    have the signs of ``c``, so that ``ω = d ⊙ y`` with ``d = diagonal_map(body, coeffs)``
    solves its Euler equations.
    """
    if name == "B5":
        return B5_BODY, B5_COEFFS, B5_Y0
    return HNW_BODY, HNW_COEFFS, HNW_Y0


def published_map(case: Case) -> np.ndarray:
    """``d`` (3,) of the case's ``ω = d ⊙ y`` (published checks only)."""
    body, coeffs, _ = published(case.published)
    return diagonal_map(body, coeffs)


def b5_exact(t) -> np.ndarray:
    """DETEST B5's exact solution ``(sn, cn, dn)(t | 0.51)`` by ``jrigid.special``, ``(T, 3)``."""
    from jrigid import special

    sn, cn, dn, _ = special.ellipj(jnp.asarray(t, jnp.float64), jnp.float64(0.51))
    return np.stack([np.asarray(sn), np.asarray(cn), np.asarray(dn)], axis=-1)


def hnw_invariants(y) -> np.ndarray:
    """HNW's invariants ``(Σ I_k y_k², Σ I_k² y_k²)`` with ``I = (0.5, 2, 3)``: ``(..., 2)``."""
    y = np.asarray(y, float)
    inertia = np.array(HNW_MOMENTS)
    return np.stack([np.sum(inertia * y * y, -1), np.sum(inertia**2 * y * y, -1)], axis=-1)


# ------------------------------------------------------------------ the cases


def _cases() -> dict[str, Case]:
    general = dict(moments=(1.0, 2.0, 3.0), omega0=(1.0, 0.3, 0.7))
    cases = [
        Case("general", "1", "general asymmetric body (1, 2, 3), ω0 = (1, 0.3, 0.7), 100 periods",
             periods=100, small_periods=3, checks="exact solver against 30-digit reference",
             **general),
        *[
            Case(f"separatrix_{e:.0e}".replace("e-0", "e-"), "2",
                 f"near the intermediate-axis separatrix, ω0 = ({e:g}, 1, {e:g}), 4 periods",
                 moments=(1.0, 2.0, 3.0), omega0=(e, 1.0, e), periods=4, small_periods=1.2,
                 eps=e, checks="time between flips of ω2 against 2K(m)/λ")
            for e in (1e-2, 1e-4, 1e-6)
        ],
        Case("nearly_symmetric", "3",
             "nearly symmetric (1 − 1e-10, 1, 1.5), ω0 = (0.3, 0.4, 1), 20 periods",
             moments=(1.0 - 1e-10, 1.0, 1.5), omega0=(0.3, 0.4, 1.0), periods=20,
             small_periods=2, checks="exact solver against 30-digit reference"),
        Case("thin_rod", "4", "thin-rod-like (1, 1.00005, 1e-4), ω0 = (1, 0.5, 10), 20 periods",
             moments=(1.0, 1.00005, 1e-4), omega0=(1.0, 0.5, 10.0), periods=20, small_periods=2,
             checks="exact solver against 30-digit reference"),
        *[
            Case(f"top_fast_{r}", "5",
                 f"fast heavy top, moments (1, 1, 1.5), Mgl = 1, θ0 = 0.5, ω3 = {r}× slow "
                 "precession, 20 nutation periods",
                 moments=(1.0, 1.0, 1.5), tilt=0.5, spin_ratio=float(r), periods=20,
                 small_periods=2, checks="nutation period and amplitude against analytic")
            for r in (20, 100)
        ],
        Case("long_horizon", "6", "case 1 over 10⁴ periods", periods=1e4, small_periods=100,
             checks="drift of energy, |L|, |q|", **general),
        Case("top_long_horizon", "6", "case 5 (fast top, 20×) over 10⁴ nutation periods",
             moments=(1.0, 1.0, 1.5), tilt=0.5, spin_ratio=20.0, periods=1e4,
             small_periods=100, checks="drift of energy and vertical momentum"),
        Case("general_f32", "7", "case 1 in float32", periods=100, small_periods=3,
             dtype="float32", checks="float32 error bounds", **general),
        Case("separatrix_1e-2_f32", "7", "case 2 (ε = 1e-2) in float32",
             moments=(1.0, 2.0, 3.0), omega0=(1e-2, 1.0, 1e-2), periods=4, small_periods=1.2,
             eps=1e-2, dtype="float32", checks="float32 error bounds"),
        Case("long_horizon_f32", "7", "case 6 in float32 (10⁴ periods)", periods=1e4,
             small_periods=100, dtype="float32", checks="float32 drift bounds", **general),
        Case("gimbal_lock", "8", "sleeping top at θ0 = 1e-3, ω3 = 10 (Euler angles: gimbal lock)",
             moments=(1.0, 1.0, 1.5), tilt=1e-3, spin=10.0, periods=5, small_periods=1,
             checks="Euler angles report gimbal lock; quaternions integrate"),
        Case("detest_b5", "B5", "DETEST B5, y(0) = (0, 1, 1), t ≤ 20, exact (sn, cn, dn)(t|0.51)",
             moments=B5_BODY, omega0=tuple(diagonal_map(B5_BODY, B5_COEFFS) * B5_Y0),
             published="B5", checks="against (sn, cn, dn)(t | 0.51)"),
        Case("hairer_rigid_body", "HNW",
             "Hairer–Nørsett–Wanner rigid body, y(0) = (1, 0, 0.9), t ≤ 20",
             moments=HNW_BODY, omega0=tuple(diagonal_map(HNW_BODY, HNW_COEFFS) * HNW_Y0),
             published="HNW", checks="against the exact solution; two quadratic invariants"),
    ]
    return {c.key: c for c in cases}


CASES: dict[str, Case] = _cases()


# ------------------------------------------------------------------ periods and horizons


def free_period(moments, omega0) -> float:
    """Period ``4K(m)/λ`` of ω for a torque-free body (Landau & Lifshitz §37), scipy only.

    The distance to the separatrix ``L² − 2E I_mid = Σ I_k (I_k − I_mid) ω_k²`` is formed
    term by term, and ``K`` through ``scipy.special.ellipkm1(1 − m)``. ``inf`` for a steady
    spin.
    """
    moments, omega0 = np.asarray(moments, float), np.asarray(omega0, float)
    order = np.argsort(moments)
    i1, i2, i3 = moments[order]
    w = omega0[order]
    d = [float(np.sum(moments[order] * (moments[order] - ij) * w * w)) for ij in (i1, i2, i3)]
    d1, d2, d3 = d  # L² − 2E Ij: d1 ≥ 0 ≥ d3
    if d2 >= 0:  # L² ≥ 2E I2: ω circulates about axis 3
        lam2 = (i3 - i2) * d1 / (i1 * i2 * i3)
        m1 = (i3 - i1) * d2 / ((i3 - i2) * d1) if d1 > 0 else 0.0
    else:
        lam2 = (i2 - i1) * (-d3) / (i1 * i2 * i3)
        m1 = (i3 - i1) * (-d2) / ((i2 - i1) * (-d3))
    if lam2 <= 0 or m1 <= 0:
        return math.inf
    return float(4.0 * sps.ellipkm1(m1) / math.sqrt(lam2))


def top_analytic(case: Case) -> dict:
    """Nutation of the symmetric heavy top released at rest at tilt θ0 (classical).

    With ``u = cos θ``, ``I1'`` the transverse moment about the pivot, ``a = I3 ω3 / I1'``
    and ``β = 2Mgl / I1'``, energy and the two momenta give
    ``u̇² = β (u0 − u)(u − u1)(u3 − u)``: u oscillates between ``u0`` (top of the swing)
    and ``u1``; from the bottom, ``u = u1 + (u0 − u1) sn²(ω_n t' | m)`` with
    ``m = (u0 − u1)/(u3 − u1)``, ``ω_n = ½ √(β (u3 − u1))``, so from the release at the
    top ``u(t) = u1 + (u0 − u1) cd²(ω_n t | m)``; nutation period ``2K(m)/ω_n``.
    Differences are formed without cancellation.

    Returns:
        dict with ``u0, u1, u3, m, omega_n, period, theta_min, theta_max, amplitude``
        (``theta_max − theta_min``) and ``slow_precession`` (``Mgl/(I3 ω3)``).
    """
    i1p = case.moments[0] + case.mass * case.height**2
    i3 = case.moments[2]
    w3 = case.top_spin
    a = i3 * w3 / i1p
    beta = 2.0 * case.mass * case.g * case.height / i1p
    u0 = math.cos(case.tilt)
    s2 = math.sin(case.tilt) ** 2
    p = a * a - 2.0 * beta * u0
    root = math.sqrt(p * p + 4.0 * beta * beta * s2)
    drop = 2.0 * beta * s2 / (p + root)  # u0 − u1, the positive root of β x² + p x − β s2
    spread = root / beta  # u3 − u1
    m = drop / spread
    omega_n = 0.5 * math.sqrt(beta * spread)
    u1 = u0 - drop
    return {
        "u0": u0, "u1": u1, "u3": u1 + spread, "m": m, "omega_n": omega_n,
        "period": 2.0 * float(sps.ellipk(m)) / omega_n,
        "theta_min": case.tilt, "theta_max": math.acos(u1),
        "amplitude": math.acos(u1) - case.tilt,
        "slow_precession": case.mass * case.g * case.height / (i3 * w3),
    }


def top_u(case: Case, t) -> np.ndarray:
    """Analytic ``cos θ(t)`` of the top (see :func:`top_analytic`), scipy's ``ellipj``."""
    an = top_analytic(case)
    _, cn, dn, _ = sps.ellipj(an["omega_n"] * np.asarray(t, float), an["m"])
    return an["u1"] + (an["u0"] - an["u1"]) * (cn / dn) ** 2


def period(case: Case) -> float:
    """The case's period: of ω (torque free) or of the nutation (top)."""
    if case.torque_free:
        return free_period(case.moments, case.omega0)
    if case.spin_ratio is None:  # sleeping top: one turn of the spin
        return 2.0 * math.pi / case.top_spin
    return top_analytic(case)["period"]


def horizon(case: Case, size: str = "full") -> float:
    """Final time: ``periods`` (or ``small_periods``) periods; 20 for the published checks."""
    if size not in SIZES:
        raise ValueError(f"size must be one of {SIZES}, got {size!r}")
    if case.published:
        return 20.0
    return (case.periods if size == "full" else case.small_periods) * period(case)


def time_scale(case: Case) -> float:
    """Shortest time scale of the motion, for fixed-step sizes: ``min(period, 2π/|ω0|)``."""
    if case.torque_free:
        return min(period(case), 2.0 * math.pi / float(np.linalg.norm(case.omega0)))
    return min(period(case), 2.0 * math.pi / case.top_spin)


# ------------------------------------------------------------------ scenes and states


def problem(case: Case, size: str = "full") -> harness.Problem:
    """The case as a :class:`harness.Problem` (scene, state, numpy equations)."""
    t1 = horizon(case, size)
    if case.torque_free:
        return harness.Problem(case.key, case.title, case.moments, omega0=case.omega0, t1=t1)
    return harness.Problem(
        case.key, case.title, case.moments, euler0=(0.0, case.tilt, 0.0),
        rates0=(0.0, 0.0, case.top_spin), mass=case.mass, com=(0.0, 0.0, case.height),
        g=case.g, t1=t1,
    )


def scene(case: Case):
    """The jrigid :class:`~jrigid.scene.Scene` (arrays of JAX's default float dtype)."""
    return problem(case, "small").scene()


def initial_state(case: Case):
    """The initial :class:`~jrigid.state.State` (default float dtype)."""
    return problem(case, "small").state()


# ------------------------------------------------------------------ references


def _dop853(rhs, y0, t1, t_eval=None, rtol=1e-13):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy raises rtol below 100 eps and says so
        return solve_ivp(rhs, (0.0, t1), y0, method="DOP853", rtol=rtol, atol=1e-15,
                         t_eval=t_eval)


def exact_final(case: Case, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """``jrigid.exact`` at ``t1`` in float64: ``(q (4,), ω (3,))``.

    Starts from the initial :class:`~jrigid.state.State` as every method under test does:
    its ``ω`` (``2 q* ⊗ q̇``, rounded) rather than the case's ``omega0``. Near the
    separatrix the two differ enough to matter: at ε = 1e-6 the state's ω3 is
    ``omega0[2]`` times ``1 + 2.9e-11`` (an absolute 3e-17), which moves the state at the
    small horizon by 1.5e-11, more than the errors being measured there.
    """
    from jrigid import exact

    with jax.enable_x64(True):
        state = problem(case, "small").state()
        q, w = exact.solve(
            jnp.asarray(case.moments, jnp.float64), jnp.asarray(state.q, jnp.float64),
            jnp.asarray(state.omega, jnp.float64), jnp.asarray([0.0, t1], jnp.float64),
        )
        return np.asarray(q[-1], float), np.asarray(w[-1], float)


def reference(case: Case, size: str = "full") -> dict:
    """Final state at the horizon from a reference that is not a method under test.

    Returns:
        dict with ``q``, ``omega`` (float64), ``t1``, ``source``, ``check`` (words),
        ``floor`` (disagreement of the two references, or ``None``), ``seconds``.
    """
    t1 = horizon(case, size)
    prob = problem(case, size)
    start = time.perf_counter()
    if case.torque_free:
        q, w = exact_final(case, t1)
        out = {"q": q, "omega": w, "t1": t1, "source": "jrigid.exact (closed form), float64",
               "floor": None, "check": "none (horizon > 2000: see tests/test_exact.py)"}
        if t1 <= 2000:
            with jax.enable_x64(True):
                y0 = prob.y0()
            dop = _dop853(prob.numpy_rhs(), y0, t1)
            floor = max(harness.omega_error(dop.y[4:, -1], w),
                        harness.quaternion_error(dop.y[:4, -1], q))
            out["floor"] = floor
            out["check"] = f"scipy DOP853 at rtol 1e-13 agrees to {floor:.2g}"
        out["seconds"] = time.perf_counter() - start
        return out
    q, w = top_final(case, t1)
    out = {"q": q, "omega": w, "t1": t1, "source": "jrigid.lagrange_top (closed form), float64",
           "floor": None, "check": "none (horizon > 2000: see tests/test_lagrange_top.py)"}
    if t1 <= 2000:
        with jax.enable_x64(True):
            y0 = prob.y0()
        dop = _dop853(prob.numpy_rhs(), y0, t1)
        floor = max(harness.omega_error(dop.y[4:, -1], w),
                    harness.quaternion_error(dop.y[:4, -1] / np.linalg.norm(dop.y[:4, -1]), q))
        out["floor"] = floor
        out["check"] = f"scipy DOP853 at rtol 1e-13 on the (q, ω) equations agrees to {floor:.2g}"
    out["seconds"] = time.perf_counter() - start
    return out


def top_final(case: Case, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """``jrigid.lagrange_top`` (the heavy symmetric top in closed form) at ``t1`` in float64."""
    from jrigid import lagrange_top

    with jax.enable_x64(True):
        prob = problem(case, "small")
        state = prob.state()
        scene = prob.scene()
        g = lagrange_top.scene_gravity(scene)
        q, w = lagrange_top.solve(
            jnp.asarray(scene.body.moments, jnp.float64), jnp.asarray(scene.body.mass),
            jnp.asarray(scene.body.com, jnp.float64), g, jnp.asarray(state.q, jnp.float64),
            jnp.asarray(state.omega, jnp.float64), jnp.asarray([0.0, t1], jnp.float64),
        )
        return np.asarray(q[-1], float), np.asarray(w[-1], float)


# ------------------------------------------------------------------ measurements


def _roots(f, t_grid) -> np.ndarray:
    """Roots of a scalar ``f`` (vectorised on a grid, scalar in refinement) by ``brentq``."""
    t_grid = np.asarray(t_grid, float)
    v = np.asarray(f(t_grid), float)
    out = []
    for k in np.nonzero(np.sign(v[:-1]) * np.sign(v[1:]) < 0)[0]:
        out.append(brentq(lambda t: float(np.asarray(f(np.array([t])))[0]),
                          t_grid[k], t_grid[k + 1], xtol=1e-14, rtol=1e-15, maxiter=200))
    return np.array(out)


def flip_times(omega2, t1: float, n: int = 4000) -> np.ndarray:
    """Times in ``(0, t1)`` where ω2 changes sign; ``omega2(t (K,)) -> (K,)``."""
    return _roots(omega2, np.linspace(0.0, t1, n))


def u_and_rate(q, omega) -> tuple[np.ndarray, np.ndarray]:
    """``u = cos θ`` (space z of body axis 3) and ``u̇`` from ``q (..., 4)``, ``ω (..., 3)``.

    ``a = R e3`` and ``ȧ = R (ω × e3)``: ``u = R22``, ``u̇ = R20 ω2 − R21 ω1``.
    """
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    omega = np.asarray(omega, float)
    return r22, r20 * omega[..., 1] - r21 * omega[..., 0]


def turning_points(qw, t1: float, n: int = 4000) -> np.ndarray:
    """Times in ``(0, t1)`` where ``u̇ = 0``; ``qw(t (K,)) -> (q (K, 4), ω (K, 3))``."""
    return _roots(lambda t: u_and_rate(*qw(t))[1], np.linspace(0.0, t1, n))


def nutation_from_turning_points(turns, u_at) -> dict:
    """Measured nutation period and amplitude from the turning times of ``u``.

    Args:
        turns: ``(K,)`` increasing times where ``u̇ = 0``, alternating top/bottom.
        u_at: ``u(t (K,)) -> (K,)``.

    Returns:
        dict with ``period`` (twice the mean spacing of turning times), ``amplitude``
        (mean ``θ`` at the bottoms minus mean at the tops), ``count``.
    """
    turns = np.asarray(turns, float)
    theta = np.arccos(np.clip(np.asarray(u_at(turns), float), -1.0, 1.0))
    spacing = np.diff(turns)
    top = theta < np.median(theta)
    return {
        "period": 2.0 * float(np.mean(spacing)),
        "amplitude": float(np.mean(theta[~top]) - np.mean(theta[top])),
        "count": int(turns.size),
    }


def flips_from_samples(moments, ts, omega) -> np.ndarray:
    """Sign changes of ω2 from samples ``ω (K, 3)`` at ``ts (K,)``.

    Cubic Hermite interpolation with ``ω̇2`` from Euler's equations (error ``O(h⁴)``).
    """
    from scipy.interpolate import CubicHermiteSpline

    ts, omega = np.asarray(ts, float), np.asarray(omega, float)
    a = euler_coeffs(moments)
    spline = CubicHermiteSpline(ts, omega[:, 1], a[1] * omega[:, 2] * omega[:, 0])
    return np.array([r for r in spline.roots(extrapolate=False) if ts[0] < r < ts[-1]])


def nutation_from_samples(ts, q, omega) -> dict:
    """Nutation period and amplitude (:func:`nutation_from_turning_points`) from samples.

    ``u = cos θ`` is interpolated by cubic Hermite with ``u̇`` from ``q, ω``; the turning
    points are the roots of the interpolant's derivative.
    """
    from scipy.interpolate import CubicHermiteSpline

    ts = np.asarray(ts, float)
    u, udot = u_and_rate(q, omega)
    spline = CubicHermiteSpline(ts, u, udot)
    turns = [r for r in spline.derivative().roots(extrapolate=False)
             if ts[0] + 1e-9 * ts[-1] < r < ts[-1]]
    return nutation_from_turning_points(turns, spline)


def invariants(case: Case, q, omega) -> dict[str, np.ndarray]:
    """Energy ``½ ω·Iω`` (torque free), ``|L|`` and ``|q|`` along a trajectory."""
    inertia = np.asarray(case.moments, float)
    omega = np.asarray(omega, float)
    return {
        "energy": 0.5 * np.sum(inertia * omega * omega, -1),
        "L": np.linalg.norm(inertia * omega, axis=-1),
        "q_norm": np.linalg.norm(np.asarray(q, float), axis=-1),
    }


def drift(case: Case, q, omega) -> dict[str, float]:
    """Largest relative change of energy and ``|L|`` from the first sample; of ``|q|`` from 1."""
    inv = invariants(case, q, omega)
    return {
        "energy": float(np.max(np.abs(inv["energy"] / inv["energy"][0] - 1.0))),
        "L": float(np.max(np.abs(inv["L"] / inv["L"][0] - 1.0))),
        "q_norm": float(np.max(np.abs(inv["q_norm"] - 1.0))),
    }
