"""Reading recordings as users export them: epoch stamps, a BOM, stdin, pipes, wrong delimiters, odd units."""

import io
import os
import sys
import threading
import tracemalloc

import numpy as np
import pytest

from crosscert.planner.cli import main
from crosscert.robots import DEXTAR
from crosscert.robots.errors import TrajectoryFileError
from crosscert.verifier.trajfile import TrajectoryReader, parse_number, read_trajectory, step_tolerance

Q = "1.9223,1.2191"


def _rows(t0, k, t_s=1e-3, fmt="{:.3f}"):
    return "".join(f"{fmt.format(t0 + i * t_s)},{Q}\n" for i in range(k))


def test_epoch_time_stamps_are_even_sampling(tmp_path):
    """1.7e9 + k 0.001 is not exact in doubles: the steps differ by ~2e-7 s, and the file is still accepted."""
    f = tmp_path / "epoch.csv"
    f.write_text("t,q1,q2\n" + _rows(1.7e9, 500))
    steps = np.diff([1.7e9 + round(i * 1e-3, 3) for i in range(500)])
    assert np.ptp(steps) > 1e-6 * 1e-3  # the old relative test alone would refuse it
    traj = read_trajectory(f, 2, nominal_t_s=1e-3)
    assert traj.t_s == 1e-3 and len(traj) == 500
    with open(f, newline="") as fh:
        reader = TrajectoryReader(fh, 2, f, nominal_t_s=1e-3)
        assert len(list(reader)) == 500 and reader.t_s == 1e-3 and reader.warnings == []


def test_the_tolerance_still_sees_a_dropped_sample(tmp_path):
    f = tmp_path / "gap.csv"
    f.write_text("t,q1,q2\n" + _rows(1.7e9, 10) + _rows(1.7e9 + 0.011, 10))
    with pytest.raises(TrajectoryFileError, match="uneven sampling"):
        read_trajectory(f, 2)
    assert step_tolerance(1.7e9, 1.7e9 + 1e-3, 1e-3) < 1e-5  # far below one period


def test_a_byte_order_mark_is_accepted(tmp_path):
    f = tmp_path / "bom.csv"
    f.write_bytes("\ufefft,q1,q2\n".encode() + _rows(0.0, 5).encode())
    assert len(read_trajectory(f, 2)) == 5
    reader = TrajectoryReader(io.StringIO("\ufefft,q1,q2\n" + _rows(0.0, 3)), 2, "s")
    assert len(list(reader)) == 3


@pytest.mark.parametrize("text, hint", [
    ("t;q1;q2\n0;1;2\n", "semicolons"),
    ("t\tq1\tq2\n0\t1\t2\n", "tabs"),
    ("t,q1,q2\n0,001,1,2\n", "decimal comma"),
])
def test_a_wrong_delimiter_gets_a_hint(tmp_path, text, hint):
    f = tmp_path / "d.csv"
    f.write_text(text)
    with pytest.raises(TrajectoryFileError, match=hint):
        read_trajectory(f, 2)


@pytest.mark.parametrize("cell", ["1_0", "\u0661", "nan", "inf", "-Infinity", "0x10", "1e"])
def test_cells_that_python_would_guess_are_refused(cell, tmp_path):
    with pytest.raises(ValueError):
        parse_number(cell)
    f = tmp_path / "c.csv"
    f.write_text(f"t,q1,q2\n0,{cell},1\n0.001,1,1\n")
    with pytest.raises(TrajectoryFileError, match="line 2"):
        read_trajectory(f, 2)


def test_warnings_name_the_first_odd_sample():
    text = "t,q1,q2\n" + "".join(f"{i},1.9,{1.2 if i < 3 else 100.0}\n" for i in range(6))  # t in s, 1 s apart
    reader = TrajectoryReader(io.StringIO(text), 2, "rec", nominal_t_s=1e-3,
                              q_range=(DEXTAR.q_lo_array, DEXTAR.q_hi_array))
    list(reader)
    assert len(reader.warnings) == 2
    assert "sampling period 1 s differs from the robot's nominal 0.001 s" in reader.warnings[0]
    assert "line 5: q2 = 100 rad is outside the robot's joint range" in reader.warnings[1]


def _peak_memory(rows: int) -> int:
    lines = ("t,q1,q2\n" if i < 0 else f"{i * 1e-3:.3f},{Q}\n" for i in range(-1, rows))
    tracemalloc.start()
    count = sum(1 for _ in TrajectoryReader(lines, 2, "gen", nominal_t_s=1e-3))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert count == rows
    return peak


def test_reading_is_streamed():
    """Eight times more rows through the reader, the same peak memory (within 64 KiB)."""
    small, large = _peak_memory(5_000), _peak_memory(40_000)
    assert large < small + (64 << 10), (small, large)


def test_check_reads_stdin_and_a_named_pipe(tmp_path, monkeypatch, capsys, simulated_recording):
    text = simulated_recording.read_text()
    monkeypatch.setattr(sys, "stdin", io.StringIO(text))
    assert main(["check", "-", "--initial-mode", "1", "--no-progress", "--json"]) == 0
    from_stdin = capsys.readouterr().out
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    writer = threading.Thread(target=lambda: fifo.write_text(text))
    writer.start()
    assert main(["check", str(fifo), "--initial-mode", "1", "--no-progress", "--json"]) == 0
    writer.join()
    from_pipe = capsys.readouterr().out
    assert '"verdict": "mode-changed"' in from_stdin
    assert from_stdin.split('"elapsed_s"')[0] == from_pipe.split('"elapsed_s"')[0]


def test_check_warns_and_still_answers(tmp_path, capsys, simulated_recording):
    q = simulated_recording.read_text().splitlines()[1].split(",", 1)[1]
    f = tmp_path / "ms.csv"
    f.write_text("t,q1,q2\n" + "".join(f"{i},{q}\n" for i in range(30)))  # times written in ms
    assert main(["check", str(f), "--initial-mode", "1", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "crosscert: warning:" in err and "seems to be in ms: convert it to seconds" in err
    assert "pass --t-s 1 to state it" in err  # an option check has
