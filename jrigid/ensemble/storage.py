"""On-disk layout of an ensemble run: ``meta.json`` plus one ``chunk_NNNNN.npz`` per chunk.

Every file is written to a temporary name in the same folder, flushed to disk and
renamed with :func:`os.replace`, which is atomic: a killed run leaves either a complete
chunk file or none, never half of one. ``meta.json`` describes the run (member count,
chunking, output names, shapes and dtypes, a SHA-256 fingerprint of the inputs, the
user's metadata and the library versions); a resumed run must match it.

Each chunk file also holds its own index and the run's identity (:func:`run_id`, a
SHA-256 over the fields of ``meta.json`` a resumed run must match), so a chunk file
copied to another index or from another run is never loaded as this one.

One driver at a time: :func:`lock` takes an exclusive ``fcntl`` lock on
``out_dir/.lock`` for as long as a run uses the folder. The operating system releases
it when the process ends, however it ends (``kill -9`` included), so a killed driver
leaves no stale lock.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import pathlib
import platform
import re
import time
from importlib import metadata as importlib_metadata
from typing import Any

import numpy as np

from jrigid._files import write_atomic

__all__ = [
    "CHUNK_PATTERN",
    "META_NAME",
    "chunk_path",
    "folder_for",
    "fingerprint",
    "load_chunk",
    "lock",
    "mismatches",
    "now",
    "read_meta",
    "remove_run",
    "remove_stale_temporaries",
    "run_id",
    "structure",
    "versions",
    "write_atomic",
    "write_chunk",
    "write_meta",
]

META_NAME = "meta.json"
CHUNK_PATTERN = "chunk_{:05d}.npz"
LOCK_NAME = ".lock"
# The key under which a chunk file stores its index and run identity.
TAG = "__jrigid_chunk__"
# Fields of meta.json a resumed run must reproduce exactly.
MATCHED = (
    "format", "n_members", "chunk_size", "n_chunks", "inputs", "shared", "outputs", "metadata",
    "batched",
)
# Fields added after runs were first stored: their value when a stored meta.json lacks them.
_DEFAULTS = {"batched": False}


def versions() -> dict[str, str]:
    """Versions of jrigid, jax, jaxlib, diffrax, equinox, numpy and Python."""
    out = {"python": platform.python_version()}
    for dist in ("jrigid", "jax", "jaxlib", "diffrax", "equinox", "numpy"):
        try:
            out[dist] = importlib_metadata.version(dist)
        except importlib_metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


def fingerprint(named_leaves: list[tuple[str, np.ndarray]]) -> str:
    """SHA-256 over every input leaf's name, dtype, shape and bytes (C order)."""
    h = hashlib.sha256()
    for name, leaf in named_leaves:
        h.update(f"{name}|{leaf.dtype.str}|{leaf.shape}\n".encode())
        h.update(np.ascontiguousarray(leaf).tobytes())
    return h.hexdigest()


def folder_for(base: str | os.PathLike, settings: dict) -> pathlib.Path:
    """``base / <12 hex digits of the settings' SHA-256>``: one chunk folder per set of
    settings, so that an experiment run again with other parameters starts its own
    sweep (and resumes its own after an interruption) instead of finding another run's
    chunks. ``settings`` must be JSON-serialisable (sorted keys)."""
    text = json.dumps(settings, sort_keys=True, default=str)
    return pathlib.Path(base) / hashlib.sha256(text.encode()).hexdigest()[:12]


def structure(treedef) -> np.ndarray:
    """A pytree structure as a fingerprintable array (memory addresses removed)."""
    return np.array(re.sub(r" at 0x[0-9a-fA-F]+", "", str(treedef)))


def chunk_path(out_dir: pathlib.Path, index: int) -> pathlib.Path:
    """``out_dir / chunk_{index:05d}.npz``."""
    return out_dir / CHUNK_PATTERN.format(index)



def run_id(meta: dict[str, Any]) -> str:
    """SHA-256 over the fields of ``meta`` that a resumed run must match (the run's identity)."""
    matched = {k: meta.get(k, _DEFAULTS.get(k)) for k in MATCHED}
    return hashlib.sha256(json.dumps(matched, sort_keys=True).encode()).hexdigest()


def _tag(index: int, run: str) -> np.ndarray:
    return np.array(f"{index}:{run}")


def write_chunk(
    out_dir: pathlib.Path, index: int, arrays: dict[str, np.ndarray], run: str
) -> None:
    """Write one chunk's outputs atomically as an uncompressed ``.npz``, tagged with
    ``index`` and the run identity ``run`` (:func:`run_id`)."""
    tagged = {**arrays, TAG: _tag(index, run)}
    write_atomic(chunk_path(out_dir, index), lambda fh: np.savez(fh, **tagged))


def load_chunk(
    out_dir: pathlib.Path,
    index: int,
    spec: dict[str, tuple[tuple[int, ...], str]],
    size: int,
    run: str,
) -> dict[str, np.ndarray] | None:
    """The outputs stored for chunk ``index``, or ``None`` if absent or not as expected.

    ``spec`` maps output names to (per-member shape, dtype string); ``size`` is the
    chunk's member count; ``run`` the run identity (:func:`run_id`). A file that cannot
    be read, does not match the outputs, or carries another index or run (a file copied
    or left from elsewhere) is reported as ``None`` (so it is computed again and
    overwritten).
    """
    path = chunk_path(out_dir, index)
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            if TAG not in data.files or data[TAG] != _tag(index, run):
                return None
            out = {name: data[name] for name in spec}
    except Exception:  # noqa: BLE001 - any unreadable file is recomputed
        return None
    for name, (shape, dtype) in spec.items():
        a = out[name]
        if a.shape != (size, *shape) or a.dtype != np.dtype(dtype):
            return None
    return out


def write_meta(out_dir: pathlib.Path, meta: dict[str, Any]) -> None:
    """Write ``meta.json`` atomically."""
    text = json.dumps(meta, indent=1, ensure_ascii=False) + "\n"
    write_atomic(out_dir / META_NAME, lambda fh: fh.write(text.encode()))


def read_meta(out_dir: pathlib.Path) -> dict[str, Any] | None:
    """The stored ``meta.json`` (``None`` if there is none); ``ValueError`` if unreadable."""
    path = out_dir / META_NAME
    if not path.exists():
        return None
    try:
        meta = json.loads(path.read_text("utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(
            f"{path} is unreadable ({err}): it does not describe a jrigid ensemble run. "
            "Choose another out_dir, or pass resume=False to overwrite this run."
        ) from None
    if not isinstance(meta, dict) or meta.get("format") != "jrigid.ensemble/1":
        raise ValueError(
            f"{path} is not the meta.json of a jrigid ensemble run. Choose another "
            "out_dir, or pass resume=False to overwrite this run."
        )
    return meta


def mismatches(stored: dict[str, Any], wanted: dict[str, Any]) -> list[str]:
    """What a resumed run must reproduce and does not: one short text per difference,
    naming the field (and, for the inputs, the leaf whose shape or dtype changed)."""
    out = []
    for k in MATCHED:
        old, new = stored.get(k, _DEFAULTS.get(k)), wanted.get(k, _DEFAULTS.get(k))
        if old == new:
            continue
        if k in ("inputs", "shared") and isinstance(old, dict) and isinstance(new, dict):
            out.extend(_leaf_changes(k, old.get("leaves", {}), new.get("leaves", {})))
        elif isinstance(old, int | str | bool) and isinstance(new, int | str | bool):
            out.append(f"{k} ({old!r} → {new!r})")
        else:
            out.append(k)
    return out


def _leaf_changes(what: str, old: dict, new: dict) -> list[str]:
    label = "the shared inputs" if what == "shared" else "the members' inputs"
    changed = []
    for name in sorted(set(old) | set(new)):
        a, b = old.get(name), new.get(name)
        if a is None or b is None:
            changed.append(f"{label}: {name} {'added' if a is None else 'removed'}")
        elif a != b:
            changed.append(f"{label}: {name} (shape {a['shape']} dtype {a['dtype']} → shape "
                           f"{b['shape']} dtype {b['dtype']})")
    return changed or [f"{label}' values ({', '.join(sorted(new)) or 'structure'})"]


def remove_stale_temporaries(out_dir: pathlib.Path) -> None:
    """Delete temporary files a killed run left behind (``.chunk_*.tmp``, ``.meta.json.*``)."""
    for pattern in (".chunk_*.npz.*.tmp", f".{META_NAME}.*.tmp"):
        for path in out_dir.glob(pattern):
            path.unlink(missing_ok=True)


def remove_run(out_dir: pathlib.Path) -> None:
    """Delete ``meta.json`` and every ``chunk_*.npz`` of a run (nothing else)."""
    for path in out_dir.glob("chunk_*.npz"):
        path.unlink()
    meta = out_dir / META_NAME
    if meta.exists():
        meta.unlink()


_HELD: set[str] = set()  # folders locked by this process


@contextlib.contextmanager
def lock(out_dir: pathlib.Path):
    """Hold an exclusive lock on ``out_dir/.lock`` for one driver (a context manager).

    Raises ``ValueError`` if another process holds it (naming the host and process id
    recorded in the file). The lock is an ``fcntl.lockf`` lock, released by the operating
    system when its holder exits or is killed; it works on local file systems and on NFS
    with a lock manager. Within one process a second lock on the same folder is refused
    too. Where ``fcntl`` does not exist (Windows) only the latter holds.
    """
    path = pathlib.Path(out_dir) / LOCK_NAME
    key = str(path.resolve())
    if key in _HELD:
        raise ValueError(
            f"{path.parent} is in use by another run in this process: one run per out_dir "
            "at a time"
        )
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        fcntl = None
    with open(path, "a+") as fh:
        if fcntl is not None:
            try:
                fcntl.lockf(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                fh.seek(0)
                holder = fh.read().strip() or "unknown"
                raise ValueError(
                    f"{path.parent} is in use by another run ({holder}): wait for it to "
                    "finish or choose another out_dir (the lock goes when that process "
                    "ends; its finished chunks are kept)"
                ) from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"host {platform.node()}, pid {os.getpid()}, since {now()}\n")
        fh.flush()
        _HELD.add(key)
        try:
            yield path
        finally:
            _HELD.discard(key)
    # closing the file released the lockf lock


def now() -> str:
    """UTC time stamp for ``meta.json``."""
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
