"""The online monitor (verifier.window.online): the tracker, and a window anchored where it lost the mode.

Sound on adversarial runs (bang-bang at 0.999 a_max, readings at the edges
of +-eps_q, geometries at corners of [xi]; crossings and bounces, some just
past the locus and back): the truth inside every reported box, every
certified mode and every event's mode the true one.  Stronger than the
tracker alone: it certifies crossings the tracker leaves open, finds the pose
again in the new mode, and reports each change of a there-and-back run.
"""

from __future__ import annotations

import numpy as np
import pytest

from adversarial import near_scenarios
from problems import T_REST, check_contains, interval_model, kinematics
from crosscert.planner.simulate import simulate_crossing
from crosscert.planner.sweep import cruise_for
from crosscert.robots.dextar import benchmark_crossing
from crosscert.robots.errors import InputError
from crosscert.verifier.step import Event
from crosscert.verifier.tracker import Tracker, initial_box_from_mode
from crosscert.verifier.settings import Verdict
from crosscert.verifier.window import OnlineMonitor, WindowState
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
    ``(monitor, results, events)``."""
    x, xd, mode = _truth(run)
    settle = kw.pop("settle", True)
    mon = OnlineMonitor(interval_model(), settings, _x0(run, settings), worker=kw.pop("worker", False), **kw)
    results, events = [], []
    for k, q in enumerate(run.q_meas):
        r = mon.update(q)
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


def test_worker_thread_is_sound_and_decides(settings):
    """The window on its thread: the same guarantees, and (after settle) the 1.1 m/s crossing decided."""
    run = _simulated(1.1, 1)
    mon, _, events = _online(run, settings, worker=True)
    assert mon.verdict() is Verdict.MODE_CHANGED
    assert any(e.event is Event.MODE_CHANGED and e.by_window for e in events)


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
