"""The closed-form heavy symmetric top (``jrigid.lagrange_top``) against independent references.

References (none shares code with the module under test):

* ``MpTop``: the textbook closed form in 30-digit mpmath — ZXZ Euler angles about the
  vertical, the roots of the cubic by ``mpmath.polyroots``, ``φ`` and ``ψ`` through
  ``mpmath.ellippi`` with the characteristics ``n± = ∓(u2 − u1)/(1 ± u1)`` taken as they
  come (the module under test uses half-angle phases, a quarter-period shift and Carlson's
  ``R_J``) — itself checked against ``mpmath.odefun`` (Taylor series, 30 digits) on the
  ``(q, ω)`` equations; it serves as the reference over 10 and 10⁴ nutation periods;
* scipy ``solve_ivp`` (DOP853, rtol 1e-13) on the ``(q, ω)`` equations, for the motions the
  Euler-angle reference cannot take (through or from the poles ``θ = 0, π``);
* the analytic nutation period and range of ``benchmarks/hard_cases.py`` (scipy's elliptic
  functions) and the steady-precession roots of ``experiments/gyroscope.py``;
* the free precession of a symmetric body, for a top whose centre of mass is at the pivot;
* the equations of motion themselves (``q̇``, ``ω̇`` by ``jax.jvp`` in ``t``);
* finite differences and forward-mode ``jrigid.simulate`` (diffrax) for derivatives.

All float64 evaluations go through one jitted ``prepare`` for 8 tops and one vmapped
``evaluate`` at 6 times per top, so the file compiles the closed form only a few times.
"""

from __future__ import annotations

import math
import pathlib
import sys
import warnings

import diffrax
import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from jrigid import initial, lagrange_top, special
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.scene import FreeRotation, Gravity, Pivot, Scene, Torque

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "experiments"))

import gyroscope  # noqa: E402
import hard_cases as hc  # noqa: E402

EPS = np.finfo(np.float64).eps
DPS = 30
B, N_T = 8, 6  # every batched solve: 8 tops, 6 times each (one compilation)

PREPARE = jax.jit(lagrange_top.prepare)
EVALUATE = jax.jit(jax.vmap(lagrange_top.evaluate))


# --------------------------------------------------------------------------- helpers


def _unit(q):
    q = np.asarray(q, float)
    return q / np.linalg.norm(q)


def _rates(angles, rates):
    """``(q0, ω0)`` from ZXZ angles and rates (``initial.from_euler_rates``)."""
    s = initial.from_euler_rates(angles, rates)
    return np.asarray(s.q), np.asarray(s.omega)


TOP = ((1.0, 1.0, 0.5), 1.0, (0.0, 0.0, 1.0), (0.0, 0.0, -1.0))  # A = 2, C = 0.5, Mgl = 1


def _through_pole(theta, w3, pole, scale=1.0):
    """``(q0, ω0)`` of the top ``TOP`` at tilt ``θ`` with ``b = ±a`` times ``scale``."""
    a = 0.5 * w3 / 2.0
    u0 = math.cos(theta)
    w2 = a * (1 - u0) / math.sin(theta) if pole == "up" else -a * (1 + u0) / math.sin(theta)
    q0 = np.array([math.cos(theta / 2), math.sin(theta / 2), 0.0, 0.0])
    return q0, np.array([0.3, w2 * scale, w3])


def _solve(cases, times):
    """Closed form for up to ``B`` tops at ``N_T`` times each: ``q (k, N_T, 4), ω (k, N_T, 3)``."""
    k = len(cases)
    assert 1 <= k <= B
    padded = list(cases) + [cases[0]] * (B - k)
    args = [np.stack([np.asarray(c[i], float) for c in padded]) for i in range(6)]
    ts = np.stack([np.asarray(t, float) for t in list(times) + [times[0]] * (B - k)])
    assert ts.shape == (B, N_T)
    consts = PREPARE(*args)
    q, w = EVALUATE(consts, ts)
    return np.asarray(q)[:k], np.asarray(w)[:k], consts


def _rot(q):
    """Rotation matrices of quaternions ``(..., 4)`` (numpy, scalar first)."""
    w, x, y, z = (q[..., i] for i in range(4))
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)  # fmt: skip


def _qdist(p, q):
    """Sign-invariant max-abs distance between quaternions ``(..., 4)``."""
    return np.minimum(np.abs(p - q).max(-1), np.abs(p + q).max(-1))


# ------------------------------------------------------------------ references


def _mp_rot(q):
    w, x, y, z = q
    n = mp.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = (v / n for v in (w, x, y, z))
    return mp.matrix([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


def _rz(a):
    c, s = mp.cos(a), mp.sin(a)
    return mp.matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _rx(a):
    c, s = mp.cos(a), mp.sin(a)
    return mp.matrix([[1, 0, 0], [0, c, -s], [0, s, c]])


class MpTop:
    """Textbook closed form of the heavy symmetric top in 30-digit arithmetic (Goldstein §5.7).

    With ``ẑ = −sign(l) g/|g|``, ``u = cos θ``, ``A = I1 + M l²``: ``a = C ω3/A``,
    ``b = L·ẑ/A``, ``β = 2 M |g| |l|/A``, ``α = ω1² + ω2² + β u0``; ``u = u1 + (u2 − u1)
    sn²(ω_n t + τ0 | m)`` between the two lower roots of ``β u³ − (α + a²) u² + (2ab − β) u
    + α − b²``; ``φ̇ = ((b − a)/(1 − u) + (b + a)/(1 + u))/2`` and ``ψ̇ = ω3 − a − ((b − a)/(1 − u)
    − (b + a)/(1 + u))/2`` integrated with ``mpmath.ellippi``; ``R = Q_v Rz(φ) Rx(θ) Rz(ψ)``.
    Needs ``0 < θ < π`` throughout and a nutating motion (``u1 < u2``).
    """

    def __init__(self, moments, mass, com, g, q0, omega0):
        with mp.workdps(DPS):
            f = lambda v: mp.mpf(float(v))  # noqa: E731
            i1, i2, i3 = (f(v) for v in moments)
            mass, lever = f(mass), f(com[2])
            gv = [f(v) for v in g]
            big_a = (i1 + i2) / 2 + mass * lever**2
            gn = mp.sqrt(sum(v * v for v in gv))
            sgn = 1 if lever >= 0 else -1
            zhat = mp.matrix([-sgn * v / gn for v in gv])
            trial = mp.matrix([1, 0, 0]) if abs(zhat[0]) < 0.9 else mp.matrix([0, 1, 0])
            e1 = trial - (trial.T * zhat)[0] * zhat
            e1 = e1 / mp.norm(e1)
            e2 = mp.matrix([zhat[1] * e1[2] - zhat[2] * e1[1], zhat[2] * e1[0] - zhat[0] * e1[2],
                            zhat[0] * e1[1] - zhat[1] * e1[0]])  # fmt: skip
            self.qv = mp.matrix(3, 3)
            for k in range(3):
                self.qv[k, 0], self.qv[k, 1], self.qv[k, 2] = e1[k], e2[k], zhat[k]
            r0 = _mp_rot([f(v) for v in q0])
            rp = self.qv.T * r0
            w = [f(v) for v in omega0]
            n = r0.T * zhat
            u0 = n[2]
            self.w3 = w[2]
            self.a = a = i3 * w[2] / big_a
            self.b = b = (big_a * (w[0] * n[0] + w[1] * n[1]) + i3 * w[2] * u0) / big_a
            beta = 2 * mass * gn * abs(lever) / big_a
            alpha = w[0] ** 2 + w[1] ** 2 + beta * u0
            roots = mp.polyroots([alpha - b * b, 2 * a * b - beta, -(alpha + a * a), beta],
                                 maxsteps=200, extraprec=200, asc=True)  # fmt: skip
            self.u1, self.u2, self.u3 = sorted(mp.re(r) for r in roots)
            self.m = (self.u2 - self.u1) / (self.u3 - self.u1)
            self.wn = mp.sqrt(beta * (self.u3 - self.u1)) / 2
            self.kk = mp.ellipk(self.m)
            self.period = 2 * self.kk / self.wn
            udot0 = n[0] * w[1] - n[1] * w[0]
            s2 = min(max((u0 - self.u1) / (self.u2 - self.u1), 0), 1)
            self.tau0 = (1 if udot0 >= 0 else -1) * mp.ellipf(mp.asin(mp.sqrt(s2)), self.m)
            self.n_minus = (self.u2 - self.u1) / (1 - self.u1)
            self.n_plus = -(self.u2 - self.u1) / (1 + self.u1)
            self.phi0 = mp.atan2(rp[0, 2], -rp[1, 2])
            self.psi0 = mp.atan2(rp[2, 0], rp[2, 1])
            self.pi0 = self._pis(self.tau0)

    def _pis(self, tau):
        j = mp.nint(tau / (2 * self.kk))
        phi = mp.asin(mp.ellipfun("sn", tau - 2 * j * self.kk, self.m)) + j * mp.pi
        return mp.ellippi(self.n_minus, phi, self.m), mp.ellippi(self.n_plus, phi, self.m)

    def at(self, t):
        """``(R (3, 3), ω_body (3,))`` as float arrays at time ``t``."""
        with mp.workdps(DPS):
            t = mp.mpf(float(t))
            tau = self.wn * t + self.tau0
            sn, cn, dn = (mp.ellipfun(k, tau, self.m) for k in ("sn", "cn", "dn"))
            u = self.u1 + (self.u2 - self.u1) * sn**2
            udot = 2 * (self.u2 - self.u1) * self.wn * sn * cn * dn
            pm, pp = self._pis(tau)
            jm = (pm - self.pi0[0]) / ((1 - self.u1) * self.wn)
            jp = (pp - self.pi0[1]) / ((1 + self.u1) * self.wn)
            a, b = self.a, self.b
            phi = self.phi0 + ((b - a) * jm + (b + a) * jp) / 2
            psi = self.psi0 + (self.w3 - a) * t - ((b - a) * jm - (b + a) * jp) / 2
            theta = mp.acos(u)
            rot = self.qv * _rz(phi) * _rx(theta) * _rz(psi)
            sth = mp.sin(theta)
            phidot, thdot = (b - a * u) / (1 - u * u), -udot / sth
            w1 = phidot * sth * mp.sin(psi) + thdot * mp.cos(psi)
            w2 = phidot * sth * mp.cos(psi) - thdot * mp.sin(psi)
            return (np.array(rot.tolist(), dtype=float),
                    np.array([float(w1), float(w2), float(self.w3)]))  # fmt: skip


def _odefun(moments, mass, com, g, q0, omega0, ts):
    """``mpmath.odefun`` (Taylor, 30 digits) on ``q̇ = ½ q ⊗ (0, ω)``, ``I' ω̇ = N − ω × I'ω``."""
    with mp.workdps(DPS):
        f = lambda v: mp.mpf(float(v))  # noqa: E731
        mass, r, gv = f(mass), [f(v) for v in com], [f(v) for v in g]
        inertia = [f(moments[0]) + mass * r[2] ** 2, f(moments[1]) + mass * r[2] ** 2,
                   f(moments[2])]  # fmt: skip
        qm = [f(v) for v in _unit(q0)]

        def rhs(_, y):
            w, x, yy, z, o1, o2, o3 = y
            gb = _mp_rot([w, x, yy, z]).T * mp.matrix(gv)
            force = [mass * gb[k] for k in range(3)]
            torque = [r[1] * force[2] - r[2] * force[1], r[2] * force[0] - r[0] * force[2],
                      r[0] * force[1] - r[1] * force[0]]  # fmt: skip
            L = [inertia[0] * o1, inertia[1] * o2, inertia[2] * o3]
            wxl = [o2 * L[2] - o3 * L[1], o3 * L[0] - o1 * L[2], o1 * L[1] - o2 * L[0]]
            dq = [(-x * o1 - yy * o2 - z * o3) / 2, (w * o1 + yy * o3 - z * o2) / 2,
                  (w * o2 + z * o1 - x * o3) / 2, (w * o3 + x * o2 - yy * o1) / 2]  # fmt: skip
            return dq + [(torque[k] - wxl[k]) / inertia[k] for k in range(3)]

        sol = mp.odefun(rhs, 0, qm + [f(v) for v in omega0])
        out = []
        for t in ts:
            y = sol(f(t))
            out.append((np.array(_mp_rot(y[:4]).tolist(), dtype=float),
                        np.array([float(v) for v in y[4:]])))  # fmt: skip
        return out


def _rotate(q, v, inverse=False):
    """Rotate ``v (K, 3)`` by unit quaternions ``q (K, 4)`` (numpy; ``inverse``: by ``q*``)."""
    w, u = q[:, :1], q[:, 1:] * (-1.0 if inverse else 1.0)
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _dop853(cases, ts):
    """scipy DOP853 (rtol 1e-13) on the ``(q, ω)`` equations of several tops at once."""
    mom = np.array([c[0] for c in cases], float)
    mass = np.array([c[1] for c in cases], float)
    lever = np.array([c[2][2] for c in cases], float)
    g = np.array([c[3] for c in cases], float)
    inertia = np.stack([mom[:, 0] + mass * lever**2, mom[:, 1] + mass * lever**2, mom[:, 2]], 1)
    y0 = np.concatenate([np.stack([_unit(c[4]) for c in cases]),
                         np.array([c[5] for c in cases], float)], 1)  # fmt: skip

    def rhs(_, y):
        y = y.reshape(-1, 7)
        q, w = y[:, :4], y[:, 4:]
        force = mass[:, None] * _rotate(q, g, inverse=True)
        torque = np.stack([-lever * force[:, 1], lever * force[:, 0], np.zeros_like(lever)], 1)
        wdot = (torque - np.cross(w, inertia * w)) / inertia
        qw, qv = q[:, :1], q[:, 1:]
        qdot = 0.5 * np.concatenate(
            [-np.sum(qv * w, 1, keepdims=True), qw * w + np.cross(qv, w)], 1
        )
        return np.concatenate([qdot, wdot], 1).ravel()

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy raises rtol below 100 eps and says so
        sol = solve_ivp(rhs, (0.0, float(ts[-1])), y0.ravel(), method="DOP853", rtol=1e-13,
                        atol=1e-15, t_eval=ts)  # fmt: skip
    y = sol.y.T.reshape(len(ts), len(cases), 7).transpose(1, 0, 2)
    q = y[..., :4] / np.linalg.norm(y[..., :4], axis=-1, keepdims=True)
    return q, y[..., 4:]


# --------------------------------------------------------------------------- cases

GENERIC = ((1.0, 1.0, 0.5), 1.3, (0.0, 0.0, 0.8), (0.2, -0.3, -1.9),
           _unit([0.9, 0.1, -0.3, 0.2]), (0.4, -0.7, 4.0))  # fmt: skip

REFERENCE_CASES = {
    "generic": GENERIC,
    "cusp": TOP + _rates((0.3, 0.6, 0.2), (0.0, 0.0, 8.0)),
    "looping": TOP + _rates((0.3, 0.6, 0.2), (-0.4, 0.0, 8.0)),
    "slow": TOP + _rates((0.3, 0.6, 0.2), (0.05, 0.3, 0.3)),
    "hanging_l_negative": ((2.0, 2.0, 0.7), 0.5, (0.0, 0.0, -1.5), (0.0, 0.0, -9.81))
    + _rates((0.1, 2.5, 0.0), (0.3, 0.2, 1.0)),
    "near_vertical_1e-6": TOP + _through_pole(0.4, 4.0, "up", 1 + 1e-6),
    "near_bottom_1e-6": TOP + _through_pole(0.4, 4.0, "down", 1 + 1e-6),
    "fast_top": TOP + _rates((0.0, 0.5, 0.0), (0.0, 0.0, 100.0)),
}
REFERENCES = {name: MpTop(*case) for name, case in REFERENCE_CASES.items()}
OFFSETS = np.array([0.0, 0.13, 0.5, 0.77, 1.0, 1.31])


def _reference_errors(periods):
    """Max errors of R and ω against ``MpTop`` at ``periods + OFFSETS`` nutation periods."""
    names = list(REFERENCE_CASES)
    times = [(periods + OFFSETS) * float(REFERENCES[n].period) for n in names]
    q, w, _ = _solve([REFERENCE_CASES[n] for n in names], times)
    out = {}
    for k, name in enumerate(names):
        refs = [REFERENCES[name].at(t) for t in times[k]]
        err_r = max(np.abs(_rot(q[k, i]) - refs[i][0]).max() for i in range(N_T))
        err_w = max(np.abs(w[k, i] - refs[i][1]).max() for i in range(N_T))
        w_max = max(np.linalg.norm(r[1]) for r in refs)
        out[name] = (err_r, err_w, w_max, times[k][-1])
    return out


# ------------------------------------------------------------------ the reference itself


def test_reference_agrees_with_odefun():
    """The Euler-angle mpmath closed form equals a 30-digit Taylor integration (to float64)."""
    ref = REFERENCES["generic"]
    ts = [0.4, 1.3]
    for t, (r_ode, w_ode) in zip(ts, _odefun(*GENERIC, ts), strict=True):
        r_ref, w_ref = ref.at(t)
        assert np.abs(r_ref - r_ode).max() < 1e-15 and np.abs(w_ref - w_ode).max() < 1e-15


# ------------------------------------------------------------------ accuracy


def test_ten_periods_against_reference():
    """Every family of motion (waves, cusps, loops, slow, hanging, near the poles, fast) to
    within a few times the rounding of t itself, and below 1e-12 absolutely."""
    for name, (err_r, err_w, w_max, t_end) in _reference_errors(10.0).items():
        bound = 10 * EPS * t_end * w_max
        assert err_r <= max(bound, 1e-13) and err_w <= max(bound, 1e-13) * w_max, name
        assert err_r < 1e-12 and err_w < 1e-12 * w_max, name


def test_ten_thousand_periods_within_time_rounding():
    """At 10⁴ nutation periods the error is within 5x what rounding t causes (eps t |ω|)."""
    for name, (err_r, err_w, w_max, t_end) in _reference_errors(1e4).items():
        bound = 5 * EPS * t_end * w_max
        assert err_r <= bound and err_w <= bound * w_max, (name, err_r, err_w, bound)


def test_initial_state_reproduced():
    q, w, _ = _solve(list(REFERENCE_CASES.values()), [np.zeros(N_T)] * B)
    for k, case in enumerate(REFERENCE_CASES.values()):
        assert _qdist(q[k, 0], _unit(case[4])) < 4 * EPS
        np.testing.assert_allclose(w[k, 0], case[5], rtol=0, atol=8 * EPS * np.abs(case[5]).max())


# ------------------------------------------------------------------ special motions


POLE_CASES = {
    "start_at_vertical_kicked": TOP + ((1.0, 0.0, 0.0, 0.0), (0.4, 0.2, 6.0)),
    "start_at_vertical_slow": TOP + ((1.0, 0.0, 0.0, 0.0), (0.4, 0.2, 0.5)),
    "through_vertical_b_eq_a": TOP + _through_pole(0.4, 4.0, "up"),
    "near_vertical_1e-9": TOP + _through_pole(0.4, 4.0, "up", 1 + 1e-9),
    "start_hanging_kicked": TOP + ((0.0, 1.0, 0.0, 0.0), (0.5, 0.3, 2.0)),
    "pendulum_from_rest": TOP + ((math.cos(0.3), math.sin(0.3), 0.0, 0.0), (0.0, 0.0, 0.0)),
    "through_bottom_b_eq_minus_a": TOP + _through_pole(0.4, 4.0, "down"),
    "sleeping_perturbed": TOP + ((1.0, 0.0, 0.0, 0.0), (1e-3, 0.0, 6.0)),
}
OTHER_CASES = {
    "cusp": REFERENCE_CASES["cusp"],
    "looping": REFERENCE_CASES["looping"],
    "slow": REFERENCE_CASES["slow"],
    "tilted_gravity_l_negative": (
        (1.5, 1.5, 0.4),
        0.7,
        (0.0, 0.0, -0.6),
        (1.0, 2.0, -0.5),
        _unit([0.2, 0.9, -0.1, 0.4]),
        (1.1, -0.3, 2.5),
    ),  # fmt: skip
    "no_gravity": (
        (1.0, 1.0, 0.5),
        1.0,
        (0.0, 0.0, 1.0),
        (0.0, 0.0, 0.0),
        _unit([0.9, 0.3, 0.1, 0.0]),
        (0.3, 0.2, 1.0),
    ),  # fmt: skip
    "unstable_sleeping_upright_spin": TOP + ((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "upright_at_rest": TOP + ((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    "hanging_at_rest_spinning": TOP + ((0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 3.0)),
}


@pytest.mark.parametrize("cases", [POLE_CASES, OTHER_CASES], ids=["poles", "others"])
def test_special_motions_against_dop853(cases):
    """Through, near and from the poles, equilibria, no gravity: as DOP853 at rtol 1e-13.

    The unstable equilibria stay put in both (the gravity torque vanishes exactly there).
    """
    ts = np.array([0.0, 0.9, 2.3, 4.1, 6.6, 9.5])
    q_ref, w_ref = _dop853(list(cases.values()), ts)
    q, w, _ = _solve(list(cases.values()), [ts] * len(cases))
    assert np.isfinite(q).all() and np.isfinite(w).all()
    for k, name in enumerate(cases):
        scale = max(1.0, np.abs(w_ref[k]).max())
        assert _qdist(q[k], q_ref[k]).max() < 2e-11, name
        assert np.abs(w[k] - w_ref[k]).max() < 2e-11 * scale, name


def test_near_the_separatrix_of_the_sleeping_top():
    """An unstable sleeping top nudged by ``ε`` falls and comes back up once a period: the
    period grows by ``2 ln(10³)/λ`` per factor 10³ in ``ε``, with ``λ = √(Mgl/A − (Cω3/2A)²)``
    the growth rate of a small tilt at the upright position; the motion is DOP853's (whose
    error the unstable equilibrium amplifies to ~1e-11 by t = 30)."""
    nudges = [1e-3, 1e-6, 1e-9, 1e-12]
    cases = [TOP + ((1.0, 0.0, 0.0, 0.0), (eps, 0.0, 1.0)) for eps in nudges]
    ts = np.array([0.0, 2.0, 5.0, 10.0, 20.0, 30.0])
    q, w, consts = _solve(cases, [ts] * len(cases))
    period = np.asarray(lagrange_top.nutation_period(consts))[: len(cases)]
    big_a, big_c, mgl, w3 = 2.0, 0.5, 1.0, 1.0
    growth = math.sqrt(mgl / big_a - (big_c * w3 / (2 * big_a)) ** 2)
    # corrections are O(ε²) relative: 1e-6 for the first step
    np.testing.assert_allclose(np.diff(period), 2 * math.log(1e3) / growth, rtol=1e-5)
    q_ref, w_ref = _dop853(cases[1:], ts)
    assert _qdist(q[1:], q_ref).max() < 2e-10 and np.abs(w[1:] - w_ref).max() < 2e-10


def test_sleeping_top_and_equilibria_exact():
    """Spinning upright (stable or not) or hanging: ``q = q0 ⊗ (cos ω3t/2, 0, 0, sin ω3t/2)``."""
    ts = np.array([0.0, 0.5, 3.0, 40.0, 700.0, 1e4])
    cases = [TOP + (q0, (0.0, 0.0, w3)) for q0 in ([1.0, 0, 0, 0], [0.0, 1, 0, 0])
             for w3 in (6.0, 1.0, 0.0)]  # fmt: skip
    q, w, consts = _solve(cases, [ts] * len(cases))
    for k, case in enumerate(cases):
        w3 = case[5][2]
        spin = np.stack([np.cos(w3 * ts / 2), 0 * ts, 0 * ts, np.sin(w3 * ts / 2)], -1)
        q0 = np.asarray(case[4])
        expected = np.stack([_quat_mul(q0, s) for s in spin])
        assert (_qdist(q[k], expected) <= 4 * EPS * (1 + abs(w3) * ts)).all()
        np.testing.assert_array_equal(w[k], np.broadcast_to(case[5], (N_T, 3)))
        assert float(consts.u1[k]) == float(consts.u2[k])
    assert np.isinf(np.asarray(lagrange_top.nutation_period(consts))[: len(cases)]).all()


def _quat_mul(p, q):
    pw, pv, qw, qv = p[0], np.asarray(p[1:]), q[0], np.asarray(q[1:])
    return np.concatenate([[pw * qw - pv @ qv], pw * qv + qw * pv + np.cross(pv, qv)])


def test_steady_precession_at_the_exact_roots():
    """Started on a root of ``I1 Ω² cos θ − I3 ω3 Ω + Mgl = 0`` (experiments/gyroscope.py):
    ``θ`` stays, ``q(t) = Rz(Ωt) q0 Rz(ψ̇t)`` with ``ψ̇ = ω3 − Ω cos θ``, up to 10⁴ turns."""
    scene = gyroscope.top()
    theta, omega3 = 0.7, 20.0
    roots = gyroscope.steady_roots(scene, theta, omega3)
    body = scene.body
    cases, rates = [], []
    for name in ("slow", "fast"):
        rate = roots[name]
        q0, w0 = _rates((0.0, theta, 0.0), (rate, 0.0, omega3 - rate * math.cos(theta)))
        cases.append((body.moments, body.mass, body.com, scene.loads[0].g, q0, w0))
        rates.append((rate, omega3 - rate * math.cos(theta)))
    times = [np.array([0.0, 1.0, 10.0, 1e2, 1e3, 1e4]) * 2 * math.pi / r[0] for r in rates]
    q, w, consts = _solve(cases, times)
    for k, (rate, psidot) in enumerate(rates):
        u1, u2 = float(consts.u1[k]), float(consts.u2[k])
        assert abs(u1 - math.cos(theta)) < 4 * EPS and abs(u2 - math.cos(theta)) < 4 * EPS
        ts = times[k]
        q0 = _unit(cases[k][4])
        expected = np.stack([
            _quat_mul(_quat_mul([math.cos(rate * t / 2), 0, 0, math.sin(rate * t / 2)], q0),
                      [math.cos(psidot * t / 2), 0, 0, math.sin(psidot * t / 2)])
            for t in ts
        ])  # fmt: skip
        w_max = np.linalg.norm(cases[k][5])
        assert (_qdist(q[k], expected) <= 8 * EPS * (1 + (abs(rate) + w_max) * ts)).all()


def test_com_at_pivot_is_the_torque_free_symmetric_body():
    """``l = 0`` with gravity: free precession, ``q(t) = exp(L̂ |L| t/2A) q0 exp(e3 Ω t/2)``
    with ``Ω = ω3 (A − C)/A``; the body ω turns about ``e3`` at ``−Ω``."""
    moments, q0, w0 = (1.0, 1.0, 0.5), _unit([0.9, 0.3, 0.1, 0.0]), np.array([0.3, 0.2, 1.0])
    ts = np.array([0.0, 0.7, 3.0, 11.0, 150.0, 2000.0])
    q, w, _ = _solve([(moments, 2.0, (0.0, 0.0, 0.0), (0.0, -9.81, 0.0), q0, w0)], [ts])
    big_a, big_c = moments[0], moments[2]
    L = _rotate(q0[None], (np.array([big_a, big_a, big_c]) * w0)[None])[0]
    rate_l, rate_b = np.linalg.norm(L) / big_a, w0[2] * (big_a - big_c) / big_a
    for k, t in enumerate(ts):
        axis = L / np.linalg.norm(L)
        turn = np.concatenate([[math.cos(rate_l * t / 2)], math.sin(rate_l * t / 2) * axis])
        spin = [math.cos(rate_b * t / 2), 0.0, 0.0, math.sin(rate_b * t / 2)]
        c, sn = math.cos(rate_b * t), math.sin(rate_b * t)
        w_expected = [c * w0[0] + sn * w0[1], -sn * w0[0] + c * w0[1], w0[2]]
        bound = 10 * EPS * (1 + np.linalg.norm(w0) * t)
        assert _qdist(q[0, k], _quat_mul(_quat_mul(turn, q0), spin)) <= bound
        assert np.abs(w[0, k] - w_expected).max() <= bound


# ------------------------------------------------------------------ theory


def test_nutation_period_and_range_against_hard_cases():
    """``2K(m)/ω_n`` and ``[u1, u2]`` against ``hard_cases.top_analytic`` (released at rest;
    scipy's elliptic functions, independent of ``jrigid.special``)."""
    cases = [c for c in hc.CASES.values() if c.key.startswith("top_fast")]
    cases += [hc.Case("slow_release", "5", "", moments=(1.0, 1.0, 1.5), tilt=0.9, spin_ratio=3.0),
              hc.Case("low_release", "5", "", moments=(0.7, 0.7, 0.3), tilt=2.2, spin_ratio=6.0,
                      mass=2.0, height=0.4, g=3.0)]  # fmt: skip
    tops = []
    for case in cases:
        scene, state = hc.scene(case), hc.initial_state(case)
        body = scene.body
        tops.append((body.moments, body.mass, body.com, scene.loads[0].g, state.q, state.omega))
    _, _, consts = _solve(tops, [np.zeros(N_T)] * len(tops))
    period = np.asarray(lagrange_top.nutation_period(consts))
    u1, u2 = (np.asarray(u) for u in lagrange_top.nutation_range(consts))
    for k, case in enumerate(cases):
        an = hc.top_analytic(case)
        assert period[k] == pytest.approx(an["period"], rel=1e-13), case.key
        assert abs(u2[k] - an["u0"]) < 4 * EPS and abs(u1[k] - an["u1"]) < 4 * EPS, case.key


def test_invariants_conserved_to_rounding():
    """Energy, ``L·ĝ`` and ``L·e3`` along random tops (any g direction, either sign of l)."""
    rng = np.random.default_rng(7)
    cases = []
    for _ in range(B):
        i1 = rng.uniform(0.3, 2.0)
        cases.append(((i1, i1, rng.uniform(0.1, 2 * i1)), rng.uniform(0.5, 2.0),
                      (0.0, 0.0, rng.uniform(-1.5, 1.5)), rng.normal(size=3) * 3,
                      rng.normal(size=4), rng.normal(size=3) * 2))  # fmt: skip
    ts = np.array([0.0, 1.7, 13.0, 120.0, 1900.0, 31000.0])
    q, w, _ = _solve(cases, [ts] * B)
    for k, (mom, mass, com, g, _, _) in enumerate(cases):
        inertia = np.array([mom[0] + mass * com[2] ** 2] * 2 + [mom[2]])
        L = inertia * w[k]
        axis = _rot(q[k])[:, :, 2]
        energy = 0.5 * np.sum(w[k] * L, -1) - mass * com[2] * axis @ g
        L_g = np.einsum("tij,tj->ti", _rot(q[k]), L) @ g
        scale_e = 0.5 * np.sum(w[k, 0] * L[0]) + mass * abs(com[2]) * np.linalg.norm(g)
        scale_l = np.linalg.norm(L[0]) * np.linalg.norm(g)
        assert np.ptp(energy) <= 16 * EPS * scale_e
        assert np.ptp(L_g) <= 16 * EPS * scale_l
        assert np.ptp(L[:, 2]) == 0.0


def test_restart_at_long_times():
    """``q(t1 + t2)`` from ``(q0, ω0)`` equals ``q(t2)`` restarted from the state at ``t1``."""
    t1 = 12345.678
    t2 = np.linspace(0.0, 30.0, N_T)
    q1, w1, _ = _solve([GENERIC], [np.full(N_T, t1)])
    q_full, w_full, _ = _solve([GENERIC], [t1 + t2])
    restart = GENERIC[:4] + (q1[0, 0], w1[0, 0])
    q_re, w_re, _ = _solve([restart], [t2])
    scale = 20 * EPS * t1 * np.linalg.norm(GENERIC[5])
    assert _qdist(q_full[0], q_re[0]).max() < scale
    assert np.abs(w_full[0] - w_re[0]).max() < scale * np.linalg.norm(GENERIC[5])


# ------------------------------------------------------------------ API, batching, float32


def test_broadcasting_equals_vmap_and_shapes():
    _, _, consts = _solve(list(REFERENCE_CASES.values()), [np.linspace(0, 5, N_T)] * B)
    ts = np.linspace(0.0, 5.0, N_T)
    q_b, w_b = lagrange_top.evaluate(consts, ts)  # (B, N_T, ...) by broadcasting
    q_v, w_v = EVALUATE(consts, np.broadcast_to(ts, (B, N_T)))
    assert q_b.shape == (B, N_T, 4) and w_b.shape == (B, N_T, 3)
    np.testing.assert_allclose(np.asarray(q_b), np.asarray(q_v), rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(w_b), np.asarray(w_v), rtol=0, atol=1e-14)
    assert q_b.dtype == jnp.float64


def test_float32(float32):
    """float32 in, float32 out; error of the order of float32 rounding of t (DOP853 reference)."""
    cases = [GENERIC, POLE_CASES["start_at_vertical_kicked"], POLE_CASES["start_hanging_kicked"],
             POLE_CASES["through_vertical_b_eq_a"], POLE_CASES["pendulum_from_rest"],
             OTHER_CASES["unstable_sleeping_upright_spin"], OTHER_CASES["no_gravity"],
             REFERENCE_CASES["looping"]]  # fmt: skip
    ts = np.array([0.0, 0.9, 2.3, 4.1, 6.6, 9.5])
    q_ref, w_ref = _dop853(cases, ts)
    args = [jnp.asarray(np.stack([np.asarray(c[i], float) for c in cases]), jnp.float32)
            for i in range(6)]  # fmt: skip
    q, w = lagrange_top.solve(*args, jnp.asarray(ts, jnp.float32))
    assert q.dtype == jnp.float32 and w.dtype == jnp.float32
    q, w = np.asarray(q, float), np.asarray(w, float)
    for k in range(len(cases)):
        # q agrees along the diagonal: case k at times ts (the broadcast solve is B x T)
        scale = max(1.0, np.abs(w_ref[k]).max())
        assert _qdist(q[k], q_ref[k]).max() < 3e-5 * scale
        assert np.abs(w[k] - w_ref[k]).max() < 3e-5 * scale**2


# ------------------------------------------------------------------ derivatives


X0 = np.array([1.0, 0.5, 1.3, 0.8, 0.2, -0.3, -1.9, *GENERIC[4], *GENERIC[5]])
TS_GRAD = np.array([0.0, 0.7, 1.9, 3.1])


def _unpack(x):
    """Packed parameters → ``(moments, mass, com, g, q0, ω0)`` along the symmetric family."""
    zero = 0.0 * x[3]
    return (jnp.stack([x[0], x[0], x[1]]), x[2], jnp.stack([zero, zero, x[3]]), x[4:7],
            x[7:11], x[11:14])  # fmt: skip


def _flat(q, w):
    return jnp.concatenate([(q * jnp.sign(q[..., :1])).ravel(), w.ravel()])


def _closed(x):
    return _flat(*lagrange_top.solve(*_unpack(x), jnp.asarray(TS_GRAD)))


DIRECTION = np.random.default_rng(3).normal(size=14)  # moves every input at once
V_GRAD = np.random.default_rng(5).normal(size=len(TS_GRAD) * (4 + 3))


@pytest.fixture(scope="module")
def derivatives():
    """Forward-mode derivative along ``DIRECTION`` and reverse-mode gradient of ``v·f`` of
    the closed form, run op by op (``jax.disable_jit``): the same derivative rules without
    a half-minute compilation each (a jitted derivative is tested by
    :func:`test_jitted_time_derivative_satisfies_the_equations_of_motion`)."""
    with jax.disable_jit():
        _, tangent = jax.jvp(_closed, (jnp.asarray(X0),), (jnp.asarray(DIRECTION),))
        grad = jax.grad(lambda x: jnp.dot(_closed(x), V_GRAD))(jnp.asarray(X0))
    return np.asarray(tangent), np.asarray(grad)


def _finite_differences(directions, h=1e-6):
    """Central differences of the packed outputs along each row of ``directions``."""
    cases, times = [], []
    for d in directions:
        for sign in (1.0, -1.0):
            cases.append(_unpack(X0 + sign * h * d))
            times.append(np.concatenate([TS_GRAD, TS_GRAD[:2]]))
    flat = []
    for i in range(0, len(cases), B):
        q, w, _ = _solve(cases[i : i + B], times[i : i + B])
        flat += [
            np.asarray(_flat(jnp.asarray(q[k, :4]), jnp.asarray(w[k, :4]))) for k in range(len(q))
        ]
    return np.stack([(flat[2 * k] - flat[2 * k + 1]) / (2 * h) for k in range(len(directions))])


def test_forward_mode_against_finite_differences(derivatives):
    # central differences: truncation h² times a third derivative, rounding eps |f|/h
    fd = _finite_differences([DIRECTION])[0]
    np.testing.assert_allclose(derivatives[0], fd, rtol=0, atol=1e-8)


def test_reverse_mode_against_finite_differences(derivatives):
    """Every component: moments (``I1 = I2`` together, ``I3``), mass, lever, g, q0, ω0."""
    fd = _finite_differences(np.eye(14)) @ V_GRAD
    np.testing.assert_allclose(derivatives[1], fd, rtol=0, atol=1e-7)


def test_forward_mode_against_forward_mode_integration(derivatives):
    """``jax.jacfwd`` through ``jrigid.simulate(adjoint=ForwardMode, rtol 1e-12)``."""

    def integrated(s):
        moments, mass, com, g, q0, w0 = _unpack(X0 + DIRECTION * s)
        scene = Scene(RigidBody(moments, mass, com), Pivot(), Gravity(g))
        state = initial.from_omega(q0 / jnp.linalg.norm(q0), w0)
        traj = simulate(scene, state, jnp.asarray(TS_GRAD), rtol=1e-12, atol=1e-14,
                        max_steps=20_000, adjoint=diffrax.ForwardMode())  # fmt: skip
        return _flat(traj.q, traj.omega)

    jac = jax.jit(jax.jacfwd(integrated))(jnp.zeros(()))
    np.testing.assert_allclose(derivatives[0], np.asarray(jac), rtol=0, atol=1e-9)


def test_reverse_mode_equals_forward_mode(derivatives):
    tangent, grad = derivatives
    assert grad @ DIRECTION == pytest.approx(V_GRAD @ tangent, rel=1e-12)


def test_jitted_time_derivative_satisfies_the_equations_of_motion():
    """``jax.jvp`` in ``t`` under ``jit``: ``q̇ = ½ q ⊗ (0, ω)`` and ``I' ω̇ = N − ω × I' ω``
    with the gravity torque ``N = r × M R^T g``, for tops through and from the poles too.

    (Not at the very instant a top sits exactly at a pole, ``t = 0`` for two of these: there
    the derivatives miss the first-order tilt, as documented.)"""
    cases = [GENERIC, REFERENCE_CASES["looping"], REFERENCE_CASES["hanging_l_negative"],
             POLE_CASES["start_at_vertical_kicked"], POLE_CASES["through_vertical_b_eq_a"],
             POLE_CASES["pendulum_from_rest"], POLE_CASES["start_hanging_kicked"],
             OTHER_CASES["tilted_gravity_l_negative"]]  # fmt: skip
    _, _, consts = _solve(cases, [np.zeros(N_T)] * B)
    ts = jnp.asarray(np.broadcast_to(np.array([0.05, 0.37, 1.1, 2.9, 7.3, 41.0]), (B, N_T)))
    tangent = jnp.ones_like(ts)
    run = jax.jit(lambda t: jax.jvp(lambda s: EVALUATE(consts, s), (t,), (tangent,)))
    (q, w), (dq, dw) = run(ts)
    q, w, dq, dw = (np.asarray(a) for a in (q, w, dq, dw))
    for k, (mom, mass, com, g, _, _) in enumerate(cases):
        inertia = np.array([mom[0] + mass * com[2] ** 2] * 2 + [mom[2]])
        scale = max(1.0, np.abs(w[k]).max()) ** 2 + mass * abs(com[2]) * np.linalg.norm(g)
        for i in range(N_T):
            expected_dq = 0.5 * _quat_mul(q[k, i], np.concatenate([[0.0], w[k, i]]))
            assert np.abs(dq[k, i] - expected_dq).max() < 1e-12 * scale
            force = mass * _rotate(q[k, i][None], np.asarray(g, float)[None], inverse=True)[0]
            torque = np.cross([0.0, 0.0, com[2]], force)
            expected_dw = (torque - np.cross(w[k, i], inertia * w[k, i])) / inertia
            assert np.abs(dw[k, i] - expected_dw).max() < 1e-12 * scale


# ------------------------------------------------------------------ scenes and bad input


def _scene(moments=(1.0, 1.0, 0.5), com=(0.0, 0.0, 1.0), holder=None, loads=None):
    body = RigidBody(moments, 1.0, com)
    return Scene(body, Pivot() if holder is None else holder, (Gravity(1.0),) if loads is None
                 else loads)  # fmt: skip


def test_applies_and_check_scene():
    assert lagrange_top.applies(_scene())
    assert lagrange_top.applies(_scene(loads=()))  # torque free about the pivot
    assert lagrange_top.applies(_scene(loads=(Gravity(1.0), Gravity((0.3, 0.0, 0.0)))))
    bad = {
        "Pivot holder": _scene(holder=FreeRotation()),
        "only loads may be Gravity": _scene(loads=(Torque(lambda t, kin, p: kin.omega),)),
        "I1 == I2": _scene(moments=(1.0, 1.0 + 1e-12, 0.5)),
        "symmetry axis": _scene(com=(1e-9, 0.0, 1.0)),
    }
    for reason, scene in bad.items():
        assert not lagrange_top.applies(scene)
        with pytest.raises(ValueError, match=reason):
            lagrange_top.check_scene(scene)


def test_prepare_scene_sums_gravity():
    scene = _scene(loads=(Gravity((0.0, 0.0, -0.4)), Gravity((0.0, 0.0, -0.6))))
    assert np.allclose(np.asarray(lagrange_top.scene_gravity(scene)), [0.0, 0.0, -1.0])


def test_bad_input_raises():
    good = list(GENERIC)
    for index, value, message in [
        (0, (1.0, 1.1, 0.5), "symmetric"),
        (0, (1.0, 1.0, -0.5), "positive"),
        (1, -1.0, "mass must be positive"),
        (2, (0.1, 0.0, 1.0), "symmetry axis"),
        (4, (0.0, 0.0, 0.0, 0.0), "non-zero quaternion"),
        (5, (1.0, 2.0), r"shape \(\.\.\., 3\)"),
    ]:
        args = list(good)
        args[index] = value
        with pytest.raises(ValueError, match=message):
            lagrange_top.prepare(*args)


def test_bad_input_under_jit_raises_at_run_time():
    """Traced values are checked with equinox runtime errors (same compiled PREPARE)."""
    cases = list(REFERENCE_CASES.values())
    cases[3] = ((1.0, 1.2, 0.5),) + cases[3][1:]
    args = [np.stack([np.asarray(c[i], float) for c in cases]) for i in range(6)]
    with pytest.raises(Exception, match="symmetric about axis 3"):
        jax.block_until_ready(PREPARE(*args))


# ------------------------------------------------------------------ special functions


def test_square_root_forms_of_carlson_integrals():
    """``elliprf_sqrt``/``elliprj_sqrt`` equal mpmath; derivatives finite at a zero argument.

    Points as ``lagrange_top`` uses them: ``z = 1``, ``x, y, p ≤ 1``, ``x`` or ``y`` tiny, ``p``
    not far below ``x`` (for ``p ≪ x`` the relative accuracy of ``R_J`` degrades: its
    docstring says how).
    """
    pts = [(0.0, 0.3, 1.0, 0.7), (0.5, 1e-8, 1.0, 0.4), (1e-9, 0.9, 1.0, 1e-9),
           (0.0, 1e-30, 1.0, 1e-40), (1.0, 0.4, 0.8, 2.0)]  # fmt: skip
    for sx, sy, sz, sp in pts:
        rf = float(special.elliprf_sqrt(sx, sy, sz))
        rj = float(special.elliprj_sqrt(sx, sy, sz, sp))
        with mp.workdps(DPS):
            assert rf == pytest.approx(float(mp.elliprf(sx**2, sy**2, sz**2)), rel=4 * EPS)
            assert rj == pytest.approx(float(mp.elliprj(sx**2, sy**2, sz**2, sp**2)), rel=1e-14)
    d = jax.grad(lambda c: special.elliprf_sqrt(c, 0.5, 1.0))(0.0)
    # R_F(c², y, z) = R_F(0, y, z) − c/√(yz) + O(c²)
    assert float(d) == pytest.approx(-1.0 / math.sqrt(0.25), rel=1e-12)


def _top_motion(moments, g, com, omega0):
    ts = jnp.array([0.3, 2.7])
    q, w = lagrange_top.solve(moments, 1.0, com, g, jnp.array([0.98, 0.2, 0.0, 0.0]), omega0, ts)
    return jnp.concatenate([q.ravel(), w.ravel()])


def test_derivatives_where_the_closed_form_is_not_smooth_are_nan_not_zero():
    """Without gravity the derivative in g came out exactly 0 (the motion's is 0.62), and
    with the pivot at the centre of mass the one in l was 5 % off: NaN now. The other
    derivatives there stay finite and right (against the numerical solve)."""
    moments, w0 = jnp.array([1.0, 1.0, 0.5]), jnp.array([0.3, -0.2, 5.0])
    lever, g = jnp.array([0.0, 0.0, 1.0]), jnp.array([0.0, 0.0, -9.81])
    d_g = jax.jacfwd(_top_motion, argnums=1)(moments, jnp.zeros(3), lever, w0)
    # one reverse-mode program for the derivatives in the moments and in com
    d_m_l = jax.jacrev(_top_motion, argnums=(0, 2))
    d_l = d_m_l(moments, g, jnp.zeros(3), w0)[1]
    spin = np.array([10, 13])  # ω3 at the two times: conserved, its derivative 0 is right
    others = np.setdiff1d(np.arange(14), spin)
    assert np.all(np.isnan(d_g[others])) and np.all(np.isnan(d_l[others, 2]))
    assert np.all(d_g[spin] == 0.0)
    d_m = d_m_l(moments, jnp.zeros(3), lever, w0)[0]
    assert np.all(np.isfinite(d_m))
    h = 1e-6
    bump = jnp.array([h, h, 0.0])  # within the family of symmetric tops
    fd = (_top_motion(moments + bump, jnp.zeros(3), lever, w0)
          - _top_motion(moments - bump, jnp.zeros(3), lever, w0)) / (2 * h)
    np.testing.assert_allclose(d_m @ jnp.array([1.0, 1.0, 0.0]), fd, atol=1e-7)
    # away from those points the derivatives in g and l are finite
    assert np.all(np.isfinite(jax.jacfwd(_top_motion, argnums=1)(moments, g, lever, w0)))


def test_a_sleeping_top_has_finite_derivatives_in_both_modes():
    """Forward mode gave NaN (a square root at zero), reverse mode zero."""
    args = (jnp.array([1.0, 1.0, 0.5]), jnp.array([0.0, 0.0, -9.81]), jnp.array([0.0, 0.0, 1.0]))
    w0 = jnp.array([0.0, 0.0, 30.0])

    def motion(w):
        q, w_t = lagrange_top.solve(args[0], 1.0, args[2], args[1], jnp.array([1.0, 0, 0, 0]), w,
                                    jnp.array([0.3, 2.7]))
        return jnp.concatenate([q.ravel(), w_t.ravel()])

    fwd, rev = jax.jacfwd(motion)(w0), jax.jacrev(motion)(w0)
    assert np.all(np.isfinite(fwd))
    np.testing.assert_allclose(fwd, rev, atol=1e-12)


@pytest.mark.parametrize("which", ["g", "com", "omega0"])
def test_non_finite_gravity_or_state_is_refused_not_read_as_none(which):
    """NaN gravity gave exactly the motion without gravity."""
    values = dict(g=jnp.array([0.0, 0.0, -9.81]), com=jnp.array([0.0, 0.0, 1.0]),
                  omega0=jnp.array([0.3, -0.2, 5.0]))
    values[which] = values[which].at[2].set(jnp.nan)
    with pytest.raises(ValueError, match=f"{which} has non-finite entries"):
        lagrange_top.solve(jnp.array([1.0, 1.0, 0.5]), 1.0, values["com"], values["g"],
                           jnp.array([1.0, 0, 0, 0]), values["omega0"], jnp.array([0.5]))
