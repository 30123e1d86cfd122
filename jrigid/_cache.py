"""JAX's persistent compilation cache, turned on when jrigid is imported.

Most of a script's first ``simulate`` is XLA compiling the solve (2–4 s on 2 cores for a
free rotor or a heavy top, ``benchmarks/first_call.py``); the same script run again
compiles the same programs again. With JAX's persistent compilation cache, compiled
programs are kept on disk and a later process loads them instead: measured on this
project's machine (AMD EPYC, 2 cores), the compilation of a new process's first
``simulate`` of a free rotor took 4.1 s with an empty cache and 1.6 s with the program
cached (heavy top: 5.6 and 1.9 s); what is left is tracing and lowering, which no cache
saves.

``configure`` points JAX's ``jax_compilation_cache_dir`` at ``DEFAULT_DIR`` (under
``$XDG_CACHE_HOME``, else ``~/.cache``) when JAX is imported, unless:

- ``JRIGID_CACHE_DIR`` (the environment variable ``ENV``) says otherwise: a directory
  to use instead, or one of ``OFF`` (``0``, ``off``, ``false``, ``no``, ``none`` or
  empty) to leave JAX's cache alone;
- a cache directory is already set (JAX's ``JAX_COMPILATION_CACHE_DIR``, or
  ``jax.config.update("jax_compilation_cache_dir", ...)`` before importing jrigid), or
  JAX's caching is off (``jax_enable_compilation_cache``);
- the directory cannot be created or written (then nothing is cached, silently).

JAX only writes programs whose compilation took at least
``jax_persistent_cache_min_compile_time_secs``. JAX's default, 1 s, left out a free
rotor's solve, which XLA compiles in 0.9–1.0 s on 2 cores: jrigid lowers it to
``MIN_COMPILE_SECONDS`` unless it was set to another value (the option or its
environment variable ``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS``). Each of jrigid's
solves is a few hundred kB.
The cache holds at most ``MAX_BYTES`` (JAX's ``jax_compilation_cache_max_size``, unless
set): JAX then removes the least recently used programs, and reads and writes the
directory under a file lock (``filelock``), so that processes sharing it (the workers
of a sweep, of a test run) never read a program another is still writing.
The cache applies to every program of the process, not only jrigid's (it is JAX's
own). The directory is created readable by its owner only: JAX trusts what it loads
from it. Delete it to clear the cache. A cache set after JAX's first compilation has
no effect (JAX decides once whether it uses one).
"""

from __future__ import annotations

import importlib.util
import os

from jrigid._on_jax import after_jax_import

__all__ = ["DEFAULT_DIR", "ENV", "MAX_BYTES", "MIN_COMPILE_SECONDS", "OFF", "OPTION",
           "cache_dir", "clear", "configure", "contents"]

#: The environment variable that chooses the directory (or turns the cache off).
ENV = "JRIGID_CACHE_DIR"

#: Values of ``ENV`` (case-insensitive, stripped) that leave JAX's cache alone.
OFF = frozenset({"", "0", "off", "false", "no", "none"})

#: JAX's configuration option for the cache's directory.
OPTION = "jax_compilation_cache_dir"

#: The directory used when ``ENV`` is not set, below the user's cache directory.
DEFAULT_DIR = os.path.join("jrigid", "xla")

#: The cache's size limit (bytes), about a thousand of jrigid's compiled solves.
MAX_BYTES = 1 << 30

#: The shortest compilation (seconds) whose program is written to the cache.
MIN_COMPILE_SECONDS = 0.25

_MAX_OPTION = "jax_compilation_cache_max_size"
_MIN_TIME_OPTION = "jax_persistent_cache_min_compile_time_secs"
_JAX_MIN_TIME = 1.0  # JAX's default for _MIN_TIME_OPTION

# How JAX names a cached program's file and its access-time file.
_PROGRAM, _ACCESSED = "-cache", "-atime"


def cache_dir(environ=None) -> str | None:
    """The directory jrigid asks JAX to cache compiled programs in, or ``None`` (off).

    Args:
        environ: a mapping of environment variables (default ``os.environ``).

    Returns:
        ``environ[ENV]`` if set and not one of ``OFF``, ``None`` if one of ``OFF``, else
        ``DEFAULT_DIR`` below ``$XDG_CACHE_HOME`` (or ``~/.cache``).
    """
    environ = os.environ if environ is None else environ
    chosen = environ.get(ENV)
    if chosen is not None:
        return None if chosen.strip().lower() in OFF else os.path.expanduser(chosen)
    base = environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, DEFAULT_DIR)


def _writable(path: str) -> bool:
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
    except OSError:
        return False
    return os.path.isdir(path) and os.access(path, os.W_OK | os.X_OK)


def _enable() -> None:
    import jax

    path = cache_dir()
    if path is None or getattr(jax.config, OPTION, None):
        return
    if not getattr(jax.config, "jax_enable_compilation_cache", True):
        return
    if not _writable(path):
        return
    jax.config.update(OPTION, path)
    # JAX's default is no limit and no lock; a limit needs filelock (a dependency)
    if getattr(jax.config, _MAX_OPTION, None) == -1 and importlib.util.find_spec("filelock"):
        jax.config.update(_MAX_OPTION, MAX_BYTES)
    if getattr(jax.config, _MIN_TIME_OPTION, None) == _JAX_MIN_TIME:
        jax.config.update(_MIN_TIME_OPTION, MIN_COMPILE_SECONDS)


def configure() -> None:
    """Point JAX's persistent compilation cache at :func:`cache_dir` (see the module
    docstring): now if JAX is imported, else as soon as it is."""
    after_jax_import(_enable)


def _entries(path: str) -> list[str]:
    try:
        names = os.listdir(path)
    except OSError:
        return []
    return [os.path.join(path, n) for n in names if n.endswith((_PROGRAM, _ACCESSED))]


def contents(path: str) -> tuple[int, int]:
    """``(programs, bytes)``: how many compiled programs the cache at ``path`` holds and
    the bytes its files take (``(0, 0)`` if there is no such directory)."""
    entries = _entries(path)
    size = 0
    for entry in entries:
        try:
            size += os.path.getsize(entry)
        except OSError:  # removed meanwhile
            pass
    return sum(e.endswith(_PROGRAM) for e in entries), size


def clear(path: str) -> int:
    """Remove the compiled programs of the cache at ``path``; returns how many."""
    removed = 0
    for entry in _entries(path):
        try:
            os.remove(entry)
        except OSError:
            continue
        removed += entry.endswith(_PROGRAM)
    return removed
