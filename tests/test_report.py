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


def test_figure_names_with_dots_get_png_and_bad_names_are_refused(tmp_path):
    """"tilt_0.5deg" was taken as a file of format "5deg" (matplotlib's ValueError); "" wrote
    ".png.png" and linked ".png"."""
    rep = Report(tmp_path)
    fig = Figure()
    fig.add_subplot().plot([0, 1], [0, 1])
    assert rep.figure("tilt_0.5deg", fig).name == "tilt_0.5deg.png"
    assert rep.figure("omega.svg", fig).name == "omega.svg"
    assert rep.figure("my plot", fig).name == "my plot.png"
    assert {p.name for p in tmp_path.iterdir()} == {"tilt_0.5deg.png", "omega.svg",
                                                    "my plot.png"}
    for bad in ("", "..", "sub/omega"):
        with pytest.raises(ValueError, match="file name"):
            rep.figure(bad, fig)
    text = rep.write_summary().read_text()
    assert "(my%20plot.png)" in text and "(tilt_0.5deg.png)" in text


def test_numbers_that_cannot_be_stored_change_nothing(tmp_path):
    rep = Report(tmp_path)
    rep.numbers(a=1)
    with pytest.raises(TypeError):
        rep.numbers(b=2, c={1, 2})
    rep.numbers(d=4)
    assert json.loads((tmp_path / "numbers.json").read_text()) == {"a": 1, "d": 4}
    with pytest.raises(TypeError, match="same as text"):
        to_jsonable({1: "a", "1": "b"})


def test_table_rows_must_match_the_headers(tmp_path):
    rep = Report(tmp_path)
    with pytest.raises(ValueError, match="row 1 has 3 cells for 2 headers"):
        rep.table([(1, 2), (1, 2, 3)], headers=("a", "b"))


def test_format_number_of_numpy_and_jax_scalars():
    import jax.numpy as jnp

    assert format_number(np.True_) == "True" and format_number(jnp.array(False)) == "False"
    assert format_number(jnp.array(123456789)) == "123456789"
    assert format_number(np.uint8(7)) == "7" and format_number(jnp.array(2.5)) == "2.5"
