"""XLA:CPU's small-while-loop threshold, raised when jrigid is imported.

XLA:CPU compiles a ``while`` loop into one kernel only when the bytes its loop carries
are below ``xla_cpu_small_while_loop_byte_threshold`` (1 kB by default). Above it, every
operation of every iteration is dispatched on its own (measured by
``benchmarks/xla_threshold.py``, free rotor, rtol 1e-8: ``simulate`` 3.9–4.9× slower saving
2 times, 5.7–6.4× saving 101 times, a reverse-mode gradient through it 13–14×).
diffrax's loop carries its output buffers, so any solve saving more than a handful of
times is above 1 kB. Loops holding a ``dot``, a convolution, a scatter or a custom call
(LAPACK, ...) are never compiled into one kernel, whatever the threshold.

``configure`` adds the option to ``XLA_FLAGS``; JAX reads that variable when its
first computation starts its backend, so it acts only if jrigid is imported before then.
A threshold the user already set (``XLA_FLAGS`` naming the option) is kept: set it to
``1024`` to get XLA's default back.

It also turns XLA:CPU's MLIR fusion emitters off (``EMITTERS``), for the XLA
versions known to have that flag (``EMITTER_JAXLIB``; XLA stops the process on a flag
it does not know). The older emitters generate the same kernels' code with less work:
measured on this project's test files (2 cores), 172 s against 232 s for three files of
derivative tests, and 2.5–2.7 s against 2.9 s of XLA compilation for a first ``simulate``
of a free rotor, with the same run time (0.39, 0.77 and 1.2 ms at rtol 1e-4, 1e-8,
1e-10 either way). A setting the user made (``XLA_FLAGS`` naming the flag) is kept: set
``--xla_cpu_use_fusion_emitters=true`` to get XLA's default back.
"""

from __future__ import annotations

import os
import re
import sys
import warnings

__all__ = ["EMITTERS", "EMITTER_FLAG", "EMITTER_JAXLIB", "OPTION", "THRESHOLD_BYTES", "configure",
           "with_emitters", "with_threshold"]

#: The XLA:CPU backend option (one of ``--xla_backend_extra_options``).
OPTION = "xla_cpu_small_while_loop_byte_threshold"

#: The threshold jrigid sets: loops carrying up to 100 MB (a solve saving 10⁶ states, a
#: vmapped chunk of 1024 members saving 1000 times) compile into one kernel each.
THRESHOLD_BYTES = 100_000_000

#: The XLA flag that selects XLA:CPU's MLIR fusion emitters.
EMITTER_FLAG = "xla_cpu_use_fusion_emitters"

#: ``EMITTER_FLAG`` set to turn the MLIR fusion emitters off.
EMITTERS = f"--{EMITTER_FLAG}=false"

#: The ``(major, minor)`` jaxlib releases whose XLA has ``EMITTERS`` and where it was
#: measured; :func:`configure` leaves other versions' flags alone.
EMITTER_JAXLIB = ((0, 10),)

_EXTRA = re.compile(r"--xla_backend_extra_options=(\S*)")
_DIST_INFO = re.compile(r"jaxlib-(\d+)\.(\d+)\.[^-]*\.dist-info")


def with_threshold(flags: str, threshold: int = THRESHOLD_BYTES) -> str:
    """``flags`` (an ``XLA_FLAGS`` value) with ``OPTION`` set to ``threshold``.

    Unchanged if ``flags`` already names ``OPTION``; otherwise the option joins an
    existing ``--xla_backend_extra_options=`` list (comma separated) or is appended.
    """
    if OPTION in flags:
        return flags
    entry = f"{OPTION}={int(threshold)}"
    match = _EXTRA.search(flags)
    if match is None:
        return f"{flags} --xla_backend_extra_options={entry}".strip()
    value = f"{match.group(1)},{entry}" if match.group(1) else entry
    return flags[: match.start(1)] + value + flags[match.end(1):]


def with_emitters(flags: str) -> str:
    """``flags`` (an ``XLA_FLAGS`` value) with ``EMITTERS`` appended, unless it
    already names ``EMITTER_FLAG``."""
    if EMITTER_FLAG in flags:
        return flags
    return f"{flags} {EMITTERS}".strip()


def _jaxlib_release() -> tuple[int, int] | None:
    """The installed jaxlib's ``(major, minor)``, or ``None`` if unknown.

    Read from the name of its ``jaxlib-X.Y.Z.dist-info`` folder beside the package:
    ``importlib.metadata`` took about 50 ms, most of ``import jrigid``'s time."""
    import importlib.util

    spec = importlib.util.find_spec("jaxlib")
    if spec is None or not spec.origin:
        return None
    site = os.path.dirname(os.path.dirname(spec.origin))
    try:
        names = os.listdir(site)
    except OSError:
        return None
    for name in names:
        match = _DIST_INFO.fullmatch(name)
        if match:
            return int(match.group(1)), int(match.group(2))
    return None


def _backend_started() -> bool:
    if "jax" not in sys.modules:
        return False
    try:
        from jax._src import xla_bridge
    except ImportError:  # pragma: no cover - JAX's layout changed
        return False
    started = getattr(xla_bridge, "backends_are_initialized", None)
    return bool(started()) if started is not None else False


def configure() -> bool:
    """Add ``OPTION`` (and, for the jaxlib releases of ``EMITTER_JAXLIB``,
    ``EMITTERS``) to ``XLA_FLAGS`` unless set; warn if JAX has already started.

    Returns:
        Whether ``XLA_FLAGS`` was changed.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    updated = with_threshold(flags)
    if _jaxlib_release() in EMITTER_JAXLIB:
        updated = with_emitters(updated)
    if updated == flags:
        return False
    os.environ["XLA_FLAGS"] = updated
    if _backend_started():
        warnings.warn(
            "jrigid was imported after JAX ran its first computation, so XLA:CPU keeps "
            f"its 1 kB {OPTION}: jrigid's solves run 4-6x slower, gradients 13x. Import jrigid "
            "before running JAX, or set XLA_FLAGS="
            f"--xla_backend_extra_options={OPTION}={THRESHOLD_BYTES} before starting Python.",
            RuntimeWarning,
            stacklevel=3,
        )
    return True
