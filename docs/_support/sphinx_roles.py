"""A griffe extension: Sphinx roles in jrigid's docstrings become mkdocstrings links.

jrigid's docstrings cross-reference with Sphinx roles (``:func:`simulate```,
``:class:`~jrigid.trajectory.Result```, ``:func:`title <target>```, ``:mod:`jrigid.fit```),
which the code reads well and markdown does not know. After griffe has loaded the
package, every role is resolved the way Python would look the name up from where the
docstring is (the object, then the scopes around it, then the package) and rewritten:

- a jrigid object: a cross-reference ``[`name`][canonical.path]`` to the page that
  documents it (through aliases to the object's own module; a name defined in a
  private module links to the public package that exports it);
- a name from another library (``jax.jit``, ``diffrax.diffeqsolve``): inline code;
- a private name (``_helper``) or a builtin (``ValueError``): inline code;
- a bare name found nowhere: a warning, which fails ``mkdocs build --strict``.

An attribute without a docstring of its own (an enum member, a dataclass field, a
module constant) is not rendered separately, so its link goes to the class or module
that documents it.

It also splits the ``a, b: description`` lines of ``Args:`` sections, which griffe's
Google-style parser reads as one parameter named ``"a, b"``, into one line per name with
the same description.
"""

from __future__ import annotations

import builtins
import logging
import re
from typing import Any

import griffe

_log = logging.getLogger("mkdocs.plugins.jrigid.sphinx_roles")

ROLE = re.compile(
    r":(?:py:)?(?:func|class|mod|meth|attr|data|exc|obj|const):`(?P<tilde>~?)"
    r"(?:(?P<title>[^`<>]+?)\s*<(?P<inner>[^`<>\s]+?)>|(?P<target>[^`<>\s]+?))(?:\(\))?`"
)


_EXTERNAL = object()  # a name that leads out of jrigid


def _lookup(scope: griffe.Object, dotted: str) -> Any:
    """The object at ``dotted`` from ``scope``; None if missing, _EXTERNAL if outside."""
    obj: Any = scope
    for part in dotted.split("."):
        if isinstance(obj, griffe.Alias):
            obj = _final(obj)
            if obj is None:
                return _EXTERNAL
        if part not in obj.members:
            return None
        obj = obj.members[part]
    return obj


def _final(obj: Any) -> Any | None:
    """The object an alias points to, or None when it leaves jrigid."""
    while isinstance(obj, griffe.Alias):
        try:
            obj = obj.final_target
        except Exception:
            return None
    return obj


def _public_path(obj: griffe.Object, exported_as: str | None = None) -> str | None:
    """The path under which ``obj`` is documented, or None if it is not documented."""
    path = obj.path
    if not path.startswith("jrigid"):
        return None
    parts = path.split(".")
    private = [i for i, p in enumerate(parts) if p.startswith("_") and not p.startswith("__")]
    if not private:
        return path
    first = private[0]
    if first == len(parts) - 1:
        return None  # a private name
    # Defined in a private module: documented where the nearest public package exports it.
    package = ".".join(parts[:first])
    rest = parts[first + 1 :]
    return f"{package}.{'.'.join(rest)}"


def _documented(found: Any) -> str | None | bool:
    if found is _EXTERNAL:
        return None
    if found is None:
        return False
    final = _final(found)
    if final is None:
        return None
    if final.is_attribute and final.docstring is None and final.parent is not None:
        final = final.parent  # documented by its class or module
    return _public_path(final) or False


def _resolve(obj: griffe.Object, target: str) -> str | None | bool:
    """Canonical documented path; None for something outside jrigid; False if unknown."""
    head = target.split(".")[0]
    if head.startswith("_") or hasattr(builtins, head):
        return None
    scopes = []
    scope: Any = obj
    while scope is not None:
        scopes.append(scope)
        scope = scope.parent
    for scope in scopes:
        if head in scope.members:
            return _documented(_lookup(scope, target))
    if head == "jrigid":
        root = scopes[-1]
        return _documented(_lookup(root, target.split(".", 1)[1]) if "." in target else root)
    return None if "." in target else False


class SphinxRoles(griffe.Extension):
    """Rewrite Sphinx roles in every docstring of the loaded package."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        self._walk(pkg, seen=set())

    def _walk(self, obj: Any, seen: set) -> None:
        if obj.path in seen:
            return
        seen.add(obj.path)
        if obj.docstring is not None:
            obj.docstring.value = _split_names(self._rewrite(obj, obj.docstring.value))
        for member in obj.members.values():
            if not isinstance(member, griffe.Alias):
                self._walk(member, seen)

    def _rewrite(self, obj: griffe.Object, text: str) -> str:
        def replace(match: re.Match) -> str:
            target = match["target"] or match["inner"]
            shown = target.rsplit(".", 1)[-1] if match["tilde"] else target
            if match["title"]:
                shown = match["title"]
            resolved = _resolve(obj, target)
            if resolved is None:
                return f"`{shown}`"
            if resolved is False:
                _log.warning("%s: cannot resolve the reference %s", obj.path, match[0])
                return f"`{shown}`"
            return f"[`{shown}`][{resolved}]"

        return ROLE.sub(replace, text)


_SECTION = re.compile(r"^(\s*)(Args|Arguments|Parameters|Keyword Args|Other Parameters):\s*$")
_MULTI = re.compile(r"^(\s+)(\*{0,2}\w+(?:\s*,\s*\*{0,2}\w+)+)(\s*(?:\([^)]*\))?:\s.*)$")


def _split_names(text: str) -> str:
    """``a, b: text`` (plus its indented continuation) -> ``a: text`` and ``b: text``."""
    lines = text.split("\n")
    out: list[str] = []
    in_args = False
    section_indent = ""
    i = 0
    while i < len(lines):
        line = lines[i]
        header = _SECTION.match(line)
        if header:
            in_args, section_indent = True, header[1]
            out.append(line)
            i += 1
            continue
        if in_args and line.strip() and not line.startswith(section_indent + " "):
            in_args = False
        match = _MULTI.match(line) if in_args else None
        if match is None:
            out.append(line)
            i += 1
            continue
        indent, names, rest = match[1], match[2], match[3]
        block = [rest]
        i += 1
        while i < len(lines) and (not lines[i].strip() or lines[i].startswith(indent + " ")):
            last = i + 1 >= len(lines) or not lines[i + 1].startswith(indent + " ")
            if not lines[i].strip() and last:
                break
            block.append("\n" + lines[i])
            i += 1
        for name in (n.strip() for n in names.split(",")):
            out.append(indent + name + "".join(block))
    return "\n".join(out)
