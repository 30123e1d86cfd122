"""report: an experiment's result folder — figure, numbers.json and report.md."""

import json
import math

import numpy as np
import pytest
from matplotlib.figure import Figure

from jrigid.report import Report, format_number, to_jsonable


def test_report_writes_figure_numbers_and_summary(tmp_path):
    out = tmp_path / "results" / "demo"  # created with its parents
    rep = Report(out, title="Plate wobble")
    fig = Figure(figsize=(4, 3))
    fig.add_subplot().plot([0, 1, 2], [0, 1, 4])
    png = rep.figure("omega", fig, caption="body angular velocity")
    rep.text("Measured against theory:")
    rep.numbers({"period": np.float64(1.25), "ratio": np.array([1.0, np.nan])}, spins=3)
    md_table = rep.table([("period", 1.2345678, 1.23), ("a|b", 2, None)],
                         headers=("quantity", "measured", "theory"), digits=3)
    summary = rep.write_summary("What was found.")

    assert png == out / "omega.png" and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads((out / "numbers.json").read_text()) == {
        "period": 1.25, "ratio": [1.0, "nan"], "spins": 3}
    assert summary == out / "report.md"
    text = summary.read_text()
    parts = text.split("\n\n")
    assert parts[:3] == ["# Plate wobble", "What was found.", "![omega](omega.png)"]
    assert "*body angular velocity*" in text
    assert text.index("omega.png") < text.index("Measured against") < text.index("| quantity")
    assert "| period | 1.23 | 1.23 |" in md_table and "| a\\|b | 2 | None |" in md_table
    assert md_table in text


def test_numbers_merge_and_rewrite(tmp_path):
    rep = Report(tmp_path)
    rep.numbers(a=1)
    path = rep.numbers({"b": [1, 2]}, a=2.5)
    assert json.loads(path.read_text()) == {"a": 2.5, "b": [1, 2]}
    assert rep.write_summary().read_text() == "\n"


def test_to_jsonable_and_format_number():
    assert to_jsonable({1: (np.int64(2), math.inf, -math.inf), "m": np.eye(2, dtype=bool)}) == {
        "1": [2, "inf", "-inf"], "m": [[True, False], [False, True]]}
    with pytest.raises(TypeError, match="numbers.json"):
        to_jsonable(object())
    assert format_number(3.14159265, 3) == "3.14" and format_number(np.int32(7)) == "7"
    assert format_number(True) == "True" and format_number("x") == "x"
