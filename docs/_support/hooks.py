"""mkdocs hooks for the jrigid site: generated pages and the quick mode.

- One API page per public module or package of ``jrigid`` (found on disk, so a new
  module gets its page without editing anything), appended to the navigation.
- The chapter map (``chapter_map.md``), built from the equation numbers cited in the
  docstrings, the experiments and the tests (:mod:`chapter`).
- The measured figures of ``benchmarks/figures`` and ``experiments/gallery`` copied into
  the site, so the pages can show them without keeping a second copy in ``docs/``.
- ``JRIGID_DOCS_QUICK=1`` (the tutorials run at small sizes) keeps its executed
  notebooks in a cache folder of its own, so a quick build never serves a full one;
  ``JRIGID_DOCS_CACHE=0`` executes every tutorial afresh (the test of the site does).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from mkdocs.structure.files import File

sys.path.insert(0, str(Path(__file__).parent))

import apipages  # noqa: E402
import chapter  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
FIGURE_DIRS = {"benchmarks/figures": "assets/benchmarks", "experiments/gallery": "assets/gallery"}


def quick() -> bool:
    """Whether the tutorials run in quick mode (``JRIGID_DOCS_QUICK`` set and not 0)."""
    return os.environ.get("JRIGID_DOCS_QUICK", "0") not in ("", "0", "false", "False")


def on_config(config):
    jupyter = config.plugins.get("mkdocs-jupyter")
    if jupyter is not None:
        cache_dir = Path(jupyter.config["cache_dir"])
        if not cache_dir.is_absolute():
            cache_dir = ROOT / cache_dir
        if quick():
            cache_dir = cache_dir.with_name(cache_dir.name + "-quick")
        jupyter.config["cache_dir"] = str(cache_dir)
        if os.environ.get("JRIGID_DOCS_CACHE", "1") in ("0", "false", "False"):
            jupyter.config["cache"] = False
    config.nav.append({"API reference": apipages.nav(ROOT)})
    return config


def on_files(files, config):
    for src_uri, text in apipages.pages(ROOT).items():
        files.append(File.generated(config, src_uri, content=text))
    files.append(File.generated(config, "chapter_map.md", content=chapter.page(ROOT)))
    for source, target in FIGURE_DIRS.items():
        for path in sorted((ROOT / source).glob("*")):
            if path.suffix in (".png", ".gif", ".svg"):
                files.append(
                    File.generated(config, f"{target}/{path.name}", abs_src_path=str(path))
                )
    return files
