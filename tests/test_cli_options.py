"""Every option of every command with its bad values: one line on stderr, exit 2, nothing written, no work done.

One table: ``(command line, what the message must say)``.  ``{d}`` is a
fresh folder (checked to stay empty), ``{rec}`` a valid recording in another.
"""

import os
import time

import numpy as np
import pytest

from crosscert.planner.cli import main
from crosscert.verifier.trajfile import write_trajectory

SIM = ["simulate", "--v-sing", "1.2", "-o", "{d}/o.csv"]
PLAN = ["plan", "--v-sing", "1.2", "-o", "{d}/p.csv"]
CERT = ["certify", "--out", "{d}/c"]
CHECK = ["check", "{rec}", "--initial-mode", "1"]
SWEEP = ["sweep", "--out", "{d}/s"]

CASES = [
    # robots
    (["robots", "--validate", "delta"], "unknown robot 'delta'"),
    (["robots", "--seed", "-1"], "not a non-negative whole number"),
    # simulate
    (SIM[:2] + ["0", *SIM[3:]], "--v-sing = 0 m/s is out of range"),
    (SIM[:2] + ["1e-9", *SIM[3:]], "samples"),
    (SIM[:2] + ["nan", *SIM[3:]], "not a decimal number"),
    (SIM[:2] + ["1_0.5", *SIM[3:]], "not a decimal number"),
    (SIM[:2] + ["\u0661", *SIM[3:]], "not a decimal number"),
    (SIM + ["--a-peak", "1e-6"], "samples"),
    (SIM + ["--a-peak", "1000"], "exceeds the robot's bound a_max"),
    (SIM + ["--a-peak", "-1"], "--a-peak = -1"),
    (SIM + ["--t-rest", "1e4"], "--t-rest = 10000 s is out of range"),
    (SIM + ["--t-rest", "-1"], "--t-rest = -1 s is out of range"),
    (SIM + ["--seed", "-1"], "not a non-negative whole number"),
    (SIM + ["--robot", "delta"], "unknown robot 'delta'"),
    (SIM[:4] + ["/dev/null"], "must end in .csv"),
    (SIM[:4] + ["{d}/no/o.csv"], "does not exist"),
    (SIM[:4] + ["{d}/o.xyz"], "must end in .csv"),
    (SIM[:4] + [""], "must end in .csv"),
    # plan
    (PLAN[:2] + ["1e-9", *PLAN[3:]], "samples"),
    (PLAN[:2] + ["-1", *PLAN[3:]], "--v-sing = -1 m/s is out of range"),
    (PLAN + ["--a-peak", "1000"], "exceeds the robot's bound a_max"),
    (PLAN + ["--start", "0,0.14,3"], "expected 2 comma-separated numbers"),
    (PLAN + ["--start", "0,abc"], "expected comma-separated numbers"),
    (PLAN + ["--start", "0,0.0244926", "--goal", "0,0.0244926"], "coincide"),
    (PLAN + ["--method", "fast"], "invalid choice"),
    (PLAN[:4] + ["{d}"], "must end in .csv"),
    # certify
    (CERT + ["--tol", "0"], "--tol = 0 m/s is out of range"),
    (CERT + ["--tol", "1e-12"], "--tol = 1e-12 m/s is out of range"),
    (CERT + ["--tol", "-1"], "--tol = -1 m/s is out of range"),
    (CERT + ["--tol", "nan"], "not a decimal number"),
    (CERT + ["--refute-tol", "0"], "--refute-tol = 0 m/s is out of range"),
    (CERT + ["--refute-tol", "2"], "--refute-tol = 2 m/s is out of range"),
    (CERT + ["--refute-tol", "inf"], "not a decimal number"),
    (CERT + ["--monte-carlo", "-1"], "not a non-negative whole number"),
    (CERT + ["--monte-carlo", "1000000"], "--monte-carlo = 1e+06 is out of range"),
    (CERT + ["--seed", "-1"], "not a non-negative whole number"),
    (CERT + ["--eps-q", "1"], "--eps-q = 1 rad is out of range"),
    (CERT + ["--eps-q", "0"], "--eps-q = 0 rad is out of range"),
    (CERT + ["--tracking-error", "1"], "--tracking-error = 1 rad is out of range"),
    (CERT + ["--a-peak", "1000"], "exceeds the robot's bound a_max"),
    (CERT + ["--a-max", "30"], "--a-max 30 m/s^2 is below --a-peak 60"),
    (CERT + ["--a-max", "0"], "--a-max = 0 m/s^2 is out of range"),
    (CERT + ["--v-low", "0"], "--v-low = 0 m/s is out of range"),
    (CERT + ["--v-low", "1", "--v-high", "0.5"], "--v-high = 0.5 m/s is out of range"),
    (CERT + ["--v-low", "1e-9"], "samples"),
    (CERT + ["--execution", "loose"], "invalid choice"),
    (CERT[:2] + ["{rec}"], "exists and is not a folder"),
    (CERT[:2] + ["{d}/no/deeper"], "cannot create or write"),
    # check and monitor
    (CHECK + ["--eps-q", "1"], "--eps-q = 1 rad is out of range"),
    (CHECK + ["--eps-q=-1e-4"], "--eps-q = -0.0001 rad is out of range"),
    (CHECK + ["--a-max", "0"], "--a-max = 0 m/s^2 is out of range"),
    (CHECK + ["--xd0", "-1"], "--xd0 = -1 m/s is out of range"),
    (CHECK + ["--plot", "{d}/x.xyz"], "must end in .png"),
    (CHECK + ["--plot", "{rec}"], "must end in .png"),
    (CHECK + ["--plot", ""], "must end in .png"),
    (CHECK + ["--plot", "{d}/nodir/x.png"], "does not exist"),
    (CHECK + ["--plot", "/dev/full"], "must end in .png"),
    (["check", "{rec}", "--x0=0,1,2"], "expected 4 comma-separated numbers"),
    (CHECK + ["--initial-mode", "2"], "invalid choice"),
    (CHECK + ["--reasoning", "psychic"], "invalid choice"),
    (["monitor", "{rec}", "--initial-mode", "1", "--horizon", "500000"],
     "--horizon = 500000 samples is out of range: it must lie in [2, 100000] samples"),
    (["check", "{rec}", "--initial-mode", "1", "--horizon", "1"],
     "--horizon = 1 samples is out of range: it must lie in [2, 100000] samples"),
    (["check", "{rec}", "--x0=0.1,0,0,0.1"], "--x0: component 1 has lower bound 0.1 above upper bound 0"),
    (["monitor", "{rec}", "--x0=0,0.1,0.2,0.1"], "--x0: component 2 has lower bound 0.2 above upper bound 0.1"),
    (CHECK + ["--stamp-error=-1e-5"], "--stamp-error = -1e-05 s is out of range"),
    (CHECK + ["--stamp-error", "6"], "--stamp-error = 6 s is out of range"),
    (CHECK + ["--stamp-error", "1e-5", "--certificate", "{d}/certificate.json"],
     "--certificate pairs each reading with the certified plan's sample of the same index"),
    (CHECK + ["--t-s", "0"], "--t-s = 0 s is out of range"),
    (CHECK + ["--t-s", "11"], "--t-s = 11 s is out of range"),
    (["monitor", "{rec}", "--initial-mode", "1", "--horizon", "-3"], "not a non-negative whole number"),
    (["check", "{d}", "--initial-mode", "1"], "is a directory"),
    (["check", "{d}/none.csv", "--initial-mode", "1"], "no such file"),
    (["monitor", "{rec}", "--initial-mode", "1", "--t-s", "0"], "--t-s = 0 s is out of range"),
    (["monitor", "{rec}", "--initial-mode", "1", "--t-s", "-1"], "--t-s = -1 s is out of range"),
    # sweep
    (SWEEP + ["--speeds", "1e-9"], "samples"),
    (SWEEP + ["--speeds", "1,-2"], "--speeds = -2 m/s is out of range"),
    (SWEEP + ["--speeds", "1,x"], "expected comma-separated numbers"),
    (SWEEP + ["--seed", "-3"], "not a non-negative whole number"),
    (SWEEP[:2] + ["{rec}"], "exists and is not a folder"),
    # study (the grid: docs/examples/study_grid.toml; bad grid files: tests/test_cli_study.py)
    (["study", os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "study_grid.toml"),
      "-o", "{d}/r.csv", "--workers", "0"], "--workers = 0 is out of range"),
    (["study", os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "study_grid.toml"),
      "-o", "{d}/r.csv", "--workers", "-1"], "not a non-negative whole number"),
    (["study", os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "study_grid.toml"),
      "-o", "{d}/r.csv", "--workers", "2", "--scheduler", "tcp://localhost:8786"], "not allowed with argument"),
    (["study", os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "study_grid.toml"),
      "-o", "{d}/r.txt"], "must end in .csv"),
    (["study", os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "study_grid.toml"),
      "-o", "{d}/no/r.csv"], "does not exist"),
    (["study", os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "study_grid.toml"),
      "-o", "{rec}"], "is not the CSV of a study"),
    (["study", os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "study_grid.toml"),
      "-o", "{d}/r.csv", "--plot", "{d}/p.jpg"], "must end in .png"),
    (["study", os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "study_grid.toml"),
      "-o", "{d}/r.csv", "--robot", "delta"], "unknown robot 'delta'"),
    (["study", os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "study_grid.toml"),
      "-o", "{d}/r.csv", "--scheduler", "notanaddress"], "--scheduler 'notanaddress' is not the address of a Dask"),
    (["study", os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "study_grid.toml"),
      "-o", "{d}/r.csv", "--scheduler", "tcp://host:port"], "write tcp://HOST:PORT"),
    (["study", "{rec}", "-o", "{d}/r.csv"], "is not valid TOML"),
    (["study", "{d}/none.toml", "-o", "{d}/r.csv"], "no such file"),
    (["study", "{d}", "-o", "{d}/r.csv"], "is a directory"),
    (["study", "{d}/none.toml"], "the following arguments are required: -o/--output"),
]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "rec.csv"
    t = np.arange(20) * 1e-3
    write_trajectory(path, t, np.tile([1.9, 1.2], (20, 1)))
    return path


@pytest.mark.parametrize("argv, message", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_bad_option_is_refused_before_any_work(argv, message, tmp_path, recording, capsys):
    args = [a.format(d=tmp_path, rec=recording) for a in argv]
    before = os.stat(recording).st_mtime_ns
    t0 = time.perf_counter()
    assert main(args) == 2
    elapsed = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert message in err, err
    assert list(tmp_path.iterdir()) == [], "nothing may be written on refusal"
    assert os.stat(recording).st_mtime_ns == before
    assert elapsed < 5.0, f"refused after {elapsed:.1f} s of work"


def test_every_command_is_in_the_table():
    from crosscert.planner.cli import _COMMANDS

    tried = {c[0][0] for c in CASES}
    assert tried == set(_COMMANDS)


def test_help_shows_defaults_and_robots_and_version(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["certify", "--help"])
    assert stop.value.code == 0
    out = capsys.readouterr().out
    assert "(default: 0.01)" in out and "(default: 60.0)" in out and "(default: 0.0)" in out
    assert "one of 3rpr, dextar, gough-stewart" in out and "``" not in out
    with pytest.raises(SystemExit):
        main(["--help"])  # the README: `crosscert --help` lists the robots
    assert "3rpr, dextar, gough-stewart" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.startswith("crosscert ")


@pytest.mark.parametrize("argv, shown", [
    (["check", "--help"], ["default of dextar: 9.23998e-05 rad", "default of dextar: 80 m/s^2", "0.001 s"]),
    # units from the robot's assumptions: its legs are prismatic (m), its pose mixes m and rad
    (["monitor", "--robot", "3rpr", "--help"], ["encoder error bound, m (default of 3rpr: 5e-06 m",
                                                "(80, 80, 200) (m/s^2, m/s^2, rad/s^2)",
                                                "(0.1, 0.1, 1) (m/s, m/s, rad/s)"]),
    (["certify", "--robot=gough-stewart", "--help"], ["default of gough-stewart: 5e-06 m"]),
])
def test_help_gives_the_robot_defaults_with_values(argv, shown, capsys):
    """Robot defaults in --help are values, of --robot's robot (the default robot without one)."""
    with pytest.raises(SystemExit):
        main(argv)
    out = " ".join(capsys.readouterr().out.split())
    assert "robot default" not in out
    for text in shown:
        assert text in out, text


def test_robots_list_gives_units(capsys):
    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    assert "dextar: n = 2, m = 7, t_s = 0.001 s, eps_q = 9.23998e-05 rad, a_max = (80, 80) m/s^2" in out
    assert "xd0 = (0.1, 0.1) m/s" in out
