"""Messages a user acts on: the cause named, never a bare ``None``, no progress bar in a log."""

from __future__ import annotations

import io

import numpy as np

from crosscert.planner import PlanningBounds
from crosscert.planner.cli import main, setup
from crosscert.planner.plan import plan_crossing
from crosscert.verifier.trajfile import write_trajectory


def test_a_recording_that_starts_moving_names_xd0(kin, task, tmp_path, capsys):
    plan = plan_crossing(kin, task, 1.3, PlanningBounds())
    k = plan.k_sing - 30  # 30 ms before the locus, at 1.3 m/s
    rec = tmp_path / "moving.csv"
    write_trajectory(rec, plan.t[: len(plan.t) - k], plan.q[k:])
    code = main(["check", str(rec), "--initial-mode", "1", "--reasoning", "forward", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 3 and "--xd0" in err and "starts while the robot moves" in err, err


def test_a_window_decided_verdict_says_so_instead_of_none(kin, task, tmp_path, capsys):
    plan = plan_crossing(kin, task, 1.1, PlanningBounds())
    rec = tmp_path / "plan.csv"
    write_trajectory(rec, plan.t, plan.q)
    # a horizon too short for the anchored windows: the window over the whole recording decides
    assert main(["check", str(rec), "--initial-mode", "1", "--no-progress", "--horizon", "2"]) == 0
    out = capsys.readouterr().out
    assert "verdict: mode-changed" in out
    assert "certified_at_step: none: decided by window reasoning over the whole run" in out and "None" not in out


def test_progress_bars_only_on_a_terminal(monkeypatch):
    class Tty(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.setattr("sys.stderr", io.StringIO())
    assert setup.phase_bar(True, "certify") is None and setup.progress_bar(10, True, "sweep") == (None, None)
    monkeypatch.setattr("sys.stderr", Tty())
    bar = setup.phase_bar(True, "certify")
    assert bar is not None
    bar.close()
    assert setup.phase_bar(False, "certify") is None


def test_a_file_of_another_period_than_stated_says_both(tmp_path, capsys):
    rec = tmp_path / "500hz.csv"
    q = np.tile([1.7, 1.4], (5, 1))
    write_trajectory(rec, 0.002 * np.arange(5), q)
    assert main(["check", str(rec), "--initial-mode", "1", "--t-s", "0.001", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("the file's step is 0.002 s, --t-s says 0.001 s: drop --t-s to read the period from the "
                        "file, or correct it") and len(err.splitlines()) == 1
