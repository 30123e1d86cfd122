"""Shared machinery for jrigid's benchmarks: timing, errors, machine description, writers.

Every benchmark script in ``benchmarks/`` imports this module (``import harness`` after
putting ``benchmarks/`` on ``sys.path``). It holds:

- :func:`command_line` — the options every benchmark's ``main`` shares (``--quick``,
  ``--out``, ``--quiet``), :func:`logger` and :func:`stem` (the output files' name);
- :class:`Problem` — a benchmark problem (a free rotor or a heavy top): its scene, initial
  state and the numpy/JAX right-hand sides a user would write by hand;
- :func:`machine_info` / :func:`machine_line` — CPU model, cores, load, library versions;
- :func:`warm_jit` — the first call of a ``jax.jit`` function timed on its own (trace and
  compile), so compile time is never mixed into run times, and the function returned
  warm; :func:`compile_jax` — ahead-of-time ``lower(...).compile()``, for a compiled
  program's memory analysis;
- :func:`time_runs` — median (and min/max) wall time of several calls, each blocked with
  ``jax.block_until_ready``;
- :func:`time_interleaved` — several calls timed in alternating rounds, so that load
  from other processes on a shared machine falls on all of them alike;
- :func:`sweep_methods` / :func:`sweep` — methods over a list of tolerances (interleaved):
  time, error, step counts;
- :func:`omega_error`, :func:`quaternion_error` — final-state errors (``q`` sign-invariant);
- :func:`pareto_front`, :func:`time_to_error` — log-log interpolation of a work-precision
  curve at a target error;
- :func:`markdown_table`, :func:`write_json`, :func:`write_text`,
  :func:`work_precision_figure`, :func:`work_precision_grid` — the JSON, markdown and
  PNG outputs (matplotlib through
  its object-oriented API: ``Figure`` and the Agg canvas, no pyplot state).

Results go to ``benchmarks/results/`` (git-ignored); see :func:`results_dir`.

The module imports neither JAX nor jrigid at the top (:class:`Problem` does when used),
so a benchmark can parse its command line and set XLA flags before JAX starts. It turns
jrigid's persistent compilation cache off (``JRIGID_CACHE_DIR=off``, unless set), so
that the compile times the benchmarks report are those of a first compilation
(``first_call.py`` measures the cache itself).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import pathlib
import platform
import statistics
import textwrap
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from importlib import metadata
from typing import Any

import numpy as np

os.environ.setdefault("JRIGID_CACHE_DIR", "off")  # cold compiles (see the docstring)

__all__ = [
    "Point",
    "Problem",
    "Timing",
    "command_line",
    "compile_jax",
    "scalar",
    "warm_jit",
    "fmt_seconds",
    "machine_info",
    "machine_line",
    "markdown_table",
    "omega_error",
    "pareto_front",
    "points_as_dicts",
    "quaternion_error",
    "logger",
    "results_dir",
    "stem",
    "sweep",
    "sweep_methods",
    "time_interleaved",
    "time_runs",
    "time_to_error",
    "work_precision_figure",
    "work_precision_grid",
    "write_json",
    "write_text",
]

RESULTS = pathlib.Path(__file__).resolve().parent / "results"
OUT_HELP = "output directory (default benchmarks/results)"


# --------------------------------------------------------------------------- command line


def command_line(doc: str | None, *, quick: str | None = None, out: bool = True,
                 quiet: bool = False) -> argparse.ArgumentParser:
    """The argument parser every benchmark's ``main`` starts from.

    The description is the first paragraph of the script's docstring ``doc``. Options:
    ``--quick`` (when ``quick`` is given: its help, saying what the quick run does),
    ``--out`` (the output directory, default ``benchmarks/results``; see
    :func:`results_dir`) and ``--quiet`` (print only the final tables; see
    :func:`logger`). The script adds its own options to the returned parser.
    """
    parser = argparse.ArgumentParser(description=(doc or "").split("\n\n")[0])
    if quick is not None:
        parser.add_argument("--quick", action="store_true", help=quick)
    if out:
        parser.add_argument("--out", default=None, help=OUT_HELP)
    if quiet:
        parser.add_argument("--quiet", action="store_true", help="print only the final tables")
    return parser


def logger(quiet: bool = False) -> Callable[..., None]:
    """``print`` (flushed) for progress lines, or nothing with ``--quiet``."""
    if quiet:
        return lambda *a: None
    return lambda *a: print(*a, flush=True)


def stem(name: str, quick: bool) -> str:
    """The output files' name: ``name`` or ``name_quick``."""
    return name + ("_quick" if quick else "")


def results_dir(path: str | os.PathLike | None = None) -> pathlib.Path:
    """The output directory (default ``benchmarks/results/``), created if missing."""
    out = RESULTS if path is None else pathlib.Path(path)
    out.mkdir(parents=True, exist_ok=True)
    return out


# --------------------------------------------------------------------------- problems


@dataclass(frozen=True)
class Problem:
    """A benchmark problem: scene, initial state, horizon and its numpy equations."""

    key: str
    title: str
    moments: tuple[float, float, float]  # central principal moments
    omega0: tuple[float, float, float] | None = None  # body ω0 (free rotor)
    euler0: tuple[float, float, float] | None = None  # ZXZ (φ, θ, ψ) (top)
    rates0: tuple[float, float, float] | None = None  # (φ̇, θ̇, ψ̇) (top)
    mass: float = 1.0
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    g: float = 0.0  # gravity along −z; > 0 means a pivoted top
    t1: float = 100.0

    @property
    def pivoted(self) -> bool:
        return self.g > 0

    def scene(self):
        """The :class:`jrigid.scene.Scene`: a free body, or a top on a pivot under gravity."""
        import jax.numpy as jnp

        from jrigid.body import RigidBody
        from jrigid.scene import Gravity, Pivot, Scene

        body = RigidBody(jnp.array(self.moments), self.mass, jnp.array(self.com))
        if self.pivoted:
            return Scene(body, Pivot(), (Gravity(self.g),))
        return Scene(body)

    def state(self):
        """The initial :class:`jrigid.state.State`: the top from its Euler angles and rates;
        the free body turned so that its angular momentum points along space z."""
        import jax.numpy as jnp

        from jrigid import quaternion as quat
        from jrigid.initial import from_euler_rates, from_omega

        if self.pivoted:
            return from_euler_rates(jnp.array(self.euler0), jnp.array(self.rates0))
        omega = jnp.array(self.omega0)
        L = jnp.array(self.moments) * omega
        # Orient the body so that L points along space z, then turn about z by 0.7 rad.
        q_align = _shortest_arc(np.asarray(L) / float(jnp.linalg.norm(L)), np.array([0, 0, 1.0]))
        q0 = quat.multiply(quat.from_axis_angle(jnp.array([0.0, 0.0, 1.0]), 0.7), q_align)
        return from_omega(q0, omega)

    def y0(self) -> np.ndarray:
        """``(7,)`` initial ``(q, ω)`` for the numpy right-hand side."""
        state = self.state()
        return np.concatenate([np.asarray(state.q), np.asarray(state.omega)])

    def support_moments(self) -> tuple[float, float, float]:
        """Principal moments about the support point (parallel axis; ``com`` on an axis)."""
        r = np.asarray(self.com, float)
        if np.count_nonzero(r) > 1:
            raise ValueError("the numpy equations assume the centre of mass on a principal axis")
        shift = self.mass * (r @ r - r * r) if self.pivoted else np.zeros(3)
        return tuple(float(x) for x in np.asarray(self.moments) + shift)

    def jax_rhs(self):
        """``f(t, y, args)`` for diffrax on a flat ``y = (q (4), ω (3))``: what a user would
        write by hand for :func:`diffrax.diffeqsolve` (same equations as :meth:`numpy_rhs`)."""
        import jax.numpy as jnp

        J1, J2, J3 = self.support_moments()
        a1, a2, a3 = (J2 - J3) / J1, (J3 - J1) / J2, (J1 - J2) / J3
        r1, r2, r3 = (float(x) for x in self.com)
        mg = self.mass * self.g if self.pivoted else 0.0

        def rhs(t, y, args):
            q0, q1, q2, q3, w1, w2, w3 = (y[i] for i in range(7))
            s = -mg / (q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
            f1 = 2.0 * s * (q1 * q3 - q0 * q2)
            f2 = 2.0 * s * (q2 * q3 + q0 * q1)
            f3 = s * (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3)
            return jnp.stack([
                0.5 * (-q1 * w1 - q2 * w2 - q3 * w3),
                0.5 * (q0 * w1 + q2 * w3 - q3 * w2),
                0.5 * (q0 * w2 + q3 * w1 - q1 * w3),
                0.5 * (q0 * w3 + q1 * w2 - q2 * w1),
                (r2 * f3 - r3 * f2) / J1 + a1 * w2 * w3,
                (r3 * f1 - r1 * f3) / J2 + a2 * w3 * w1,
                (r1 * f2 - r2 * f1) / J3 + a3 * w1 * w2,
            ])

        return rhs

    def numpy_rhs(self):
        """``f(t, y)`` for scipy: ``y = (q (4), ω (3))``, Euler's equations + (17.44)."""
        J1, J2, J3 = self.support_moments()
        a1, a2, a3 = (J2 - J3) / J1, (J3 - J1) / J2, (J1 - J2) / J3
        if not self.pivoted:

            def rhs(t, y):
                q0, q1, q2, q3, w1, w2, w3 = y.tolist()
                return np.array(
                    [
                        0.5 * (-q1 * w1 - q2 * w2 - q3 * w3),
                        0.5 * (q0 * w1 + q2 * w3 - q3 * w2),
                        0.5 * (q0 * w2 + q3 * w1 - q1 * w3),
                        0.5 * (q0 * w3 + q1 * w2 - q2 * w1),
                        a1 * w2 * w3,
                        a2 * w3 * w1,
                        a3 * w1 * w2,
                    ]
                )

            return rhs

        r1, r2, r3 = (float(x) for x in self.com)
        mg = self.mass * self.g

        def rhs(t, y):
            q0, q1, q2, q3, w1, w2, w3 = y.tolist()
            # Body-frame weight M Rᵀ (0, 0, −g) with R the rotation of q/|q|.
            s = -mg / (q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
            f1 = 2.0 * s * (q1 * q3 - q0 * q2)
            f2 = 2.0 * s * (q2 * q3 + q0 * q1)
            f3 = s * (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3)
            return np.array(
                [
                    0.5 * (-q1 * w1 - q2 * w2 - q3 * w3),
                    0.5 * (q0 * w1 + q2 * w3 - q3 * w2),
                    0.5 * (q0 * w2 + q3 * w1 - q1 * w3),
                    0.5 * (q0 * w3 + q1 * w2 - q2 * w1),
                    (r2 * f3 - r3 * f2) / J1 + a1 * w2 * w3,
                    (r3 * f1 - r1 * f3) / J2 + a2 * w3 * w1,
                    (r1 * f2 - r2 * f1) / J3 + a3 * w1 * w2,
                ]
            )

        return rhs


def _shortest_arc(a: np.ndarray, b: np.ndarray):
    """Unit quaternion rotating unit vector ``a`` onto unit vector ``b`` (not antiparallel)."""
    import jax.numpy as jnp

    q = np.concatenate([[1.0 + a @ b], np.cross(a, b)])
    return jnp.asarray(q / np.linalg.norm(q))


# --------------------------------------------------------------------------- machine


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def _version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def machine_info() -> dict[str, Any]:
    """Describe the machine and software stack the numbers were measured on.

    Returns:
        dict with ``cpu`` (model name from ``/proc/cpuinfo``), ``cores_usable`` (CPU
        affinity), ``cores_total``, ``load_average`` (1, 5, 15 min, at call time),
        ``python``, ``platform``, library versions (jax, jaxlib, diffrax, equinox, scipy,
        numpy), the JAX backend and whether 64-bit mode is on.
    """
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        usable = os.cpu_count() or 0
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = []
    info: dict[str, Any] = {
        "cpu": _cpu_model(),
        "cores_usable": usable,
        "cores_total": os.cpu_count(),
        "load_average": load,
        "python": platform.python_version(),
        "platform": platform.platform(),
    }
    for dist in ("jax", "jaxlib", "diffrax", "equinox", "scipy", "numpy"):
        info[dist] = _version(dist)
    try:
        import jax

        info["jax_backend"] = jax.default_backend()
        info["jax_x64"] = bool(jax.config.jax_enable_x64)
    except ImportError:  # pragma: no cover - jax is a dependency
        pass
    return info


def machine_line(info: dict[str, Any] | None = None) -> str:
    """One line naming the machine, e.g. for the head of a results table."""
    info = machine_info() if info is None else info
    load = info.get("load_average") or []
    load_txt = f", load average {load[0]:.1f} at start" if load else ""
    return (
        f"{info['cpu']}, {info['cores_usable']} usable cores{load_txt}; "
        f"Python {info['python']}, jax {info['jax']} ({info.get('jax_backend', '?')}, "
        f"x64={'on' if info.get('jax_x64') else 'off'}), diffrax {info['diffrax']}, "
        f"equinox {info['equinox']}, scipy {info['scipy']}, numpy {info['numpy']}"
    )


# --------------------------------------------------------------------------- timing


@dataclass
class Timing:
    """Wall times (seconds) of repeated calls."""

    runs: list[float]

    @property
    def median(self) -> float:
        return statistics.median(self.runs)

    @property
    def min(self) -> float:
        return min(self.runs)

    @property
    def max(self) -> float:
        return max(self.runs)

    def as_dict(self) -> dict[str, Any]:
        return {"median": self.median, "min": self.min, "max": self.max, "runs": self.runs}


def _block(out):
    try:
        import jax
    except ImportError:  # pragma: no cover
        return out
    return jax.block_until_ready(out)


def time_runs(
    fn: Callable[[], Any],
    repeats: int,
    *,
    warmup: int = 1,
    min_time: float = 0.0,
    max_repeats: int = 200,
    block: Callable[[Any], Any] = _block,
) -> tuple[Timing, Any]:
    """Time at least ``repeats`` calls of ``fn()`` after ``warmup`` untimed ones.

    Each call's result is passed through ``block`` (default ``jax.block_until_ready``)
    inside the timed region, so asynchronous JAX dispatch is waited for. Fast calls are
    repeated more often, until about ``min_time`` seconds are spent (at most
    ``max_repeats`` calls): on a shared machine a median of many short runs is far
    steadier than one of five.

    Args:
        fn: zero-argument callable (for JAX: an already compiled function, see
            :func:`warm_jit`, so no compile time is included).
        repeats: minimum number of timed calls, ``≥ 1``.
        warmup: untimed calls first (allocation, caches).
        min_time: target total timed seconds (extra repeats for fast calls).
        max_repeats: cap on the number of timed calls.
        block: applied to each result before the clock stops.

    Returns:
        ``(Timing, last result)``.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    out = None
    for _ in range(warmup):
        out = block(fn())
    runs: list[float] = []
    target = repeats
    while len(runs) < target:
        start = time.perf_counter()
        out = block(fn())
        runs.append(time.perf_counter() - start)
        if len(runs) == 1 and min_time > 0:
            extra = math.ceil(min_time / max(runs[0], 1e-9))
            target = max(repeats, min(max_repeats, extra))
    return Timing(runs), out


@functools.cache
def scalar(x: float, dtype: str = "float64"):
    """``jnp.asarray(x, dtype)``, made once per value: converting a tolerance on every
    timed call would add about 10 µs to each."""
    import jax.numpy as jnp

    return jnp.asarray(x, dtype)


def warm_jit(jitted, *args, **kwargs) -> tuple[Callable, float]:
    """Call ``jitted`` (a ``jax.jit`` function) once to trace and compile it; time that.

    The timed calls then go through ``jax.jit``'s C++ dispatch, which is what a user
    calling a jitted function gets. (An ahead-of-time ``Compiled`` object dispatches
    through Python: on this machine that adds 50–100 µs per call for a solve with a few
    pytree inputs, more than a whole loose-tolerance solve takes.) Later calls must use
    arguments of the same shapes, dtypes and weak types, or JAX compiles again.

    Returns:
        ``(jitted, seconds)``: the warm function and the time of its first call (tracing,
        lowering, XLA compilation) less the median of three more calls (the run itself).
    """
    start = time.perf_counter()
    _block(jitted(*args, **kwargs))
    first = time.perf_counter() - start
    runs = []
    for _ in range(3):
        start = time.perf_counter()
        _block(jitted(*args, **kwargs))
        runs.append(time.perf_counter() - start)
    return jitted, max(first - statistics.median(runs), 0.0)


def compile_jax(jitted, *args, **kwargs) -> tuple[Callable, float]:
    """Compile ``jitted`` (a ``jax.jit`` function) ahead of time for these arguments.

    For a compiled program's ``memory_analysis``; calls of the result dispatch through
    Python, slower than ``jax.jit``'s own (time calls with :func:`warm_jit` instead).

    Returns:
        ``(compiled, seconds)``: the compiled executable (call it with arguments of the
        same shapes, dtypes and static structure) and the wall time of tracing,
        lowering and XLA compilation together.
    """
    start = time.perf_counter()
    compiled = jitted.lower(*args, **kwargs).compile()
    return compiled, time.perf_counter() - start


# --------------------------------------------------------------------------- errors


def omega_error(omega, reference) -> float:
    """Relative error ``|ω − ω_ref| / |ω_ref|`` of a final angular velocity ``(3,)``."""
    omega, reference = np.asarray(omega, float), np.asarray(reference, float)
    return float(np.linalg.norm(omega - reference) / np.linalg.norm(reference))


def quaternion_error(q, reference) -> float:
    """Sign-invariant distance ``min(|q − q_ref|, |q + q_ref|)`` of unit quaternions ``(4,)``.

    ``q`` is normalised first; for small errors this is half the rotation angle between
    the two orientations.
    """
    q, reference = np.asarray(q, float), np.asarray(reference, float)
    q = q / np.linalg.norm(q)
    reference = reference / np.linalg.norm(reference)
    return float(min(np.linalg.norm(q - reference), np.linalg.norm(q + reference)))


# --------------------------------------------------------------------------- sweeps


@dataclass
class Point:
    """One run of one method at one tolerance."""

    rtol: float
    atol: float
    time: float  # median wall time, seconds
    times: list[float]
    time_min: float  # fastest run, seconds (least disturbed by other load)
    error: float  # the error that the work-precision curve uses
    errors: dict[str, float] = field(default_factory=dict)  # e.g. {"omega": .., "q": ..}
    steps: int | None = None  # steps attempted (accepted + rejected)
    accepted: int | None = None
    nfev: int | None = None  # right-hand-side evaluations, when known
    ok: bool = True
    note: str = ""


def time_interleaved(
    calls: dict[str, Callable[[], Any]],
    repeats: int | dict[str, int],
    *,
    warmup: int = 1,
    durations: dict[str, float] | None = None,
    min_time: float = 0.0,
    max_inner: int = 10,
    block: Callable[[Any], Any] = _block,
) -> dict[str, tuple[Timing, Any]]:
    """Time several calls in interleaved rounds, so that other load hits all of them alike.

    On a shared machine other processes come and go within seconds; timing one method
    after another lets a burst of load fall on one of them only. Here round ``r`` calls
    every entry once (in alternating order), so each median is taken over samples
    spread across the whole measurement, and ratios between entries stay fair.

    Args:
        calls: ``{label: zero-argument callable}`` (already compiled, for JAX).
        repeats: rounds per entry (an int for all, or per label), the minimum number
            of timed samples.
        warmup: untimed calls of each entry first; the last one's duration sets how
            many back-to-back samples (``≤ max_inner``) an entry takes per round, so
            that it gets about ``min_time`` seconds of samples in all.
        durations: known durations per label (e.g. from an earlier pass), used instead
            of the warm-up's when given.
        min_time: target total timed seconds per entry.
        max_inner: cap on samples per entry per round.
        block: applied to each result before the clock stops.

    Returns:
        ``{label: (Timing, last result)}``.
    """
    reps = repeats if isinstance(repeats, dict) else {k: repeats for k in calls}
    if any(reps[k] < 1 for k in calls):
        raise ValueError(f"repeats must be >= 1, got {reps}")
    outs: dict[str, Any] = {}
    seen = dict(durations or {})
    for key, fn in calls.items():
        for _ in range(warmup):
            start = time.perf_counter()
            outs[key] = block(fn())
            seen[key] = time.perf_counter() - start
    inner = {
        k: 1 if min_time <= 0 or k not in seen
        else max(1, min(max_inner, math.ceil(min_time / (reps[k] * max(seen[k], 1e-9)))))
        for k in calls
    }
    runs: dict[str, list[float]] = {k: [] for k in calls}
    keys = list(calls)
    for r in range(max(reps[k] for k in calls)):
        for key in keys if r % 2 == 0 else keys[::-1]:
            if r >= reps[key]:
                continue
            for _ in range(inner[key]):
                start = time.perf_counter()
                outs[key] = block(calls[key]())
                runs[key].append(time.perf_counter() - start)
    return {k: (Timing(runs[k]), outs[k]) for k in calls}


def sweep_methods(
    methods: dict[str, tuple[Callable[[float, float], dict[str, Any]], int]],
    error: Callable[[dict[str, Any]], dict[str, float]],
    tolerances: Sequence[tuple[float, float]],
    *,
    min_time: float = 0.0,
    budget_seconds: float | None = None,
) -> dict[str, list[Point]]:
    """Run several methods over tolerances, timed in interleaved rounds; measure errors.

    A first pass calls every (method, tolerance) once, in order (warm-up; it also
    stops a method's sweep at the first tolerance whose call exceeds
    ``budget_seconds``). Then every kept (method, tolerance) is timed with
    :func:`time_interleaved`.

    Args:
        methods: ``{label: (run, repeats)}``. ``run(rtol, atol)`` performs one complete
            solve and returns a dict of results (JAX or numpy arrays) with ``q`` and
            ``omega`` as the error function needs; optional keys ``steps``,
            ``accepted``, ``nfev`` (counts) and ``ok`` (bool, success) are recorded.
            ``repeats`` is the minimum number of timed calls (the median is reported).
        error: maps a result to a dict of named errors; the largest is the point's
            ``error`` (so the curve is the worst of, e.g., ω and ``q``).
        tolerances: ``(rtol, atol)`` pairs, loosest first.
        min_time: see :func:`time_interleaved` (more samples for fast calls).
        budget_seconds: skip a method's tighter tolerances once a call takes longer.

    Returns:
        ``{label: [Point, ...]}``, one point per tolerance run.
    """
    calls: dict[str, Callable[[], Any]] = {}
    reps: dict[str, int] = {}
    seen: dict[str, float] = {}
    index: dict[str, tuple[str, int]] = {}
    notes: dict[str, str] = {}
    for label, (run, repeats) in methods.items():
        for i, (rtol, atol) in enumerate(tolerances):
            key = f"{label} @ {i}"
            call = lambda run=run, r=rtol, a=atol: run(r, a)  # noqa: E731
            start = time.perf_counter()
            _block(call())
            seen[key] = time.perf_counter() - start
            calls[key], reps[key], index[key] = call, repeats, (label, i)
            if budget_seconds is not None and seen[key] > budget_seconds:
                notes[key] = f"tighter tolerances skipped: a run took > {budget_seconds:g} s"
                break
    timed = time_interleaved(calls, reps, warmup=0, durations=seen, min_time=min_time)
    points: dict[str, list[Point]] = {label: [] for label in methods}
    for key, (timing, out) in timed.items():
        label, i = index[key]
        rtol, atol = tolerances[i]
        ok = bool(np.asarray(out.get("ok", True)))
        errs = {k: float(v) for k, v in error(out).items()} if ok else {}
        finite = errs and all(map(math.isfinite, errs.values()))
        worst = max(errs.values()) if finite else math.nan
        points[label].append(
            Point(
                rtol=rtol,
                atol=atol,
                time=timing.median,
                times=timing.runs,
                time_min=timing.min,
                error=worst,
                errors=errs,
                steps=_int_or_none(out.get("steps")),
                accepted=_int_or_none(out.get("accepted")),
                nfev=_int_or_none(out.get("nfev")),
                ok=ok and math.isfinite(worst),
                note=notes.get(key, str(out.get("note", ""))),
            )
        )
    return points


def sweep(
    run: Callable[[float, float], dict[str, Any]],
    error: Callable[[dict[str, Any]], dict[str, float]],
    tolerances: Sequence[tuple[float, float]],
    repeats: int,
    *,
    min_time: float = 0.0,
    budget_seconds: float | None = None,
) -> list[Point]:
    """One method over tolerances: :func:`sweep_methods` with a single entry."""
    return sweep_methods(
        {"method": (run, repeats)}, error, tolerances,
        min_time=min_time, budget_seconds=budget_seconds,
    )["method"]


def _int_or_none(x) -> int | None:
    return None if x is None else int(np.asarray(x))


def points_as_dicts(points: Sequence[Point]) -> list[dict[str, Any]]:
    """JSON-ready form of a sweep."""
    return [asdict(p) for p in points]


def pareto_front(errors: Sequence[float], times: Sequence[float]) -> list[tuple[float, float]]:
    """The runs no other run beats in both error and time, sorted by time.

    Non-finite or non-positive errors are dropped. Returns ``[(error, time), ...]`` with
    time increasing and error strictly decreasing.
    """
    pairs = sorted(
        (t, e) for e, t in zip(errors, times, strict=True)
        if e is not None and math.isfinite(e) and e > 0 and math.isfinite(t)
    )
    front: list[tuple[float, float]] = []
    for t, e in pairs:
        if not front or e < front[-1][0]:
            front.append((e, t))
    return front


def time_to_error(
    errors: Sequence[float], times: Sequence[float], target: float
) -> tuple[float | None, str]:
    """Time a method needs to reach final error ``target``, from its work-precision curve.

    Interpolates ``log time`` linearly in ``log error`` along the :func:`pareto_front`.

    Returns:
        ``(seconds, kind)`` where ``kind`` is ``"interp"`` (bracketed by two runs),
        ``"bound"`` (already the cheapest run is more accurate than ``target``: the
        time is that run's, an upper bound) or ``"unreached"`` (no run got down to
        ``target``; seconds is ``None``).
    """
    front = pareto_front(errors, times)
    if not front:
        return None, "unreached"
    if front[-1][0] > target:
        return None, "unreached"
    if front[0][0] <= target:
        return front[0][1], "bound"
    for (e0, t0), (e1, t1) in zip(front, front[1:], strict=False):
        if e0 > target >= e1:
            w = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + w * (math.log(t1) - math.log(t0))), "interp"
    return None, "unreached"  # pragma: no cover - the loop always brackets


# --------------------------------------------------------------------------- writers


def fmt_seconds(seconds: float | None, kind: str = "interp") -> str:
    """Human-readable time for a table cell (``—`` when unreached, ``≤`` for a bound)."""
    if seconds is None or kind == "unreached":
        return "—"
    prefix = "≤ " if kind == "bound" else ""
    if seconds >= 1.0:
        return f"{prefix}{seconds:.2f} s"
    if seconds >= 1e-3:
        return f"{prefix}{seconds * 1e3:.3g} ms"
    return f"{prefix}{seconds * 1e6:.3g} µs"


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A GitHub markdown table (cells converted with ``str``)."""
    lines = ["| " + " | ".join(map(str, headers)) + " |"]
    lines.append("| " + " | ".join("---" for _ in headers) + " |")
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        x = float(x)
        return x if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    return x


def write_json(path: str | os.PathLike, obj: Any) -> pathlib.Path:
    """Write ``obj`` as indented JSON (numpy scalars converted, NaN/inf as ``null``)."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_jsonable(obj), indent=1, ensure_ascii=False) + "\n", "utf-8")
    return path


def write_text(path: str | os.PathLike, text: str) -> pathlib.Path:
    """Write a text (markdown) file."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, "utf-8")
    return path


PALETTE = [f"C{i}" for i in range(10)] + [
    "olive", "navy", "brown", "teal", "magenta", "black", "gold", "lime", "crimson",
    "slategray", "orchid", "peru", "darkgreen", "steelblue", "salmon",
]


def _colours(panels) -> dict[str, str]:
    """One colour per method label, the same in every panel."""
    labels = list(dict.fromkeys(label for curves in panels.values() for label in curves))
    return {label: PALETTE[i % len(PALETTE)] for i, label in enumerate(labels)}


def _style(label: str, n_points: int, highlight: Sequence[str]) -> dict[str, Any]:
    """Line style of a method: peers dashed with squares, fixed-step splitting dash-dotted
    with diamonds, a single run a star, highlighted labels thick."""
    peer = not label.startswith("jrigid")
    splitting = label.startswith("jrigid splitting")
    marker = "s" if peer else "D" if splitting else "o"
    return dict(
        marker="*" if n_points == 1 else marker,
        markersize=11 if n_points == 1 else 3.5,
        linestyle="--" if peer else "-." if splitting else "-",
        linewidth=2.8 if label in highlight else 1.1,
    )


def _draw_panel(ax, name, curves, colour, *, targets, highlight, wrap: int,
                fontsize: float) -> dict[str, Any]:
    """One work-precision panel (error on x, inverted; time on y; log-log): its lines."""
    handles = {}
    for label, (errs, times) in curves.items():
        pts = sorted(
            (e, t) for e, t in zip(errs, times, strict=True)
            if e is not None and math.isfinite(e) and e > 0
        )
        if not pts:
            continue
        xs, ys = zip(*pts, strict=True)
        (line,) = ax.loglog(xs, ys, color=colour[label], label=label,
                            **_style(label, len(pts), highlight))
        handles[label] = line
    for target in targets:
        ax.axvline(target, color="0.7", linestyle=":", linewidth=0.8)
    ax.set_title("\n".join(textwrap.wrap(name, wrap)), fontsize=fontsize + 1)
    ax.set_xlabel("final error (worst of relative ω and q)", fontsize=fontsize)
    ax.set_ylabel("wall time after compilation [s]", fontsize=fontsize)
    ax.invert_xaxis()
    ax.grid(True, which="major", alpha=0.3)
    return handles


def _save(fig, path, title: str, dpi: int) -> pathlib.Path:
    if title:
        fig.suptitle(title, fontsize=8)
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path


def work_precision_figure(
    panels: dict[str, dict[str, tuple[Sequence[float], Sequence[float]]]],
    path: str | os.PathLike,
    *,
    targets: Sequence[float] = (),
    highlight: Sequence[str] = (),
    title: str = "",
) -> pathlib.Path:
    """Work-precision diagram: final error (x) against wall time (y), log-log, one row.

    Each panel carries its own legend; styles as in :func:`work_precision_grid`.

    Args:
        panels: ``{panel title: {method label: (errors, times)}}``, one subplot each.
        path: PNG file to write.
        targets: error levels drawn as dotted vertical lines.
        highlight: labels drawn thick (e.g. the default method).
        title: figure title (e.g. the machine line).

    Returns:
        the PNG path.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    n = max(len(panels), 1)
    fig = Figure(figsize=(6.4 * n, 5.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, n, squeeze=False)[0]
    colour = _colours(panels)
    for ax, (name, curves) in zip(axes, panels.items(), strict=False):
        _draw_panel(ax, name, curves, colour, targets=targets, highlight=highlight, wrap=60,
                    fontsize=9)
        ax.legend(fontsize=6.5, loc="upper left")
    return _save(fig, path, title, dpi=160)


def work_precision_grid(
    panels: dict[str, dict[str, tuple[Sequence[float], Sequence[float]]]],
    path: str | os.PathLike,
    *,
    ncols: int = 2,
    targets: Sequence[float] = (),
    highlight: Sequence[str] = (),
    title: str = "",
) -> pathlib.Path:
    """Work-precision diagrams of several problems on a grid, one legend for all.

    Error on x (inverted), time on y, log-log, ``ncols`` panels a row. Methods not
    starting with ``"jrigid"`` (the peers) are drawn dashed with square markers, the
    fixed-step splitting methods dash-dotted with diamonds, a method with a single run as
    a star; a method keeps its colour in every panel.

    Args:
        panels: ``{panel title: {method label: (errors, times)}}``.
        path: PNG file to write.
        ncols: panels per row.
        targets: error levels drawn as dotted vertical lines.
        highlight: labels drawn thick.
        title: figure title (e.g. the machine line).

    Returns:
        the PNG path.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    n = max(len(panels), 1)
    ncols = max(1, min(ncols, n))
    nrows = math.ceil(n / ncols)
    fig = Figure(figsize=(6.0 * ncols + 3.2, 4.6 * nrows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    colour = _colours(panels)
    handles: dict[str, Any] = {}
    for ax, (name, curves) in zip(axes, panels.items(), strict=False):
        for label, line in _draw_panel(ax, name, curves, colour, targets=targets,
                                       highlight=highlight, wrap=55, fontsize=8).items():
            handles.setdefault(label, line)
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.legend(list(handles.values()), list(handles), loc="outside right center", fontsize=7)
    return _save(fig, path, title, dpi=100)
