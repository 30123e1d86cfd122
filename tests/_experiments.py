"""Shared harness for the experiment tests: run each quick mode once, check its outputs."""

import json

import pytest

from jrigid import cli, registry


def run_quick(tmp_path_factory, names) -> dict:
    """``name -> (numbers, out_dir)``: each experiment run once via ``jrigid run --quick``."""
    out = {}
    for name in names:
        folder = tmp_path_factory.mktemp(name)
        assert cli.main(["run", name, "--quick", "--out", str(folder)]) == 0
        out[name] = (json.loads((folder / "numbers.json").read_text()), folder)
    return out


def assert_listed_and_written(name, results) -> None:
    """The experiment is listed with a description and wrote a report, run record and figure."""
    exp = registry.discover()[name]
    assert exp.summary and exp.summary != "(no description)"
    _, folder = results[name]
    assert (folder / "report.md").is_file() and (folder / "run.json").is_file()
    assert list(folder.glob("*.png")), "no figure written"


def quick_suite(names):
    """``(results, test_listed_and_writes_outputs)`` for a test module of experiments.

    ``results`` is a module-scoped fixture running each experiment's quick mode once
    (:func:`run_quick`); the test checks each is listed and wrote its outputs. Use as
    ``results, test_listed_and_writes_outputs = quick_suite(NAMES)``.
    """

    @pytest.fixture(scope="module")
    def results(tmp_path_factory):
        return run_quick(tmp_path_factory, names)

    @pytest.mark.parametrize("name", names)
    def test_listed_and_writes_outputs(name, results):
        assert_listed_and_written(name, results)

    return results, test_listed_and_writes_outputs
