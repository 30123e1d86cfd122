"""Speed against error: jrigid's default against hand-written diffrax and scipy ``solve_ivp``.

Three problems, each integrated over 100 time units:

- **free rotor** — asymmetric body, moments (1, 2, 3), ω0 = (1, 0.3, 0.7), oriented so
  that the angular momentum points along space z (then the ZXZ Euler angles never reach
  gimbal lock and the Euler-angle formulation can run too);
- **near the intermediate axis** — moments (1, 2, 2.5), ω0 = (0.05, 2, 0.1): a rotor that
  flips, where phase errors grow fastest;
- **heavy top** — symmetric top on a fixed pivot under gravity: central moments
  (1, 1, 0.5), mass 1, centre of mass 1 above the pivot on the symmetry axis, g = 1,
  released at tilt θ0 = 0.6 with spin ψ̇ = 5, precession φ̇ = 0.2, nutation θ̇ = 0.1.

Methods: **jrigid's default** (``simulate`` with no options: quaternion acceleration,
:data:`jrigid.integrate.DEFAULT_SOLVER`, projection onto the constraints and the
invariants); jrigid 0.1's default (the same form with the chapter's literal ``q̈``,
``QuaternionAcceleration(centripetal=True)``, diffrax's ``Tsit5`` and ``|q|`` projection
only) for comparison; in full mode other formulations and solvers; a
**hand-written** ``diffrax.diffeqsolve`` on the flat ``(q, ω)`` equations with ``Tsit5``
and ``Dopri8`` (jitted, ``SaveAt(t1=True)``: what a user writing the equations by hand
gets); and scipy ``solve_ivp`` ``DOP853`` and ``RK45`` on the same equations — body ω from
Euler's equations and ``q̇ = ½ q ⊗ (0, ω)``, gravity torque ``r × (M Rᵀ g)`` in the body
frame — written as a plain Python/numpy right-hand side (scalar arithmetic, the fastest
form for scipy). All run over the same tolerance sweep (``rtol`` = 1e-1 … 1e-12,
``atol = 1e-2 rtol``).

Each jrigid (formulation, solver) is jitted once with ``rtol``/``atol`` as traced
arguments; its first call (trace and compile) is timed on its own, and the timed calls
go through ``jax.jit``'s dispatch, as a user's calls do; each solve is then timed as the
median of ≥ 7 calls (``block_until_ready``; more for fast calls), each scipy solve
as the median of ≥ 5 (quick mode: 5 and 3). All (method, tolerance) runs of
a problem are timed in interleaved rounds, so that load from other processes on a shared
machine falls on every method alike. The error is the worst of the relative final-time
error in ω and the sign-invariant final-time error in ``q``, against a reference that is
not a method under test: ``jrigid.exact`` (closed form) cross-checked with scipy DOP853
at rtol 1e-14 for the free rotors; scipy DOP853 at rtol 1e-14 cross-checked with Radau at
rtol 1e-13 for the heavy top (their disagreement is the reference's own error floor).
Each method's (error, time) curve is interpolated (log-log, on its Pareto front) at the
target errors 1e-4, 1e-6, 1e-8, 1e-10. Two targets are checked there: the default at
least 40× faster than scipy DOP853, and no slower than the better hand-written diffrax
solve. A profile section explains the ratio: per-step cost against scipy's, steps
needed, projection cost, the plain-call overhead, and float32 against float64.

Usage::

    python benchmarks/speed_vs_error.py            # full run, < 15 min on 2 cores
    python benchmarks/speed_vs_error.py --quick    # free rotor, default vs peers, < 1 min

Writes ``speed_vs_error[_quick].json`` (raw numbers), ``.md`` (tables) and ``.png``
(work-precision diagram) to ``benchmarks/results/`` (or ``--out``) and prints the tables.
"""

from __future__ import annotations

import dataclasses
import math
import pathlib
import sys
import time
import warnings

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import harness  # noqa: E402
from harness import Problem  # noqa: E402

from jrigid.formulations import QuaternionAcceleration  # noqa: E402
from jrigid.integrate import DEFAULT_SOLVER, simulate  # noqa: E402
from jrigid.solvers import FusedDop853, FusedDopri8, FusedTsit5  # noqa: E402

TARGETS = (1e-4, 1e-6, 1e-8, 1e-10)
DEFAULT = "jrigid default"
OLD_DEFAULT = "jrigid 0.1 default (diffrax Tsit5, |q| projection only)"
HAND = "hand-written diffrax (q, ω)"
PEER = "scipy DOP853"
SPEED_TARGET = 40.0  # default ≥ 40× scipy DOP853 at equal error
JAX_REPEATS = 7
SCIPY_REPEATS = 5
MIN_TIME = 0.15  # seconds of timed calls per point at least (more repeats for fast runs)


# --------------------------------------------------------------------------- problems


FREE_ROTOR = Problem(
    key="free_rotor",
    title="free rotor, moments (1, 2, 3), ω0 = (1, 0.3, 0.7), t = 0…100",
    moments=(1.0, 2.0, 3.0),
    omega0=(1.0, 0.3, 0.7),
)
NEAR_INTERMEDIATE = Problem(
    key="near_intermediate",
    title="free rotor near the intermediate axis, moments (1, 2, 2.5), ω0 = (0.05, 2, 0.1), "
    "t = 0…100",
    moments=(1.0, 2.0, 2.5),
    omega0=(0.05, 2.0, 0.1),
)
HEAVY_TOP = Problem(
    key="heavy_top",
    title="heavy top, moments (1, 1, 0.5), l = M = g = 1, θ0 = 0.6, ψ̇0 = 5, t = 0…100",
    moments=(1.0, 1.0, 0.5),
    euler0=(0.0, 0.6, 0.0),
    rates0=(0.2, 0.1, 5.0),
    mass=1.0,
    com=(0.0, 0.0, 1.0),
    g=1.0,
)


# --------------------------------------------------------------------------- methods


def jrigid_method(problem: Problem, max_steps: int = 100_000, **options):
    """Compile ``simulate`` with ``options`` (none: the default); ``(run, compile_seconds)``.

    ``run(rtol, atol)`` calls the compiled solve (tolerances are traced arguments, so no
    recompilation) and returns the final ``q``, ω, step counts and a success flag.
    """
    scene, state = problem.scene(), problem.state()
    dtype = scene.body.moments.dtype
    ts = jnp.array([0.0, problem.t1], dtype=dtype)

    def solve(scene, state, ts, rtol, atol):
        traj = simulate(scene, state, ts, rtol=rtol, atol=atol, max_steps=max_steps,
                        throw=False, **options)
        q = traj.q[-1] if traj.q is not None else jnp.full(4, jnp.nan, dtype)
        return {
            "q": q,
            "omega": traj.omega[-1],
            "steps": traj.stats["num_steps"],
            "accepted": traj.stats["num_accepted_steps"],
            "ok": traj.result == 0,
        }

    name = jnp.dtype(dtype).name
    tol = harness.scalar(1e-6, name)
    compiled, seconds = harness.warm_jit(jax.jit(solve), scene, state, ts, tol, tol)

    def run(rtol, atol):
        return compiled(scene, state, ts, harness.scalar(rtol, name), harness.scalar(atol, name))

    return run, seconds


def hand_written_method(problem: Problem, solver, max_steps: int = 100_000):
    """``diffrax.diffeqsolve`` on the flat ``(q, ω)`` field, jitted, ``SaveAt(t1=True)``.

    What a user who writes the equations by hand gets from diffrax (no projection, no
    checks, no trajectory): the peer the default must match. ``(run, compile_seconds)``.
    """
    y0 = jnp.asarray(problem.y0())
    term = diffrax.ODETerm(problem.jax_rhs())

    def solve(y0, rtol, atol):
        sol = diffrax.diffeqsolve(
            term, solver, 0.0, problem.t1, None, y0,
            stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
            saveat=diffrax.SaveAt(t1=True), max_steps=max_steps, throw=False,
        )
        y = sol.ys[-1]
        return {
            "q": y[:4] / jnp.linalg.norm(y[:4]),
            "omega": y[4:],
            "steps": sol.stats["num_steps"],
            "accepted": sol.stats["num_accepted_steps"],
            "ok": sol.result == diffrax.RESULTS.successful,
        }

    tol = harness.scalar(1e-6)
    compiled, seconds = harness.warm_jit(jax.jit(solve), y0, tol, tol)
    return (lambda rtol, atol: compiled(y0, harness.scalar(rtol), harness.scalar(atol))), seconds


def scipy_method(problem: Problem, method: str):
    """``run(rtol, atol)`` for scipy ``solve_ivp`` on the numpy equations."""
    rhs, y0, span = problem.numpy_rhs(), problem.y0(), (0.0, problem.t1)

    def run(rtol, atol):
        sol = solve_ivp(rhs, span, y0, method=method, rtol=rtol, atol=atol)
        return {
            "q": sol.y[:4, -1],
            "omega": sol.y[4:, -1],
            "accepted": len(sol.t) - 1,
            "nfev": sol.nfev,
            "ok": bool(sol.success),
        }

    return run


# --------------------------------------------------------------------------- reference


def reference(problem: Problem, *, quick: bool) -> dict:
    """High-precision final state and its estimated error floor (not a method under test).

    Free rotor: ``jrigid.exact`` cross-checked with scipy DOP853 at rtol 1e-14 (in quick
    mode DOP853 alone, to skip the exact solver's compilation). Heavy top: DOP853 at
    rtol 1e-14 cross-checked with Radau at rtol 1e-13 (quick mode: DOP853 alone).
    """
    rhs, y0 = problem.numpy_rhs(), problem.y0()
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy raises rtol 1e-14 to 100 eps and says so
        dop = solve_ivp(rhs, (0.0, problem.t1), y0, method="DOP853", rtol=1e-14, atol=1e-16)
    dop_time = time.perf_counter() - start
    dop_q, dop_w = dop.y[:4, -1] / np.linalg.norm(dop.y[:4, -1]), dop.y[4:, -1]
    ref = {
        "q": dop_q, "omega": dop_w, "source": "scipy DOP853 rtol 1e-14 (raised by scipy to "
        "100 eps = 2.2e-14), atol 1e-16", "seconds": dop_time, "floor": None,
        "check": "none (quick mode)",
    }
    if quick:
        return ref
    if not problem.pivoted:
        try:
            from jrigid import exact

            start = time.perf_counter()
            solve = jax.jit(exact.solve)
            state = problem.state()  # its ω (2 q* ⊗ q̇) is omega0 rounded, as solved
            q, w = solve(
                jnp.array(problem.moments), jnp.asarray(state.q), jnp.asarray(state.omega),
                jnp.array([0.0, problem.t1]),
            )
            q, w = np.asarray(q[-1]), np.asarray(w[-1])
            seconds = time.perf_counter() - start
            floor = max(harness.omega_error(dop_w, w), harness.quaternion_error(dop_q, q))
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(w)) and floor < 1e-10):
                raise ValueError(f"jrigid.exact disagrees with DOP853 by {floor:.3g}")
        except (ImportError, AttributeError, ValueError) as exc:
            ref["check"] = f"jrigid.exact unavailable or failed ({exc}); DOP853 used alone"
            return ref
        return {
            "q": q, "omega": w, "source": "jrigid.exact (closed form, elliptic functions)",
            "seconds": seconds, "floor": floor,
            "check": f"scipy DOP853 at rtol 1e-14 agrees to {floor:.2g}",
        }
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rad = solve_ivp(rhs, (0.0, problem.t1), y0, method="Radau", rtol=1e-13, atol=1e-15)
    floor = max(
        harness.omega_error(rad.y[4:, -1], dop_w), harness.quaternion_error(rad.y[:4, -1], dop_q)
    )
    ref["floor"] = floor
    ref["check"] = (
        f"scipy Radau at rtol 1e-13 agrees to {floor:.2g} "
        f"({time.perf_counter() - start:.0f} s, {len(rad.t) - 1} steps)"
    )
    return ref


def error_fn(ref: dict):
    def errors(out: dict) -> dict[str, float]:
        errs = {"omega": harness.omega_error(out["omega"], ref["omega"])}
        q = np.asarray(out.get("q"))
        if q.shape == (4,) and np.all(np.isfinite(q)):
            errs["q"] = harness.quaternion_error(q, ref["q"])
        return errs

    return errors


# --------------------------------------------------------------------------- runs


def method_list(problem: Problem, *, quick: bool):
    """``[(label, kind, spec)]``: the methods run on ``problem``.

    ``jrigid`` specs are keyword options of :func:`jrigid.simulate` (none: the default),
    ``hand`` specs a diffrax solver for :func:`hand_written_method`, ``scipy`` specs a
    ``solve_ivp`` method.
    """
    old = dict(solver=diffrax.Tsit5(), project="manifold",
               formulation=QuaternionAcceleration(centripetal=True, tolerance_scale=1))
    methods = [(DEFAULT, "jrigid", {}), (OLD_DEFAULT, "jrigid", old)]
    if not quick:
        methods += [
            ("jrigid quaternion_acceleration + FusedDopri8", "jrigid",
             dict(solver=FusedDopri8())),
            ("jrigid quaternion_acceleration + FusedDop853", "jrigid",
             dict(solver=FusedDop853())),
            ("jrigid quaternion_acceleration + FusedTsit5", "jrigid",
             dict(solver=FusedTsit5())),
            ("jrigid quaternion_omega", "jrigid", dict(formulation="quaternion_omega")),
            ("jrigid euler_angles", "jrigid", dict(formulation="euler_angles")),
        ]
        if not problem.pivoted:
            methods.append(("jrigid body_omega", "jrigid", dict(formulation="body_omega")))
    methods += [
        (f"{HAND} + Tsit5", "hand", diffrax.Tsit5()),
        (f"{HAND} + Dopri8", "hand", diffrax.Dopri8()),
        ("scipy DOP853", "scipy", "DOP853"),
    ]
    if not quick:
        methods.append(("scipy RK45", "scipy", "RK45"))
    return methods


def run_problem(problem: Problem, tolerances, *, quick: bool, log) -> dict:
    """Reference, then every method compiled, then all sweeps timed interleaved."""
    min_time = MIN_TIME if not quick else 0.1
    ref = reference(problem, quick=quick)
    log(f"[{problem.key}] reference: {ref['source']}; {ref['check']}")
    specs, compile_times, runs = {}, {}, {}
    for label, kind, spec in method_list(problem, quick=quick):
        if kind in ("jrigid", "hand"):
            if kind == "jrigid":
                run, compile_s = jrigid_method(problem, **spec)
            else:
                run, compile_s = hand_written_method(problem, spec)
            repeats = JAX_REPEATS if not quick else 5
            log(f"[{problem.key}] {label}: compiled in {compile_s:.1f} s")
        else:
            run, compile_s = scipy_method(problem, spec), None
            repeats = SCIPY_REPEATS if not quick else 3
        specs[label], compile_times[label], runs[label] = (run, repeats), compile_s, run
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        points = harness.sweep_methods(
            specs, error_fn(ref), tolerances, min_time=min_time, budget_seconds=20.0
        )
    log(f"[{problem.key}] sweeps timed (interleaved) in {time.perf_counter() - start:.0f} s")
    methods = {
        label: {"compile_seconds": compile_times[label], "points": points[label]}
        for label in specs
    }
    for label, m in methods.items():
        best = min((p.error for p in m["points"] if p.ok), default=math.nan)
        log(f"[{problem.key}] {label}: best error {best:.2g}")
    return {"problem": problem, "reference": ref, "methods": methods, "runs": runs}


def summarise(result: dict) -> dict:
    """Time (and steps) to each target error for every method, and the ratios."""
    summary = {}
    for label, m in result["methods"].items():
        pts = [p for p in m["points"] if p.ok]
        errs = [p.error for p in pts]
        row = {}
        for target in TARGETS:
            t, kind = harness.time_to_error(errs, [p.time for p in pts], target)
            t_min, _ = harness.time_to_error(errs, [p.time_min for p in pts], target)
            steps, _ = harness.time_to_error(
                errs, [float(p.accepted) for p in pts], target
            )
            row[target] = {
                "seconds": t, "seconds_min": t_min, "kind": kind, "accepted_steps": steps
            }
        summary[label] = row
    ratios = {}
    jrigid_labels = [k for k in summary if k.startswith("jrigid")]
    for target in TARGETS:
        peer = summary.get(PEER, {}).get(target, {}).get("seconds")
        default = summary.get(DEFAULT, {}).get(target, {}).get("seconds")
        peer_min = summary.get(PEER, {}).get(target, {}).get("seconds_min")
        default_min = summary.get(DEFAULT, {}).get(target, {}).get("seconds_min")
        best_label, best = None, None
        for k in jrigid_labels:
            t = summary[k][target]["seconds"]
            if t is not None and (best is None or t < best):
                best_label, best = k, t
        hand = [summary[k][target]["seconds"] for k in summary if k.startswith(HAND)]
        hand = [t for t in hand if t is not None]
        ratios[target] = {
            "default": peer / default if peer and default else None,
            "default_min": peer_min / default_min if peer_min and default_min else None,
            "best": peer / best if peer and best else None,
            "best_label": best_label,
            # > 1: the default is faster than the better hand-written diffrax solve
            "hand_over_default": min(hand) / default if hand and default else None,
        }
    return {"time_to_error": summary, "ratio_peer_over_jrigid": ratios}


# --------------------------------------------------------------------------- profile


def _fmt_us(seconds: float | None) -> str:
    return "—" if seconds is None else f"{seconds * 1e6:.3g} µs"


def profile(result: dict, rtol: float) -> dict:
    """Per-step and per-evaluation costs at one tolerance of the sweep (from its points)."""
    rows = {}
    for label, m in result["methods"].items():
        p = next((p for p in m["points"] if p.rtol == rtol and p.ok), None)
        if p is None:
            continue
        rows[label] = {
            "rtol": rtol,
            "time": p.time,
            "accepted": p.accepted,
            "steps": p.steps,
            "nfev": p.nfev,
            "per_accepted_step": p.time / p.accepted if p.accepted else None,
            "per_accepted_step_min": p.time_min / p.accepted if p.accepted else None,
            "error": p.error,
        }
    return rows


def _field_and_state(problem: Problem):
    scene, state = problem.scene(), problem.state()
    field = QuaternionAcceleration()
    return field, field.from_state(scene, state), scene


def _axpy(y, dy, h):
    return jax.tree_util.tree_map(lambda a, b: a + h * b, y, dy)


def field_loop(problem: Problem, n: int = 20_000):
    """``n`` chained evaluations of the quaternion-acceleration field in ``lax.fori_loop``.

    ``y ← y + 1e-9 f(y)``, compiled: time / n is one evaluation plus one loop iteration.
    """
    field, y0, scene = _field_and_state(problem)

    def loop(y, scene):
        body = lambda i, y: _axpy(y, field.vector_field(0.0, y, scene), 1e-9)
        return jax.lax.fori_loop(0, n, body, y)

    compiled, compile_s = harness.warm_jit(jax.jit(loop), y0, scene)
    return (lambda: compiled(y0, scene)), (lambda out: n), compile_s


def numpy_rhs_loop(problem: Problem, n: int = 5_000):
    """``n`` calls of the numpy right-hand side scipy integrates."""
    rhs, y = problem.numpy_rhs(), problem.y0()

    def loop():
        for _ in range(n):
            rhs(0.0, y)

    return loop, (lambda out: n), None


def diffrax_alone(problem: Problem, rtol: float):
    """``diffrax.diffeqsolve`` on the default's field with the default solver and PID.

    No projection, no event, no input checks, no output trajectory: what jrigid's own
    layer adds per step is the difference to the default.
    """
    field, y0, scene = _field_and_state(problem)
    saveat = diffrax.SaveAt(ts=jnp.array([0.0, problem.t1]), t1=True)

    def solve(y0, scene, rtol, atol):
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field.vector_field), DEFAULT_SOLVER(), 0.0, problem.t1, None, y0,
            args=scene, stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
            saveat=saveat, max_steps=100_000,
        )
        return sol.ys, sol.stats["num_accepted_steps"]

    compiled, compile_s = harness.warm_jit(jax.jit(solve), y0, scene, rtol, rtol * 1e-2)
    return (lambda: compiled(y0, scene, rtol, rtol * 1e-2)), (lambda out: int(out[1])), compile_s


def plain_call(problem: Problem, rtol: float):
    """:func:`jrigid.simulate` called without ``jit`` (what a script does in a loop)."""
    scene, state = problem.scene(), problem.state()
    ts = jnp.array([0.0, problem.t1])

    def call():
        traj = simulate(scene, state, ts, rtol=rtol, atol=rtol * 1e-2)
        return {"accepted": traj.stats["num_accepted_steps"], "q": traj.q}

    start = time.perf_counter()
    jax.block_until_ready(call())
    return call, _accepted, time.perf_counter() - start


def fused_rk4(problem: Problem, steps: int = 2000):
    """A hand-written fixed-step RK4 in ``lax.fori_loop`` on the same field (4 evals/step).

    No error estimate and no step control: the floor of an XLA loop over this field.
    """
    field, y0, scene = _field_and_state(problem)
    h = problem.t1 / steps

    def solve(y0, scene):
        f = lambda y: field.vector_field(0.0, y, scene)

        def body(i, y):
            k1 = f(y)
            k2 = f(_axpy(y, k1, h / 2))
            k3 = f(_axpy(y, k2, h / 2))
            k4 = f(_axpy(y, k3, h))
            return jax.tree_util.tree_map(
                lambda a, b, c, d, e: a + (h / 6) * (b + 2 * c + 2 * d + e), y, k1, k2, k3, k4
            )

        return jax.lax.fori_loop(0, steps, body, y0)

    compiled, compile_s = harness.warm_jit(jax.jit(solve), y0, scene)
    return (lambda: compiled(y0, scene)), (lambda out: steps), compile_s


def default_float32(problem: Problem, rtol: float):
    """The default method compiled in float32 (x64 off while building and compiling)."""
    with jax.enable_x64(False):
        run, compile_s = jrigid_method(problem)

    def call():
        with jax.enable_x64(False):  # the program was traced without x64
            return run(rtol, rtol * 1e-2)

    return call, (lambda out: int(out["accepted"])), compile_s


def _accepted(out) -> int:
    return int(np.asarray(out["accepted"]))


F32_RTOL = 1e-5  # float32 cannot go much tighter (rtol ≥ 10 eps)
SHORT = 1e-3  # the fraction of the horizon on which a plain call's overhead is measured
PROFILE_ROWS = {
    "default": "jrigid default (jitted)",
    "plain": "jrigid default, plain call (not jitted)",
    "short": f"jrigid default (jitted), {SHORT} of the horizon",
    "plain_short": f"jrigid default, plain call (not jitted), {SHORT} of the horizon",
    "scipy": "scipy DOP853",
    "manifold": "jrigid default with project='manifold' (no invariants)",
    "no_projection": "jrigid default with project=False",
    "alone": "diffrax.diffeqsolve alone on the same field and solver (PID, saving as simulate)",
    "rk4": "hand-written fixed-step RK4 in lax.fori_loop, same field (4 evals/step)",
    "f64_loose": f"jrigid default, float64, rtol {F32_RTOL:.0e}",
    "f32_loose": f"jrigid default, float32, rtol {F32_RTOL:.0e}",
    "field": "one evaluation of the quaternion-acceleration field in XLA (+ loop iteration)",
    "numpy": "one call of the numpy right-hand side scipy integrates",
}


def extra_profile(problem: Problem, result: dict, rtol: float, log) -> dict:
    """Where a step's time goes, all timed interleaved at one tolerance.

    Entries (see ``PROFILE_ROWS``): the default (jitted and as a plain call, over the
    horizon and over :data:`SHORT` of it, where a plain call's overhead is not lost in the
    solve's own noise) and scipy
    DOP853 as in the sweep; the default with less projection; diffrax alone on the same
    field and solver; a hand-written RK4 loop (the floor of an XLA loop over this field);
    the default in float64 and float32 at a looser tolerance; one field evaluation; one
    numpy right-hand-side call.
    """
    default, scipy_run = result["runs"][DEFAULT], result["runs"][PEER]
    manifold, c_m = jrigid_method(problem, project="manifold")
    short_problem = dataclasses.replace(problem, t1=problem.t1 * SHORT)
    short, c_s = jrigid_method(short_problem)
    no_proj, c_np = jrigid_method(problem, project=False)
    builders = {
        "default": ((lambda: default(rtol, rtol * 1e-2)), _accepted, None),
        "plain": plain_call(problem, rtol),
        "short": ((lambda: short(rtol, rtol * 1e-2)), _accepted, c_s),
        "plain_short": plain_call(short_problem, rtol),
        "scipy": ((lambda: scipy_run(rtol, rtol * 1e-2)), _accepted, None),
        "manifold": ((lambda: manifold(rtol, rtol * 1e-2)), _accepted, c_m),
        "no_projection": ((lambda: no_proj(rtol, rtol * 1e-2)), _accepted, c_np),
        "alone": diffrax_alone(problem, rtol),
        "rk4": fused_rk4(problem),
        "f64_loose": ((lambda: default(F32_RTOL, F32_RTOL * 1e-2)), _accepted, None),
        "f32_loose": default_float32(problem, F32_RTOL),
        "field": field_loop(problem),
        "numpy": numpy_rhs_loop(problem),
    }
    calls = {k: b[0] for k, b in builders.items()}
    repeats = {k: SCIPY_REPEATS if k in ("scipy", "numpy") else JAX_REPEATS for k in calls}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        timed = harness.time_interleaved(calls, repeats, min_time=MIN_TIME)
    rows = {}
    for key, (timing, out) in timed.items():
        units = builders[key][1](out)
        rows[key] = {
            "label": PROFILE_ROWS[key], "time": timing.median, "time_min": timing.min,
            "units": units, "per_unit": timing.median / units,
            "per_unit_min": timing.min / units, "compile_seconds": builders[key][2],
            "rtol": F32_RTOL if key.endswith("_loose") else rtol,
        }
        log(f"[{problem.key}] profile: {PROFILE_ROWS[key]}: "
            f"{rows[key]['per_unit'] * 1e6:.3g} µs per step/call")
    return rows


# --------------------------------------------------------------------------- report


def _cell(entry: dict) -> str:
    return harness.fmt_seconds(entry["seconds"], entry["kind"])


def _ratio(x: float | None) -> str:
    return "—" if x is None else f"{x:.2g}×"


def report(results: list[dict], machine: dict, *, quick: bool, tolerances, seconds: float) -> str:
    lines = [
        f"# Speed against error{' (quick mode)' if quick else ''}",
        "",
        f"Machine: {harness.machine_line(machine)}.",
        f"Tolerance sweep: rtol = {', '.join(f'{r:.0e}' for r, _ in tolerances)}; "
        "atol = 1e-2 rtol. Times are wall-clock medians after compilation (at least "
        f"{JAX_REPEATS if not quick else 5} runs for jrigid, "
        f"{SCIPY_REPEATS if not quick else 3} for scipy, more for fast runs: about "
        f"{MIN_TIME if not quick else 0.1:g} s of runs per point), interpolated log-log at each "
        "target error on the method's Pareto front; `≤` means already the loosest "
        "tolerance was more accurate (its time is shown), `—` that no tolerance reached "
        "the error. Error = worst of relative final ω error and sign-invariant final q "
        "error (ω only for body_omega).",
        "",
    ]
    for res in results:
        problem, ref, summ = res["problem"], res["reference"], res["summary"]
        floor = ref["floor"]
        lines += [
            f"## {problem.title}",
            "",
            f"Reference: {ref['source']}; {ref['check']}"
            + (f" (error floor ≈ {floor:.1g})." if floor is not None else "."),
            "",
        ]
        headers = ["method", "compile"] + [f"time to {t:.0e}" for t in TARGETS]
        headers += ["best error", "steps at best"]
        rows = []
        for label, m in res["methods"].items():
            tte = summ["time_to_error"][label]
            ok_pts = [p for p in m["points"] if p.ok]
            best = min(ok_pts, key=lambda p: p.error, default=None)
            c = m["compile_seconds"]
            name = f"**{label}** (default)" if label == DEFAULT else label
            rows.append(
                [name, "—" if c is None else f"{c:.1f} s"]
                + [_cell(tte[t]) for t in TARGETS]
                + ["—" if best is None else f"{best.error:.1g}",
                   "—" if best is None else f"{best.accepted}"]
            )
        ratios = summ["ratio_peer_over_jrigid"]
        rows.append(
            ["**scipy DOP853 / jrigid default**", ""]
            + [f"**{_ratio(ratios[t]['default'])}**" for t in TARGETS] + ["", ""]
        )
        rows.append(
            ["scipy DOP853 / jrigid default, from fastest runs", ""]
            + [_ratio(ratios[t]["default_min"]) for t in TARGETS] + ["", ""]
        )
        rows.append(
            ["**better hand-written diffrax / jrigid default**", ""]
            + [f"**{_ratio(ratios[t].get('hand_over_default'))}**" for t in TARGETS] + ["", ""]
        )
        rows.append(
            ["scipy DOP853 / fastest jrigid", ""]
            + [
                _ratio(ratios[t]["best"])
                + (f" ({ratios[t]['best_label'].removeprefix('jrigid ')})"
                   if ratios[t]["best_label"] else "")
                for t in TARGETS
            ]
            + ["", ""]
        )
        lines += [harness.markdown_table(headers, rows), ""]
        prof = res.get("profile", {})
        if prof:
            rtol = next(iter(prof.values()))["rtol"]
            lines += [f"Cost per step at rtol = {rtol:.0e}:", ""]
            prow = []
            for label, p in prof.items():
                prow.append([
                    label, f"{p['accepted']}", "—" if p["nfev"] is None else f"{p['nfev']}",
                    harness.fmt_seconds(p["time"]), _fmt_us(p["per_accepted_step"]),
                    _fmt_us(p["per_accepted_step_min"]), f"{p['error']:.1g}",
                ])
            lines += [
                harness.markdown_table(
                    ["method", "accepted steps", "RHS evals", "time", "per step",
                     "per step, fastest run", "error"],
                    prow,
                ),
                "",
            ]
        extra = res.get("extra_profile")
        if extra:
            rtol = extra["default"]["rtol"]
            lines += [
                f"Where the time of a step goes (rtol = {rtol:.0e} unless stated; all entries "
                "timed in interleaved rounds, so other load on the machine falls on all alike):",
                "",
            ]
            xrow = []
            for row in extra.values():
                xrow.append([
                    row["label"], f"{row['units']}", harness.fmt_seconds(row["time"]),
                    _fmt_us(row["per_unit"]), _fmt_us(row["per_unit_min"]),
                    "—" if row["compile_seconds"] is None else f"{row['compile_seconds']:.1f} s",
                ])
            lines += [
                harness.markdown_table(
                    ["entry", "steps or calls", "time", "per step or call",
                     "per step or call, fastest run", "compile"],
                    xrow,
                ),
                "",
            ]
        lines += _verdict(res) + _why(res)
    lines += [f"Total benchmark wall time: {seconds:.0f} s.", ""]
    return "\n".join(lines)


def _verdict(res: dict) -> list[str]:
    """The two speed targets at each error: ≥ 40× scipy DOP853, and no slower than the
    better hand-written diffrax solve on the (q, ω) equations."""
    ratios = res["summary"]["ratio_peer_over_jrigid"]
    tte = res["summary"]["time_to_error"]
    parts, hand_parts = [], []
    for t in TARGETS:
        r = ratios[t]["default"]
        if r is None:
            parts.append(f"{t:.0e}: not comparable")
        else:
            d, p = tte[DEFAULT][t], tte[PEER][t]
            steps = ""
            if d["accepted_steps"] and p["accepted_steps"]:
                per_d = d["seconds"] / d["accepted_steps"]
                per_p = p["seconds"] / p["accepted_steps"]
                steps = (
                    f" (steps {d['accepted_steps']:.0f} vs {p['accepted_steps']:.0f}; "
                    f"per step {per_d * 1e6:.2g} vs {per_p * 1e6:.2g} µs)"
                )
            met = "met" if r >= SPEED_TARGET else "not met"
            parts.append(f"{t:.0e}: {r:.2g}× {met}{steps}")
        h = ratios[t].get("hand_over_default")
        hand_parts.append(
            f"{t:.0e}: —" if h is None else f"{t:.0e}: {h:.2g}× ({'met' if h >= 1 else 'not met'})"
        )
    return [
        f"Target 1 (jrigid default ≥ {SPEED_TARGET:g}× faster than scipy DOP853 at equal "
        "error), jrigid default vs DOP853: " + "; ".join(parts) + ".",
        "",
        "Target 2 (jrigid default no slower than the better of hand-written diffrax Tsit5 / "
        "Dopri8 on the (q, ω) equations at equal error), time of the better hand-written "
        "solve ÷ time of the default: " + "; ".join(hand_parts) + ".",
        "",
    ]


def _share(full: float, without: float) -> str:
    """Words for how much of a per-step cost ``full`` goes away without some part."""
    saved = (full - without) / full
    if saved < 0.15:
        return "no measurable part of a step (within ±15 %)"
    return f"about {100 * saved:.0f} % of a step"


def _why(res: dict) -> list[str]:
    """Decompose the ratio into steps needed and cost per step (full mode only)."""
    x = res.get("extra_profile")
    if not x:
        return []
    us = lambda v: f"{v * 1e6:.2g} µs"  # noqa: E731
    step = {k: r["per_unit"] for k, r in x.items()}
    tte = res["summary"]["time_to_error"]
    target = next(
        (t for t in reversed(TARGETS)
         if tte[DEFAULT][t]["accepted_steps"] and tte[PEER][t]["accepted_steps"]),
        None,
    )
    steps_txt = ""
    if target is not None:
        n_d, n_p = tte[DEFAULT][target]["accepted_steps"], tte[PEER][target]["accepted_steps"]
        steps_txt = (
            f" and needs {n_d / n_p:.2g}× as many steps to reach an error of {target:.0e} "
            f"({n_d:.0f} against {n_p:.0f})"
        )
    stages = DEFAULT_SOLVER.tableau.num_stages - 1
    overhead = x["plain_short"]["time"] - x["short"]["time"]
    plain = (f"adds {overhead * 1e3:.2g} ms to the jitted one (on {SHORT:g} of the horizon, "
             f"{x['short']['units']:.0f} steps: {x['plain_short']['time'] * 1e3:.2g} against "
             f"{x['short']['time'] * 1e3:.2g} ms; on the whole horizon "
             f"{(x['plain']['time'] - x['default']['time']) * 1e3:.2g} ms, within the noise "
             "of the solve)")
    return [
        f"Why (medians of the interleaved profile): at rtol = {x['default']['rtol']:.0e} a "
        f"step of jrigid's default costs {us(step['default'])} and a step of scipy DOP853 "
        f"{us(step['scipy'])}: jrigid is {step['scipy'] / step['default']:.2g}× cheaper per "
        f"step{steps_txt}. Of the default's step, the {stages} new field evaluations take "
        f"about {us(stages * step['field'])}; restoring the invariants costs "
        f"{_share(step['default'], step['manifold'])}, the whole projection "
        f"{_share(step['default'], step['no_projection'])}; "
        f"diffrax alone on the same field and solver costs {us(step['alone'])} per step. In "
        f"float32 a step costs {us(step['f32_loose'])} against {us(step['f64_loose'])} in "
        f"float64 at rtol {F32_RTOL:.0e}. A plain (not jitted) call {plain}. A hand-written "
        "RK4 loop in "
        f"lax.fori_loop on the same field costs {us(step['rk4'])} per step (four "
        "evaluations).",
        "",
    ]


# --------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> dict:
    parser = harness.command_line(__doc__, quick="free rotor, default vs scipy, < 40 s",
                                  quiet=True)
    args = parser.parse_args(argv)
    start = time.perf_counter()
    log = harness.logger(args.quiet)
    machine = harness.machine_info()
    log(harness.machine_line(machine))
    if args.quick:
        tolerances = [(10.0**-k, 10.0 ** -(k + 2)) for k in (1, 3, 5, 7, 9, 12)]
        problems = [FREE_ROTOR]
    else:
        tolerances = [(10.0**-k, 10.0 ** -(k + 2)) for k in range(1, 13)]
        problems = [FREE_ROTOR, NEAR_INTERMEDIATE, HEAVY_TOP]
    profile_rtol = 1e-7 if args.quick else 1e-8
    results = []
    for problem in problems:
        res = run_problem(problem, tolerances, quick=args.quick, log=log)
        res["summary"] = summarise(res)
        res["profile"] = profile(res, profile_rtol)
        if not args.quick:
            res["extra_profile"] = extra_profile(problem, res, profile_rtol, log)
        results.append(res)
    seconds = time.perf_counter() - start
    machine["load_average_end"] = harness.machine_info()["load_average"]

    out_dir = harness.results_dir(args.out)
    stem = harness.stem("speed_vs_error", args.quick)
    text = report(results, machine, quick=args.quick, tolerances=tolerances, seconds=seconds)
    harness.write_text(out_dir / f"{stem}.md", text)
    harness.write_json(out_dir / f"{stem}.json", {
        "machine": machine,
        "quick": args.quick,
        "targets": TARGETS,
        "tolerances": tolerances,
        "total_seconds": seconds,
        "problems": {
            r["problem"].key: {
                "title": r["problem"].title,
                "problem": r["problem"].__dict__,
                "reference": {k: v for k, v in r["reference"].items()},
                "methods": {
                    k: {"compile_seconds": m["compile_seconds"],
                        "points": harness.points_as_dicts(m["points"])}
                    for k, m in r["methods"].items()
                },
                "summary": r["summary"],
                "profile": r["profile"],
                "extra_profile": r.get("extra_profile"),
            }
            for r in results
        },
    })
    panels = {
        r["problem"].title: {
            label: ([p.error for p in m["points"] if p.ok], [p.time for p in m["points"] if p.ok])
            for label, m in r["methods"].items()
        }
        for r in results
    }
    harness.work_precision_figure(
        panels, out_dir / f"{stem}.png", targets=TARGETS, highlight=(DEFAULT, PEER),
        title=harness.machine_line(machine),
    )
    print(text)
    return {"results": results, "markdown": text, "out_dir": out_dir, "stem": stem}


if __name__ == "__main__":
    main()
