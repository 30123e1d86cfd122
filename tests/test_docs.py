"""The documentation site builds strictly, with every tutorial executed and drawn.

One quick build (``JRIGID_DOCS_QUICK=1``: the tutorials at small sizes; no notebook
cache) into a temporary folder with ``mkdocs build --strict``: a tutorial that raises, a
dangling cross-reference or a docstring griffe cannot parse fails it. The built pages are
then checked: each tutorial carries its figures (PNG, at least 1000 px wide), the API
reference has an anchor for every public module, the chapter map a row for every
equation. Small unit tests cover the page generators' parsing.
"""

from __future__ import annotations

import base64
import os
import re
import struct
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "docs" / "_support"))

import apipages  # noqa: E402
import chapter  # noqa: E402

# tutorial -> smallest number of figures its page must carry
TUTORIALS = {
    "first_steps": 6,
    "inference": 2,
    "stability_sweeps": 1,
    "autodiff": 2,
    "choosing_a_solver": 1,
}
PNG = re.compile(r'src="data:image/png;base64,([A-Za-z0-9+/=\s]+)"')


def _png_width(data: str) -> int:
    raw = base64.b64decode(data)
    assert raw[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">I", raw[16:20])[0]


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocs_jupyter")
    out = tmp_path_factory.mktemp("site")
    env = {
        **os.environ,
        "JRIGID_DOCS_QUICK": "1",
        "JRIGID_DOCS_CACHE": "0",
        "NO_MKDOCS_2_WARNING": "1",
        "EQX_ON_ERROR": "raise",
    }
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml"),
         "-d", str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=1500,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-8000:]
    return out


def test_tutorials_executed_with_their_figures(site):
    for name, n_figures in TUTORIALS.items():
        page = (site / "tutorials" / name / "index.html").read_text(encoding="utf-8")
        images = PNG.findall(page)
        assert len(images) >= n_figures, f"{name}: {len(images)} figures"
        widths = [_png_width(re.sub(r"\s", "", data)) for data in images]
        assert min(widths) >= 1000, f"{name}: figure widths {widths}"
        assert "Traceback" not in page, f"{name} shows a traceback"
        assert (site / "tutorials" / name / f"{name}.py").is_file()  # the source, downloadable


def test_api_reference_covers_every_public_module(site):
    html = "".join(p.read_text(encoding="utf-8") for p in (site / "api").rglob("index.html"))
    modules = apipages.public_modules(ROOT)
    assert "jrigid.fit.driver" in modules and "jrigid.quaternion" in modules
    assert not [m for m in modules if "._" in m]
    missing = [m for m in modules if f'id="{m}"' not in html]
    assert not missing
    # Sphinx roles became links, not literal ":func:" text
    assert ":func:" not in html and ":class:" not in html


def test_chapter_map_and_benchmarks(site):
    page = (site / "chapter_map" / "index.html").read_text(encoding="utf-8")
    for n in range(1, 52):
        assert f"<td>17.{n}</td>" in page
    assert 'href="../api/quaternion/#jrigid.quaternion.core.multiply"' in page  # 17.24
    bench = (site / "benchmarks" / "index.html").read_text(encoding="utf-8")
    for figure in ("speed_vs_error", "work_precision", "ensemble_throughput"):
        assert f"assets/benchmarks/{figure}.png" in bench
        assert (site / "assets" / "benchmarks" / f"{figure}.png").is_file()


def test_equation_references_are_parsed():
    assert chapter.equations_in("Hamilton product (eq. 17.24)") == {24}
    assert chapter.equations_in("eqs. 17.45–17.46 and (17.51a)") == {45, 46, 51}
    assert chapter.equations_in("(17.11-17.13)") == {11, 12, 13}
    # exercises, problems, tables and sections are not equations
    assert chapter.equations_in("Problem 17.3, Table 17.1, Section 17.4, Exercise 17.2") == set()
    assert chapter.equations_in("version 1.17.1") == set()


def test_api_pages_list_every_top_level_module():
    pages = apipages.pages(ROOT)
    top = {m.split(".")[1] for m in apipages.public_modules(ROOT) if m.count(".") >= 1}
    assert {f"api/{name}.md" for name in top} | {"api/index.md"} == set(pages)
    assert "::: jrigid.fit.driver" in pages["api/fit.md"]
    assert "- ellipk" in pages["api/special.md"]  # defined in a private module
