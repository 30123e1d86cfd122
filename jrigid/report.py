"""Result folders for experiments: figures, a JSON of the numbers, a markdown summary.

Every experiment run by ``jrigid run NAME`` (and ``jrigid demo``) writes into one folder::

    results/NAME/
        report.md        short markdown summary with the images inline
        numbers.json     the measured numbers, machine readable
        *.png, *.gif     figures and animations

:class:`Report` collects these as an experiment goes and writes them. It does not import
matplotlib: :meth:`Report.figure` only calls the figure's own ``savefig``, so this module
stays importable without the plotting stack.

Example::

    rep = Report(out_dir, title="Hello")
    rep.figure("omega", fig, caption="body angular velocity")
    rep.numbers({"period": 1.23, "period_theory": 1.2301})
    rep.table([("period", 1.23, 1.2301)], headers=("quantity", "measured", "theory"))
    path = rep.write_summary("One paragraph on what was found.")
"""

from __future__ import annotations

import json
import math
import numbers
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import quote

from jrigid._files import write_atomic

__all__ = ["IMAGE_SUFFIXES", "Report", "to_jsonable", "format_number"]

#: File name endings :meth:`Report.figure` keeps (matplotlib's formats); any other name
#: gets ``.png`` added (so ``"tilt_0.5deg"`` is ``tilt_0.5deg.png``).
IMAGE_SUFFIXES = frozenset({".png", ".svg", ".pdf", ".jpg", ".jpeg", ".eps", ".ps", ".tif",
                            ".tiff", ".webp"})


def to_jsonable(x: Any) -> Any:
    """Convert numbers, arrays (numpy or JAX) and nested containers to JSON-ready values.

    Arrays become (nested) lists; numpy/JAX scalars become Python numbers; non-finite floats
    become the strings ``"nan"``, ``"inf"``, ``"-inf"`` (strict JSON has no such numbers);
    paths become strings. Anything else that is not JSON-ready raises ``TypeError``.
    """
    if x is None or isinstance(x, bool | str):
        return x
    if isinstance(x, os.PathLike):
        return os.fspath(x)
    if isinstance(x, Mapping):
        out = {str(k): to_jsonable(v) for k, v in x.items()}
        if len(out) < len(x):
            raise TypeError(f"keys that are the same as text cannot be stored in numbers.json: "
                            f"{sorted(map(repr, x))}")
        return out
    if isinstance(x, list | tuple):
        return [to_jsonable(v) for v in x]
    if hasattr(x, "__array__") or hasattr(x, "tolist"):
        import numpy as np

        arr = np.asarray(x)
        if arr.dtype == bool:
            return arr.tolist()
        if arr.ndim == 0:
            return to_jsonable(arr.item())
        return [to_jsonable(v) for v in arr.tolist()]
    if isinstance(x, numbers.Integral):
        return int(x)
    if isinstance(x, numbers.Real):
        f = float(x)
        return f if math.isfinite(f) else str(f)
    raise TypeError(f"cannot store a {type(x).__name__} in numbers.json: {x!r}")


def format_number(x: Any, digits: int = 6) -> str:
    """Short text for a table cell: floats with ``digits`` significant digits; integers
    in full and booleans as ``True``/``False`` (Python's, numpy's or JAX's scalars)."""
    if isinstance(x, bool) or x is None:
        return str(x)
    if isinstance(x, numbers.Integral):
        return str(int(x))
    kind = getattr(getattr(x, "dtype", None), "kind", None)
    if kind is not None and getattr(x, "ndim", None) == 0:  # a numpy or JAX scalar
        if kind == "b":
            return str(bool(x))
        if kind in "iu":
            return str(int(x))
    if isinstance(x, numbers.Real) or hasattr(x, "__float__"):
        try:
            return f"{float(x):.{digits}g}"
        except (TypeError, ValueError):
            pass
    return str(x)


class Report:
    """Collect the outputs of one experiment run in ``out_dir``.

    Args:
        out_dir: folder for the outputs; created (with parents) if missing.
        title: heading of the markdown summary.
        summary_name: file name of the summary, ``"report.md"`` by default.
    """

    def __init__(
        self, out_dir: str | os.PathLike, title: str = "", summary_name: str = "report.md"
    ):
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.title = title
        self.summary_name = summary_name
        self._numbers: dict[str, Any] = {}
        self._blocks: list[str] = []

    # ----------------------------------------------------------------- files
    def path(self, name: str) -> Path:
        """Path of an output file ``name`` inside the folder (for files written elsewhere)."""
        return self.out_dir / name

    def figure(
        self, name: str, fig, *, caption: str = "", dpi: int = 100, show: bool = True
    ) -> Path:
        """Save a matplotlib figure as ``name.png`` (or ``name`` if it has an extension).

        The image is shown at this point of the summary (after the blocks added so far).

        Args:
            name: file stem, e.g. ``"omega"`` or ``"tilt_0.5deg"`` (``.png`` is added);
                a name ending in one of ``IMAGE_SUFFIXES`` (``".svg"``, ``".pdf"``, ...)
                keeps it. A file name, not a path.
            fig: anything with ``savefig(path, dpi=...)``.
            caption: text under the image in the summary.
            dpi: resolution, raised where needed so that a raster image is at least
                ``jrigid.viz.MIN_WIDTH_PX`` pixels wide (:func:`jrigid.viz.save`).
            show: show the image in the summary (default True).

        Returns:
            the written path.
        """
        from jrigid.viz import save  # matplotlib is loaded already: fig is a figure

        if not name or name in (".", "..") or Path(name).name != name:
            raise ValueError(f"Report.figure: name must be a file name, got {name!r}")
        suffix = Path(name).suffix.lower()
        path = save(fig, self.out_dir / (name if suffix in IMAGE_SUFFIXES else f"{name}.png"),
                    dpi)
        if show:
            self.image(path, caption)
        return path

    def image(self, path: str | os.PathLike, caption: str = "") -> None:
        """Show an image already written (e.g. a GIF) at this point of the summary."""
        path = Path(path)
        try:
            rel = path.resolve().relative_to(self.out_dir.resolve()).as_posix()
        except ValueError:
            rel = path.as_posix()
        link = quote(rel, safe="/")  # a space would end the link in CommonMark
        text = f"![{Path(rel).stem}]({link})"
        self._blocks.append(text + (f"\n\n*{caption}*" if caption else ""))

    # ----------------------------------------------------------------- numbers
    def numbers(self, values: Mapping[str, Any] | None = None, **more: Any) -> Path:
        """Merge ``values`` (and keyword ``more``) into ``numbers.json`` and rewrite it.

        Returns:
            the path of ``numbers.json``.
        """
        merged = {**self._numbers, **to_jsonable({**(values or {}), **more})}
        path = self.out_dir / "numbers.json"
        text = json.dumps(merged, indent=2, allow_nan=False) + "\n"
        write_atomic(path, lambda fh: fh.write(text.encode()))  # whole, or the old file
        self._numbers = merged  # (only once all of them could be stored)
        return path

    # ----------------------------------------------------------------- text
    def text(self, markdown: str) -> None:
        """Append a paragraph of markdown to the summary."""
        self._blocks.append(markdown.strip())

    def table(self, rows: Iterable[Sequence[Any]], headers: Sequence[str], digits: int = 6) -> str:
        """Append a markdown table (numbers formatted to ``digits`` significant digits).

        Returns:
            the table's markdown.
        """
        headers = list(headers)
        rows = [list(row) for row in rows]
        for i, row in enumerate(rows):
            if len(row) != len(headers):
                raise ValueError(f"Report.table: row {i} has {len(row)} cells for "
                                 f"{len(headers)} headers: {row!r}")
        head = (str(h).replace("|", "\\|") for h in headers)
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(headers)]
        for row in rows:
            cells = (format_number(c, digits).replace("|", "\\|") for c in row)
            lines.append("| " + " | ".join(cells) + " |")
        md = "\n".join(lines)
        self._blocks.append(md)
        return md

    def write_summary(self, text: str = "") -> Path:
        """Write the markdown summary: title, ``text``, then the blocks in the order added.

        Can be called again after more is added; the file is rewritten.

        Returns:
            the summary's path.
        """
        parts = [f"# {self.title}"] if self.title else []
        if text:
            parts.append(text.strip())
        parts.extend(self._blocks)
        path = self.out_dir / self.summary_name
        summary = "\n\n".join(parts) + "\n"
        write_atomic(path, lambda fh: fh.write(summary.encode()))
        return path
