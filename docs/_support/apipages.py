"""API pages: one per public top-level module or package of ``jrigid``.

A module is public when no part of its dotted name starts with an underscore. A
package's page has the package docstring, the names it re-exports from private modules
(``jrigid.special`` defines everything in ``_carlson`` and friends), and then each public
submodule in full. Everything is rendered by mkdocstrings from the docstrings.
"""

from __future__ import annotations

from pathlib import Path

# Where each top-level module sits in the layers of the design (README "What is inside").
# A module missing here still gets a page, under "other".
LAYERS = {
    "geometry": ["quaternion", "affine", "inertia", "linalg"],
    "dynamics": ["body", "scene", "state", "initial", "formulations", "invariants"],
    "integration": [
        "integrate",
        "solve",
        "trajectory",
        "closed_form",
        "exact",
        "lagrange_top",
        "special",
        "solvers",
        "leapfrog",
        "contact",
    ],
    "applications": ["fit", "ensemble", "stability"],
    "presentation": ["viz", "cli", "demo", "registry", "report"],
}


def public_modules(root: Path) -> list[str]:
    """Dotted names of every public module and package under ``root/jrigid``, sorted."""
    names = []
    for path in sorted((root / "jrigid").rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if any(p.startswith("_") for p in parts):
            continue
        names.append(".".join(parts))
    return names


def _top_level(root: Path) -> list[str]:
    return [n.split(".", 1)[1] for n in public_modules(root) if n.count(".") == 1]


def _private_exports(root: Path, package: str) -> list[str]:
    """Names in ``package.__all__`` that are defined in one of its private modules."""
    import ast

    init = root / "jrigid" / package / "__init__.py"
    tree = ast.parse(init.read_text(encoding="utf-8"))
    names = []
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module not in (None, "__future__"):
            module = node.module.rsplit(".", 1)[-1]
            if not module.startswith("_"):
                continue
            if [a.name for a in node.names] == ["*"]:
                names += _module_all(root / "jrigid" / package / f"{module}.py")
            else:
                names += [a.asname or a.name for a in node.names]
    return names


def _module_all(path: Path) -> list[str]:
    """The literal ``__all__`` list of the module at ``path``."""
    import ast

    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return list(ast.literal_eval(node.value))
    return []


def _page(root: Path, name: str) -> str:
    path = root / "jrigid" / name
    lines = []
    if not path.is_dir():
        return f"::: jrigid.{name}\n"
    private = _private_exports(root, name)
    lines.append(f"::: jrigid.{name}")
    lines.append("    options:")
    if private:
        lines.append("      members:")
        lines += [f"        - {n}" for n in private]
    else:
        lines.append("      members: false")
    lines.append("")
    for sub in public_modules(root):
        if sub.startswith(f"jrigid.{name}.") and sub.count(".") == 2:
            lines.append(f"::: {sub}")
            lines.append("")
    return "\n".join(lines)


def _index(root: Path) -> str:
    rows = []
    for layer, names in _layers(root):
        for name in names:
            rows.append(f"| {layer} | [`jrigid.{name}`]({name}.md) |")
            layer = ""
    return "\n".join(
        [
            "# API reference",
            "",
            "Generated from the docstrings: argument shapes, the chapter's equation numbers and "
            "the errors raised. Imports point down the layers, never up.",
            "",
            "::: jrigid",
            "    options:",
            "      members: false",
            "      show_root_heading: false",
            "",
            "| layer | module |",
            "| --- | --- |",
            *rows,
            "",
        ]
    )


def _layers(root: Path) -> list[tuple[str, list[str]]]:
    present = set(_top_level(root))
    out = [(layer, [n for n in names if n in present]) for layer, names in LAYERS.items()]
    known = {n for names in LAYERS.values() for n in names}
    other = sorted(present - known)
    if other:
        out.append(("other", other))
    return [(layer, names) for layer, names in out if names]


def pages(root: Path) -> dict[str, str]:
    """``{"api/NAME.md": markdown}`` for the index and every top-level module."""
    out = {"api/index.md": _index(root)}
    for name in _top_level(root):
        out[f"api/{name}.md"] = _page(root, name)
    return out


def nav(root: Path) -> list:
    """The navigation entries of the API section, by layer."""
    entries: list = [{"Overview": "api/index.md"}]
    for layer, names in _layers(root):
        entries.append({layer.capitalize(): [{f"jrigid.{n}": f"api/{n}.md"} for n in names]})
    return entries
