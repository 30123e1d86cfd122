"""The experiment registry behind ``jrigid list`` and ``jrigid run``.

An experiment is a module with a docstring (its first line is the one-line description
shown by ``jrigid list``) and a function::

    def main(out_dir, quick=False, *, name1=default1, name2=default2, ...): ...

``out_dir`` is the results folder (a :class:`pathlib.Path`, created before the call),
``quick`` asks for a short run (used by the tests; optional: an experiment without it
always runs in full), and the keyword parameters with their
defaults are the experiment's parameters: ``jrigid run NAME key=value`` converts each value
to the type of the default (see
:func:`~jrigid.experiment_parameters.parse_params`). ``main`` writes its figures, numbers
and summary with :class:`jrigid.report.Report`; if it returns a mapping and wrote no
``numbers.json`` / ``report.md``, the runner writes them from that mapping.

Values are converted and checked before the run by :mod:`jrigid.experiment_parameters`
(numbers must be finite; masses and parameters annotated with
:data:`~jrigid.experiment_parameters.POSITIVE` must be ``> 0``).

Where experiments are found
---------------------------
1. Built in: ``demo`` (:mod:`jrigid.demo`) ships inside the package, so ``jrigid list`` and
   ``jrigid demo`` work in any install.
2. The repository's top-level ``experiments/`` folder, located next to the ``jrigid``
   package (``<repo>/jrigid/..`` holding a ``pyproject.toml`` for jrigid). This is the case
   for an editable install (``pip install -e .``) and for running from a checkout, from any
   working directory. A wheel install does not carry ``experiments/``; point to a checkout
   with the environment variable below.
3. Every folder listed in the environment variable ``JRIGID_EXPERIMENTS``
   (``os.pathsep``-separated).

In each folder every ``*.py`` file not starting with ``_`` that defines a top-level
``main`` is an experiment named after the file. Discovery reads the files with :mod:`ast`
and imports nothing, so ``jrigid list`` is instant. ``run`` imports the module as a
submodule of a package named after the folder (``experiments.NAME`` for the repository), so
experiments may share code through ``from experiments import _common`` or relative imports.
The first definition of a name wins (built-ins, then the repository, then the variable).
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import json
import os
import sys
import time
import types
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from jrigid.experiment_parameters import (  # the parameter checks, also importable from here
    POSITIVE,  # noqa: F401
    ParameterError,  # noqa: F401
    convert,  # noqa: F401
    describe_parameters,  # noqa: F401
    parameters,  # noqa: F401
    parse_params,
    positive_parameters,  # noqa: F401
    split_pairs,  # noqa: F401
)

__all__ = [
    "Experiment",
    "ExperimentError",
    "experiment_dirs",
    "discover",
    "get",
    "run",
    "BUILTIN",
]

#: Experiments shipped inside the package: name -> module.
BUILTIN: dict[str, str] = {"demo": "jrigid.demo"}

ENV_VAR = "JRIGID_EXPERIMENTS"


class ExperimentError(LookupError):
    """Unknown experiment name, or an experiment module without a usable ``main``."""


@dataclass(frozen=True)
class Experiment:
    """One runnable experiment.

    Attributes:
        name: the name used on the command line.
        summary: one-line description (first line of the module docstring).
        module: importable module name for built-ins, else ``None``.
        path: source file for folder experiments, else ``None``.
    """

    name: str
    summary: str
    module: str | None = None
    path: Path | None = None
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def load(self) -> types.ModuleType:
        """Import the experiment's module (once) and return it."""
        if "module" not in self._cache:
            if self.module is not None:
                mod = importlib.import_module(self.module)
            else:
                mod = _import_from_folder(self.path)
            if not callable(getattr(mod, "main", None)):
                raise ExperimentError(f"experiment {self.name!r} ({mod.__name__}) has no main()")
            self._cache["module"] = mod
        return self._cache["module"]

    @property
    def main(self) -> Callable[..., Any]:
        """The experiment's ``main`` function."""
        return self.load().main


# --------------------------------------------------------------------------- discovery


def _repo_experiments_dir() -> Path | None:
    root = Path(__file__).resolve().parent.parent
    pyproject = root / "pyproject.toml"
    folder = root / "experiments"
    if folder.is_dir() and pyproject.is_file():
        try:
            if 'name = "jrigid"' in pyproject.read_text():
                return folder
        except OSError:
            return None
    return None


def experiment_dirs() -> list[Path]:
    """Folders searched: the repository's ``experiments/``, then ``$JRIGID_EXPERIMENTS``."""
    dirs: list[Path] = []
    repo = _repo_experiments_dir()
    if repo is not None:
        dirs.append(repo)
    for entry in os.environ.get(ENV_VAR, "").split(os.pathsep):
        if entry.strip():
            p = Path(entry).expanduser().resolve()
            if p.is_dir() and p not in dirs:
                dirs.append(p)
    return dirs


def _first_line(doc: str | None) -> str:
    if not doc:
        return "(no description)"
    return doc.strip().splitlines()[0].strip()


def _scan_file(path: Path) -> str | None:
    """The summary line if ``path`` defines a top-level ``main``, else ``None``."""
    try:
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    except (OSError, SyntaxError, UnicodeDecodeError):
        return None
    has_main = any(
        isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.name == "main"
        for node in tree.body
    )
    return _first_line(ast.get_docstring(tree)) if has_main else None


def _builtin_summary(module: str) -> str:
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        return "(not available)"
    return _scan_file(Path(spec.origin)) or "(no main)"


def discover() -> dict[str, Experiment]:
    """All experiments by name, in listing order (built-ins first, then each folder sorted)."""
    found: dict[str, Experiment] = {}
    for name, module in BUILTIN.items():
        found[name] = Experiment(name, _builtin_summary(module), module=module)
    for folder in experiment_dirs():
        for path in sorted(folder.glob("*.py")):
            name = path.stem
            if name.startswith("_") or name in found or not name.isidentifier():
                continue
            summary = _scan_file(path)
            if summary is not None:
                found[name] = Experiment(name, summary, path=path)
    return found


def get(name: str) -> Experiment:
    """The experiment called ``name``; ``ExperimentError`` listing the valid names otherwise."""
    found = discover()
    if name not in found:
        valid = ", ".join(found) or "(none found)"
        raise ExperimentError(f"unknown experiment {name!r}; valid names: {valid}, or 'all'")
    return found[name]


def _import_from_folder(path: Path) -> types.ModuleType:
    """Import ``path`` as ``<package>.<stem>`` with ``<package>`` bound to its folder."""
    folder = path.resolve().parent
    pkg = folder.name if folder.name.isidentifier() else "jrigid_experiments"
    existing = sys.modules.get(pkg)
    paths = [str(Path(p).resolve()) for p in getattr(existing, "__path__", [])]
    if existing is not None and str(folder) not in paths:
        pkg = f"_jrigid_experiments_{abs(hash(str(folder))):x}"
        existing = sys.modules.get(pkg)
    if existing is None:
        init = folder / "__init__.py"
        if init.is_file():
            spec = importlib.util.spec_from_file_location(
                pkg, init, submodule_search_locations=[str(folder)]
            )
            module = importlib.util.module_from_spec(spec)
            sys.modules[pkg] = module
            spec.loader.exec_module(module)
        else:
            module = types.ModuleType(pkg)
            module.__path__ = [str(folder)]
            module.__file__ = None
            sys.modules[pkg] = module
    return importlib.import_module(f"{pkg}.{path.stem}")


# --------------------------------------------------------------------------- running


def _fallback_outputs(out_dir: Path, name: str, result: Any) -> None:
    from jrigid.report import Report

    if not isinstance(result, Mapping):
        return
    rep = Report(out_dir, title=name)
    if not (out_dir / "numbers.json").exists():
        rep.numbers(result)
    if not (out_dir / rep.summary_name).exists():
        flat = [(k, v) for k, v in result.items() if not isinstance(v, Mapping | list | tuple)]
        if flat:
            rep.table(flat, headers=("quantity", "value"))
        rep.write_summary()


def run(
    name: str,
    out_dir: str | os.PathLike | None = None,
    *,
    quick: bool = False,
    params: Mapping[str, Any] | None = None,
) -> Any:
    """Run one experiment and return what its ``main`` returns.

    Args:
        name: experiment name (see :func:`discover`).
        out_dir: results folder; default ``results/<name>`` under the working directory.
        quick: pass ``quick=True`` (a short run).
        params: parameter name -> text or value, converted by :func:`parse_params`.

    Also writes ``run.json`` into ``out_dir``: name, parameters, quick, and ``status``,
    ``"running"`` from the start (a folder whose run was interrupted says so), then
    ``"finished"`` with the wall time, or ``"failed"`` with the error.

    An experiment refuses its parameters by raising ``ParameterError``, or any
    ``ValueError`` before it has written a file (its checks of the values, the library's
    included), when ``params`` were given. Then the folder is left as it was (an earlier
    run's ``run.json`` is put back) and the error is raised as a ``ParameterError``
    (a ``ValueError``). A ``ValueError`` after the experiment wrote its first file is a
    failure of the run, as any other exception.

    Raises:
        ExperimentError: no experiment ``name``.
        ParameterError: a parameter ``main`` does not take or refuses.
    """
    exp = get(name)
    typed = parse_params(name, exp.main, params or {})
    out = Path(out_dir) if out_dir is not None else Path("results") / name
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    sig = inspect.signature(exp.main).parameters
    takes_quick = "quick" in sig or any(p.kind is p.VAR_KEYWORD for p in sig.values())
    if quick and not takes_quick:
        print(f"note: experiment {name!r} has no quick mode; running it in full", file=sys.stderr)
    kwargs = {"quick": quick} if takes_quick else {}
    from jrigid import __version__
    from jrigid.report import to_jsonable

    meta = {"experiment": name, "params": to_jsonable(typed), "quick": quick,
            "jrigid_version": __version__}

    def record(**status):
        (out / "run.json").write_text(json.dumps({**meta, **status}, indent=2) + "\n")

    previous = (out / "run.json").read_bytes() if (out / "run.json").is_file() else None
    before = _outputs(out)
    record(status="running")
    start = time.perf_counter()
    try:
        result = exp.main(out, **kwargs, **typed)
        seconds = time.perf_counter() - start
        _fallback_outputs(out, name, result)
    except ValueError as e:
        # refused before it ran (nothing written): the folder stays as it was
        if isinstance(e, ParameterError) or (typed and before is not None
                                              and _outputs(out) == before):
            _restore(out, previous, created)
            if isinstance(e, ParameterError):
                raise
            raise ParameterError(str(e)) from e
        record(status="failed", error=f"{type(e).__name__}: {e}")
        raise
    except BaseException as e:  # Ctrl-C included: the folder must not look finished
        record(status="failed", error=f"{type(e).__name__}: {e}")
        raise
    record(status="finished", seconds=round(seconds, 3))
    return result


_MAX_SCANNED = 10_000  # entries of a results folder _outputs looks at, at most


def _outputs(out: Path) -> dict[str, int] | None:
    """The files below ``out`` (``run.json`` aside) with their modification times (ns);
    ``None`` (not known) for a folder of more than ``_MAX_SCANNED`` entries."""
    found = {}
    for i, path in enumerate(out.rglob("*")):
        if i >= _MAX_SCANNED:
            return None
        try:
            if path.name != "run.json" and path.is_file():
                found[str(path)] = path.stat().st_mtime_ns
        except OSError:  # removed meanwhile
            pass
    return found


def _restore(out: Path, previous: bytes | None, created: bool) -> None:
    """Put back ``out``'s earlier ``run.json`` (or remove the new one, and ``out`` itself
    if this run created it and nothing else is in it)."""
    if previous is not None:
        (out / "run.json").write_bytes(previous)
        return
    (out / "run.json").unlink(missing_ok=True)
    if created:
        try:
            out.rmdir()
        except OSError:  # the experiment wrote something
            pass
