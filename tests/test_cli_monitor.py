"""``crosscert monitor``: samples tracked as they arrive, events, the summary line, exit codes."""

import io
import json
import os
import queue
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from problems import CATALOGUE, default_settings, interval_model, run_of
from crosscert.planner.cli import main
from crosscert.verifier.tracker import track
from crosscert.verifier.trajfile import write_trajectory

FLAGS = ["--initial-mode", "1", "--json"]


@pytest.fixture(scope="module")
def csv_text(tmp_path_factory):
    """CSV text of each reference problem, by name (written by write_trajectory)."""
    folder = tmp_path_factory.mktemp("monitor")

    def text(name):
        run = run_of(CATALOGUE[name])
        path = folder / f"{name}.csv"
        write_trajectory(path, run.t, run.q_meas)
        return path.read_text()

    return text


def _monitor(monkeypatch, capsys, text, *args):
    """Run ``main(["monitor", *args])`` on ``text`` as stdin: (exit code, JSON lines of stdout, stderr)."""
    monkeypatch.setattr(sys, "stdin", io.StringIO(text))
    code = main(["monitor", *args])
    out, err = capsys.readouterr()
    return code, [json.loads(v) for v in out.splitlines()] if "--json" in args else out, err


def _events(name):
    """The events ``track`` implies on a problem: (k, event, mode) whenever the certified mode changes, and the
    result.  A mode certified again is ``mode-changed`` when it is not the last one certified (on these
    problems the tracker decides alone: no window decides earlier)."""
    res = track(interval_model(), run_of(CATALOGUE[name]).q_meas, default_settings(t_s=0.001), initial_mode=1)
    out, prev, last = [], 0, 0
    for k, m in enumerate(res.mode):
        if m != prev:
            out.append((k, "mode-lost" if m == 0 else "mode-gained" if last in (0, m) else "mode-changed", int(m)))
        prev, last = m, m or last
    return out, res


@pytest.mark.parametrize("name", ["crossing_1458", "bounce_1458"])
def test_forward_verdict_and_events_equal_track(monkeypatch, capsys, csv_text, name):
    """``--reasoning forward``: the tracker alone, its events and summary those of ``track``."""
    code, lines, _ = _monitor(monkeypatch, capsys, csv_text(name), "-", *FLAGS, "--reasoning", "forward")
    run = run_of(CATALOGUE[name])
    expected, res = _events(name)
    *events, last = lines
    assert code == 0
    assert [(e["k"], e["event"], e["mode"]) for e in events] == expected
    assert all(e["t"] == pytest.approx(run.t[e["k"]]) and e["line"] == e["k"] + 2 for e in events)
    summary = res.summary()
    for key in ("verdict", "initial_mode", "final_mode", "certified_at_step", "inconsistent_at_step", "steps"):
        assert last[key] == summary[key], key
    assert last["verdict"] in {v.value for v in CATALOGUE[name].expected}
    assert last["interrupted"] is False and last["t_s"] == 0.001
    assert 0 < last["latency_us_mean"] <= last["latency_us_p99"] <= last["latency_us_max"]


def test_a_dropped_line_is_a_step_of_two_periods_online(monkeypatch, capsys, csv_text):
    """A stream that lost one sample: tracked as a step of two periods, with the stream's verdict, and the
    events still name the samples' own times and lines."""
    lines = csv_text("crossing_1458").splitlines()
    del lines[151]  # sample 150
    code, out, _ = _monitor(monkeypatch, capsys, "\n".join(lines) + "\n", "-", *FLAGS, "--reasoning", "forward")
    *events, last = out
    assert code == 0 and last["verdict"] == "mode-changed" and last["steps"] == len(lines) - 1
    run = run_of(CATALOGUE["crossing_1458"])
    for e in events:
        true_k = e["k"] + (e["k"] >= 150)  # the samples after the gap are one later in the recording
        assert e["t"] == pytest.approx(run.t[true_k]) and e["line"] == e["k"] + 2


def test_check_draws_a_dropped_sample_at_its_time(tmp_path, capsys, csv_text, monkeypatch):
    """``check --plot`` of a recording that lost a sample: the figure's time axis is the stamps'."""
    import crosscert.planner.cli.track as T

    lines = csv_text("crossing_1458").splitlines()
    del lines[151]
    path, png = tmp_path / "gap.csv", tmp_path / "gap.png"
    path.write_text("\n".join(lines) + "\n")
    drawn = {}
    real = T.plot_run
    monkeypatch.setattr(T, "plot_run", lambda *args, **kw: (drawn.update(kw), real(*args, **kw)))
    assert main(["check", str(path), "--initial-mode", "1", "--json", "--plot", str(png), "--reasoning", "forward"]) == 0
    capsys.readouterr()
    t = drawn["t"]
    assert png.stat().st_size > 0 and len(t) == len(lines) - 1
    assert t[150] - t[149] == pytest.approx(2 * (t[1] - t[0]))  # sample 150 was dropped


def test_text_output_from_a_named_pipe(tmp_path, capsys, csv_text):
    run = run_of(CATALOGUE["crossing_1458"])
    x, y = run.x_true[0]
    fifo = tmp_path / "samples"
    os.mkfifo(fifo)
    writer = threading.Thread(target=lambda: fifo.write_text(csv_text("crossing_1458")))
    writer.start()
    code = main(["monitor", str(fifo), f"--x0={x - 0.003},{x + 0.003},{y - 0.003},{y + 0.003}"])
    writer.join()
    out = capsys.readouterr().out
    assert code == 0
    assert "mode-changed, mode -1" in out and "verdict: mode-changed" in out and "update latency: mean" in out


@pytest.mark.parametrize(
    "bad, message",
    [
        ("0.1,abc,1.0", "'abc' in column q1 is not a number"),
        ("0.1,1.0", "2 values for 3 columns"),
        ("0.1,1.0,nan", "NaN and infinities"),
        ("0.0995,1.0,1.0", "is not a whole number of periods"),
        ("0.099,1.0,1.0", "does not increase"),
    ],
)
def test_bad_line_mid_stream(monkeypatch, capsys, csv_text, bad, message):
    lines = csv_text("crossing_1458").splitlines()
    lines[101] = bad  # sample 100, line 102 (the header is line 1)
    code, out, err = _monitor(monkeypatch, capsys, "\n".join(lines) + "\n", "-", *FLAGS)
    *events, last = out
    assert code == 2
    assert err.startswith("crosscert: error: <stdin>, line 102: ") and message in err and "\n" not in err.strip()
    before = [(k, e, m) for k, e, m in _events("crossing_1458")[0] if k < 100]
    assert before and [(e["k"], e["event"], e["mode"]) for e in events] == before  # decided before line 102
    assert last["interrupted"] is True and message in last["error"]
    assert last["steps"] == 100 and last["verdict"] == "unknown" and last["initial_mode"] == 1


def test_inconsistent_exit_3(monkeypatch, capsys, csv_text):
    code, lines, err = _monitor(monkeypatch, capsys, csv_text("crossing_1458"), "-", *FLAGS, "--a-max", "2")
    assert code == 3
    assert [e["event"] for e in lines[:-1]][-1] == "inconsistent"
    assert lines[-1]["verdict"] == "inconsistent" and lines[-1]["inconsistent_at_step"] == lines[-2]["k"]
    assert "a box became empty" in err


@pytest.mark.parametrize(
    "text, args, message",
    [
        ("", (), "empty"),
        ("t,q1,q2\n0,{q}\n", (), "at least two samples"),
        ("t,q1,q2\n0,{q}\n0.002,{q}\n", ("--t-s", "0.001"), "the file's step is 0.002 s, --t-s says 0.001 s"),
        ("t,q1\n0,1\n", (), "missing column"),
    ],
)
def test_bad_input_exit_2(monkeypatch, capsys, text, args, message):
    q = ",".join(repr(float(v)) for v in run_of(CATALOGUE["crossing_1458"]).q_meas[0])
    code, lines, err = _monitor(monkeypatch, capsys, text.format(q=q), *FLAGS, *args)
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert lines[-1]["interrupted"] is True


def test_piped_through_a_subprocess(csv_text):
    """A real pipe: each event is read before the next sample is written; then the summary line."""
    rows = csv_text("crossing_1458").splitlines(keepends=True)
    expected = _events("crossing_1458")[0]
    proc = subprocess.Popen([sys.executable, "-m", "crosscert", "monitor", "-", *FLAGS], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=Path(__file__).resolve().parents[1])
    out = queue.Queue()
    threading.Thread(target=lambda: [out.put(v) for v in proc.stdout], daemon=True).start()
    sent = 0
    try:
        for k, kind, mode in expected:
            upto = max(k, 1) + 2  # header and samples 0..k (sample 0 is tracked once sample 1 fixes t_s)
            for row in rows[sent:upto]:
                proc.stdin.write(row)
                proc.stdin.flush()
            sent = upto
            event = json.loads(out.get(timeout=120))  # arrives while the input is still open
            assert (event["k"], event["event"], event["mode"]) == (k, kind, mode)
        proc.stdin.writelines(rows[sent:])
        proc.stdin.close()
        assert proc.wait(timeout=120) == 0
        last = json.loads(out.get(timeout=10))
    finally:
        proc.kill()
    assert last["verdict"] == "mode-changed" and last["steps"] == 249 and last["certified_at_step"] == 109
    print(f"\nlatency per update over a pipe: mean {last['latency_us_mean']} us, p99 {last['latency_us_p99']} us, "
          f"max {last['latency_us_max']} us")


def test_latency_statistics_in_constant_memory():
    """The histogram's p99 is never below the true one and at most 1 % above; its size does not grow."""
    from crosscert.planner.cli.track import LatencyStats

    rng = np.random.default_rng(7)
    values = rng.lognormal(11.0, 1.0, 50_000).astype(int)
    stats = LatencyStats()
    size = stats.bins.nbytes
    for v in values:
        stats.add(int(v))
    true = np.percentile(values, 99, method="inverted_cdf") / 1e3
    assert true <= stats.quantile_us(0.99) <= true * 1.0101 + 0.1
    assert stats.max_us() == round(values.max() / 1e3, 1) and stats.bins.nbytes == size


@pytest.mark.parametrize("name", ["crossing_1458", "bounce_1458", "crossing_1264", "bounce_0800"])
def test_window_events_are_true(monkeypatch, capsys, csv_text, name):
    """The default (the anchored window on its thread): the tracker's events until it first loses the mode,
    then every certified mode the true one at its sample (a window's event known at or after it), the final
    pose box holding the true pose in the final mode, and a verdict the problem allows."""
    code, lines, _ = _monitor(monkeypatch, capsys, csv_text(name), "-", *FLAGS)
    run = run_of(CATALOGUE[name])
    *events, last = lines
    assert code == 0 and last["reasoning"] == "window"
    tracker_events = _events(name)[0]
    lost = next(i for i, e in enumerate(tracker_events) if e[1] == "mode-lost")
    assert [(e["k"], e["event"], e["mode"]) for e in events[:lost + 1]] == tracker_events[:lost + 1]
    assert all(e["mode"] in (0, run.mode_true[e["k"]]) for e in events), events
    assert all(e.get("known_at_k", e["k"]) >= e["k"] and e["t"] == pytest.approx(run.t[e["k"]]) for e in events)
    assert last["verdict"] in {v.value for v in CATALOGUE[name].expected}
    if last["final_mode"]:
        assert last["final_mode"] == run.mode_true[-1]
    lo, hi = np.array(last["final_pose_lo"]), np.array(last["final_pose_hi"])
    assert np.all(lo <= run.x_true[-1]) and np.all(run.x_true[-1] <= hi)


def test_interrupted_stream_gives_no_verdict_on_the_whole(monkeypatch, capsys, csv_text):
    """Cut before the crossing: the prefix says mode-unchanged, the field a machine reads says unknown."""
    lines = csv_text("crossing_1458").splitlines()
    lines[41] = "0.04,abc,1.0"  # sample 40, line 42
    code, out, err = _monitor(monkeypatch, capsys, "\n".join(lines) + "\n", "-", *FLAGS)
    last = out[-1]
    assert code == 2 and last["interrupted"] is True
    assert last["verdict"] == "unknown" and last["verdict_so_far"] == "mode-unchanged" and last["steps"] == 40
    code, text, _ = _monitor(monkeypatch, capsys, "\n".join(lines) + "\n", "-", "--initial-mode", "1")
    assert "verdict: unknown (input interrupted; on the 40 samples read: mode-unchanged)" in text
    code, out, _ = _monitor(monkeypatch, capsys, csv_text("crossing_1458"), "-", *FLAGS)
    assert out[-1]["verdict"] == out[-1]["verdict_so_far"] == "mode-changed"  # a whole stream: the same


class _InterruptedStdin(io.StringIO):
    """stdin that raises KeyboardInterrupt (Ctrl-C) once ``after`` lines were read."""

    def __init__(self, text, after):
        super().__init__(text)
        self.left = after

    def __next__(self):
        self.left -= 1
        if self.left < 0:
            raise KeyboardInterrupt
        return super().__next__()


def test_ctrl_c_exits_130_with_the_summary_so_far(monkeypatch, capsys, csv_text):
    monkeypatch.setattr(sys, "stdin", _InterruptedStdin(csv_text("crossing_1458"), 60))
    code = main(["monitor", "-", *FLAGS])
    out, err = capsys.readouterr()
    last = json.loads(out.splitlines()[-1])
    assert code == 130 and err == "crosscert: interrupted\n"
    assert last["interrupted"] is True and last["verdict"] == "unknown" and last["steps"] == 59  # the header and 59 samples


@pytest.mark.parametrize("errors", ["strict", "surrogateescape"])
def test_gzip_on_stdin_is_named(monkeypatch, capsys, csv_text, errors):
    import gzip

    data = gzip.compress(csv_text("crossing_1458").encode())
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data), encoding="utf-8", errors=errors))
    assert main(["monitor", "-", *FLAGS]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "gzip-compressed: decompress them first" in err and "semicolons" not in err, err


def test_closed_reader_is_a_quiet_end(csv_text):
    """``crosscert monitor ... | head -1``: the reader goes away; no error, no traceback, exit 141 (as cat)."""
    rows = csv_text("crossing_1458").splitlines(keepends=True)
    proc = subprocess.Popen([sys.executable, "-m", "crosscert", "monitor", "-", *FLAGS], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=Path(__file__).resolve().parents[1])
    try:
        proc.stdin.writelines(rows[:3])  # header, samples 0 and 1: the first event
        proc.stdin.flush()
        assert json.loads(proc.stdout.readline())["event"] == "mode-gained"
        proc.stdout.close()  # head -1 has its line
        try:
            proc.stdin.writelines(rows[3:])  # the next event and the summary meet a closed pipe
            proc.stdin.close()
        except BrokenPipeError:  # the monitor already ended
            pass
        assert proc.wait(timeout=120) == 141
        assert proc.stderr.read() == ""
    finally:
        proc.kill()
