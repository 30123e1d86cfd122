"""The parameters of an experiment's ``main``: read from its signature, converted, checked.

``jrigid run NAME key=value`` passes each value as text; :func:`parse_params` converts
it to the type of the parameter's default (:func:`convert`) and checks it before the
run: numbers must be finite (``nan``, ``inf`` and ``1e400`` are refused), and a
parameter that must be positive is refused unless it is ``> 0`` (every number in it, for
a list). A parameter must be positive when it is a mass (named ``mass``, ``mass_*`` or
``*_mass``) or when the experiment declares it so in its annotation with
:data:`POSITIVE`::

    from typing import Annotated
    from jrigid.experiment_parameters import POSITIVE

    def main(out_dir, quick=False, *, radius: Annotated[float, POSITIVE] = 1.0): ...
"""

from __future__ import annotations

import ast
import inspect
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

__all__ = [
    "POSITIVE",
    "ParameterError",
    "convert",
    "describe_parameters",
    "parameters",
    "parse_params",
    "positive_parameters",
    "split_pairs",
]


class ParameterError(ValueError):
    """A parameter the experiment does not accept: unknown, not convertible, or a value
    outside its range.

    Raised by :func:`parse_params`, and by an experiment's ``main`` for a value it
    refuses before it runs (a ``ValueError``, so Python callers catch it as one).
    ``jrigid run`` reports it as a usage error (exit code 2), and leaves the results
    folder of an earlier run as it was; so it does a ``ValueError`` raised before the
    experiment wrote its first file (``jrigid.registry.run``). Any other exception is the
    experiment's failure (a traceback, exit code 1).
    """


class _Positive:
    """The marker behind :data:`POSITIVE`."""

    def __repr__(self) -> str:
        return "POSITIVE"


POSITIVE = _Positive()
"""Annotation marker of a parameter that must be ``> 0``: ``Annotated[float, POSITIVE]``."""


_RESERVED = {"out_dir": "--out", "quick": "--quick"}  # name -> the command-line option
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
    """Split ``["a=1", "b=x"]`` into ``{"a": "1", "b": "x"}``; ``ParameterError`` if malformed
    or if a key is given twice."""
    out: dict[str, str] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or not key.isidentifier():
            raise ParameterError(f"parameters are written key=value, got {pair!r}")
        if key in out:
            raise ParameterError(f"{key} is given twice ({key}={out[key]} and {pair})")
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
                f"{key!r} is set with {_RESERVED[key]}, not as a parameter of {name}"
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
