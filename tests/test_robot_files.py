"""A user's robot in every command: a robot file (``--robot path.py:NAME``) and an installed distribution's entry
point (group ``crosscert.robots``), through the real command line (``planner.cli.main``)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from crosscert.planner.cli import main
from crosscert.robots import registry

EXAMPLE = Path(__file__).resolve().parents[1] / "docs" / "examples" / "five_bar.py"
ROBOT = f"{EXAMPLE}:FIVE_BAR"
#: Far enough from the locus that the calibration box leaves one solution per mode (docs/your-robot.md).
START = "0.05"
#: A narrow, quick speed search: the test is about the robot reaching the command, not about v_min.
QUICK_CERTIFY = ["--v-low", "0.6", "--v-high", "1.0", "--tol", "0.2", "--monte-carlo", "0", "--no-refute",
                 "--no-progress"]


@pytest.fixture
def fresh_registry(monkeypatch):
    """No robot loaded from a file or an entry point by another test of this process."""
    monkeypatch.setattr(registry, "_LOADED", {})


def _one_line_error(capsys, argv, *expected) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("crosscert: error: "), err
    for text in expected:
        assert text in err, err
    return err


def test_the_example_five_bar_from_its_file_is_simulated_checked_and_certified(tmp_path, capsys, fresh_registry):
    run = tmp_path / "run.csv"
    assert main(["simulate", "--robot", ROBOT, "--v-sing", "1.0", "--start-distance", START, "-o", str(run)]) == 0
    assert "start 50.0 mm before the locus" in capsys.readouterr().out
    assert main(["check", str(run), "--robot", ROBOT, "--initial-mode", "1", "--json", "--no-progress"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["verdict"] == "mode-changed" and summary["final_mode"] == -1
    out = tmp_path / "cert"
    assert main(["certify", "--robot", ROBOT, "--out", str(out), *QUICK_CERTIFY]) == 0
    assert "minimal certified v_sing" in capsys.readouterr().out
    assert json.loads((out / "certificate.json").read_text())["robot"] == "five-bar-250"


def test_a_start_next_to_the_locus_says_why_it_is_refused(tmp_path, capsys, fresh_registry):
    run = tmp_path / "near.csv"
    assert main(["simulate", "--robot", ROBOT, "--v-sing", "1.0", "-o", str(run)]) == 0
    capsys.readouterr()
    _one_line_error(capsys, ["check", str(run), "--robot", ROBOT, "--initial-mode", "1", "--no-progress"],
                    "too close to the Type 2 locus for the calibration box")


def test_robots_lists_a_file_with_where_it_comes_from(capsys, fresh_registry):
    assert main(["robots", "--robot", ROBOT]) == 0
    rows = capsys.readouterr().out.splitlines()
    assert any(r.startswith("dextar: ") and r.endswith("; from built-in") for r in rows)
    assert rows[-1].startswith("five-bar-250: n = 2, m = 7") and rows[-1].endswith(f"from file {ROBOT}")
    assert main(["robots", "--validate", ROBOT]) == 0
    assert "five-bar-250: every check passed" in capsys.readouterr().out


def test_a_relative_robot_file_is_found_from_the_current_folder(tmp_path, monkeypatch, capsys, fresh_registry):
    shutil.copy(EXAMPLE, tmp_path / "mine.py")
    monkeypatch.chdir(tmp_path)
    assert main(["robots", "--robot", "mine.py:FIVE_BAR"]) == 0
    assert capsys.readouterr().out.splitlines()[-1].endswith(f"from file {tmp_path / 'mine.py'}:FIVE_BAR")
    # one RobotEntry in the file: its name may be left out
    assert main(["simulate", "--robot", "mine.py", "--v-sing", "1", "-o", "r.csv"]) == 0


BROKEN = {
    "missing file": (None, "does not exist"),
    "syntax error": ("x = (\n", "SyntaxError at line 1"),
    "exception": ("import math\n\nraise RuntimeError('no calibration data')\n", "RuntimeError at line 3: no calibration data"),
    "missing name": ("from five_bar_copy import ROBOT  # a Robot, no RobotEntry\n", "defines no 'FIVE_BAR' (it defines no RobotEntry)"),
    "not an entry": ("FIVE_BAR = 3\n", "is a int, not a RobotEntry"),
    "bad robot": ("import dataclasses\nfrom five_bar_copy import ROBOT\n"
                  "FIVE_BAR = dataclasses.replace(ROBOT, xi_lo=ROBOT.xi_hi, xi_hi=ROBOT.xi_lo)\n",
                  "ModelError at line 3: Robot five-bar-250: interval of l11 is empty"),
    "fails validation": ("import dataclasses\nfrom crosscert.robots import RobotEntry\nfrom five_bar_copy import ROBOT, benchmark\n"
                         "FIVE_BAR = RobotEntry(dataclasses.replace(ROBOT, mode_sign=-1.0), benchmark=benchmark)\n",
                         "fails validation (mode-convention: ", "mode_sign has the wrong sign"),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
@pytest.mark.parametrize("command", ["check", "certify", "simulate"])
def test_a_broken_robot_file_is_one_line_and_exit_2(case, command, tmp_path, monkeypatch, capsys, fresh_registry):
    source, *expected = BROKEN[case]
    shutil.copy(EXAMPLE, tmp_path / "five_bar_copy.py")
    monkeypatch.syspath_prepend(str(tmp_path))
    path = tmp_path / "robot.py"
    if source is not None:
        path.write_text(source)
    robot = f"{path}:FIVE_BAR"
    argv = {"check": ["check", str(tmp_path / "any.csv"), "--initial-mode", "1"],
            "certify": ["certify", "--out", str(tmp_path / "c"), *QUICK_CERTIFY],
            "simulate": ["simulate", "--v-sing", "1", "-o", str(tmp_path / "s.csv")]}[command]
    _one_line_error(capsys, [*argv, "--robot", robot], *expected)
    assert not (tmp_path / "s.csv").exists() and not (tmp_path / "c").exists()


def test_an_unknown_robot_names_the_file_form(capsys):
    _one_line_error(capsys, ["robots", "--validate", "delta"], "unknown robot 'delta'", "path/to/file.py:NAME")


# ------------------------------------------------------------------ an installed distribution's entry point
def _install(site: Path, entry_points: str, module: str = "my_robots") -> None:
    """A distribution ``my-robots 1.0`` in folder ``site``: its module and its ``*.dist-info`` with entry points."""
    shutil.copy(EXAMPLE, site / f"{module}.py")
    info = site / "my_robots-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: my-robots\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[crosscert.robots]\n{entry_points}\n")


def test_an_installed_entry_point_is_listed_checked_and_certified(tmp_path, monkeypatch, capsys, fresh_registry):
    _install(tmp_path, "five-bar-250 = my_robots:FIVE_BAR")
    monkeypatch.syspath_prepend(str(tmp_path))  # importlib.metadata finds the dist-info on sys.path
    assert "five-bar-250" in registry.available_robots()
    assert main(["robots"]) == 0
    row = next(r for r in capsys.readouterr().out.splitlines() if r.startswith("five-bar-250: "))
    assert row.endswith("from entry point my-robots 1.0 (my_robots:FIVE_BAR)")
    run = tmp_path / "run.csv"
    assert main(["simulate", "--robot", "five-bar-250", "--v-sing", "1.0", "--start-distance", START, "-o", str(run)]) == 0
    assert main(["check", str(run), "--robot", "Five-Bar-250", "--initial-mode", "1", "--json", "--no-progress"]) == 0
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["verdict"] == "mode-changed"
    assert main(["certify", "--robot", "five-bar-250", "--out", str(tmp_path / "cert"), *QUICK_CERTIFY]) == 0
    assert "minimal certified v_sing" in capsys.readouterr().out


@pytest.mark.parametrize("entry, expected", [
    ("other-name = my_robots:FIVE_BAR", "holds the robot 'five-bar-250': name the entry point after its robot"),
    ("five-bar-250 = my_robots:NOT_THERE", "failed to load: AttributeError"),
    ("five-bar-250 = my_robots:ROBOT.n", "is a int, not a RobotEntry"),
])
def test_a_broken_entry_point_is_one_line_and_exit_2(entry, expected, tmp_path, monkeypatch, capsys, fresh_registry):
    _install(tmp_path, entry)
    monkeypatch.syspath_prepend(str(tmp_path))
    name = entry.split(" = ")[0]
    _one_line_error(capsys, ["check", str(tmp_path / "any.csv"), "--robot", name, "--initial-mode", "1"],
                    "entry point", "of my-robots 1.0", expected)
    _one_line_error(capsys, ["robots"], expected)  # the listing loads every entry point


# ------------------------------------------------------------------ simulate --start-distance
def test_start_distance_is_refused_where_it_means_nothing(tmp_path, capsys):
    _one_line_error(capsys, ["simulate", "--robot", "gough-stewart", "--v-sing", "0.3", "--start-distance", "0.05",
                             "-o", str(tmp_path / "m.csv")], "no locus to start away from")
    _one_line_error(capsys, ["simulate", "--v-sing", "1", "--start-distance", "0", "-o", str(tmp_path / "m.csv")],
                    "--start-distance")


def test_a_bounce_starts_the_distance_before_its_turning_point(tmp_path, capsys):
    assert main(["simulate", "--v-sing", "1", "--bounce", "--start-distance", "0.08", "-o", str(tmp_path / "b.csv")]) == 0
    out = capsys.readouterr().out
    assert "samples of a bounce" in out and "start 80.0 mm before the locus" in out


# ------------------------------------------------------------------ sweep on a cold numba cache
@pytest.mark.parametrize("cold", [True, False])
def test_sweep_says_when_the_kernels_compile(cold, tmp_path, monkeypatch, capsys):
    from crosscert.verifier.compiled import warm

    monkeypatch.setattr(warm, "cached", lambda code: not cold)  # the cache as after an install, or as after a run
    assert main(["sweep", "--speeds", "1.458", "--out", str(tmp_path / "s"), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert err == ("crosscert: compiling the kernels (first run only, about 20 s)\n" if cold else "")
