"""The command line, through main(argv): verdicts, exit codes, bad input."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from problems import CATALOGUE, run_of
from crosscert.planner.cli import build_parser, main
from crosscert.verifier.trajfile import write_trajectory


@pytest.fixture(scope="module")
def crossing_csv(tmp_path_factory):
    run = run_of(CATALOGUE["crossing_1458"])
    path = tmp_path_factory.mktemp("traj") / "crossing.csv"
    write_trajectory(path, run.t, run.q_meas)
    return path


def _write(tmp_path, text, name="t.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _one_line_error(capsys):
    err = capsys.readouterr().err.strip()
    assert err and "\n" not in err and "Traceback" not in err
    return err


def test_parser_is_separate_from_main():
    p = build_parser()
    a = p.parse_args(["check", "f.csv", "--initial-mode", "1"])
    assert a.command == "check" and a.initial_mode == 1 and a.robot == "dextar"


def test_check_crossing_json(crossing_csv, capsys):
    code = main(["check", str(crossing_csv), "--initial-mode", "1", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert out["verdict"] == "mode-changed"
    assert out["initial_mode"] == 1 and out["final_mode"] == -1
    for key in ("certified_at_step", "inconsistent_at_step", "steps", "max_width_pose_m", "max_width_velocity_mps", "elapsed_s"):
        assert key in out
    assert out["inconsistent_at_step"] is None


def test_check_with_plot_and_x0(crossing_csv, tmp_path, capsys):
    run = run_of(CATALOGUE["crossing_1458"])
    x, y = run.x_true[0]
    png = tmp_path / "boxes.png"
    code = main(["check", str(crossing_csv), f"--x0={x - 0.003},{x + 0.003},{y - 0.003},{y + 0.003}",
                 "--plot", str(png), "--no-progress"])
    assert code == 0
    assert "verdict:" in capsys.readouterr().out
    assert png.stat().st_size > 10_000


def test_check_inconsistent_exit_3(crossing_csv, capsys):
    code = main(["check", str(crossing_csv), "--initial-mode", "1", "--a-max", "2", "--json"])
    assert code == 3
    assert json.loads(capsys.readouterr().out)["verdict"] == "inconsistent"


def test_simulate_then_check_bounce(tmp_path, capsys):
    out = tmp_path / "bounce.csv"
    assert main(["simulate", "--v-sing", "1.0", "--bounce", "--seed", "5", "--t-rest", "0.05", "-o", str(out)]) == 0
    capsys.readouterr()
    assert main(["check", str(out), "--initial-mode", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    # a bounce: never a certified change (measured: unknown, the mode is lost at the locus)
    assert out["initial_mode"] == 1 and out["final_mode"] != -1, out
    assert out["verdict"] in ("mode-unchanged", "unknown"), out


def test_check_window_reasoning_decides_what_the_forward_tracker_leaves_open(tmp_path, capsys):
    """A simulated crossing at 1.1 m/s: the tracker alone says unknown; the window anchored where it lost the
    mode certifies the change (and the final pose in the new mode); with a horizon too short for it, the
    window over the whole recording does."""
    rec = tmp_path / "slow.csv"
    assert main(["simulate", "--v-sing", "1.1", "--t-rest", "0.05", "-o", str(rec)]) == 0
    capsys.readouterr()
    reports = {}
    for name, extra in (("forward", ["--reasoning", "forward"]), ("window", []), ("whole", ["--horizon", "2"])):
        assert main(["check", str(rec), "--initial-mode", "1", "--json", *extra]) == 0
        reports[name] = json.loads(capsys.readouterr().out)
    assert reports["forward"]["verdict"] == "unknown" and reports["forward"]["window"] is None
    assert reports["forward"]["window_decisions"] == 0
    win = reports["window"]
    assert win["online_verdict"] == win["verdict"] == "mode-changed" and win["final_mode"] == -1
    assert win["window"] is None and win["window_decisions"] >= 1
    lo, hi = np.array(win["final_pose_lo"]), np.array(win["final_pose_hi"])
    assert np.all(hi - lo < 5e-3)  # the tracker runs from the new mode's boxes: tight again
    whole = reports["whole"]
    assert whole["online_verdict"] == "unknown" and whole["verdict"] == "mode-changed" and whole["final_mode"] == -1
    assert {h["final_mode"]: h["status"] for h in whole["window"]["hypotheses"]} == {1: "refuted", -1: "consistent"}
    assert np.all(np.array(whole["final_pose_lo"]) <= np.array(whole["final_pose_hi"]))
    assert main(["check", str(rec), "--initial-mode", "1", "--horizon", "2"]) == 0
    assert "window passes over the whole run: mode-changed" in capsys.readouterr().out


GOOD_HEAD = "t,q1,q2\n0.000,2.0,1.1\n0.001,2.0,1.1\n0.002,2.0,1.1\n"


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "empty"),
        ("t,q1\n0,1\n0.001,1\n", "missing column"),
        ("t,q1,q2,q3\n0,1,1,1\n0.001,1,1,1\n", "unexpected column"),
        ("t,q1,q2\n0,1,abc\n0.001,1,1\n", "not a number"),
        ("t,q1,q2\n0,1,nan\n0.001,1,1\n", "NaN"),
        ("t,q1,q2\n0,1,inf\n0.001,1,1\n", "NaN and infinities"),
        ("t,q1,q2\n0,1,1\n0.001,1\n", "values for"),
        ("t,q1,q2\n0,1,1\n0,1,1\n", "does not increase"),
        ("t,q1,q2\n0,1,1\n0.001,1,1\n0.0025,1,1\n", "is not a whole number of periods"),
        ("t,q1,q2\n0,1,1\n", "at least two"),
        ("t,q1,q2,qd1\n0,1,1,0\n0.001,1,1,0\n", "or none"),
    ],
)
def test_malformed_files_exit_2(tmp_path, capsys, text, message):
    p = _write(tmp_path, text)
    assert main(["check", str(p), "--initial-mode", "1"]) == 2
    assert message in _one_line_error(capsys)


def test_missing_file_unknown_robot_and_usage(tmp_path, capsys):
    assert main(["check", str(tmp_path / "nope.csv"), "--initial-mode", "1"]) == 2
    assert "no such file" in _one_line_error(capsys)
    p = _write(tmp_path, GOOD_HEAD)
    assert main(["check", str(p), "--robot", "hexapod", "--initial-mode", "1"]) == 2
    assert "unknown robot" in _one_line_error(capsys)
    assert main(["check", str(p)]) == 2  # neither --initial-mode nor --x0
    assert "--initial-mode --x0 is required" in _one_line_error(capsys)
    assert main(["check", str(p), "--x0", "1,2,3"]) == 2
    assert "--x0" in _one_line_error(capsys)
    assert main(["frobnicate"]) == 2
    assert "invalid choice: 'frobnicate'" in _one_line_error(capsys)


def test_initial_mode_that_does_not_match_the_data(tmp_path, capsys):
    # joints of a pose far from the singular locus; pose box given far away
    run = run_of(CATALOGUE["crossing_1458"])
    p = tmp_path / "c.csv"
    write_trajectory(p, run.t[:20], run.q_meas[:20])
    # a well-formed --x0 that the data contradict is not bad input (exit 2) but a violated
    # assumption (A7): the box empties at the first sample, verdict inconsistent, exit 3
    assert main(["check", str(p), "--x0", "0.5,0.6,0.5,0.6", "--json"]) == 3
    out = json.loads(capsys.readouterr().out)
    assert out["verdict"] == "inconsistent" and out["inconsistent_at_step"] == 0, out
    # joint readings no geometry in the box can produce
    q = np.tile([[np.pi, 0.0]], (20, 1))  # proximal links opposite: distal links cannot meet
    write_trajectory(p, run.t[:20], q)
    assert main(["check", str(p), "--initial-mode", "1"]) == 2
    assert "no forward-kinematics solution" in _one_line_error(capsys)


def test_simulate_errors(tmp_path, capsys):
    assert main(["simulate", "--v-sing", "9", "-o", str(tmp_path / "x.csv")]) == 2
    assert "v_sing" in _one_line_error(capsys)
    assert not (tmp_path / "x.csv").exists()
    assert main(["simulate", "--v-sing", "-1", "-o", str(tmp_path / "x.csv")]) == 2
    assert "--v-sing = -1 m/s is out of range" in _one_line_error(capsys)


def test_check_backends_give_the_same_report(crossing_csv, capsys):
    """``--backend numpy`` runs the reference tracker: the same verdict, steps and widths."""
    out = {}
    for backend in ("compiled", "numpy"):
        assert main(["check", str(crossing_csv), "--initial-mode", "1", "--json", "--backend", backend]) == 0
        rep = json.loads(capsys.readouterr().out)
        rep.pop("elapsed_s")
        out[backend] = rep
    assert out["compiled"] == out["numpy"]
    assert out["compiled"]["verdict"] == "mode-changed"


def _restamped(path, tmp_path, stamp, name):
    """The recording at ``path`` with its time column replaced by ``stamp(t)``."""
    lines = path.read_text().splitlines()
    out = [lines[0]]
    for row in lines[1:]:
        t, rest = row.split(",", 1)
        out.append(f"{stamp(float(t))!r},{rest}")
    return _write(tmp_path, "\n".join(out) + "\n", name)


def test_check_t_s_states_the_period_and_warnings_name_it(crossing_csv, tmp_path, capsys):
    """A 2 ms recording: a warning naming --t-s (an option check has); with --t-s 0.002, none."""
    rec = _restamped(crossing_csv, tmp_path, lambda t: 2 * t, "slow.csv")
    assert main(["check", str(rec), "--initial-mode", "1", "--json", "--reasoning", "forward"]) == 0
    cap = capsys.readouterr()
    assert "pass --t-s 0.002 to state it" in cap.err and json.loads(cap.out)["t_s"] == 0.002
    assert main(["check", str(rec), "--initial-mode", "1", "--json", "--reasoning", "forward", "--t-s", "0.002"]) == 0
    cap = capsys.readouterr()
    assert cap.err == "" and json.loads(cap.out)["t_s"] == 0.002
    assert main(["check", str(crossing_csv), "--initial-mode", "1", "--t-s", "0.002"]) == 2  # every step is checked
    # a file of another period than the one stated is said to be so, not "uneven"
    assert "the file's step is 0.001 s, --t-s says 0.002 s: drop --t-s" in _one_line_error(capsys)


@pytest.mark.parametrize(
    "stamp, args, message",
    [
        # milliseconds: said at once, with the fix, not after a run at t_s = 1 s
        (lambda t: 1e3 * t, ("--t-s", "0.001"), "the time column seems to be in ms: convert it to seconds"),
        # float32 stamps at 100 s: re-stamp at the nominal period; never "resample"
        (lambda t: float(np.float32(100.0 + t)), (), "re-stamp the time column at it (t_k = t_0 + k t_s"),
        # 1e-9 s of clock jitter
        (lambda t: t + 1e-9 * ((round(t * 1e3) * 7919) % 3 - 1), (), "float32 stamps or clock jitter?"),
    ],
)
def test_imprecise_stamps_get_advice_that_keeps_eps_q(crossing_csv, tmp_path, capsys, stamp, args, message):
    rec = _restamped(crossing_csv, tmp_path, stamp, "stamped.csv")
    assert main(["check", str(rec), "--initial-mode", "1", "--no-progress", *args]) == 2
    err = _one_line_error(capsys)
    assert message in err and "resample or" not in err, err


def test_ms_stamps_without_t_s_are_named_in_the_warning(crossing_csv, tmp_path, capsys):
    rec = _restamped(crossing_csv, tmp_path, lambda t: 1e3 * t, "ms.csv")
    assert main(["check", str(rec), "--initial-mode", "1", "--json", "--reasoning", "forward"]) == 0
    err = capsys.readouterr().err
    assert "the time column seems to be in ms: convert it to seconds" in err, err


@pytest.mark.parametrize(
    "text, message",
    [
        ("# logged by the controller\nt,q1,q2\n0,1,1\n0.001,1,1\n", "line 1 starts with '#'"),
        ("T,Q1,Q2\n0,1,1\n0.001,1,1\n", "column names are lower-case"),
        ("t;q1;q2\n0;1;1\n", "semicolons"),
    ],
)
def test_header_hints(tmp_path, capsys, text, message):
    p = _write(tmp_path, text)
    assert main(["check", str(p), "--initial-mode", "1"]) == 2
    err = _one_line_error(capsys)
    assert "missing column(s)" in err and message in err, err


def test_gzip_file_is_named(crossing_csv, tmp_path, capsys):
    import gzip

    p = tmp_path / "rec.csv.gz"
    p.write_bytes(gzip.compress(crossing_csv.read_bytes()))
    assert main(["check", str(p), "--initial-mode", "1"]) == 2
    err = _one_line_error(capsys)
    assert "gzip-compressed: decompress them first" in err and "semicolons" not in err, err


def test_a_failed_figure_does_not_cost_the_verdict(crossing_csv, tmp_path, capsys, monkeypatch):
    """The figure is drawn after the verdict is printed: a write that fails (full disk) is reported after it."""
    import sys

    def full_disk(path, *a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(sys.modules["crosscert.planner.cli.track"], "plot_run", full_disk)
    code = main(["check", str(crossing_csv), "--initial-mode", "1", "--json", "--plot", str(tmp_path / "f.png")])
    out, err = capsys.readouterr()
    assert code == 2
    assert json.loads(out)["verdict"] == "mode-changed"
    assert err.count("\n") == 1 and "the verdict above stands, but the figure was not written" in err
    assert "No space left on device" in err and not (tmp_path / "f.png").exists()


# the robot's own a_max on both axes: the comparison run under it coincides and is skipped
CERTIFY_NARROW = ["certify", "--v-low", "0.9", "--v-high", "1.3", "--tol", "0.1", "--monte-carlo", "0", "--a-max", "80",
                  "--no-progress"]


def test_certify_names_the_gap_and_times_the_bounce(tmp_path, capsys, monkeypatch):
    """The printed gap is the JSON's gap_mps (a difference) with the ratio named beside it; the bounce search's
    time is its own run time, not the wait left after the other phases; certified_at_step is null or a step.
    The figure draws what certified v_min: the window passes' tubes when they decided, named in the title."""
    import re

    planning = sys.modules["crosscert.planner.cli.planning"]
    drawn = []
    for name in ("plot_run", "plot_certificate"):
        real = getattr(planning, name)
        monkeypatch.setattr(planning, name, lambda *a, _real=real, _name=name, **k: (drawn.append((_name, a, k)),
                                                                                     _real(*a, **k))[1])
    assert main([*CERTIFY_NARROW, "--out", str(tmp_path / "c")]) == 0
    report = json.loads((tmp_path / "c" / "certificate.json").read_text())
    assert len(drawn) == 1 and Path(drawn[0][1][0]).stat().st_size > 10_000
    name, args, kwargs = drawn[0]
    if report["window"] is not None:
        assert name == "plot_certificate" and "certified by window reasoning" in kwargs["title"]
        assert {h.final_mode for h in args[3].hypotheses} == {1, -1}
        assert any(h.status.value == "refuted" for h in args[3].hypotheses)
        # the run drawn as the online monitor reports it: the decided mode's boxes to the end, not both modes
        assert kwargs["forward_label"].startswith("online") and np.all(args[2]["x_hi"][-1] - args[2]["x_lo"][-1] < 5e-3)
    else:
        assert name == "plot_run" and "certified by the forward pass" in kwargs["title"]
    out = capsys.readouterr().out
    report = json.loads((tmp_path / "c" / "certificate.json").read_text())
    assert report["execution"]["proved"] is True and report["execution"]["proof"]["boxes_explored"] > 0
    assert "execution class: cartesian, C, e and d proved for every geometry of [xi]" in out
    line = next(v for v in out.splitlines() if v.startswith("gap"))
    diff, ratio = map(float, re.fullmatch(r"gap \(mode-changed\): v_min - refutation bound = ([0-9.]+) m/s "
                                          r"\(gap_mps\); ratio v_min / refutation bound = ([0-9.]+)", line).groups())
    assert diff == pytest.approx(report["gap_mps"], abs=5e-5)
    assert ratio == pytest.approx(report["v_min_mps"] / report["refutation_bound_mps"], abs=5e-4)
    assert report["bounce"] is not None and report["timings_s"]["bounce"] > 1.0  # a search of seconds
    steps = [t["certified_at_step"] for t in report["trials"]]
    assert None in steps and all(s is None or (isinstance(s, int) and s >= 0) for s in steps), steps
    assert all((t["certified_at_step"] is None) == (t["forward_verdict"] != "mode-changed") for t in report["trials"])


def test_ctrl_c_stops_certify_promptly_with_130(tmp_path):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it): exit 130 within seconds, one line, and the
    background worker process gone."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    proc = subprocess.Popen([sys.executable, "-m", "crosscert", *CERTIFY_NARROW, "--out", str(tmp_path / "c")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=root,
                            start_new_session=True)
    children = f"/proc/{proc.pid}/task/{proc.pid}/children"
    try:
        # once the background worker is up, the speed search and the counterexample searches run for
        # seconds (the whole command takes about 8 s on an idle machine): interrupt 2 s into them, not
        # after a fixed time from the start, which an idle machine can outrun
        deadline = time.perf_counter() + 60.0
        while proc.poll() is None and not open(children).read().split() and time.perf_counter() < deadline:
            time.sleep(0.05)
        time.sleep(2.0)
        assert proc.poll() is None
        workers = open(children).read().split()
        t0 = time.perf_counter()
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        waited = time.perf_counter() - t0
    finally:
        proc.kill()
    assert proc.returncode == 130 and err == "crosscert: interrupted\n", err
    assert waited < 5.0, f"exited {waited:.1f} s after Ctrl-C"
    assert workers and not any(os.path.exists(f"/proc/{w}") for w in workers)


def test_an_interrupt_swallowed_by_a_c_callback_is_sent_again(tmp_path):
    """Ctrl-C that lands in a ctypes callback (numba's cache notifications while kernels compile) is only
    printed as "Exception ignored" by Python: the CLI sends it again until the command ends, quietly."""
    import subprocess
    import sys
    import time
    from pathlib import Path

    script = tmp_path / "swallow.py"
    script.write_text(
        "import ctypes, os, signal, sys, threading, time\n"
        "from crosscert.planner.cli import _Interrupts\n"
        "def busy():\n"
        "    t = time.time()\n"
        "    while time.time() - t < 1.0:\n"
        "        pass\n"
        "callback = ctypes.CFUNCTYPE(None)(busy)\n"
        "with _Interrupts() as interrupts:\n"
        "    try:\n"
        "        threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT)).start()\n"
        "        callback()  # the interrupt lands in here and is swallowed\n"
        "        t = time.time()\n"
        "        while time.time() - t < 20.0:\n"
        "            pass\n"
        "        print('never interrupted')\n"
        "    except KeyboardInterrupt:\n"
        "        sys.exit(interrupts.report())\n")
    root = Path(__file__).resolve().parents[1]
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=root, timeout=60,
                          env={**__import__("os").environ, "PYTHONPATH": str(root)})
    waited = time.perf_counter() - t0
    assert proc.returncode == 130 and proc.stderr == "crosscert: interrupted\n", (proc.stdout, proc.stderr)
    assert waited < 10.0, waited


def test_what_an_interrupt_leaves_half_built_is_finalised_quietly(tmp_path):
    """Ctrl-C that cuts a C object's constructor short (llvmlite's ``ObjectRef`` while kernels compile: the
    CI saw its ``__del__`` print "Exception ignored ... AttributeError" after "crosscert: interrupted"): once
    interrupted, such errors print nothing, in reference cycles too; before an interrupt they print as
    always.  Fails when the hook passes them on once interrupted."""
    import subprocess
    import sys
    from pathlib import Path

    script = tmp_path / "debris.py"
    script.write_text(
        "import os, signal, sys\n"
        "from crosscert.planner.cli import _Interrupts\n"
        "class HalfBuilt:\n"
        "    def __del__(self):\n"
        "        del self._as_parameter_  # never set: the constructor was cut short\n"
        "with _Interrupts() as interrupts:\n"
        "    x = HalfBuilt()\n"
        "    del x  # before an interrupt: printed\n"
        "    print('--', file=sys.stderr, flush=True)\n"
        "    try:\n"
        "        os.kill(os.getpid(), signal.SIGINT)\n"
        "    except KeyboardInterrupt:\n"
        "        code = interrupts.report()\n"
        "    y = HalfBuilt()\n"
        "    del y\n"
        "    z = HalfBuilt()\n"
        "    z.self = z  # a cycle: finalised by the collection on the way out\n"
        "    del z\n"
        "sys.exit(code)\n")
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=root, timeout=60,
                          env={**__import__("os").environ, "PYTHONPATH": str(root)})
    before, _, after = proc.stderr.partition("--\n")
    assert "AttributeError" in before, proc.stderr
    assert proc.returncode == 130 and after == "crosscert: interrupted\n", proc.stderr


def test_progress_names_each_phase_with_its_total_and_says_when_it_compiles(monkeypatch):
    """The certify bar: one named phase after another with its size; numba's compile events show as
    'compiling kernels' and hand the name back; a phase that counts nothing still redraws its time."""
    from numba.core import event

    from crosscert.planner.cli import setup
    from crosscert.planner.progress import Phase, enter

    bars = []

    class FakeBar:
        def __init__(self, total=None, desc="", unit="", **_):
            self.total, self.desc, self.unit, self.n, self.refreshed, self.closed = total, desc, unit, 0, 0, False
            bars.append(self)

        def update(self, k):
            self.n += k

        def set_description_str(self, d, refresh=True):
            self.desc = d

        def refresh(self):
            self.refreshed += 1

        def close(self):
            self.closed = True

    monkeypatch.setattr("tqdm.tqdm", FakeBar)
    bar = setup.PhaseBar("certify")
    try:
        enter(bar, Phase.SEARCH, 9, unit="speed")
        bar(1)
        assert (bars[-1].desc, bars[-1].total, bars[-1].unit, bars[-1].n) == ("certify: speed search", 9, "speed", 1)
        assert bars[0].closed  # the previous phase's bar is closed
        with event.trigger_event("numba:compile", data={}):
            assert bars[-1].desc == f"certify: {setup.COMPILING}"
        assert bars[-1].desc == "certify: speed search"
        enter(bar, Phase.REFUTATION, unit="search")
        import time as _time

        _time.sleep(1.2)
        assert bars[-1].refreshed >= 1  # the elapsed time moves although nothing is counted
    finally:
        bar.close()
    bar.close()  # twice is harmless
    assert all(b.closed for b in bars)


@pytest.mark.parametrize("bad", ["-1", "1.5", "x"])
def test_certify_refuses_a_bad_one_motion_count_before_any_work(tmp_path, capsys, bad):
    assert main(["certify", "--one-motion", bad, "--out", str(tmp_path / "c"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--one-motion" in err and "Traceback" not in err
    assert not (tmp_path / "c").exists()


def test_certify_passes_refute_tol_to_both_certifications(tmp_path, monkeypatch):
    """``--refute-tol`` reaches the certification and the one at the robot's a_max; absent, both keep their
    defaults (None: a tenth of --tol for the first, --tol for the second)."""
    planning = sys.modules["crosscert.planner.cli.planning"]
    seen = []

    class Stop(Exception):
        pass

    def first(*a, **k):
        seen.append(("first", k["refute_tol"]))
        raise Stop

    monkeypatch.setattr(planning, "certify_crossing", first)
    for extra, want in (([], None), (["--refute-tol", "0.002"], 0.002)):
        seen.clear()
        with pytest.raises(Stop):
            main([*CERTIFY_NARROW, *extra, "--out", str(tmp_path / "c")])
        assert seen == [("first", want)]
    calls = []

    def second(*a, **k):
        calls.append(k["refute_tol"])
        raise Stop

    monkeypatch.setattr(planning, "certify_crossing", lambda *a, **k: object())
    monkeypatch.setattr(planning, "_figure", lambda *a, **k: None)
    monkeypatch.setattr(planning, "compares", lambda *a, **k: False)
    monkeypatch.setattr(planning, "certify_at_robot_a_max", second)
    with pytest.raises(Stop):
        main([*CERTIFY_NARROW, "--refute-tol", "0.003", "--out", str(tmp_path / "d")])
    assert calls == [0.003]
