"""``crosscert study`` through main(argv): the grid file, refusals before any work, a tiny real run and its restart."""

import csv
import math
import os
from pathlib import Path

import pytest

from planner.cli import main
from planner.cli.study import read_grid

EXAMPLE = Path(__file__).resolve().parents[1] / "docs" / "examples" / "study_grid.toml"


def test_example_grid_is_read():
    spec = read_grid(EXAMPLE)
    assert spec["robot"] == "dextar"
    assert spec["grid"] == {"a_max": [70.0, 100.0], "width_scale": [0.5, 1.0]}
    assert spec["certify"] == {"tol": 0.02, "refute": True, "monte_carlo_runs": 0}
    assert spec["bounds"] == {"a_peak": 60.0}


def test_sub_tables_are_flattened(tmp_path):
    p = tmp_path / "g.toml"
    p.write_text("[grid.width_scale]\nlengths = [0.5]\noffsets = [1.0, 2.0]\n")
    assert read_grid(p)["grid"] == {"width_scale.lengths": [0.5], "width_scale.offsets": [1.0, 2.0]}


BAD = [
    ("[grid]\nspeed = [1.0]\n", "unknown study input 'speed'"),
    ("[grid]\na_max = []\n", "has no values"),
    ("[grid]\na_max = ['fast']\n", "a_max must be a number"),
    ("[grid]\na_max = [80.0]\n[certify]\nexecutor = 1\n", "allowed: tol, v_low, v_high, monte_carlo_runs, refute, seed"),
    ("[grid]\na_max = [80.0]\n[certify]\nrefute = 1\n", "refute must be true or false"),
    ("[grid]\na_max = [80.0]\n[certify]\ntol = 0\n", "[certify] tol = 0 m/s is out of range"),
    ("[grid]\na_max = [80.0]\n[certify]\nmonte_carlo_runs = -1\n", "non-negative whole number"),
    ("[grid]\na_max = [80.0]\n[bounds]\nspeed = 1\n", "unknown [bounds] key 'speed'"),
    ("[grid]\na_max = [80.0]\n[bounds]\neps_q = 1.0\n", "[bounds] eps_q = 1 rad is out of range"),
    ("[grid]\na_max = [80.0]\n[bounds]\na_peak = 'x'\n", "a_peak must be a number"),
    ("[grid]\neps_q = [1.0]\n", "[grid] eps_q = 1 rad is out of range"),
    ("[grid]\nmethod = ['fast']\n", "method"),
    ("robot = 'delta'\n[grid]\na_max = [80.0]\n", "unknown robot 'delta'"),
    ("robot = 3\n[grid]\na_max = [80.0]\n", "robot must be a name"),
    ("grid = 3\n", "[grid] must be a table"),
    ("[bounds]\na_peak = 60.0\n", "no [grid] table"),
    ("seed = 1\n[grid]\na_max = [80.0]\n", "unknown entry 'seed'"),
    ("[grid]\na_max = [", "is not valid TOML"),
    ("t,q1,q2\n0,1.9,1.2\n", "is not valid TOML"),
    ("[grid]\na_max = [" + ", ".join(str(50.0 + i) for i in range(101)) + "]\nwidth_scale = ["
     + ", ".join(str(0.5 + 0.01 * i) for i in range(100)) + "]\n", "the grid has 10100 cases, more than 10000"),
]


@pytest.mark.parametrize("text, message", BAD, ids=[m for _, m in BAD])
def test_bad_grid_is_refused_before_any_work(text, message, tmp_path, capsys):
    grid = tmp_path / "grid.toml"
    grid.write_text(text)
    out = tmp_path / "out"
    out.mkdir()
    assert main(["study", str(grid), "-o", str(out / "r.csv"), "--plot", str(out / "p.png"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert message in err, err
    assert list(out.iterdir()) == []


@pytest.mark.parametrize("where, message", [("none.toml", "no such file"), (".", "is a directory")])
def test_missing_grid_file_is_refused(where, message, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    assert main(["study", str(tmp_path / where), "-o", str(out / "r.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert list(out.iterdir()) == []


def test_unreadable_grid_file_is_refused(tmp_path, capsys):
    if os.geteuid() == 0:
        pytest.skip("root reads every file")
    grid = tmp_path / "grid.toml"
    grid.write_text("[grid]\na_max = [80.0]\n")
    grid.chmod(0)
    assert main(["study", str(grid), "-o", str(tmp_path / "r.csv")]) == 2
    assert "cannot read" in capsys.readouterr().err
    assert not (tmp_path / "r.csv").exists()


TINY = """robot = "dextar"
[grid]
a_max = [80.0]
[certify]
refute = false
monte_carlo_runs = 0
tol = 0.05
"""


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_tiny_study_runs_then_restarts_without_work(tmp_path, capsys):
    grid = tmp_path / "tiny.toml"
    grid.write_text(TINY)
    res, png = tmp_path / "res.csv", tmp_path / "p.png"
    argv = ["study", str(grid), "--workers", "1", "--no-progress", "-o", str(res), "--plot", str(png)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    rows = _rows(res)
    assert len(rows) == 1 and rows[0]["error"] == "", rows
    assert math.isfinite(float(rows[0]["v_min_mps"])) and float(rows[0]["a_max"]) == 80.0
    assert png.stat().st_size > 0
    assert "1 case (0 already" in out and "0 errors" in out and f"wrote {res}" in out and f"wrote {png}" in out
    assert main(argv) == 0  # every case is in the CSV: nothing runs, no cluster starts
    out = capsys.readouterr().out
    assert len(_rows(res)) == 1
    assert "1 already in" in out and "0 run now" in out


def test_foreign_csv_is_not_appended_to(tmp_path, capsys):
    other = tmp_path / "other.csv"
    other.write_text("t,q1,q2\n0,1,2\n")
    before = other.read_text()
    assert main(["study", str(EXAMPLE), "-o", str(other)]) == 2
    assert "is not the CSV of a study" in capsys.readouterr().err
    assert other.read_text() == before


def test_study_without_dask_says_what_to_install(monkeypatch, tmp_path, capsys):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "distributed" else real(name, *a))
    assert main(["study", str(EXAMPLE), "-o", str(tmp_path / "r.csv")]) == 2
    assert "pip install 'crosscert[study]'" in capsys.readouterr().err
