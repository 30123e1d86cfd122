"""The chapter map: each equation of chapter 17, where it is implemented and checked.

Built at every site build from what the code says, so it cannot go stale: the functions
and classes whose docstrings cite an equation (``(17.24)``, ``eq. 17.26``,
``eqs. 17.45–17.46``), the experiments and the tests that cite it. Only the one-line
description of each equation is written here. "Problem 17.3", "Table 17.1" and the like
name exercises, not equations, and are not counted.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

EQUATIONS = {
    1: "2D rotation of a point about the origin",
    2: "2D scaling",
    3: "2D translation, an addition",
    4: "homogeneous 2D affine matrix",
    5: "homogeneous 2D translation",
    6: "a 2D skew (shear)",
    7: "block form `[A dᵀ; 0 1]`",
    8: "rotation about z, `R_z` (passive)",
    9: "homogeneous 3D affine transform",
    10: "ZXZ Euler-angle matrix `R_z(ψ) R_x(θ) R_z(φ)` (passive)",
    11: "parallel part `v∥ = (v·r̂) r̂`",
    12: "perpendicular part `v⊥ = v − v∥`",
    13: "`w = r̂ × v`",
    14: "rotation of `v⊥` in its plane",
    15: "`R(v) = R(v⊥) + v∥`",
    16: "Rodrigues' formula",
    17: "Rodrigues' matrix",
    18: "2D rotation as a complex product",
    19: "quaternion `(q0, q1, q2, q3)`",
    20: "Hamilton's rules `i² = j² = k² = ijk = −1`",
    21: "conjugate `q*`",
    22: "products of `i, j, k`",
    23: "scalar and vector parts `(q0, q)`",
    24: "Hamilton product",
    25: "unit quaternion from axis and angle",
    26: "rotation `a' = q a q*`",
    27: "axis and angle from a quaternion",
    28: "rotation matrix from a quaternion (passive)",
    29: "`dP/dt = F`, `dL/dt = N`",
    30: "`P = M V`, `L = I ω`",
    31: "moments of inertia as volume integrals",
    32: "frame change `I_space = M I_body M⁻¹`",
    33: "time derivative in the space and body frames",
    34: "Euler's equation `dL/dt + ω × (I ω) = N`",
    35: "Euler's equations in components",
    36: "body ω from Euler-angle rates",
    37: "`r(t) = q r0 q*`",
    38: "derivative of `r(t)`",
    39: "`ṙ = q̇ q* r − r q̇ q*`",
    40: "`ṙ = 2 u × r`",
    41: "`ω = 2 u`",
    42: "`ω = 2 W q̇`",
    43: "the matrix `W`",
    44: "`q̇ = ½ Wᵀ ω`",
    45: "leapfrog: half step of `L`",
    46: "leapfrog: step of `q`",
    47: "precession of ω about a symmetric body's axis",
    48: "`d(q* q̇)/dt`",
    49: "`q̈ = q (d(q* q̇)/dt − q̇* q̇)`",
    50: "quaternion acceleration `q̈ = ½ Wᵀ (ω̇, −2 Σ q̇²)`",
    51: "fast and slow steady precession of a gyroscope",
}

# "(17.24)", "eq. 17.26", "eqs. 17.45–17.46", "17.1-17.7", "(17.51a)"; not "Problem 17.3".
_REF = re.compile(
    r"(?<![\w.])(?<!Problem )(?<!Project )(?<!Exercise )(?<!Table )(?<!Section )(?<!Figure )"
    r"17\.(\d{1,2})[a-c]?(?:\s*[–-]\s*(?:17\.)?(\d{1,2})[a-c]?)?(?![\d.]\d)"
)


def equations_in(text: str) -> set[int]:
    """Equation numbers cited in ``text`` (ranges expanded)."""
    found = set()
    for first, last in _REF.findall(text):
        a = int(first)
        b = int(last) if last else a
        if not (1 <= a <= 51) or not (a <= b <= 51):
            b = a
        found.update(n for n in range(a, b + 1) if 1 <= n <= 51)
    return found


def _objects(root: Path) -> dict[int, list[str]]:
    """Equation -> documented jrigid objects citing it (functions, classes, methods)."""
    import griffe

    pkg = griffe.load("jrigid", search_paths=[str(root)], allow_inspection=False)
    cited: dict[int, set[str]] = defaultdict(set)
    modules: dict[int, set[str]] = defaultdict(set)

    def public(path: str) -> bool:
        return not any(p.startswith("_") for p in path.split("."))

    def walk(obj) -> None:
        for member in obj.members.values():
            if member.is_alias or not public(member.path):
                continue
            if member.docstring is not None:
                for n in equations_in(member.docstring.value):
                    (modules if member.is_module else cited)[n].add(member.path)
            if member.is_module or member.is_class:
                walk(member)

    walk(pkg)
    return {n: sorted(cited[n]) or sorted(modules[n]) for n in EQUATIONS}


def _checks(root: Path) -> dict[int, list[str]]:
    """Equation -> experiments and test functions citing it."""
    out: dict[int, set[str]] = defaultdict(set)
    for path in sorted((root / "experiments").glob("*.py")):
        for n in equations_in(path.read_text(encoding="utf-8")):
            out[n].add(f"experiment `{path.stem}`")
    for path in sorted((root / "tests").glob("test_*.py")):
        if path.name == "test_docs.py":  # tests of this page's parser, not of the chapter
            continue
        source = path.read_text(encoding="utf-8")
        lines = source.splitlines()
        functions = [
            node
            for node in ast.walk(ast.parse(source))
            if isinstance(node, ast.FunctionDef) and node.name.startswith("test")
        ]
        for node in functions:
            body = "\n".join(lines[node.lineno - 1 : node.end_lineno])
            for n in equations_in(body):
                out[n].add(f"`{path.name}::{node.name}`")
    return {n: sorted(out[n]) for n in EQUATIONS}


_EXERCISE = re.compile(r"\b(Problem|Exercise|Project|Table) 17\.(\d+)")


def _experiments(root: Path) -> list[str]:
    """One table row per experiment: name, what it claims (its docstring's first line), and
    the problems, exercises and equations of the chapter it cites."""
    rows = []
    for path in sorted((root / "experiments").glob("*.py")):
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
        summary = doc.strip().split("\n\n")[0].replace("\n", " ")
        cited = sorted({f"{kind} 17.{n}" for kind, n in _EXERCISE.findall(doc)})
        cited += [f"({e})" for e in _ranges(sorted(equations_in(doc)))]
        summary = summary.replace("|", "\\|")
        rows.append(f"| `{path.stem}` | {summary} | {', '.join(cited) or '—'} |")
    return rows


def _ranges(numbers: list[int]) -> list[str]:
    out: list[str] = []
    for n in numbers:
        if out and out[-1][1] == n - 1:
            out[-1] = (out[-1][0], n)
        else:
            out.append((n, n))
    return [f"17.{a}" if a == b else f"17.{a}–17.{b}" for a, b in out]


def page(root: Path) -> str:
    """The markdown of the chapter map."""
    objects = _objects(root)
    checks = _checks(root)
    rows = []
    for n, what in EQUATIONS.items():
        impl = ", ".join(f"[`{p.removeprefix('jrigid.')}`][{p}]" for p in objects[n]) or "—"
        check = ", ".join(checks[n]) or "—"
        rows.append(f"| 17.{n} | {what} | {impl} | {check} |")
    missing = [f"17.{n}" for n in EQUATIONS if not objects[n]]
    return "\n".join(
        [
            "# The chapter map",
            "",
            "Each equation of the textbook chapter (*Visualization and Rigid Body Dynamics*, "
            "chapter 17), the jrigid functions and classes whose docstrings cite it, and the "
            "experiments (`jrigid run NAME`) and tests that check it. This page is generated "
            "at every build from the docstrings and sources, so it follows the code. Where a "
            "module rather than a function cites an equation, the module is listed. Conventions "
            "differ from the chapter's in one place: jrigid's rotation matrices are active; "
            "the chapter's (17.8), (17.10) and (17.28) are the passive transposes, reproduced "
            "by the `passive_*` functions.",
            "",
            "| eq. | what | implemented by | checked by |",
            "| --- | --- | --- | --- |",
            *rows,
            "",
            f"No function cites: {', '.join(missing) or 'none'} (derivation steps or "
            "results the chapter states without an algorithm).",
            "",
            "## The experiments",
            "",
            "Each experiment (`jrigid list`; `jrigid run NAME [--quick]`) writes figures, "
            "`numbers.json` and `report.md` to `results/NAME/`, and a test runs its quick mode "
            "and asserts its claim. What each checks, from its docstring:",
            "",
            "| experiment | what it shows | chapter |",
            "| --- | --- | --- |",
            *_experiments(root),
            "",
        ]
    )
