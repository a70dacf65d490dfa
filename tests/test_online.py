"""The online monitor (verifier.window.online): the tracker, and a window anchored where it lost the mode.

Sound on adversarial runs (bang-bang at 0.999 a_max, readings at the edges
of +-eps_q, geometries at corners of [xi]; crossings and bounces, some just
past the locus and back): the truth inside every reported box, every
certified mode and every event's mode the true one.  Stronger than the
tracker alone: it certifies crossings the tracker leaves open, finds the pose
again in the new mode, and reports each change of a there-and-back run.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np
import pytest

from adversarial import near_scenarios
from problems import T_REST, check_contains, interval_model, kinematics
from crosscert.planner.simulate import simulate_crossing
from crosscert.planner.sweep import cruise_for
from crosscert.robots.dextar import benchmark_crossing
from crosscert.robots.errors import InputError
from crosscert.verifier.clock import SampleClock
from crosscert.verifier.step import Event
from crosscert.verifier.tracker import Tracker, initial_box_from_mode
from crosscert.verifier.settings import Verdict
from crosscert.verifier.window import OnlineMonitor, WindowState
from crosscert.verifier.window import lane as L
from crosscert.verifier.window import online as O


def _x0(run, settings):
    mode = run.mode[0] if hasattr(run, "mode") else run.mode_true[0]
    return initial_box_from_mode(interval_model(), run.q_meas[0], int(mode), settings)


def _truth(run):
    """True pose, velocity and mode per sample of a scenario or a simulated run."""
    if hasattr(run, "x_true"):
        return run.x_true, run.xd_true, run.mode_true
    return run.x, run.xd, run.mode


def _online(run, settings, **kw):
    """Every reading of ``run`` through an inline OnlineMonitor, checked against the truth as it goes:
    ``(monitor, results, events)``.  ``stamps``: each reading's stamp, fed with it (the monitor then
    gets a clock of ``stamp_error``)."""
    x, xd, mode = _truth(run)
    settle = kw.pop("settle", True)
    stamps = kw.pop("stamps", None)
    if stamps is not None:
        kw["clock"] = SampleClock(settings.t_s, kw.pop("stamp_error"))
    mon = OnlineMonitor(interval_model(), settings, _x0(run, settings), worker=kw.pop("worker", False), **kw)
    results, events = [], []
    for k, q in enumerate(run.q_meas):
        r = mon.update(q) if stamps is None else mon.update(q, stamps[k])
        results.append(r)
        events += r.events
        assert r.consistent, k
        check_contains(r.x[0][None], r.x[1][None], x[k][None], f"pose box at sample {k}")
        check_contains(r.xd[0][None], r.xd[1][None], xd[k][None], f"velocity box at sample {k}")
        assert r.mode in (0, mode[k]), (k, r.mode)
    if settle:
        events += mon.settle()
    for e in events:
        assert e.mode in (0, mode[e.k]), e
        assert e.known_at >= e.k, e
    mon.close()
    return mon, results, events


@pytest.fixture(scope="module")
def runs():
    """Fast and slow adversarial crossings and bounces (odd runs: bounces, some just past the locus)."""
    return near_scenarios(6, 2) + near_scenarios(10, 7, v_cross=(0.9, 1.25), v_bounce=(0.9, 1.3))


def _simulated(v, seed, back=False):
    """A simulated DexTAR crossing at ``v`` m/s from the benchmark, at rest 0.3 s after; ``back``: followed by
    the same motion in reverse (crossing back), a run at rest at the junction."""
    from crosscert.planner.simulate import random_geometry
    from crosscert.robots import DEXTAR

    bench = benchmark_crossing()
    xi = random_geometry(DEXTAR, np.random.default_rng(seed))
    run = simulate_crossing(kinematics(), bench.point, bench.direction, v, xi_true=xi, t_rest=T_REST, t_rest_end=0.3,
                            working_guess=bench.q_point, seed=seed, cruise=cruise_for(v))
    if not back:
        return run

    class There:  # the readings and truth of the run, then of the run backwards
        q_meas = np.concatenate([run.q_meas, run.q_meas[-2::-1]])
        x_true = np.concatenate([run.x_true, run.x_true[-2::-1]])
        xd_true = np.concatenate([run.xd_true, -run.xd_true[-2::-1]])
        mode_true = np.concatenate([run.mode_true, run.mode_true[-2::-1]])
    return There


def test_online_is_sound_on_adversarial_runs(runs, settings):
    """The truth in every box and every certified mode true, and the window decides some runs the tracker
    alone leaves open (else this test would not exercise it)."""
    decided = 0
    for sc in runs:
        mon, results, events = _online(sc, settings, settle=sc.name.startswith("cross"))
        decided += mon.decisions
        if sc.mode[0] == sc.mode[-1]:
            assert mon.verdict() is not Verdict.MODE_CHANGED, sc.name
        else:
            assert mon.verdict() is not Verdict.MODE_UNCHANGED, sc.name
    assert decided >= 3, decided


def test_slow_crossing_decided_and_pose_found_again(settings):
    """At 1.1 m/s the tracker alone never certifies the new mode; online, the anchored window does, soon after
    the singular instant, and the tracker then runs from that mode's boxes: 0.2 s later its box is no wider
    than 1.5 times that of a tracker that never crossed, at the same rest pose."""
    run = _simulated(1.1, 1)
    mon, results, events = _online(run, settings)
    changed = [e for e in events if e.event is Event.MODE_CHANGED]
    assert len(changed) == 1 and changed[0].by_window and changed[0].mode == run.mode_true[-1]
    assert changed[0].known_at - run.k_sing <= 150, changed  # known within 150 ms of the crossing
    assert mon.verdict() is Verdict.MODE_CHANGED and mon.mode == run.mode_true[-1]
    after = changed[0].known_at + 200
    assert after < len(run.q_meas)
    width = results[after].x[1] - results[after].x[0]
    # a run that never crossed: at rest at the same pose for as many samples, from its mode's box
    q_rest = run.q_meas[after]
    still = Tracker(interval_model(), settings, initial_box_from_mode(interval_model(), q_rest,
                                                                      int(run.mode_true[-1]), settings))
    for _ in range(201):
        r = still.update(q_rest)
    assert np.all(width <= 1.5 * (r.x[1] - r.x[0])), (width, r.x[1] - r.x[0])
    tracker_alone = Tracker(interval_model(), settings, _x0(run, settings))
    modes = [tracker_alone.update(q).mode for q in run.q_meas]
    assert modes[-1] == 0  # the tracker alone loses the mode for good


def test_there_and_back_reports_both_changes(settings):
    """Across the locus at 1.1 m/s and back the same way: two changes, each reported once by a window, and
    the final verdict is ``mode-unchanged``."""
    run = _simulated(1.1, 3, back=True)
    mon, _, events = _online(run, settings)
    changed = [e for e in events if e.event is Event.MODE_CHANGED]
    assert [e.mode for e in changed] == [-run.mode_true[0], run.mode_true[0]], events
    assert mon.verdict() is Verdict.MODE_UNCHANGED


@pytest.mark.parametrize("worker", ["thread", "process"])
def test_worker_is_sound_and_decides(settings, worker):
    """The window on its thread or in its process: the same guarantees, and (after settle) the 1.1 m/s
    crossing decided; the process ends with the monitor."""
    run = _simulated(1.1, 1)
    mon, _, events = _online(run, settings, worker=worker)
    assert mon.verdict() is Verdict.MODE_CHANGED
    assert any(e.event is Event.MODE_CHANGED and e.by_window for e in events)
    mon.close()
    if worker == "process":
        assert mon._proc._proc.poll() is not None


@pytest.mark.parametrize("worker", [False, "process"])
def test_stamped_readings_there_and_back(settings, worker):
    """Readings with stamps up to 50 us off their true times (alternating) and one sample dropped while the
    first window is open, there and back at 1.1 m/s: the windows (inline, or in the worker process, which
    gets the stamps with the readings) and the trackers they re-seed run on the stamps' steps; the truth
    inside every box, both changes reported, the verdict right."""
    run = _simulated(1.1, 3, back=True)
    K = len(run.q_meas)
    cross = int(np.flatnonzero(run.mode_true != run.mode_true[0])[0])
    keep = np.setdiff1d(np.arange(K), [cross + 10])  # while the first window is open
    part = SimpleNamespace(q_meas=run.q_meas[keep], x=run.x_true[keep], xd=run.xd_true[keep],
                           mode=run.mode_true[keep])
    delta = 5e-5
    stamps = keep * settings.t_s + (delta - 1e-12) * np.where(np.arange(len(keep)) % 2 == 0, 1.0, -1.0)
    mon, _, events = _online(part, settings, worker=worker, stamps=stamps, stamp_error=delta)
    changed = [e for e in events if e.event is Event.MODE_CHANGED]
    assert [e.mode for e in changed] == [-part.mode[0], part.mode[0]], events
    assert mon.verdict() is Verdict.MODE_UNCHANGED


@pytest.mark.parametrize("seed", [1, 3])
def test_online_windows_run_on_the_stamps(settings, seed):
    """An adversarial crossing at 1.0-1.15 m/s sampled at times jittered by up to 100 us, stamps 50 us off
    them (alternating), a sample dropped 2 ms past the locus: the anchored window reads the anchor's stamps
    (its attempts' clocks), the truth stays inside every box and the change is decided by a window.  On
    these seeds a window that took its readings every t_s lets the truth out or finds them inconsistent."""
    rng = np.random.default_rng(seed)
    K, delta = 201, 5e-5
    t_true = np.arange(K) * settings.t_s + rng.uniform(-1e-4, 1e-4, K)
    t_true[0] = 0.0
    sc = near_scenarios(2, seed, t_end=0.2, v_cross=(1.0, 1.15), times=t_true)[0]
    keep = np.setdiff1d(np.arange(K), [int(np.flatnonzero(sc.mode != sc.mode[0])[0]) + 2])
    part = SimpleNamespace(q_meas=sc.q_meas[keep], x=sc.x[keep], xd=sc.xd[keep], mode=sc.mode[keep])
    stamps = (t_true + (delta - 1e-9) * np.where(np.arange(K) % 2 == 0, 1.0, -1.0))[keep]
    mon, _, events = _online(part, settings, stamps=stamps, stamp_error=delta)
    assert mon.verdict() is Verdict.MODE_CHANGED
    assert any(e.event is Event.MODE_CHANGED and e.by_window for e in events)


def test_a_lane_crosses_processes_unchanged(settings):
    """A decided lane sent as data (pickled, as from the worker process) and restored on another tracker
    goes on with the same boxes, bit for bit, as the lane itself."""
    import pickle

    run = _simulated(1.1, 1)
    mon = OnlineMonitor(interval_model(), settings, _x0(run, settings), worker=False)
    for q in run.q_meas[:run.k_sing]:
        mon.update(q)
    lane = mon._lane
    data = pickle.loads(pickle.dumps(lane.export()))
    other = Tracker(interval_model(), settings, _x0(run, settings))
    copy = L.Lane.restore(data, other)
    for q in run.q_meas[run.k_sing:run.k_sing + 60]:
        assert lane.step(q) == copy.step(q)
        assert all(np.array_equal(a, b) for a, b in zip(np.concatenate(lane.boxes()), np.concatenate(copy.boxes())))
    assert lane.mode == copy.mode and lane.k == copy.k
    mon.close()


def test_horizon_bounds_the_window(settings, monkeypatch):
    """A window that reaches the horizon undecided gives up (mode unknown, no readings kept) until the
    tracker certifies a mode again; attempts never see more than ``horizon + 1`` readings."""
    run = _simulated(0.5, 2)  # far below the refutation floor: no window can decide it
    seen = []
    real = O.OnlineMonitor._run

    def spy(self, at):
        seen.append(len(at.q))
        return real(self, at)

    monkeypatch.setattr(O.OnlineMonitor, "_run", spy)
    mon = OnlineMonitor(interval_model(), settings, _x0(run, settings), worker=False, horizon=40)
    states = [mon.update(q).window for q in run.q_meas]
    assert WindowState.OPEN in states and states[-1] is WindowState.GAVE_UP
    assert mon._lane.anchor is None and mon.mode == 0 and mon.verdict() is Verdict.UNKNOWN
    assert seen and max(seen) <= 41
    mon.close()


def test_forward_only_is_the_tracker(settings):
    """``window=False``: the tracker alone, its modes at every sample."""
    run = _simulated(1.1, 1)
    mon = OnlineMonitor(interval_model(), settings, _x0(run, settings), window=False)
    tr = Tracker(interval_model(), settings, _x0(run, settings))
    for q in run.q_meas:
        a, b = mon.update(q), tr.update(q)
        assert a.mode == b.mode and a.window is WindowState.IDLE
        assert np.array_equal(a.x[0], b.x[0]) and np.array_equal(a.x[1], b.x[1])
    assert mon.decisions == 0
    mon.close()


def test_bad_use_is_refused(settings):
    run = _simulated(1.1, 1)
    with pytest.raises(InputError, match="horizon"):
        OnlineMonitor(interval_model(), settings, _x0(run, settings), horizon=1)
    mon = OnlineMonitor(interval_model(), settings, _x0(run, settings))
    with pytest.raises(InputError, match="finite"):
        mon.update([np.nan, 0.0])
    mon.close()
    with pytest.raises(InputError, match="closed"):
        mon.update(run.q_meas[0])


def test_decided_box_keeps_a_pose_on_the_locus(settings):
    """The re-seeded pose box keeps the undecided forward-kinematics boxes: a pose on the singular locus (the
    benchmark's nominal singular point, read exactly) is the limit of both modes and stays in the box of
    either (keeping the decided mode's certified boxes only drops it)."""
    bench = benchmark_crossing()
    model = interval_model()
    mon = OnlineMonitor(model, settings, (bench.point - 1e-3, bench.point + 1e-3), worker=False)
    lo, hi = (np.asarray(v, dtype=float) for v in model.robot.x_bounds)
    for mode in (1, -1):
        box = mon._reasoner.decided_box(np.asarray(bench.q_point, dtype=float), mode, model.xi_box(), (lo, hi))
        assert np.all(box[0] <= bench.point) and np.all(bench.point <= box[1]), (mode, box)
    mon.close()


def test_reseeded_tracker_finds_the_pose_in_a_tube_of_both_modes(settings):
    """A decision whose tube at its last sample spans both modes (the attempt's enumeration gave up, as it
    does in a wide tracker box): the re-seeded tracker starts from the decided mode's forward-kinematics
    solutions inside it, so it certifies that mode at once with a box of millimetres around the truth
    (starting from the tube itself it would keep both modes)."""
    from crosscert.verifier.window.offline import WindowStart
    from crosscert.verifier.window.results import HypothesisResult, HypothesisStatus, Refutation

    run = _simulated(1.1, 1)
    model, j = interval_model(), run.k_sing + 40
    mode = int(run.mode_true[j])
    lo, hi = (np.asarray(v, dtype=float) for v in model.robot.x_bounds)
    XI = model.xi_box()
    tube = lambda a, b: np.stack([a, b])[None].repeat(2, axis=0)  # noqa: E731 - (K = 2, n) per bound
    h = HypothesisResult(mode, HypothesisStatus.CONSISTENT, Refutation.NONE, 1, 1, True,
                         tube(lo, lo)[:, 0], tube(hi, hi)[:, 0], np.full((2, 2), -3.0), np.full((2, 2), 3.0),
                         XI[0][None], XI[1][None])
    mon = OnlineMonitor(model, settings, _x0(run, settings), worker=False)
    start = WindowStart(XI[0][None], XI[1][None], np.stack([lo, hi])[None], np.full((1, 2, 2), 3.0) * [[-1], [1]])
    anchor = L.Anchor(j - 1, -mode, start, [run.q_meas[j - 1], run.q_meas[j]], [np.stack([lo, hi])] * 2)
    at = L.Attempt(mon._lane, anchor, np.array(anchor.q), np.stack([lo, hi]), True)
    lane, first = mon._reasoner.reseeded(at, h)
    assert first.event is Event.MODE_CHANGED and first.k == j and first.mode == mode
    lane.step(run.q_meas[j])
    r = lane.tracker.state
    box = r.x_hull[0]
    assert lane.mode == mode and int(r.mode[0]) == mode
    assert np.all(box[0] <= run.x_true[j]) and np.all(run.x_true[j] <= box[1])
    assert np.all(box[1] - box[0] < 5e-3), box
    mon.close()


def test_there_and_back_through_the_cli(tmp_path, capsys, monkeypatch):
    """``check`` gives a there-and-back run the right final verdict with both changes decided by anchored
    windows; ``monitor`` on stdin (read faster than the window works: which changes it sees depends on when
    its attempts run) reports true modes only and, after its last attempt, the right verdict."""
    import io
    import json
    import sys

    from crosscert.planner.cli import main
    from crosscert.verifier.trajfile import write_trajectory

    run = _simulated(1.1, 3, back=True)
    path = tmp_path / "there_and_back.csv"
    write_trajectory(path, np.arange(len(run.q_meas)) * 1e-3, run.q_meas)
    assert main(["check", str(path), "--initial-mode", "1", "--json", "--no-progress"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["verdict"] == "mode-unchanged" and out["window_decisions"] >= 2 and out["window"] is None
    lo, hi = np.array(out["final_pose_lo"]), np.array(out["final_pose_hi"])
    assert np.all(lo <= run.x_true[-1]) and np.all(run.x_true[-1] <= hi)
    monkeypatch.setattr(sys, "stdin", io.StringIO(path.read_text()))
    assert main(["monitor", "--initial-mode", "1", "--json"]) == 0
    *events, summary = [json.loads(v) for v in capsys.readouterr().out.splitlines()]
    assert all(e["mode"] in (0, run.mode_true[e["k"]]) for e in events), events
    assert summary["verdict"] == "mode-unchanged"


def test_an_error_in_the_worker_reaches_the_caller(settings, monkeypatch):
    """An attempt that raises on the worker thread is not lost: the next ``update`` (or ``settle``) raises it."""
    run = _simulated(1.1, 1)

    def broken(self, at):
        raise RuntimeError("attempt failed")

    monkeypatch.setattr(O.OnlineMonitor, "_run", broken)
    mon = OnlineMonitor(interval_model(), settings, _x0(run, settings), worker="thread")
    with pytest.raises(RuntimeError, match="attempt failed"):
        for q in run.q_meas:
            mon.update(q)
        mon.settle()
    mon.close()


def test_the_worker_process_failing_reaches_the_caller(settings):
    """An attempt that raises in the worker process reaches the next ``update`` as its exception; a worker
    process that dies as :class:`WindowWorkerStopped`, a project error.  Neither is lost."""
    from crosscert.robots.errors import CrosscertError
    from crosscert.verifier.window.worker import WindowWorkerStopped

    run = _simulated(1.1, 1)
    mon = OnlineMonitor(interval_model(), settings, _x0(run, settings), worker="process")
    mon.update(run.q_meas[0])
    # a window whose start is missing: its attempt raises AttributeError in the child
    mon._proc.send(("open", 99, 0, 1, None, [run.q_meas[0]] * 3, [np.zeros((2, 2))] * 3, None))
    with pytest.raises(AttributeError):
        for q in run.q_meas[1:]:
            mon.update(q)
            time.sleep(1e-3)
    mon.close()
    mon = OnlineMonitor(interval_model(), settings, _x0(run, settings), worker="process")
    mon.update(run.q_meas[0])
    mon._proc._proc.kill()
    mon._proc._proc.wait()
    with pytest.raises(WindowWorkerStopped) as err:
        for q in run.q_meas[1:]:
            mon.update(q)
            time.sleep(1e-3)
    assert isinstance(err.value, CrosscertError)
    mon.close()


def test_a_robot_that_cannot_cross_processes_gets_a_thread(settings):
    """A robot whose loop closure does not pickle (defined in a script, a lambda) keeps its window on a
    thread: the monitor works the same, its window beside it."""
    import dataclasses

    from crosscert.robots import DEXTAR
    from crosscert.verifier.model import IntervalModel

    robot = dataclasses.replace(DEXTAR, loop_closure=lambda *a, **k: DEXTAR.loop_closure(*a, **k))
    run = _simulated(1.1, 1)
    mon = OnlineMonitor(IntervalModel(robot), settings, _x0(run, settings))
    assert mon._proc is None and mon._thread is not None
    mon.close()
