"""``crosscert study`` through main(argv): the grid file, refusals before any work, a tiny real run and its restart."""

import csv
import math
import os
from pathlib import Path

import pytest

from crosscert.planner.cli import main
from crosscert.planner.cli.study import read_grid

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
    ("[grid]\na_max = [80.0]\n[certify]\nexecutor = 1\n", "allowed: tol, refute_tol, v_low, v_high, monte_carlo_runs, refute, seed"),
    ("[grid]\na_max = [80.0]\n[certify]\nrefute = 1\n", "refute must be true or false"),
    ("[grid]\na_max = [80.0]\n[certify]\ntol = 0\n", "[certify] tol = 0 m/s is out of range"),
    ("[grid]\na_max = [80.0]\n[certify]\nrefute_tol = 0\n", "[certify] refute_tol = 0 m/s is out of range"),
    ("[grid]\na_max = [80.0]\n[certify]\nrefute_tol = \"fine\"\n", "[certify] refute_tol must be a finite number"),
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
    ("[grid]\nwidth_scale = [1e6]\n", "[grid] width_scale = 1e+06 is out of range"),
    ("[grid]\n\"width_scale.lengths\" = [0.5, 200.0]\n", "[grid] width_scale.lengths = 200 is out of range"),
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


def _spy_on_figures(monkeypatch) -> list:
    """The figures saved during the test (to read what was drawn, not only that a file was written)."""
    from matplotlib.figure import Figure

    saved, original = [], Figure.savefig

    def savefig(fig, *args, **kwargs):
        saved.append(fig)
        return original(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", savefig)
    return saved


def test_tiny_study_runs_then_restarts_without_work(tmp_path, capsys, monkeypatch):
    grid = tmp_path / "tiny.toml"
    grid.write_text(TINY)
    res, png = tmp_path / "res.csv", tmp_path / "p.png"
    argv = ["study", str(grid), "--workers", "1", "--no-progress", "-o", str(res), "--plot", str(png)]
    figures = _spy_on_figures(monkeypatch)
    assert main(argv) == 0
    out = capsys.readouterr().out
    rows = _rows(res)
    assert len(rows) == 1 and rows[0]["error"] == "", rows
    assert math.isfinite(float(rows[0]["v_min_mps"])) and float(rows[0]["a_max"]) == 80.0
    # the PNG shows the case: its v_min is a plotted point (a figure without the data would pass size > 0)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and len(figures) == 1
    drawn = [y for ax in figures[0].axes for line in ax.get_lines() for y in line.get_ydata()]
    assert float(rows[0]["v_min_mps"]) in drawn, drawn
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


def _fake_rows(calls):
    """A ``run_cases`` that certifies nothing: one complete row per case, and the cases it was given."""
    import json

    from crosscert.planner.study import GRID_KEYS

    def run_cases(cases, settings):
        calls.extend(c.case_id for c in cases)
        return [{"case_id": c.case_id, **{k: c.values.get(k, "") for k in GRID_KEYS}, "v_min_mps": 1.0,
                 "refutation_bound_mps": 0.9, "verdict": "mode-changed", "trials": 3, "a_max_used_mps2": "",
                 "elapsed_s": 0.1, "error": "", "versions": json.dumps({"crosscert": "test"})} for c in cases]

    return run_cases


@pytest.fixture
def fake_study(monkeypatch):
    """``crosscert study`` on a thread with a fake ``run_cases``: the CSV handling without certifications."""
    from concurrent.futures import ThreadPoolExecutor
    import functools

    import sys

    import crosscert.planner.study as study_mod

    cli_study = sys.modules["crosscert.planner.cli.study"]  # the package's name `study` is the command function

    calls = []
    monkeypatch.setattr(study_mod, "run_cases", _fake_rows(calls))
    monkeypatch.setattr(cli_study, "run_study",
                        functools.partial(study_mod.run_study, executor=ThreadPoolExecutor(max_workers=1)))
    return calls


def _grid(tmp_path, values, name="g.toml"):
    p = tmp_path / name
    p.write_text(f"robot = 'dextar'\n[grid]\na_max = {values}\n[certify]\nrefute = false\n")
    return p


def test_torn_last_row_is_cut_off_with_one_warning_and_its_case_runs_again(tmp_path, fake_study, capsys):
    grid, res = _grid(tmp_path, [70.0, 80.0, 90.0]), tmp_path / "res.csv"
    argv = ["study", str(grid), "--no-progress", "-o", str(res)]
    assert main(argv) == 0 and len(fake_study) == 3
    capsys.readouterr()
    whole = res.read_bytes()
    last = _rows(res)[-1]["case_id"]
    res.write_bytes(whole[:-25])  # killed while writing the last row
    res.chmod(0o640)
    fake_study.clear()
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "crosscert: warning:" in err and "cut short" in err, err
    assert fake_study == [last]  # the torn case, once
    rows = _rows(res)
    assert len(rows) == 3 and len({r["case_id"] for r in rows}) == 3
    assert res.read_bytes() == whole and oct(res.stat().st_mode & 0o777) == "0o640"
    fake_study.clear()
    assert main(argv) == 0 and fake_study == []  # nothing torn, nothing to run
    assert capsys.readouterr().err == ""


def test_a_row_merged_onto_a_torn_one_is_no_crash(tmp_path, fake_study, capsys):
    """A file an older version left corrupt (a new row appended onto a torn one): the line is ignored."""
    grid, res = _grid(tmp_path, [70.0, 80.0]), tmp_path / "res.csv"
    argv = ["study", str(grid), "--no-progress", "-o", str(res)]
    assert main(argv) == 0
    lines = res.read_text().splitlines(keepends=True)
    res.write_text(lines[0] + lines[1][:30] + lines[1] + lines[2])
    fake_study.clear()
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert len(fake_study) == 1 and "2 cases (1 already in" in out  # the merged line is no row: its case ran


def test_two_grids_in_one_csv_are_refused(tmp_path, fake_study, capsys):
    res = tmp_path / "res.csv"
    assert main(["study", str(_grid(tmp_path, [70.0, 80.0])), "--no-progress", "-o", str(res)]) == 0
    capsys.readouterr()
    before = res.read_bytes()
    other = _grid(tmp_path, [100.0], "other.toml")
    assert main(["study", str(other), "--no-progress", "-o", str(res)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds 2 row(s) of another grid (e.g. a_max = 70" in err, err
    assert res.read_bytes() == before
    grown = _grid(tmp_path, [70.0, 80.0, 90.0], "grown.toml")  # a value added: the same study, grown
    assert main(["study", str(grown), "--no-progress", "-o", str(res)]) == 0
    assert len(_rows(res)) == 3


def test_scheduler_that_cannot_be_reached_is_one_line(tmp_path, capsys):
    """A well-formed address nobody listens on: one line, exit 2, no row written."""
    import dask

    res = tmp_path / "res.csv"
    grid = _grid(tmp_path, [70.0])
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        assert main(["study", str(grid), "--no-progress", "-o", str(res), "--scheduler", "tcp://127.0.0.1:1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("crosscert: error: cannot reach the Dask scheduler at tcp://127.0.0.1:1"), err
    assert not res.exists()
