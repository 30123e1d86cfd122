"""Tests of the command line (jrigid.cli), the experiment registry, reports, and the demo."""

import json
import math
import subprocess
import sys
import warnings

import numpy as np
import pytest
from PIL import Image
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation
from scipy.special import ellipk

from jrigid import cli, inertia, registry, theory
from jrigid.report import Report, to_jsonable

# --------------------------------------------------------------------------- helpers


def _exit_code(argv, capsys):
    """Run the CLI expecting a usage error; return (code, stderr)."""
    with pytest.raises(SystemExit) as info:
        cli.main(argv)
    return info.value.code, capsys.readouterr().err


@pytest.fixture
def exp_dir(tmp_path, monkeypatch):
    """A folder of extra experiments on JRIGID_EXPERIMENTS."""
    folder = tmp_path / "extra_experiments"
    folder.mkdir()
    (folder / "counter.py").write_text(
        '"""Counter: returns its parameters without writing any file."""\n'
        "def main(out_dir, quick=False, *, n=3, scale=1.5, flag=False, name='x', "
        "vec=(1.0, 2.0), opt=None):\n"
        "    return {'n': n, 'scale': scale, 'flag': flag, 'name': name, 'vec': list(vec),\n"
        "            'opt': opt, 'quick': quick}\n"
    )
    (folder / "_private.py").write_text('"""Not an experiment."""\ndef main(out_dir): pass\n')
    (folder / "nomain.py").write_text('"""No main here."""\nX = 1\n')
    (folder / "noquick.py").write_text(
        '"""Has no quick mode."""\ndef main(out_dir, *, k=1):\n    return {"k": k}\n'
    )
    (folder / "broken.py").write_text('"""Fails."""\ndef main(out_dir, quick=False):\n    1 / 0\n')
    monkeypatch.setenv(registry.ENV_VAR, str(folder))
    (folder / "checked.py").write_text(
        '"""Checked: refuses a negative level, fails at level 5 after writing."""\n'
        "from jrigid.registry import ParameterError\n"
        "def main(out_dir, quick=False, *, level=1):\n"
        "    if level < 0:\n"
        "        raise ParameterError(f'level must be >= 0, got {level}')\n"
        "    (out_dir / 'numbers.json').write_text('{}')\n"
        "    (out_dir / 'report.md').write_text('# checked')\n"
        "    if level == 5:\n"
        "        raise ValueError('internal error unrelated to the parameters')\n"
        "    return {'level': level}\n"
    )
    (folder / "unstorable.py").write_text(
        '"""Unstorable: returns a set, which numbers.json cannot hold."""\n'
        "def main(out_dir, quick=False):\n"
        "    return {'a': 1, 's': {1, 2}}\n"
    )
    (folder / "silent.py").write_text(
        '"""Silent: writes nothing and returns nothing."""\n'
        "def main(out_dir, quick=False):\n"
        "    return None\n"
    )
    return folder


# --------------------------------------------------------------------------- list / help


def test_list_shows_every_experiment_one_line_each(capsys, exp_dir):
    assert cli.main(["list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    names = [line.split()[0] for line in lines]
    assert names[0] == "demo"  # the built-in main job first, then the experiments
    assert "hello" in names and "dzhanibekov" in names
    assert "counter" in names and "broken" in names
    assert "_private" not in names and "nomain" not in names
    assert any("Counter: returns its parameters" in line for line in lines)
    assert len(lines) == len(registry.discover())


def test_list_verbose_shows_parameters(capsys):
    assert cli.main(["list", "-v"]) == 0
    out = capsys.readouterr().out
    assert "rate=2.0 (float)" in out and "shape='box' (str)" in out
    assert "thickness=0.1 (float)" in out


@pytest.mark.parametrize(
    "argv", [["--help"], ["list", "--help"], ["run", "--help"], ["demo", "-h"]]
)
def test_help_for_each_command(argv, capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(argv)
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "usage: jrigid" in out
    if argv[0] == "run":
        assert "KEY=VALUE" in out and "--quick" in out and "--out" in out


def test_no_command_prints_help(capsys):
    assert cli.main([]) == 0
    assert "{list,run,demo,docs,cache}" in capsys.readouterr().out


def test_cache_shows_and_clears_the_compilation_cache(capsys, monkeypatch, tmp_path):
    """``jrigid cache`` counts what the cache directory holds; ``clear`` removes the
    compiled programs (and their access times), nothing else."""
    monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR", raising=False)
    monkeypatch.setenv("JRIGID_CACHE_DIR", str(tmp_path))
    for key, size in (("jit_a-1", 1000), ("jit_b-2", 3000)):
        (tmp_path / f"{key}-cache").write_bytes(b"x" * size)
        (tmp_path / f"{key}-atime").write_bytes(b"t" * 8)
    (tmp_path / "notes.txt").write_text("kept")
    assert cli.main(["cache"]) == 0
    assert f"{tmp_path}: 2 compiled programs" in capsys.readouterr().out
    assert cli.main(["cache", "clear"]) == 0
    assert "removed 2 compiled programs" in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]
    assert cli.main(["cache"]) == 0
    assert f"{tmp_path}: 0 compiled programs, 0.0 MiB" in capsys.readouterr().out
    monkeypatch.setenv("JRIGID_CACHE_DIR", "off")
    assert cli.main(["cache"]) == 0
    assert "cache is off" in capsys.readouterr().out
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path))
    assert cli.main(["cache", "clear"]) == 0
    assert "JAX_COMPILATION_CACHE_DIR" in capsys.readouterr().out


# --------------------------------------------------------------------------- errors


def test_unknown_experiment_exits_2_and_lists_valid_names(capsys):
    code, err = _exit_code(["run", "nope"], capsys)
    assert code == 2
    assert "unknown experiment 'nope'" in err
    assert "demo" in err and "hello" in err and "all" in err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["run", "hello", "speed=3"], "unknown parameter 'speed'"),
        (["run", "hello", "rate=fast"], "bad value for parameter 'rate'"),
        (["run", "hello", "samples=2.5"], "expected an int"),
        (["run", "hello", "axis=1,2"], "expected 3 numbers"),
        (["run", "hello", "--param", "rate"], "key=value"),
        (["run", "hello", "quick=true"], "set with --quick"),
        (["demo", "gif=maybe"], "expected a bool"),
        (["run", "all", "rate=1"], "cannot be given with `run all`"),
        (["run", "hello", "rate=1", "rate=2"], "rate is given twice"),
        (["run"], "NAME is required"),
        (["demo", "fps=0"], "parameter 'fps'"),
        (["demo", "frames=-3"], "parameter 'frames'"),
        (["run", "stability_map", "rtol=-1", "--quick"], "parameter 'rtol'"),
        (["run", "stability_map", "n_directions=0", "--quick"], "parameter 'n_directions'"),
    ],
)
def test_bad_parameters_exit_2_and_say_what_is_valid(argv, message, capsys):
    code, err = _exit_code(argv, capsys)
    assert code == 2
    assert message in err
    if "parameter" in message or "expected" in message:
        assert "valid parameters:" in err


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e400", "NaN", "-1e999"])
@pytest.mark.parametrize("key", ["rate", "axis", "samples"])
def test_non_finite_numbers_exit_2_with_one_line(key, value, capsys, tmp_path):
    """They used to reach the experiment and end in a traceback."""
    text = f"0,{value},1" if key == "axis" else value
    code, err = _exit_code(["run", "hello", f"{key}={text}", "--out", str(tmp_path)], capsys)
    assert code == 2
    assert f"bad value for parameter '{key}'" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []  # refused before anything was written


@pytest.mark.parametrize(
    "argv, key",
    [
        (["run", "body_frame", "mass=-1"], "mass"),
        (["run", "falling_box", "mass=0"], "mass"),
        (["run", "methane", "mass_h=-1.008"], "mass_h"),
    ],
)
def test_non_positive_mass_exits_2(argv, key, capsys, tmp_path):
    code, err = _exit_code([*argv, "--out", str(tmp_path)], capsys)
    assert code == 2 and f"parameter '{key}'" in err and "must be > 0" in err
    assert len(err.strip().splitlines()) == 1


def test_a_value_the_experiment_refuses_exits_2_with_one_line(capsys, tmp_path):
    """A parameter that parses but that the physics refuses (a negative thickness) used
    to end in a traceback naming an internal variable."""
    code, err = _exit_code(["run", "body_frame", "sides=1,-2,3", "--quick", "--out",
                            str(tmp_path)], capsys)
    assert code == 2 and "refused its parameters (sides=1,-2,3)" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.parametrize("argv, message", [
    (["run", "stability_map", "rtol=2", "--quick"], "rtol must be finite, > 0 and < 1"),
    (["run", "fit_tumbling", "moments=1,2,10", "--quick"], "triangle inequality"),
    (["demo", "tilt_deg=0"], "tilt_deg must be in (0, 90)"),
    (["demo", "frames=1"], "frames >= 2"),
    (["run", "hello", "samples=0"], "samples must be >= 3"),
])
def test_values_the_demo_and_hello_refuse_are_refused_before_running(argv, message, capsys,
                                                                     tmp_path):
    """fps=0 used to end in a ZeroDivisionError after the whole simulation, tilt_deg=0 in
    a 100 % disagreement with theory, samples=0 in numpy's message."""
    code, err = _exit_code([*argv, "--out", str(tmp_path)], capsys)
    assert code == 2 and message in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []  # the folder is left as it was


def test_a_refused_parameter_leaves_an_earlier_run_as_it_was(exp_dir, capsys):
    """A refused value used to rewrite run.json as "failed", beside the earlier run's
    numbers and figures; without --out it left an empty results folder."""
    out = exp_dir.parent / "out"
    assert cli.main(["run", "checked", "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert json.loads(before["run.json"])["status"] == "finished"
    code, err = _exit_code(["run", "checked", "level=-3", "--out", str(out)], capsys)
    assert code == 2 and "refused its parameters (level=-3): level must be >= 0" in err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    fresh = exp_dir.parent / "fresh"
    code, err = _exit_code(["run", "checked", "level=-3", "--out", str(fresh)], capsys)
    assert code == 2 and not fresh.exists()


def test_a_value_error_after_the_first_output_is_a_failure_with_its_traceback(exp_dir,
                                                                             capsys):
    """Any ValueError used to be reported as a refused parameter (exit code 2, no
    traceback) once a KEY=VALUE was given, a bug in the experiment included."""
    out = exp_dir.parent / "out"
    with pytest.raises(ValueError, match="internal"):
        cli.main(["run", "checked", "level=5", "--out", str(out)])
    assert json.loads((out / "run.json").read_text())["status"] == "failed"


def test_a_result_that_cannot_be_stored_marks_the_run_failed(exp_dir):
    """run.json said "running" for good when writing the returned numbers failed."""
    out = exp_dir.parent / "out"
    with pytest.raises(TypeError, match="cannot store a set"):
        registry.run("unstorable", out)
    assert json.loads((out / "run.json").read_text())["status"] == "failed"


def test_reserved_names_point_to_their_options(capsys):
    code, err = _exit_code(["run", "hello", "out_dir=x"], capsys)
    assert code == 2 and "'out_dir' is set with --out," in err


def test_a_run_without_a_summary_does_not_claim_one(exp_dir, capsys):
    out = exp_dir.parent / "out"
    assert cli.main(["run", "silent", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "no report.md" in printed and "report: " not in printed


def test_cache_names_a_cache_path_that_is_a_file(capsys, monkeypatch, tmp_path):
    monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR", raising=False)
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("JRIGID_CACHE_DIR", str(blocker))
    assert cli.main(["cache"]) == 1
    assert "is not a directory: nothing is cached" in capsys.readouterr().out


@pytest.mark.parametrize("params, message", [
    (["radius=1e-100"], "outside 1e-50"),
    (["radius=1e100"], "outside 1e-50"),
])
def test_the_demo_refuses_plates_out_of_range(params, message, capsys, tmp_path):
    """radius=1e-100 ended in a ZeroDivisionError, 1e100 in "ts must be strictly
    increasing"."""
    code, err = _exit_code(["demo", "--quick", *params, "--out", str(tmp_path)], capsys)
    assert code == 2 and message in err and "Traceback" not in err


def test_parameters_declared_positive_are_refused_unless_positive(tmp_path, monkeypatch):
    folder = tmp_path / "declared"
    folder.mkdir()
    (folder / "shapes.py").write_text(
        '"""Declares its positive parameters."""\n'
        "from __future__ import annotations\n"
        "from typing import Annotated\n"
        "from jrigid.registry import POSITIVE\n"
        "def main(out_dir, quick=False, *, radius: Annotated[float, POSITIVE] = 1.0,\n"
        "         sides: Annotated[tuple, POSITIVE] = (1.0, 2.0), shift: float = 0.0,\n"
        "         body_mass: float = 2.0):\n"
        "    return {'radius': radius}\n"
    )
    monkeypatch.setenv(registry.ENV_VAR, str(folder))
    main = registry.get("shapes").main
    assert registry.positive_parameters(main) == {"radius", "sides", "body_mass"}
    assert "radius=1.0 (float, > 0)" in registry.describe_parameters(main)
    ok = registry.parse_params("shapes", main, {"radius": "0.5", "shift": "-3", "sides": "1,3"})
    assert ok == {"radius": 0.5, "shift": -3.0, "sides": (1.0, 3.0)}
    for key, text in [("radius", "0"), ("radius", "-2"), ("sides", "1,-1"), ("body_mass", "-1")]:
        with pytest.raises(registry.ParameterError, match=f"'{key}'.*must be > 0"):
            registry.parse_params("shapes", main, {key: text})


@pytest.mark.parametrize("text, default", [("nan", 1.0), ("inf", 1.0), ("1e400", 1.0),
                                           ("1,nan", (1.0, 2.0)), ("[1e400]", None),
                                           ("1e400", 1), ("nan", 1)])
def test_convert_refuses_non_finite_numbers(text, default):
    with pytest.raises(ValueError):
        registry.convert(text, default)


def test_unwritable_out_exits_2_with_one_line(tmp_path, capsys):
    """A results folder that cannot be created used to end in a traceback."""
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    for out in (a_file, a_file / "below"):
        code, err = _exit_code(["run", "hello", "--quick", "--out", str(out)], capsys)
        assert code == 2 and "cannot write results to" in err and str(out) in err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
        code, err = _exit_code(["run", "all", "--quick", "--out", str(out)], capsys)
        assert code == 2 and "cannot write results to" in err
    assert a_file.read_text() == "x"


def test_stray_arguments_exit_2(capsys):
    code, err = _exit_code(["run", "hello", "--bogus"], capsys)
    assert code == 2 and "unrecognized arguments: --bogus" in err
    code, err = _exit_code(["list", "extra"], capsys)
    assert code == 2 and "unrecognized" in err


# --------------------------------------------------------------------------- parameters


@pytest.mark.parametrize(
    "text, default, expected",
    [
        ("3", 1, 3),
        ("1e3", 1, 1000),
        ("2.5", 1.0, 2.5),
        ("yes", False, True),
        ("OFF", True, False),
        ("0", True, False),
        ("abc", "x", "abc"),
        ("1,2,3", (0.0, 0.0, 0.0), (1.0, 2.0, 3.0)),
        ("[4, 5]", [1, 2], [4, 5]),
        ("(0.5, 1)", (1.0, 2.0), (0.5, 1.0)),
        ("a,b", ("x",), ("a", "b")),
        ("[1, 2]", None, [1, 2]),
        ("plain", None, "plain"),
        ("{'a': 1}", {"b": 2}, {"a": 1}),
    ],
)
def test_convert_uses_the_type_of_the_default(text, default, expected):
    out = registry.convert(text, default)
    assert out == expected and type(out) is type(expected)


@pytest.mark.parametrize(
    "text, default", [("x", 1), ("1.5", 2), ("maybe", True), ("1,a", (1.0, 2.0)), ("[1]", {})]
)
def test_convert_rejects_bad_text(text, default):
    with pytest.raises(ValueError):
        registry.convert(text, default)


def test_parse_params_open_ended_main_accepts_any_key():
    def main(out_dir, quick=False, *, a=1, **extra):
        return None

    assert registry.parse_params("t", main, {"a": "2", "b": "[1, 2]", "c": "word"}) == {
        "a": 2,
        "b": [1, 2],
        "c": "word",
    }


def test_parse_params_reports_required_parameters():
    def main(out_dir, quick=False, *, needed):
        return None

    with pytest.raises(registry.ParameterError, match="needs parameter"):
        registry.parse_params("t", main, {})


# --------------------------------------------------------------------------- running


def test_run_folder_experiment_with_typed_params_and_fallback_outputs(tmp_path, capsys, exp_dir):
    out = tmp_path / "res"
    argv = ["run", "counter", "n=7", "--out", str(out), "-p", "flag=yes", "vec=3,4", "opt=[1]"]
    assert cli.main(argv) == 0
    numbers = json.loads((out / "numbers.json").read_text())
    assert numbers == {
        "n": 7,
        "scale": 1.5,
        "flag": True,
        "name": "x",
        "vec": [3.0, 4.0],
        "opt": [1],
        "quick": False,
    }
    report = (out / "report.md").read_text()
    assert "| n | 7 |" in report
    run = json.loads((out / "run.json").read_text())
    assert run["experiment"] == "counter" and run["params"]["n"] == 7
    assert run["status"] == "finished" and run["seconds"] >= 0
    assert f"report: {out / 'report.md'}" in capsys.readouterr().out


def test_run_all_runs_everything_and_reports_failures(tmp_path, capsys, exp_dir, monkeypatch):
    ran = []
    real_run = registry.run

    def fake_run(name, out_dir=None, *, quick=False, params=None):
        ran.append((name, quick))
        if (exp_dir / f"{name}.py").exists():  # this test's own experiments run for real;
            return real_run(name, out_dir, quick=quick, params=params)
        return None  # the shipped ones each have a quick-mode test of their own

    monkeypatch.setattr(registry, "run", fake_run)
    assert cli.main(["run", "all", "--quick", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "ZeroDivisionError" in err and "failed: broken" in err
    assert [n for n, _ in ran] == list(registry.discover())
    assert all(q for _, q in ran)
    assert (tmp_path / "counter" / "numbers.json").exists()
    # a failed run says so in its folder (it used to keep the previous run's run.json)
    broken = json.loads((tmp_path / "broken" / "run.json").read_text())
    assert broken["status"] == "failed" and "ZeroDivisionError" in broken["error"]


def test_experiment_without_quick_mode_runs_in_full(tmp_path, capsys, exp_dir):
    assert cli.main(["run", "noquick", "--quick", "k=5", "--out", str(tmp_path)]) == 0
    assert "has no quick mode" in capsys.readouterr().err
    assert json.loads((tmp_path / "numbers.json").read_text()) == {"k": 5}


def test_run_hello_quick_writes_its_files(tmp_path, capsys):
    out = tmp_path / "hello"
    assert cli.main(["run", "hello", "--quick", "--out", str(out), "rate=3", "shape=t_handle"]) == 0
    for name in ("report.md", "numbers.json", "run.json", "body.png", "omega.png"):
        assert (out / name).stat().st_size > 0
    numbers = json.loads((out / "numbers.json").read_text())
    assert numbers["rate"] == 3.0 and numbers["samples"] == 21 and numbers["shape"] == "t_handle"
    assert numbers["max_abs_error_omega"] < 1e-6
    assert "![body](body.png)" in (out / "report.md").read_text()


def test_default_output_folder_is_results_name(tmp_path, monkeypatch, exp_dir, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "counter", "--quick"]) == 0
    assert json.loads((tmp_path / "results" / "counter" / "numbers.json").read_text())["quick"]


def test_demo_quick_succeeds_and_matches_theory(tmp_path, capsys):
    from jrigid.viz import AliasingWarning

    out = tmp_path / "demo"
    with warnings.catch_warnings():
        warnings.simplefilter("error", AliasingWarning)  # the GIFs must not alias
        assert cli.main(["demo", "--quick", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "wobble/spin" in printed and "flip interval" in printed
    assert f"report: {out / 'report.md'}" in printed
    numbers = json.loads((out / "numbers.json").read_text())
    plate, handle = numbers["plate"], numbers["t_handle"]
    assert plate["wobble_to_spin_measured"] == pytest.approx(
        plate["wobble_to_spin_theory"], rel=1e-6
    )
    # thin-plate value 2/cos θ, corrected for the thickness h = 0.1 r
    assert plate["wobble_to_spin_theory"] == pytest.approx(
        2 / ((1 - 0.1**2 / 3) * math.cos(math.radians(10.0))), rel=1e-12
    )
    assert handle["flips_seen"] >= 2
    assert handle["flip_interval_measured"] == pytest.approx(
        handle["flip_interval_theory"], rel=1e-4
    )
    assert numbers["max_relative_energy_drift"] < 1e-7
    report = (out / "report.md").read_text()
    for name in ("plate.png", "plate_angles.png", "plate.gif", "t_handle.png", "t_handle.gif"):
        assert f"({name})" in report
        assert (out / name).stat().st_size > 1000
    with Image.open(out / "plate.gif") as im:
        assert im.n_frames == 24


def test_python_m_cli_lists_without_importing_jax():
    code = (
        "import sys\n"
        "from jrigid import cli\n"
        "assert cli.main(['list']) == 0\n"
        "assert 'jax' not in sys.modules, 'jrigid list imported jax'\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("demo")


# --------------------------------------------------------------------------- report


def test_report_writes_json_table_and_images(tmp_path):
    jnp = pytest.importorskip("jax.numpy")
    rep = Report(tmp_path / "r", title="T")
    rep.text("intro")
    rep.table([("a|b", 1.23456789, np.float32(2.0))], headers=("q", "x", "y"), digits=4)
    (tmp_path / "r" / "anim.gif").write_bytes(b"GIF89a")
    rep.image(tmp_path / "r" / "anim.gif", "an animation")
    rep.numbers({"arr": jnp.arange(3.0), "nan": float("nan")}, count=np.int64(4))
    path = rep.write_summary("summary line")
    text = path.read_text()
    assert text.startswith("# T\n\nsummary line\n\nintro")
    assert "| a\\|b | 1.235 | 2 |" in text
    assert "![anim](anim.gif)\n\n*an animation*" in text
    assert json.loads((tmp_path / "r" / "numbers.json").read_text()) == {
        "arr": [0.0, 1.0, 2.0],
        "nan": "nan",
        "count": 4,
    }


def test_to_jsonable_rejects_unknown_objects():
    assert to_jsonable({"a": (1, np.bool_(True))}) == {"a": [1, True]}
    with pytest.raises(TypeError, match="cannot store"):
        to_jsonable(object())


# --------------------------------------------------------------------------- demo physics


def _euler_rhs(moments):
    A, B, C = moments

    def rhs(t, w):
        return [(B - C) * w[1] * w[2] / A, (C - A) * w[2] * w[0] / B, (A - B) * w[0] * w[1] / C]

    return rhs


@pytest.mark.parametrize("toward", [0, 2])  # both branches: L² < 2EB and L² > 2EB
def test_flip_theory_matches_scipy_integration_and_ellipk(toward):
    moments = np.array([1.0, 2.0, 3.0])
    w0 = np.zeros(3)
    w0[1], w0[toward] = math.cos(0.05), math.sin(0.05)
    th = theory.flip_theory(moments, w0)
    # independent: K from scipy, λ and m from the same closed form evaluated naively
    A, B, C = moments
    E2, L2 = np.sum(moments * w0**2), np.sum(moments**2 * w0**2)
    if L2 > E2 * B:
        lam2, m = (
            (C - B) * (L2 - E2 * A) / (A * B * C),
            (B - A) * (E2 * C - L2) / ((C - B) * (L2 - E2 * A)),
        )
    else:
        lam2, m = (
            (B - A) * (E2 * C - L2) / (A * B * C),
            (C - B) * (L2 - E2 * A) / ((B - A) * (E2 * C - L2)),
        )
    assert th["flip_interval"] == pytest.approx(2 * ellipk(m) / math.sqrt(lam2), rel=1e-9)
    # independent: integrate Euler's equations and time the sign changes of ω2
    T = 4.5 * th["flip_interval"]
    sol = solve_ivp(_euler_rhs(moments), (0, T), w0, rtol=1e-11, atol=1e-13, dense_output=True)
    ts = np.linspace(0, T, 20001)
    crossings = theory.zero_crossings(ts, sol.sol(ts)[1])
    assert len(crossings) >= 3
    assert np.mean(np.diff(crossings)) == pytest.approx(float(th["flip_interval"]), rel=1e-6)
    assert th["period"] == pytest.approx(2 * float(th["flip_interval"]))


def test_plate_theory_thin_limit_and_measurement_on_exact_motion():
    th = theory.plate_theory([1.0, 1.0, 2.0], [0.3, 0.0, 2.0])
    theta = math.atan2(1.0 * 0.3, 2.0 * 2.0)
    assert th["theta"] == pytest.approx(theta)
    assert th["ratio"] == pytest.approx(2 / math.cos(theta)) == th["ratio_thin"]
    # exact motion from Euler angles about L (scipy), measured by the demo
    I1, I3, w3, theta = 1.0, 1.8, 4.0, 0.2
    L = I3 * w3 / math.cos(theta)
    phid, psid = L / I1, w3 * (I1 - I3) / I1
    ts = np.linspace(0, 3, 600)
    ang = np.stack([phid * ts, np.full_like(ts, theta), psid * ts], axis=-1)
    q = Rotation.from_euler("ZXZ", ang).as_quat(scalar_first=True)
    meas = theory.wobble_to_spin(ts, q, [0.0, 0.0, L])
    w_body = np.array(
        [phid * math.sin(theta) * 0, phid * math.sin(theta), phid * math.cos(theta) + psid]
    )
    th = theory.plate_theory([I1, I1, I3], w_body)
    assert meas["ratio"] == pytest.approx(abs(phid / psid), rel=1e-9)
    assert th["ratio"] == pytest.approx(abs(phid / psid), rel=1e-12)
    assert meas["theta"] == pytest.approx(theta, abs=1e-10)


def test_zero_crossings_of_a_sine():
    ts = np.linspace(0.1, 10, 5000)
    assert np.allclose(theory.zero_crossings(ts, np.sin(ts)), np.pi * np.arange(1, 4), atol=1e-6)


def test_t_handle_moments_match_a_point_cloud():
    dims = dict(bar_length=1.0, bar_radius=0.08, stem_length=0.7, stem_radius=0.06)
    moments = inertia.t_handle_moments(2.0, **dims)
    # independent: uniform grid of points inside the two cylinders (numpy only)
    h = 0.006
    g = np.arange(-0.6, 0.9, h) + h / 2
    x, y, z = np.meshgrid(g[(g > -0.51) & (g < 0.51)], g, g[np.abs(g) < 0.09], indexing="ij")
    bar = (y**2 + z**2 <= 0.08**2) & (np.abs(x) <= 0.5)
    stem = (x**2 + z**2 <= 0.06**2) & (y >= 0.08) & (y <= 0.78)
    inside = bar | stem
    p = np.stack([x[inside], y[inside], z[inside]], axis=-1)
    p -= p.mean(axis=0)
    m = 2.0 / len(p)
    tensor = m * (np.sum(p * p) * np.eye(3) - p.T @ p)
    assert np.allclose(moments, np.diag(tensor), rtol=2e-2)
    assert np.abs(tensor - np.diag(np.diag(tensor))).max() < 1e-3 * np.abs(tensor).max()


def test_docs_command_builds_the_checkout_site(tmp_path):
    argv, env, root = cli.docs_command("build", True, tmp_path / "site")
    assert (root / "mkdocs.yml").is_file() and (root / "jrigid" / "cli.py").is_file()
    assert argv[1:5] == ["-m", "mkdocs", "build", "-f"] and argv[5] == str(root / "mkdocs.yml")
    assert "--strict" in argv and argv[-2:] == ["-d", str((tmp_path / "site").resolve())]
    assert env["JRIGID_DOCS_QUICK"] == "1"
    argv, env, _ = cli.docs_command("serve", False, None)
    assert argv[3] == "serve" and "--strict" not in argv and env["JRIGID_DOCS_QUICK"] == "0"
    with pytest.raises(SystemExit) as info:
        cli.main(["docs", "publish"])
    assert info.value.code == 2
