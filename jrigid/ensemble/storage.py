"""On-disk layout of an ensemble run: ``meta.json`` plus one ``chunk_NNNNN.npz`` per chunk.

Every file is written to a temporary name in the same folder, flushed to disk and
renamed with :func:`os.replace`, which is atomic: a killed run leaves either a complete
chunk file or none, never half of one. ``meta.json`` describes the run (member count,
chunking, output names, shapes and dtypes, a SHA-256 fingerprint of the inputs, the
user's metadata and the library versions); a resumed run must match it.
"""

from __future__ import annotations

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

__all__ = [
    "CHUNK_PATTERN",
    "META_NAME",
    "chunk_path",
    "fingerprint",
    "load_chunk",
    "mismatches",
    "now",
    "read_meta",
    "remove_run",
    "remove_stale_temporaries",
    "structure",
    "versions",
    "write_atomic",
    "write_chunk",
    "write_meta",
]

META_NAME = "meta.json"
CHUNK_PATTERN = "chunk_{:05d}.npz"
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


def structure(treedef) -> np.ndarray:
    """A pytree structure as a fingerprintable array (memory addresses removed)."""
    return np.array(re.sub(r" at 0x[0-9a-fA-F]+", "", str(treedef)))


def chunk_path(out_dir: pathlib.Path, index: int) -> pathlib.Path:
    """``out_dir / chunk_{index:05d}.npz``."""
    return out_dir / CHUNK_PATTERN.format(index)


def write_atomic(path: pathlib.Path, write) -> None:
    """Call ``write(fh)`` on a temporary file next to ``path``, fsync, rename onto ``path``."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_chunk(out_dir: pathlib.Path, index: int, arrays: dict[str, np.ndarray]) -> None:
    """Write one chunk's outputs atomically as an uncompressed ``.npz``."""
    write_atomic(chunk_path(out_dir, index), lambda fh: np.savez(fh, **arrays))


def load_chunk(
    out_dir: pathlib.Path, index: int, spec: dict[str, tuple[tuple[int, ...], str]], size: int
) -> dict[str, np.ndarray] | None:
    """The outputs stored for chunk ``index``, or ``None`` if absent or not as expected.

    ``spec`` maps output names to (per-member shape, dtype string); ``size`` is the
    chunk's member count. A file that cannot be read or does not match is reported as
    ``None`` (so it is computed again and overwritten).
    """
    path = chunk_path(out_dir, index)
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
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
    """Names of the fields a resumed run must reproduce that differ."""
    return [
        k for k in MATCHED if stored.get(k, _DEFAULTS.get(k)) != wanted.get(k, _DEFAULTS.get(k))
    ]


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


def now() -> str:
    """UTC time stamp for ``meta.json``."""
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
