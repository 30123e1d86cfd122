"""The experiment registry behind ``jrigid list`` and ``jrigid run``.

An experiment is a module with a docstring (its first line is the one-line description
shown by ``jrigid list``) and a function::

    def main(out_dir, quick=False, *, name1=default1, name2=default2, ...): ...

``out_dir`` is the results folder (a :class:`pathlib.Path`, created before the call),
``quick`` asks for a short run (used by the tests; optional: an experiment without it
always runs in full), and the keyword parameters with their
defaults are the experiment's parameters: ``jrigid run NAME key=value`` converts each value
to the type of the default (see :func:`parse_params`). ``main`` writes its figures, numbers
and summary with :class:`jrigid.report.Report`; if it returns a mapping and wrote no
``numbers.json`` / ``report.md``, the runner writes them from that mapping.

Values are checked before the run: numbers must be finite (``nan``, ``inf`` and
``1e400`` are refused), and a parameter that must be positive is refused unless it is
``> 0`` (every number in it, for a list). A parameter must be positive when it is a mass
(named ``mass``, ``mass_*`` or ``*_mass``) or when the experiment declares it so in its
annotation with :data:`POSITIVE`::

    from typing import Annotated
    from jrigid.registry import POSITIVE

    def main(out_dir, quick=False, *, radius: Annotated[float, POSITIVE] = 1.0): ...

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
import math
import os
import sys
import time
import types
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = [
    "Experiment",
    "ExperimentError",
    "ParameterError",
    "POSITIVE",
    "experiment_dirs",
    "discover",
    "get",
    "parameters",
    "parse_params",
    "positive_parameters",
    "run",
    "BUILTIN",
]

#: Experiments shipped inside the package: name -> module.
BUILTIN: dict[str, str] = {"demo": "jrigid.demo"}

ENV_VAR = "JRIGID_EXPERIMENTS"


class ExperimentError(LookupError):
    """Unknown experiment name, or an experiment module without a usable ``main``."""


class ParameterError(ValueError):
    """A parameter given on the command line that the experiment does not accept."""


class _Positive:
    """The marker behind :data:`POSITIVE`."""

    def __repr__(self) -> str:
        return "POSITIVE"


POSITIVE = _Positive()
"""Annotation marker of a parameter that must be ``> 0``: ``Annotated[float, POSITIVE]``."""


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


# --------------------------------------------------------------------------- parameters

_RESERVED = ("out_dir", "quick")
_TRUE = {"1", "true", "yes", "on", "y", "t"}
_FALSE = {"0", "false", "no", "off", "n", "f"}


def parameters(main: Callable[..., Any]) -> tuple[dict[str, Any], bool]:
    """The tunable parameters of an experiment's ``main``.

    Returns:
        ``(defaults, open_ended)``: ``defaults`` maps each keyword parameter (other than
        ``out_dir`` and ``quick``) to its default (``inspect.Parameter.empty`` if none);
        ``open_ended`` is True when ``main`` also takes ``**kwargs``.
    """
    sig = inspect.signature(main)
    defaults: dict[str, Any] = {}
    open_ended = False
    for p in sig.parameters.values():
        if p.kind is inspect.Parameter.VAR_KEYWORD:
            open_ended = True
        elif p.name in _RESERVED or p.kind is inspect.Parameter.VAR_POSITIONAL:
            continue
        elif p.kind is not inspect.Parameter.POSITIONAL_ONLY:
            defaults[p.name] = p.default
    return defaults, open_ended


def _is_mass(name: str) -> bool:
    return name == "mass" or name.startswith("mass_") or name.endswith("_mass")


def positive_parameters(main: Callable[..., Any]) -> set[str]:
    """Names of the parameters of ``main`` that must be ``> 0``.

    A mass (a parameter named ``mass``, ``mass_*`` or ``*_mass``) and any parameter whose
    annotation is ``Annotated[..., POSITIVE]``. String annotations (``from __future__
    import annotations``) are evaluated in the experiment's module; if that fails, only
    the names count.
    """
    try:
        sig = inspect.signature(main, eval_str=True)
    except Exception:  # an annotation that cannot be evaluated: names only
        sig = inspect.signature(main)
    out = set()
    for p in sig.parameters.values():
        if p.name in _RESERVED or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        declared = any(m is POSITIVE for m in getattr(p.annotation, "__metadata__", ()))
        if declared or _is_mass(p.name):
            out.add(p.name)
    return out


def _type_name(default: Any) -> str:
    if default is inspect.Parameter.empty or default is None:
        return "value"
    if isinstance(default, tuple | list):
        inner = {_type_name(d) for d in default}
        return f"list of {inner.pop()}" if len(inner) == 1 else "list"
    return type(default).__name__


def describe_parameters(main: Callable[..., Any]) -> str:
    """``name=default (type)`` for each parameter, comma-separated, for help and errors."""
    defaults, open_ended = parameters(main)
    positive = positive_parameters(main)
    items = [
        f"{k}={'(required)' if v is inspect.Parameter.empty else v!r} "
        f"({_type_name(v)}{', > 0' if k in positive else ''})"
        for k, v in defaults.items()
    ]
    if open_ended:
        items.append("any other key=value")
    return ", ".join(items) if items else "(none)"


def _literal(text: str) -> Any:
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def _numbers(value: Any):
    """Every int or float in ``value`` (recursing into lists, tuples and dict values)."""
    if isinstance(value, bool):
        return
    if isinstance(value, int | float):
        yield value
    elif isinstance(value, list | tuple):
        for v in value:
            yield from _numbers(v)
    elif isinstance(value, dict):
        for v in value.values():
            yield from _numbers(v)


def convert(text: str, default: Any) -> Any:
    """Convert command-line ``text`` to the type of ``default``.

    bool: ``true/false/yes/no/on/off/1/0``; int, float, str: the constructor (an int
    default also accepts an integral float such as ``1e3``); tuple/list: comma-separated
    items or a Python/JSON literal, each item converted like the default's first item;
    ``None`` or no default: a Python literal if ``text`` is one, else the string.
    Numbers must be finite: ``nan``, ``inf`` and values that overflow (``1e400``) are
    refused.

    Raises:
        ValueError: if the text does not convert, or gives a non-finite number.
    """
    if not isinstance(text, str):
        return text
    value = _convert(text, default)
    if any(not math.isfinite(x) for x in _numbers(value)):
        raise ValueError(f"expected finite numbers, got {text!r}")
    return value


def _convert(text: str, default: Any) -> Any:
    if default is inspect.Parameter.empty or default is None:
        return _literal(text)
    if isinstance(default, bool):
        low = text.strip().lower()
        if low in _TRUE:
            return True
        if low in _FALSE:
            return False
        raise ValueError(f"expected a bool (true/false), got {text!r}")
    if isinstance(default, int):
        try:
            return int(text)
        except ValueError:
            f = float(text)
            if f.is_integer():
                return int(f)
            raise ValueError(f"expected an int, got {text!r}") from None
    if isinstance(default, float):
        return float(text)
    if isinstance(default, str):
        return text
    if isinstance(default, tuple | list):
        stripped = text.strip()
        if stripped[:1] in "([":
            items = _literal(stripped)
            if not isinstance(items, tuple | list):
                raise ValueError(f"expected a list, got {text!r}")
        else:
            items = [s for s in stripped.split(",") if s.strip()]
        proto = default[0] if len(default) else None
        out = [convert(str(i) if not isinstance(i, str) else i, proto) for i in items]
        if (
            len(default)
            and len(out) != len(default)
            and all(isinstance(d, int | float) for d in default)
        ):
            raise ValueError(f"expected {len(default)} numbers, got {len(out)} in {text!r}")
        return type(default)(out)
    value = _literal(text)
    if not isinstance(value, type(default)):
        raise ValueError(f"expected a {type(default).__name__}, got {text!r}")
    return value


def split_pairs(pairs: Sequence[str]) -> dict[str, str]:
    """Split ``["a=1", "b=x"]`` into ``{"a": "1", "b": "x"}``; ``ParameterError`` if malformed."""
    out: dict[str, str] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or not key.isidentifier():
            raise ParameterError(f"parameters are written key=value, got {pair!r}")
        out[key] = value
    return out


def parse_params(name: str, main: Callable[..., Any], raw: Mapping[str, Any]) -> dict[str, Any]:
    """Check and convert raw parameters for ``main``.

    Args:
        name: experiment name (for messages).
        main: the experiment's ``main``.
        raw: parameter name -> text (or an already typed value).

    Returns:
        name -> converted value.

    Raises:
        ParameterError: an unknown name, a value that does not convert or is not finite,
            or a parameter that must be positive (see :func:`positive_parameters`) that is
            not; the message lists the valid parameters with their defaults and types.
    """
    defaults, open_ended = parameters(main)
    positive = positive_parameters(main)
    typed: dict[str, Any] = {}
    for key, text in raw.items():
        if key in _RESERVED:
            raise ParameterError(
                f"{key!r} is set with --{key.replace('_', '-')}, not as a parameter of {name}"
            )
        if key not in defaults and not open_ended:
            raise ParameterError(
                f"unknown parameter {key!r} for experiment {name!r}; "
                f"valid parameters: {describe_parameters(main)}"
            )
        default = defaults.get(key, inspect.Parameter.empty)
        try:
            typed[key] = convert(text, default)
            if key in positive and any(not x > 0 for x in _numbers(typed[key])):
                raise ValueError(f"must be > 0, got {text!r}")
        except ValueError as e:
            raise ParameterError(
                f"bad value for parameter {key!r} of experiment {name!r}: {e}; "
                f"valid parameters: {describe_parameters(main)}"
            ) from None
    missing = [k for k, v in defaults.items() if v is inspect.Parameter.empty and k not in typed]
    if missing:
        raise ParameterError(
            f"experiment {name!r} needs parameter(s) {', '.join(missing)}; "
            f"valid parameters: {describe_parameters(main)}"
        )
    return typed


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

    Also writes ``run.json`` (name, parameters, quick, wall time) into ``out_dir``.
    """
    exp = get(name)
    typed = parse_params(name, exp.main, params or {})
    out = Path(out_dir) if out_dir is not None else Path("results") / name
    out.mkdir(parents=True, exist_ok=True)
    sig = inspect.signature(exp.main).parameters
    takes_quick = "quick" in sig or any(p.kind is p.VAR_KEYWORD for p in sig.values())
    if quick and not takes_quick:
        print(f"note: experiment {name!r} has no quick mode; running it in full", file=sys.stderr)
    kwargs = {"quick": quick} if takes_quick else {}
    start = time.perf_counter()
    result = exp.main(out, **kwargs, **typed)
    seconds = time.perf_counter() - start
    _fallback_outputs(out, name, result)
    from jrigid import __version__
    from jrigid.report import to_jsonable

    meta = {
        "experiment": name,
        "params": to_jsonable(typed),
        "quick": quick,
        "seconds": round(seconds, 3),
        "jrigid_version": __version__,
    }
    (out / "run.json").write_text(json.dumps(meta, indent=2) + "\n")
    return result
