"""Work-precision report on the hard cases: every method's final error against its wall time.

For each case of ``benchmarks/hard_cases.py`` (full size) this runs

- **jrigid's default** (``simulate`` with tolerances only: the quaternion-acceleration
  form, :data:`jrigid.solve.DEFAULT_SOLVER`, projection onto the constraints and the
  invariants);
- every jrigid formulation (``quaternion_acceleration``, ``quaternion_omega``,
  ``body_omega`` where there is no torque, ``euler_angles``, each with the constraint
  projection only: ``quaternion_acceleration + Tsit5`` is jrigid 0.1's default but for
  its ``q̈``, see :class:`jrigid.formulations.QuaternionAcceleration`) × diffrax ``Tsit5``,
  ``Dopri5``, ``Dopri8`` over ``rtol`` = 1e-3 … 1e-12 (``atol = 1e-2 rtol``), plus the
  implicit ``Kvaerno5`` on the thin rod (lean where curves are predictable: the tops skip
  ``Dopri5``, the 10⁴-period case runs three (formulation, solver) pairs at rtol 1e-6 …
  1e-10, the float32 cases four pairs at rtol 1e-3 … 2e-6);
- the chapter's leapfrog (:mod:`jrigid.leapfrog`) at several step sizes;
- on the tops, the exact-flow splitting methods (:mod:`jrigid.splitting`: Strang, order 2;
  Yoshida and Suzuki, order 4; Kahan–Li, orders 6 and 8) at several fixed steps;
- the exact solver (``simulate(solver="exact")``: :mod:`jrigid.exact` torque free,
  :mod:`jrigid.lagrange_top` on the tops);
- scipy ``solve_ivp`` DOP853, RK45 and LSODA on the same equations (numpy right-hand
  side of ``speed_vs_error.Problem``; DOP853 only in float32 cases and on the top over 10⁴
  nutation periods, none on the free rotor over 10⁴ periods, where one run at rtol 1e-4
  takes 13 s for an error of 0.4);
- MuJoCo (optional ``bench`` extra): a free joint (torque-free cases) or a ball joint
  under gravity (tops), integrators ``RK4`` and ``implicitfast`` at several time steps
  (``RK4`` only on the top over 10⁴ nutation periods).
  MuJoCo's free/ball-joint quaternion is body → world, scalar first, and the angular
  velocity in ``qvel`` is in the body frame, as jrigid's (checked against
  ``jrigid.exact`` at a small step: agreement to 1e-14).

Each case also runs its own check: the flip times near the separatrix (case 2), the top's
nutation period and amplitude (case 5), the published solutions and invariants (B5, HNW),
the drift of energy, ``|L|`` (or the vertical momentum of the top) and ``|q|`` (case 6)
and gimbal lock (case 8).

The error is the worst of the relative final ω error and the sign-invariant final ``q``
error, against :func:`hard_cases.reference` (``jrigid.exact`` or scipy DOP853 at rtol
1e-13 cross-checked with a second set of equations). Times are wall-clock after
compilation (every jrigid (formulation, solver) is jitted and compiled once per scene
structure and reused across cases: the scene's arrays are inputs), medians of interleaved
rounds (``harness.time_interleaved``); calls slower than ``SLOW`` seconds are timed once,
and a method's tighter tolerances are skipped after a call slower than ``BUDGET``.
Float32 cases run with x64 off (``jax.enable_x64(False)``), against the float64
reference.

Usage::

    python benchmarks/work_precision.py            # every case, < 15 min on 2 cores
    python benchmarks/work_precision.py --quick    # three cases at small size, ~1 min

Writes ``work_precision[_quick].json`` (raw numbers), ``.md`` (tables) and one PNG per
case (``work_precision[_quick]_<case>.png``) to ``benchmarks/results/`` (or ``--out``),
and with ``--figure PATH`` a summary figure of four cases (the README's).
"""

from __future__ import annotations

import math
import pathlib
import sys
import time
import warnings
from collections.abc import Callable

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import hard_cases as hc  # noqa: E402
import harness  # noqa: E402

from jrigid.formulations import FORMULATIONS  # noqa: E402  (every formulation, by name)
from jrigid.integrate import simulate  # noqa: E402
from jrigid.leapfrog import leapfrog  # noqa: E402
from jrigid.splitting import Splitting  # noqa: E402
from jrigid.state import Kinematics  # noqa: E402

TARGETS = (1e-4, 1e-8)
TARGETS_F32 = (1e-2, 1e-4)
DEFAULT = "jrigid default"  # simulate(scene, state, ts, rtol=…): no other option
OLD_DEFAULT = "jrigid quaternion_acceleration + Tsit5"  # 0.1's default (|q| projection only)
SOLVERS = {"Tsit5": diffrax.Tsit5, "Dopri5": diffrax.Dopri5, "Dopri8": diffrax.Dopri8,
           "Kvaerno5": diffrax.Kvaerno5}
TOLS = (1e-3, 1e-5, 1e-7, 1e-9, 1e-12)
TOLS_QUICK = (1e-3, 1e-6, 1e-9)
TOLS_LONG = (1e-6, 1e-8, 1e-10)  # over 10⁴ periods, looser settings lose the phase entirely
TOLS_F32 = (1e-3, 1e-4, 1e-5, 2e-6)
STEPS_PER_SCALE = (10, 100, 300, 1000, 3000)  # fixed steps: dt = time_scale / k
STEPS_QUICK = (10, 100, 1000)
STEPS_LONG = (10, 100)
SPLITTINGS = ("strang", "yoshida4", "suzuki4", "kahan_li6", "kahan_li8")
SPLITTINGS_QUICK = ("strang", "kahan_li6")
SPLITTINGS_LONG = ("kahan_li6", "kahan_li8")
STEPS_SPLIT = (3, 10, 30, 100, 300, 1000, 3000)  # dt = time_scale / k, coarse to fine
STEPS_SPLIT_LONG = (2, 3, 5)
SPLIT_MAX_STEPS = 2_000_000  # compiled loop bound (steps past the need are skipped)
MAX_STEPS = 4_000_000
REPEATS = 3
MIN_TIME = 0.03  # seconds of samples per point at least (more samples for fast calls)
SLOW = 0.25  # calls slower than this are timed once (their first call)
BUDGET = 2.0  # a call slower than this ends the method's sweep
BUDGET_LONG = 40.0  # the same for the 10⁴-period cases (every call is long there)

FULL_CASES = ("general", "separatrix_1e-2", "separatrix_1e-4", "separatrix_1e-6",
              "nearly_symmetric", "thin_rod", "top_fast_20", "top_fast_100", "long_horizon",
              "top_long_horizon", "general_f32", "separatrix_1e-2_f32", "long_horizon_f32",
              "detest_b5", "hairer_rigid_body")
QUICK_CASES = ("general", "separatrix_1e-6", "top_fast_100")
FIGURE_CASES = ("general", "separatrix_1e-6", "top_fast_20", "top_fast_100", "long_horizon",
                "top_long_horizon")


# --------------------------------------------------------------------------- compiled solvers


class Compiled:
    """Cache of compiled (jitted, warm) solves, keyed by (scene kind, dtype, method)."""

    def __init__(self, log):
        self.fns: dict[tuple, Callable] = {}
        self.seconds: dict[tuple, float] = {}
        self.log = log

    def get(self, key, build):
        if key not in self.fns:
            self.fns[key], self.seconds[key] = build()
            self.log(f"  compiled {' / '.join(map(str, key))} in {self.seconds[key]:.1f} s")
        return self.fns[key], self.seconds[key]


def _x64(case: hc.Case):
    return jax.enable_x64(case.dtype == "float64")


def _kind(case: hc.Case) -> str:
    return "free" if case.torque_free else "top"


def _final(traj, dtype):
    q = traj.q[-1] if traj.q is not None else jnp.full(4, jnp.nan, dtype)
    return {"q": q, "omega": traj.omega[-1], "steps": traj.stats["num_steps"],
            "ok": traj.result == 0, "result": traj.result}


def jrigid_runner(case, size, formulation, solver_name, cache: Compiled):
    """``(run(rtol), compile_seconds)`` for ``simulate`` with one formulation and solver."""
    prob = hc.problem(case, size)
    with _x64(case):
        scene, state = prob.scene(), prob.state()
        dtype = scene.body.moments.dtype
        ts = jnp.array([0.0, prob.t1], dtype=dtype)

    def build():
        options = {} if solver_name == "default" else dict(
            formulation=formulation, solver=SOLVERS[solver_name](), project="manifold")

        def solve(scene, state, ts, rtol):
            traj = simulate(scene, state, ts, rtol=rtol, atol=1e-2 * rtol,
                            max_steps=MAX_STEPS, throw=False, **options)
            return _final(traj, dtype)

        with _x64(case):
            return harness.warm_jit(jax.jit(solve), scene, state, ts, harness.scalar(1e-6, dtype))

    fn, seconds = cache.get((_kind(case), case.dtype, formulation, solver_name), build)

    def run(rtol):
        with _x64(case):
            return fn(scene, state, ts, harness.scalar(rtol, dtype))

    return run, seconds


def _stepped_runner(case, size, cache: Compiled, name: str, integrate):
    """``(run(dt), compile_seconds)`` for ``integrate(scene, state, ts, dt) -> Trajectory``,
    a fixed-step method compiled once per (scene kind, dtype, ``name``)."""
    prob = hc.problem(case, size)
    with _x64(case):
        scene, state = prob.scene(), prob.state()
        dtype = scene.body.moments.dtype
        ts = jnp.array([0.0, prob.t1], dtype=dtype)

    def build():
        def solve(scene, state, ts, dt):
            return _final(integrate(scene, state, ts, dt), dtype)

        with _x64(case):
            return harness.warm_jit(jax.jit(solve), scene, state, ts, harness.scalar(0.1, dtype))

    fn, seconds = cache.get((_kind(case), case.dtype, name), build)

    def run(dt):
        with _x64(case):
            return fn(scene, state, ts, harness.scalar(dt, dtype))

    return run, seconds


def leapfrog_runner(case, size, cache: Compiled):
    """``(run(dt), compile_seconds)`` for the chapter's leapfrog (midpoint variant)."""
    return _stepped_runner(case, size, cache, "leapfrog",
                           lambda scene, state, ts, dt: leapfrog(scene, state, ts, dt=dt))


def splitting_runner(case, size, method, cache: Compiled):
    """``(run(dt), compile_seconds)`` for ``simulate(solver=Splitting(method, dt=dt))``."""

    def integrate(scene, state, ts, dt):
        solver = Splitting(method, dt=dt, max_steps=SPLIT_MAX_STEPS)
        return simulate(scene, state, ts, solver=solver, throw=False)

    return _stepped_runner(case, size, cache, f"splitting {method}", integrate)


def exact_runner(case, size, cache: Compiled):
    """``(run(_), compile_seconds)`` for ``simulate(solver="exact")``."""
    prob = hc.problem(case, size)
    with _x64(case):
        scene, state = prob.scene(), prob.state()
        dtype = scene.body.moments.dtype
        ts = jnp.array([0.0, prob.t1], dtype=dtype)

    def build():
        def solve(scene, state, ts):
            return _final(simulate(scene, state, ts, solver="exact", throw=False), dtype)

        with _x64(case):
            return harness.warm_jit(jax.jit(solve), scene, state, ts)

    fn, seconds = cache.get((_kind(case), case.dtype, "exact"), build)

    def run(_):
        with _x64(case):
            return fn(scene, state, ts)

    return run, seconds


def scipy_runner(case, size, method):
    """``run(rtol)`` for scipy ``solve_ivp`` on the numpy (q, ω) equations (float64)."""
    prob = hc.problem(case, size)
    rhs, y0, span = prob.numpy_rhs(), prob.y0(), (0.0, prob.t1)

    def run(rtol):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = solve_ivp(rhs, span, y0, method=method, rtol=rtol, atol=1e-2 * rtol)
        return {"q": sol.y[:4, -1], "omega": sol.y[4:, -1], "steps": len(sol.t) - 1,
                "nfev": sol.nfev, "ok": bool(sol.success)}

    return run


def mujoco_xml(case: hc.Case, integrator: str, dt: float) -> str:
    """MJCF of the case: a free joint (torque free, no gravity) or a ball-jointed top."""
    i1, i2, i3 = case.moments
    inertial = f'mass="{case.mass!r}" diaginertia="{i1!r} {i2!r} {i3!r}"'
    if case.torque_free:
        gravity, body = "0 0 0", f'<freejoint/><inertial pos="0 0 0" {inertial}/>'
    else:
        gravity = f"0 0 {-case.g!r}"
        body = f'<joint type="ball" pos="0 0 0"/><inertial pos="0 0 {case.height!r}" {inertial}/>'
    return (
        f'<mujoco><option timestep="{dt!r}" integrator="{integrator}" gravity="{gravity}">'
        '<flag contact="disable"/></option>'
        f'<worldbody><body name="b">{body}</body></worldbody></mujoco>'
    )


def mujoco_runner(case, size, integrator):
    """``run(dt)`` for MuJoCo with ``integrator`` (``"RK4"``/``"implicitfast"``), or ``None``."""
    try:
        import mujoco
    except ImportError:
        return None
    prob = hc.problem(case, size)
    y0, t1 = prob.y0(), prob.t1
    a = 3 if case.torque_free else 0  # quaternion offset in qpos (free joint: after x)
    v = 3 if case.torque_free else 0

    def run(dt):
        n = max(1, math.ceil(t1 / dt - 1e-9))
        model = mujoco.MjModel.from_xml_string(mujoco_xml(case, integrator, t1 / n))
        data = mujoco.MjData(model)
        data.qpos[a:a + 4] = y0[:4]
        data.qvel[v:v + 3] = y0[4:]
        mujoco.mj_step(model, data, nstep=n)
        return {"q": data.qpos[a:a + 4].copy(), "omega": data.qvel[v:v + 3].copy(),
                "steps": n, "ok": bool(np.all(np.isfinite(data.qpos)))}

    return run


# --------------------------------------------------------------------------- sweep


def errors_against(ref: dict, case: hc.Case):
    """``error(out) -> ({name: error}, {name: drift})`` against the reference's final state.

    Drifts are relative: torque free, of energy, ``|L|`` and ``|q|``; on a top, of the total
    energy and of the momentum along gravity, each over the size of its terms
    (:meth:`jrigid.scene.Scene.conserved`'s ``scales``), and of ``|q|``.
    """
    if not case.torque_free:
        with jax.enable_x64(True):
            prob = hc.problem(case, "small")
            scene64, state64 = prob.scene(), prob.state()
            start = scene64.conserved(Kinematics(state64.q, state64.omega))
            c0, scales = np.asarray(start.values, float), np.asarray(start.scales, float)

        def top_drift(q, w):
            with jax.enable_x64(True):
                kin = Kinematics(jnp.asarray(q / np.linalg.norm(q)), jnp.asarray(w))
                c = np.asarray(scene64.conserved(kin).values, float)
            return {"energy_drift": float((c[0] - c0[0]) / scales[0]),
                    "L_drift": float((c[1] - c0[1]) / scales[1]),
                    "q_norm_drift": float(np.linalg.norm(q) - 1.0)}

    def error(out):
        q, w = np.asarray(out["q"], float), np.asarray(out["omega"], float)
        errs = {"omega": harness.omega_error(w, ref["omega"])}
        if q.shape == (4,) and np.all(np.isfinite(q)):
            errs["q"] = harness.quaternion_error(q, ref["q"])
        extra = {}
        if not case.torque_free and "q" in errs:
            extra = top_drift(q, w)
        if case.torque_free:
            inertia = np.asarray(case.moments)
            w0 = np.asarray(case.omega0)
            e0, l0 = inertia @ (w0 * w0), np.linalg.norm(inertia * w0)
            extra["energy_drift"] = float(inertia @ (w * w) / e0 - 1.0)
            extra["L_drift"] = float(np.linalg.norm(inertia * w) / l0 - 1.0)
            if "q" in errs:
                extra["q_norm_drift"] = float(np.linalg.norm(q) - 1.0)
        return errs, extra

    return error


def sweep(methods: dict, error, *, quick: bool, budget: float = BUDGET) -> dict[str, list[dict]]:
    """Time every (method, parameter); errors against the reference.

    Args:
        methods: ``{label: (run, params)}``; ``run(param)`` does one complete solve.
        error: from :func:`errors_against`.

    Returns:
        ``{label: [point dict, ...]}`` with ``param``, ``time`` (median), ``time_min``,
        ``times``, ``error`` (worst of ω and q), ``errors``, ``extra``, ``steps``, ``ok``.
    """
    first, outs, calls, notes = {}, {}, {}, {}
    budget = budget / (4 if quick else 1)
    for label, (run, params) in methods.items():
        for i, p in enumerate(params):
            key = (label, i)
            start = time.perf_counter()
            try:
                out = jax.block_until_ready(run(p))
            except Exception as exc:  # noqa: BLE001 - a failed method is recorded, not fatal
                notes[key] = f"{type(exc).__name__}: {str(exc)[:160]}"
                break
            first[key], outs[key] = time.perf_counter() - start, out
            calls[key] = lambda run=run, p=p: run(p)
            if first[key] > budget:
                notes[key] = f"tighter settings skipped: a run took > {budget:g} s"
                break
    fast = {k: c for k, c in calls.items() if first[k] <= SLOW}
    timed = harness.time_interleaved(
        fast, 2 if quick else REPEATS, warmup=0, durations={k: first[k] for k in fast},
        min_time=MIN_TIME,
    )
    points: dict[str, list[dict]] = {label: [] for label in methods}
    for key in list(first) + [k for k in notes if k not in first]:
        label, i = key
        params = methods[label][1]
        if key not in first:
            points[label].append({"param": params[i], "ok": False, "note": notes[key]})
            continue
        timing, out = timed.get(key, (harness.Timing([first[key]]), outs[key]))
        ok = bool(np.asarray(out.get("ok", True)))
        if not ok and out.get("result") is not None and key not in notes:
            from jrigid.integrate import Result

            notes[key] = f"failed: Result.{Result(int(np.asarray(out['result']))).name}"
        errs, extra = error(out) if ok else ({}, {})
        worst = max(errs.values()) if errs else math.nan
        ok = ok and math.isfinite(worst)
        steps = out.get("steps")
        points[label].append({
            "param": params[i], "time": timing.median, "time_min": timing.min,
            "times": timing.runs, "error": worst if ok else None, "errors": errs,
            "extra": extra, "steps": None if steps is None else int(np.asarray(steps)),
            "nfev": None if out.get("nfev") is None else int(out["nfev"]), "ok": ok,
            "note": notes.get(key, ""),
        })
    return points


def method_table(case: hc.Case, size: str, quick: bool, cache: Compiled,
                 only: Callable[[str], bool] | None = None):
    """``{label: (run, params, compile_seconds, kind)}`` for one case.

    ``only`` (a predicate on labels) selects methods before anything is compiled.
    """
    f32 = case.dtype == "float32"
    long = case.periods >= 1e3 and size == "full"
    tols = TOLS_F32 if f32 else TOLS_QUICK if quick else TOLS_LONG if long else TOLS
    if f32 and long:  # rtol 1e-5 takes 25 s here and fails: float32 t cannot resolve a step
        tols = TOLS_F32[:2]
    scale = hc.time_scale(case)
    steps = STEPS_QUICK if quick else STEPS_LONG if long else STEPS_PER_SCALE
    dts = [scale / k for k in steps]
    if quick:
        combos = [("quaternion_acceleration", "Tsit5"), ("quaternion_omega", "Dopri8")]
    elif f32 and long:
        combos = [("quaternion_acceleration", "Tsit5"), ("quaternion_omega", "Tsit5"),
                  ("body_omega", "Tsit5")]
    elif f32:
        combos = [("quaternion_acceleration", "Tsit5"), ("quaternion_omega", "Tsit5"),
                  ("quaternion_omega", "Dopri8"), ("body_omega", "Tsit5")]
    elif long:
        combos = [("quaternion_acceleration", "Tsit5"), ("quaternion_omega", "Dopri8"),
                  ("body_omega", "Dopri8")]
    elif case.torque_free:
        combos = [(f, s) for s in ("Tsit5", "Dopri5", "Dopri8") for f in FORMULATIONS]
    else:  # tops: Dopri5 behaves as Tsit5 and each top compile is long
        combos = [(f, s) for s in ("Tsit5", "Dopri8") for f in FORMULATIONS]
    if case.key == "thin_rod" and not quick:
        combos.append(("quaternion_omega", "Kvaerno5"))
    if not case.torque_free:
        combos = [c for c in combos if c[0] != "body_omega"]
    combos = [("quaternion_acceleration", "default"), *combos]
    builders = {}
    for formulation, solver in combos:
        label = DEFAULT if solver == "default" else f"jrigid {formulation} + {solver}"
        builders[label] = (
            lambda f=formulation, s=solver: jrigid_runner(case, size, f, s, cache), tols, "rtol")
    builders["jrigid leapfrog (chapter, midpoint)"] = (
        lambda: leapfrog_runner(case, size, cache), dts, "dt")
    if not case.torque_free:
        methods = SPLITTINGS_QUICK if quick else SPLITTINGS_LONG if long else SPLITTINGS
        ks = STEPS_SPLIT[:4] if quick else STEPS_SPLIT_LONG if long else STEPS_SPLIT
        for method in methods:
            builders[f"jrigid splitting {method}"] = (
                lambda m=method: splitting_runner(case, size, m, cache), [scale / k for k in ks],
                "dt")
    builders["jrigid exact"] = (lambda: exact_runner(case, size, cache), [0.0], "—")
    # over 10⁴ periods of the free rotor scipy DOP853 takes 13 s at rtol 1e-4 for an error
    # of 0.4 and MuJoCo RK4 3 s at 10 steps a period for an error of 1: both are left out
    # there; on the top over 10⁴ nutation periods DOP853 and RK4 run at tight settings.
    long_free = long and case.torque_free
    scipy_methods = ("DOP853",) if quick or f32 or long else ("DOP853", "RK45", "LSODA")
    if not long_free:
        for m in scipy_methods:
            builders[f"scipy {m}"] = (lambda m=m: (scipy_runner(case, size, m), None),
                                      tols if quick or f32 or long else TOLS,
                                      "rtol")
    if not (f32 or long_free):
        mujoco_dts = [scale / k for k in (10, 30, 100)] if long else dts
        for integrator in ("RK4",) if quick or long else ("RK4", "implicitfast"):
            if mujoco_runner(case, size, integrator) is not None:
                builders[f"MuJoCo {integrator}"] = (
                    lambda i=integrator: (mujoco_runner(case, size, i), None), mujoco_dts, "dt")
    table = {}
    for label, (build, params, kind) in builders.items():
        if only is None or only(label):
            run, seconds = build()
            table[label] = (run, params, seconds, kind)
    return table


def is_peer(label: str) -> bool:
    return not label.startswith("jrigid")


def summarise(points: dict[str, list[dict]], targets=TARGETS) -> dict:
    """Time to each target error per method, the best peer's, and the ratios to it."""
    tte = {}
    for label, pts in points.items():
        good = [p for p in pts if p["ok"]]
        errs, times = [p["error"] for p in good], [p["time"] for p in good]
        row = {}
        for target in targets:
            t, kind = harness.time_to_error(errs, times, target)
            row[target] = {"seconds": t, "kind": kind}
        row["best_error"] = min(errs, default=None)
        tte[label] = row
    best_peer = {}
    for target in targets:
        cands = [(r[target]["seconds"], k) for k, r in tte.items()
                 if is_peer(k) and r[target]["seconds"] is not None]
        best_peer[target] = min(cands) if cands else (None, None)
        for row in tte.values():
            t, peer = row[target]["seconds"], best_peer[target][0]
            row[target]["ratio_to_best_peer"] = t / peer if t and peer else None
    return {"time_to_error": tte, "targets": list(targets),
            "best_peer": {t: {"label": k, "seconds": s} for t, (s, k) in best_peer.items()}}


# --------------------------------------------------------------------------- checks


CHECK_SAMPLES = 4001


def _sampled_default(case: hc.Case, ts: np.ndarray, rtol: float = 1e-10):
    """jrigid's default at ``rtol``, sampled at ``ts``: ``(q, ω)`` numpy arrays."""
    prob = hc.problem(case, "full")
    traj = simulate(prob.scene(), prob.state(), jnp.asarray(ts), rtol=rtol, atol=1e-2 * rtol,
                    max_steps=MAX_STEPS, throw=False)
    return np.asarray(traj.q, float), np.asarray(traj.omega, float)


def _sampled_scipy(case: hc.Case, ts: np.ndarray, rtol: float):
    prob = hc.problem(case, "full")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = solve_ivp(prob.numpy_rhs(), (0.0, ts[-1]), prob.y0(), method="DOP853", rtol=rtol,
                        atol=min(1e-2 * rtol, 1e-15), t_eval=ts)
    return sol.y[:4].T, sol.y[4:].T


def flip_check(case: hc.Case) -> dict:
    """Case 2: times between flips of ω2 against the exact value ``2K(m)/λ``.

    The exact solver's flips are found by root finding on its ω2; those of jrigid's
    default (rtol 1e-10) and scipy DOP853 (rtol 1e-10) from 4001 samples (cubic Hermite).
    """
    from jrigid import exact

    t1 = hc.horizon(case, "full")
    half = 0.5 * hc.free_period(case.moments, case.omega0)
    state = hc.initial_state(case)
    args = (jnp.asarray(case.moments), state.q, jnp.asarray(case.omega0))
    ex = hc.flip_times(lambda t: np.asarray(exact.solve(*args, jnp.asarray(t))[1])[:, 1], t1)
    ts = np.linspace(0.0, t1, CHECK_SAMPLES)
    out = {"half_period": half, "methods": {}}
    found = {"jrigid exact": ex,
             f"{DEFAULT}, rtol 1e-10": hc.flips_from_samples(
                 case.moments, ts, _sampled_default(case, ts)[1]),
             "scipy DOP853, rtol 1e-10": hc.flips_from_samples(
                 case.moments, ts, _sampled_scipy(case, ts, 1e-10)[1])}
    for label, flips in found.items():
        row = {"count": int(len(flips))}
        if len(flips) >= 2:
            row["interval_error"] = float(np.max(np.abs(np.diff(flips) / half - 1.0)))
        if len(flips) == len(ex) and len(ex):
            row["last_flip_shift"] = float(abs(flips[-1] - ex[-1]))
        out["methods"][label] = row
    return out


def nutation_check(case: hc.Case) -> dict:
    """Case 5: nutation period and amplitude, measured, against the analytic values."""
    an = hc.top_analytic(case)
    ts = np.linspace(0.0, hc.horizon(case, "full"), CHECK_SAMPLES)
    out = {"analytic": {"period": an["period"], "amplitude": an["amplitude"]}, "methods": {}}
    for label, (q, w) in {f"{DEFAULT}, rtol 1e-10": _sampled_default(case, ts),
                          "scipy DOP853, rtol 1e-13": _sampled_scipy(case, ts, 1e-13)}.items():
        m = hc.nutation_from_samples(ts, q, w)
        u, _ = hc.u_and_rate(q, w)
        out["methods"][label] = {
            "period_error": m["period"] / an["period"] - 1.0,
            "amplitude_error": m["amplitude"] / an["amplitude"] - 1.0,
            "max_cos_theta_error": float(np.max(np.abs(u - hc.top_u(case, ts)))),
            "turning_points": m["count"],
        }
    return out


def published_check(case: hc.Case) -> dict:
    """B5 / HNW: the exact solver mapped back to ``y`` against the published solution.

    B5: against ``(sn, cn, dn)(t | 0.51)`` from ``jrigid.special`` and from scipy. HNW:
    the two quadratic invariants along the exact solution and along scipy DOP853 (rtol
    1e-10) on the published equations, and the two solutions against each other.
    """
    from scipy import special as sps

    from jrigid import exact

    d = hc.published_map(case)
    ts = np.linspace(0.0, 20.0, CHECK_SAMPLES)
    state = hc.initial_state(case)
    y = np.asarray(exact.solve(jnp.asarray(case.moments), state.q, jnp.asarray(case.omega0),
                               jnp.asarray(ts))[1]) / d
    if case.published == "B5":
        sn, cn, dn, _ = sps.ellipj(ts, 0.51)
        return {"published": "B5",
                "max_error_vs_jrigid_special": float(np.max(np.abs(y - hc.b5_exact(ts)))),
                "max_error_vs_scipy_ellipj": float(np.max(np.abs(
                    y - np.stack([sn, cn, dn], axis=-1))))}
    _, coeffs, y0 = hc.published("HNW")
    sol = solve_ivp(hc.published_rhs(coeffs), (0.0, 20.0), y0, method="DOP853", rtol=1e-10,
                    atol=1e-12, t_eval=ts)
    inv0 = hc.hnw_invariants(y0)
    drift = lambda yy: float(np.max(np.abs(hc.hnw_invariants(yy) / inv0 - 1.0)))  # noqa: E731
    return {"published": "HNW", "invariant_drift_exact": drift(y),
            "invariant_drift_dop853": drift(sol.y.T),
            "max_difference_exact_vs_dop853": float(np.max(np.abs(sol.y.T - y)))}


def check_lines(res: dict) -> list[str]:
    """Markdown for a case's check (flips, nutation, published), if any."""
    chk = res.get("check")
    if not chk:
        return []
    if chk.get("published") == "B5":
        return [f"Check: the exact solver mapped to y matches (sn, cn, dn)(t | 0.51) on "
                f"t ∈ [0, 20] to {chk['max_error_vs_jrigid_special']:.1e} (jrigid.special) "
                f"and {chk['max_error_vs_scipy_ellipj']:.1e} (scipy.special.ellipj).", ""]
    if chk.get("published") == "HNW":
        return [f"Check: the two quadratic invariants drift by at most "
                f"{chk['invariant_drift_exact']:.1e} along the exact solution and "
                f"{chk['invariant_drift_dop853']:.1e} along scipy DOP853 (rtol 1e-10) on the "
                f"published equations; the two differ by at most "
                f"{chk['max_difference_exact_vs_dop853']:.1e} on [0, 20].", ""]
    if "half_period" in chk:
        rows = [[label, r["count"], f"{r['interval_error']:.1e}" if "interval_error" in r else "—",
                 f"{r['last_flip_shift']:.1e}" if "last_flip_shift" in r else "—"]
                for label, r in chk["methods"].items()]
        return [f"Flips of ω2: exact time between flips 2K(m)/λ = {chk['half_period']:.12g} "
                "(classical formula, scipy `ellipkm1`).", "",
                harness.markdown_table(["method", "flips", "max relative error of the "
                                        "interval", "last flip vs exact [time]"], rows), ""]
    an = chk["analytic"]
    rows = [[label, f"{r['period_error']:.1e}", f"{r['amplitude_error']:.1e}",
             f"{r['max_cos_theta_error']:.1e}", r["turning_points"]]
            for label, r in chk["methods"].items()]
    return [f"Nutation: analytic period {an['period']:.12g}, amplitude {an['amplitude']:.12g} rad.",
            "", harness.markdown_table(["method", "period rel. error", "amplitude rel. error",
                                        "max error of cos θ(t)", "turning points"], rows), ""]


def gimbal_lock_check(cache_log) -> dict:
    """Case 8: Euler angles must report gimbal lock; quaternion formulations must integrate."""
    from jrigid.integrate import SimulationError

    case = hc.CASES["gimbal_lock"]
    prob = hc.problem(case, "full")
    ref = hc.reference(case, "full")
    scene, state = prob.scene(), prob.state()
    ts = jnp.array([0.0, prob.t1])
    out = {}
    for formulation in ("euler_angles", "quaternion_acceleration", "quaternion_omega"):
        try:
            traj = simulate(scene, state, ts, formulation=formulation, rtol=1e-10, atol=1e-12)
            err = max(harness.omega_error(traj.omega[-1], ref["omega"]),
                      harness.quaternion_error(traj.q[-1], ref["q"]))
            out[formulation] = {"failed": False, "error": err, "message": ""}
        except (ValueError, SimulationError) as exc:
            out[formulation] = {"failed": True, "error": None, "message": str(exc)}
    cache_log(f"[gimbal_lock] {out}")
    return out


# --------------------------------------------------------------------------- report


def _fmt_ratio(r) -> str:
    return "—" if r is None else f"{r:.2g}×"


def case_markdown(res: dict) -> list[str]:
    case, summ = res["case"], res["summary"]
    tte = summ["time_to_error"]
    lines = [f"## {case['number']}. {case['title']} (`{case['key']}`)", "",
             f"Horizon t = {res['t1']:.6g} ({res['dtype']}). Reference: "
             f"{res['reference']['source']}; {res['reference']['check']}.", ""]
    targets = summ["targets"]
    head = ["method", "compile"]
    for t in targets:
        head += [f"time to {t:.0e}", "÷ best peer"]
    head += ["best error"]
    rows = []
    for label, row in tte.items():
        cs = res["methods"][label]["compile_seconds"]
        cells = [f"**{label}**" if label == DEFAULT else label,
                 "—" if cs is None else f"{cs:.1f} s"]
        for t in targets:
            cells += [harness.fmt_seconds(row[t]["seconds"], row[t]["kind"]),
                      _fmt_ratio(row[t]["ratio_to_best_peer"])]
        be = row["best_error"]
        cells.append("—" if be is None else f"{be:.1g}")
        rows.append(cells)
    lines += [harness.markdown_table(head, rows), ""]
    peers = ", ".join(
        f"{t:.0e}: {v['label']} ({harness.fmt_seconds(v['seconds'])})"
        for t, v in summ["best_peer"].items() if v["label"]
    )
    lines += [f"Best peer: {peers or 'none reached the targets'}.", ""]
    notes = [f"- {label}, setting {p['param']:.3g}: {p['note']}"
             for label, m in res["methods"].items() for p in m["points"] if p.get("note")]
    if notes:
        lines += ["Notes:", "", *notes, ""]
    lines += check_lines(res)
    if res.get("drift"):
        drow = [[label, f"{d['param']:.3g}", harness.fmt_seconds(d["time"]),
                 f"{d['error']:.1g}", f"{d['energy_drift']:.1e}", f"{d['L_drift']:.1e}",
                 "—" if d.get("q_norm_drift") is None else f"{d['q_norm_drift']:.1e}"]
                for label, d in res["drift"].items()]
        momentum = "|L|" if case.get("tilt") is None else "L·ĝ"
        lines += [f"Drift at the final time (tightest setting run; energy and {momentum} "
                  "relative):", "",
                  harness.markdown_table(["method", "rtol or dt", "time", "error", "energy",
                                          momentum, "|q| − 1"], drow), ""]
    return lines


def overview(results: list[dict]) -> list[str]:
    """One row per case: jrigid's default, its best integrator, the exact solver, the best peer.

    One table per set of target errors (float64 cases, float32 cases).
    """
    out = []
    for targets in dict.fromkeys(tuple(r["summary"]["targets"]) for r in results):
        out += _overview([r for r in results if tuple(r["summary"]["targets"]) == targets],
                         targets)
    return out


def _overview(results: list[dict], targets) -> list[str]:
    head = ["case"]
    for t in targets:
        head += [f"default to {t:.0e}", f"best jrigid integrator to {t:.0e}",
                 f"best peer to {t:.0e}", "best jrigid ÷ peer"]
    head += ["exact solver"]
    rows = []
    for res in results:
        tte = res["summary"]["time_to_error"]
        cells = [f"{res['case']['number']} `{res['case']['key']}`"]
        for t in targets:
            js = [(r[t]["seconds"], k) for k, r in tte.items()
                  if not is_peer(k) and k != "jrigid exact" and r[t]["seconds"] is not None]
            jbest = min(js) if js else (None, None)
            peer = res["summary"]["best_peer"][t]
            d = tte.get(DEFAULT, {}).get(t, {})
            cells.append(harness.fmt_seconds(d.get("seconds"), d.get("kind", "unreached")))
            cells.append("—" if jbest[0] is None else
                         f"{harness.fmt_seconds(jbest[0])} ({jbest[1].removeprefix('jrigid ')})")
            cells.append("—" if peer["label"] is None else
                         f"{harness.fmt_seconds(peer['seconds'])} ({peer['label']})")
            cells.append(_fmt_ratio(jbest[0] / peer["seconds"])
                         if jbest[0] and peer["seconds"] else "—")
        ex = res["methods"].get("jrigid exact")
        if ex and ex["points"] and ex["points"][0]["ok"]:
            p = ex["points"][0]
            cells.append(f"{harness.fmt_seconds(p['time'])}, error {p['error']:.0e}")
        else:
            cells.append("—")
        rows.append(cells)
    return [harness.markdown_table(head, rows), ""]


def compile_lines(cache: Compiled) -> list[str]:
    rows = [[" / ".join(map(str, k)), f"{s:.1f} s"] for k, s in cache.seconds.items()]
    return ["## Compile times", "",
            "Each jrigid (scene structure, dtype, method) is compiled once (its first call) and "
            "reused for every case of that structure.", "",
            harness.markdown_table(["scene / dtype / method", "compile"], rows), ""]


def report(results, machine, cache, gimbal, *, quick: bool, seconds: float) -> str:
    lines = ["# Work-precision on the hard cases" + (" (quick)" if quick else ""), "",
             f"Machine: {harness.machine_line(machine)}.", "",
             "Times are wall-clock after compilation, medians of interleaved rounds "
             f"(≥ {2 if quick else REPEATS} runs; calls over {SLOW} s once), interpolated "
             "log-log on each method's Pareto front; `≤` means the cheapest run was already "
             "more accurate, `—` that no run reached the error. Error = worst of relative "
             "final ω error and sign-invariant final q error. “÷ best peer” is the time over "
             "the fastest non-jrigid method (scipy, MuJoCo) at that error in the same run "
             "(below 1: jrigid faster).", "",
             "## Overview", ""]
    lines += overview(results)
    for res in results:
        lines += case_markdown(res)
    if gimbal:
        lines += ["## 8. Sleeping top at θ0 = 1e-3 (`gimbal_lock`)", ""]
        for f, g in gimbal.items():
            what = (f"fails clearly: {g['message'][:200]}" if g["failed"]
                    else f"integrates, final error {g['error']:.1g}")
            lines.append(f"- `{f}`: {what}")
        lines.append("")
    lines += compile_lines(cache)
    lines += [f"Total wall time: {seconds:.0f} s.", ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------- main


def run_case(case: hc.Case, size: str, *, quick: bool, cache: Compiled, log,
             only: Callable[[str], bool] | None = None, checks: bool = False) -> dict:
    """Reference, methods, sweep and summary for one case (``only`` filters labels).

    ``checks``: also run the case's own check (flips for case 2, nutation for case 5).
    """
    start = time.perf_counter()
    ref = hc.reference(case, size)
    log(f"[{case.key}] t1 = {ref['t1']:.6g}; reference {ref['source']}; {ref['check']}")
    table = method_table(case, size, quick, cache, only)
    long = case.periods >= 1e3 and size == "full" and case.dtype == "float64"
    points = sweep({k: (v[0], v[1]) for k, v in table.items()}, errors_against(ref, case),
                   quick=quick, budget=BUDGET_LONG if long else BUDGET)
    res = {
        "case": case.__dict__, "t1": ref["t1"], "dtype": case.dtype, "size": size,
        "reference": {k: v for k, v in ref.items()},
        "methods": {k: {"compile_seconds": v[2], "param": v[3], "points": points[k]}
                    for k, v in table.items()},
    }
    res["summary"] = summarise(points, TARGETS_F32 if case.dtype == "float32" else TARGETS)
    if checks and case.eps is not None and case.dtype == "float64":
        res["check"] = flip_check(case)
    if checks and case.spin_ratio is not None and case.periods < 1e3:
        res["check"] = nutation_check(case)
    if checks and case.published:
        res["check"] = published_check(case)
    if case.periods >= 1e3:
        res["drift"] = {}
        for label, pts in points.items():
            good = [p for p in pts if p["ok"] and p["extra"]]
            if good:
                res["drift"][label] = dict(good[-1]["extra"], param=good[-1]["param"],
                                           time=good[-1]["time"], error=good[-1]["error"])
    log(f"[{case.key}] done in {time.perf_counter() - start:.0f} s")
    return res


def panels_of(results) -> dict:
    return {
        f"{r['case']['number']}. {r['case']['title']}": {
            label: ([p["error"] for p in m["points"] if p["ok"]],
                    [p["time"] for p in m["points"] if p["ok"]])
            for label, m in r["methods"].items()
        }
        for r in results
    }


def main(argv: list[str] | None = None) -> dict:
    parser = harness.command_line(__doc__, quick="three cases at small size, ~1 min",
                                  quiet=True)
    parser.add_argument("--cases", default=None, help="comma-separated case keys (default all)")
    parser.add_argument("--figure", default=None, help="also write the summary figure here")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    log = harness.logger(args.quiet)
    machine = harness.machine_info()
    log(harness.machine_line(machine))
    keys = args.cases.split(",") if args.cases else (QUICK_CASES if args.quick else FULL_CASES)
    size = "small" if args.quick else "full"
    cache = Compiled(log)
    results = [run_case(hc.CASES[k], size, quick=args.quick, cache=cache, log=log,
                        checks=not args.quick) for k in keys]
    gimbal = None if args.quick or args.cases else gimbal_lock_check(log)
    seconds = time.perf_counter() - start
    machine["load_average_end"] = harness.machine_info()["load_average"]

    out_dir = harness.results_dir(args.out)
    stem = harness.stem("work_precision", args.quick)
    text = report(results, machine, cache, gimbal, quick=args.quick, seconds=seconds)
    harness.write_text(out_dir / f"{stem}.md", text)
    harness.write_json(out_dir / f"{stem}.json", {
        "machine": machine, "quick": args.quick, "size": size, "targets": TARGETS,
        "total_seconds": seconds,
        "compile_seconds": {" / ".join(map(str, k)): s for k, s in cache.seconds.items()},
        "gimbal_lock": gimbal,
        "cases": {r["case"]["key"]: r for r in results},
    })
    panels = panels_of(results)
    for res, (name, curves) in zip(results, panels.items(), strict=True):
        harness.work_precision_figure(
            {name: curves}, out_dir / f"{stem}_{res['case']['key']}.png",
            targets=res["summary"]["targets"],
            highlight=(DEFAULT, "jrigid exact"), title=harness.machine_line(machine),
        )
    if args.figure:
        chosen = {n: c for (n, c), r in zip(panels.items(), results, strict=True)
                  if r["case"]["key"] in FIGURE_CASES}
        harness.work_precision_grid(
            chosen or panels, args.figure, ncols=2, targets=TARGETS,
            highlight=(DEFAULT, "jrigid exact"), title=harness.machine_line(machine),
        )
    print(text)
    return {"results": results, "markdown": text, "out_dir": out_dir, "stem": stem}


if __name__ == "__main__":
    main()
