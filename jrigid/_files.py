"""Files written whole or not at all: :func:`write_atomic`, shared by the ensembles'
chunks and ``meta.json`` (:mod:`jrigid.ensemble.storage`) and the experiments' reports
(:mod:`jrigid.report`). Standard library only, so that importing it is free.
"""

from __future__ import annotations

import os
import pathlib
import threading

__all__ = ["write_atomic"]


def write_atomic(path: pathlib.Path, write) -> None:
    """Call ``write(fh)`` on a temporary file next to ``path``, fsync, rename onto ``path``."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
