"""Planning-time certification on the DexTAR benchmark task."""

import json

import numpy as np
import pytest

from crosscert.planner import (
    certify_crossing,
    certify_plan,
    minimal_v_sing,
    monte_carlo_confirmation,
    plan_crossing,
    speed_ceiling,
)
from crosscert.planner.cli import main
from crosscert.planner.certify.plan import certify_plan_window
from crosscert.planner.task import CrossingTask, PlanningBounds
from problems import PLANNING, check_certified_speed, check_contains, check_plan_limits
from crosscert.robots import DEXTAR
from crosscert.robots.dextar import DEXTAR_DYNAMICS
from crosscert.robots.errors import InputError, SimulationError
from crosscert.verifier.tracker import Verdict

BENCHMARK = PLANNING["dextar_benchmark"]


def test_plan_meets_the_criterion_and_the_limits(task, kin):
    """A smoothstep plan: speed and crossing criterion at the crossing sample, a_peak, rest to rest, f = 0."""
    p = plan_crossing(kin, task, 1.3, PlanningBounds())
    check_plan_limits(p, task, 1.3)
    # the crossing sample is on the nominal locus to within one sample of motion
    assert np.linalg.norm(p.x[p.k_sing] - p.crossing_point) <= 1.3 * 1e-3
    # loop closure holds
    assert np.abs(kin.f_batch(p.x, p.q, p.xi_plan)).max() <= 1e-12
    modes = kin.mode_batch(p.x, p.q, p.xi_plan)
    assert modes[0] == 1 and modes[-1] == -1


def test_time_optimal_plan_is_certified_and_meets_the_criterion(task, kin, imodel):
    b = PlanningBounds(method="time-optimal")
    p = plan_crossing(kin, task, 1.3, b)
    check_plan_limits(p, task, 1.3, v_rtol=1e-6, a_rtol=1e-6)
    res = certify_plan(imodel, p, b, 1)
    assert res.verdict is Verdict.MODE_CHANGED


def test_dynamic_plan_is_certified(task, kin, imodel):
    b = PlanningBounds(method="dynamic", dynamics=DEXTAR_DYNAMICS)
    p = plan_crossing(kin, task, 1.3, b)
    assert abs(np.linalg.norm(p.xd[p.k_sing]) - 1.3) <= 1e-6
    assert np.abs(p.xdd).max() <= 60.0 * (1 + 1e-6)
    assert certify_plan(imodel, p, b, 1).verdict is Verdict.MODE_CHANGED
    with pytest.raises(InputError, match="dynamic model"):
        plan_crossing(kin, task, 1.3, PlanningBounds(method="dynamic"))


def test_infeasible_and_contradictory_requests(task, kin, imodel):
    with pytest.raises(InputError, match="no feasible crossing"):
        plan_crossing(kin, task, 5.0, PlanningBounds())
    same = CrossingTask(task.start, task.start + np.array([0.0, 0.01]), task.working_guess)
    with pytest.raises(InputError, match="same assembly mode"):
        plan_crossing(kin, same, 1.0, PlanningBounds())
    far = CrossingTask(np.array([0.0, 0.5]), task.goal, task.working_guess)
    with pytest.raises(InputError, match="not reachable"):
        plan_crossing(kin, far, 1.0, PlanningBounds())
    p = plan_crossing(kin, task, 1.3, PlanningBounds())
    with pytest.raises(InputError, match="contradict the plan"):
        certify_plan(imodel, p, PlanningBounds(a_max=(10.0, 10.0)), 1)


def test_minimal_speed_and_monte_carlo_confirmation(task, kin, imodel):
    """The search brackets v_min; 50 admissible executions at v_min are all detected.

    The executions follow the planned Cartesian path with random geometries
    in [xi] (every fifth at a corner) and three quantisation schemes; each is
    checked to belong to the certificate's (cartesian) class, and the
    run-time tracker, fed its own readings, must detect the change in every
    one and contain the truth at every step.  Under the literal joint class
    the same executions leave the tube around the planned joints.
    """
    im = imodel
    b = PlanningBounds()
    v_min, trials = minimal_v_sing(kin, im, task, b, 0.9, 1.6, tol=0.05)
    # not the bracket handed to the search (0.9, 1.6], which any answer satisfies: a trial below v_min
    # failed within tol, and v_min is the catalogue's (checked below)
    assert v_min is not None
    by_v = {t.v_sing: t.verdict for t in trials}
    assert by_v[v_min] is Verdict.MODE_CHANGED
    assert all(v is Verdict.MODE_CHANGED for s, v in by_v.items() if s >= v_min)
    below = [s for s in by_v if s < v_min]
    assert below and by_v[max(below)] is not Verdict.MODE_CHANGED and v_min - max(below) <= 0.05
    # the coarse search lands within its resolution of the default certification's v_min, and never at or
    # below the refutation bound
    check_certified_speed(v_min, BENCHMARK.expected, tol=0.05 + BENCHMARK.expected.v_min_tol)
    assert all(s > BENCHMARK.expected.refutation_bound for s, v in by_v.items() if v is Verdict.MODE_CHANGED)
    # the forward tracker alone
    fwd = PlanningBounds(reasoning="forward")
    v_fwd, trials_fwd = minimal_v_sing(kin, im, task, fwd, 0.9, 1.6, tol=0.05)
    check_certified_speed(v_fwd, BENCHMARK.expected, tol=0.05 + BENCHMARK.expected.v_min_tol, forward=True)
    assert all(t.verdict is t.forward_verdict for t in trials_fwd)
    plan = plan_crossing(kin, task, v_min, b)
    assert certify_plan_window(im, plan, b, 1).verdict is Verdict.MODE_CHANGED
    mc = monte_carlo_confirmation(kin, im, plan, b, runs=50, seed=7)
    assert mc.runs == 50 and mc.in_class == 50 and mc.outside_class == ()
    assert mc.containment_failures == () and mc.wrong_verdicts == () and mc.not_detected == ()
    assert mc.detected_in_class == 50
    joint = monte_carlo_confirmation(kin, im, plan, PlanningBounds(execution="joint"), runs=10, seed=7)
    assert joint.in_class < 10 and joint.containment_failures == () and joint.wrong_verdicts == ()


@pytest.mark.slow
def test_default_certification_of_the_benchmark_task(task, kin, imodel):
    """The main job with every default (``certify_crossing``, about 30 s): the catalogue's v_min
    within 0.01 m/s, its refutation bound, a Monte Carlo confirmation with no containment failure and no
    wrong verdict, every execution also decided by the run-time tracker."""
    expected = BENCHMARK.expected
    cert = certify_crossing(DEXTAR, task, kin=kin, imodel=imodel)
    assert cert.verdict is Verdict.MODE_CHANGED
    check_certified_speed(cert.v_min, expected)
    assert cert.refutation_bound == pytest.approx(expected.refutation_bound, abs=1e-3), cert.refutation_bound
    mc = cert.monte_carlo
    assert mc.containment_failures == () and mc.wrong_verdicts == ()
    assert mc.not_detected == () and mc.detected_in_class == mc.in_class == 50
    check_contains(cert.enclosures.x_lo, cert.enclosures.x_hi, cert.trajectory.x, "certificate: planned pose")


def test_cli_plan_writes_a_file_check_reads(tmp_path, capsys):
    out = tmp_path / "plan.csv"
    assert main(["plan", "--v-sing", "1.4", "-o", str(out)]) == 0
    capsys.readouterr()
    assert out.read_text().splitlines()[0] == "t,q1,q2,x1,x2"
    assert main(["check", str(out), "--initial-mode", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["verdict"] == "mode-changed"


def test_speed_ceiling_is_the_fastest_feasible_plan(task, kin, bench):
    """Smoothstep: both ramps fit; time-optimal: toppra's sets, close to sqrt(2 a_peak s*) (bang-bang from rest)."""
    s_star = float(np.linalg.norm(bench.point - task.start))
    smooth = speed_ceiling(kin, task, PlanningBounds())
    # s_star of the nominal geometry; the planner uses the centre of [xi] (0.3 mm apart)
    assert smooth == pytest.approx(np.sqrt(2 * 60.0 * s_star / 1.875), rel=3e-3)
    fast = speed_ceiling(kin, task, PlanningBounds(method="time-optimal"))
    assert fast == pytest.approx(np.sqrt(2 * 60.0 * s_star), rel=1e-2)
    for method, v in (("smoothstep", smooth), ("time-optimal", fast)):
        p = plan_crossing(kin, task, v, PlanningBounds(method=method))
        assert abs(np.linalg.norm(p.xd[p.k_sing]) - v) <= 1e-6 and np.abs(p.xdd).max() <= 60.0 * (1 + 1e-6)
    # above the ceiling: refused, naming the largest feasible speed
    with pytest.raises(InputError, match=rf"no feasible crossing at v_sing = .*v_sing <= {smooth:.3f} m/s"):
        plan_crossing(kin, task, smooth * 1.01, PlanningBounds())
    with pytest.raises(SimulationError, match=rf"no feasible crossing at v_sing = .*max feasible speed .* {fast:.5f} m/s"):
        plan_crossing(kin, task, fast * 1.02, PlanningBounds(method="time-optimal"))


def test_cli_certify_bad_input(tmp_path, capsys):
    assert main(["certify", "--start", "0,0.09", "--goal", "0,0.1", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "same assembly mode" in err and "\n" not in err
    assert not (tmp_path / "o").exists()
    assert main(["certify", "--v-low", "3", "--out", str(tmp_path / "o")]) == 2
    assert "no feasible crossing speed" in capsys.readouterr().err
    assert main(["plan", "--v-sing", "9", "-o", str(tmp_path / "p.csv")]) == 2
    assert "no feasible crossing" in capsys.readouterr().err
    assert not (tmp_path / "p.csv").exists()


def test_search_from_the_previous_tasks_v_min_on_a_moved_task(task, kin, imodel):
    """The optimisation-script case (issue 19): the benchmark task moved 2 mm, searched from the
    catalogue's v_min of the unmoved task: two questions, a certified speed within tol of the
    catalogue's, a failed one within tol below it."""
    from dataclasses import replace

    from crosscert.planner.certify.plan import search_v_min

    moved = replace(task, start=task.start + np.array([0.0, 2e-3]), goal=task.goal + np.array([0.0, 2e-3]))
    expected = BENCHMARK.expected
    r = search_v_min(kin, imodel, moved, PlanningBounds(), 0.6, speed_ceiling(kin, moved, PlanningBounds()),
                     tol=0.01, parallel=False, v_guess=expected.v_min)
    assert len(r.trials) <= 3
    check_certified_speed(r.v_min, expected, tol=2 * expected.v_min_tol)
    assert r.runs[r.v_min].verdict is Verdict.MODE_CHANGED
    failed = [t.v_sing for t in r.trials if t.verdict is not Verdict.MODE_CHANGED]
    assert failed and 0 < r.v_min - max(failed) <= 0.01


def test_certify_crossing_passes_its_guess_to_the_speed_search(task, kin, imodel, monkeypatch):
    """``certify_crossing(v_guess=...)`` reaches the search; a bad guess is refused before any work."""
    import crosscert.planner.certify.crossing as crossing_mod
    from crosscert.planner.certify.plan import SpeedSearch, SpeedTrial

    seen = []

    def spy(kin, imodel, task, b, v_low, v_high, **kw):
        seen.append(kw["v_guess"])
        return SpeedSearch(None, (SpeedTrial(v_high, Verdict.UNKNOWN, 0.0, 0.0, None, Verdict.UNKNOWN),), {})

    monkeypatch.setattr(crossing_mod, "search_v_min", spy)
    cert = certify_crossing(DEXTAR, task, kin=kin, imodel=imodel, refute=False, monte_carlo_runs=0, bounce=False,
                            v_guess=0.97)
    assert seen == [0.97] and cert.v_min is None
    with pytest.raises(InputError, match="v_guess"):
        certify_crossing(DEXTAR, task, kin=kin, imodel=imodel, refute=False, monte_carlo_runs=0, v_guess=0.0)
    assert seen == [0.97]


def test_the_coarse_scan_reaches_below_a_low_bracket():
    """The default counterexample scan: every 0.1 m/s from 0.3 m/s when the speed bracket starts above it, from
    ``v_low`` when below (a robot certified under 0.3 m/s had no floor searched: the scan started above its
    ``v_min``, and every scanned speed was dropped as certified)."""
    from crosscert.planner.certify.crossing import scan_speeds

    assert scan_speeds(0.6, 1.0) == [0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]
    low = scan_speeds(0.05, 0.5)
    assert low == [0.05, 0.15, 0.25, 0.35, 0.45] and min(low) == 0.05
