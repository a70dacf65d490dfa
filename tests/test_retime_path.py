"""Re-timing a given path (``planner.path``, ``certify_path``, ``certify --plan --retime``): the path kept."""

from __future__ import annotations

import json

import numpy as np
import pytest

import problems
from crosscert.planner import PlanningBounds
from crosscert.planner.certify.trajectory import certify_path, certify_trajectory
from crosscert.planner.cli import main
from crosscert.planner.path import path_task_of, plan_along_path
from crosscert.planner.plan import plan_crossing, speed_ceiling
from crosscert.robots import DEXTAR
from crosscert.robots.errors import InputError
from crosscert.verifier.settings import Verdict
from crosscert.verifier.trajfile import write_trajectory


def test_a_straight_path_re_timed_is_the_tasks_own_plan(kin, task):
    """The path of the segment's plan, re-timed at another speed, gives the segment's plan at that speed."""
    b = PlanningBounds().resolve(DEXTAR)
    path = path_task_of(kin, plan_crossing(kin, task, 1.3, b), "segment")
    assert path.m0 == 1 or path.m0 == -1
    for v in (0.9, 1.1):
        mine, theirs = plan_along_path(kin, path, v, b), plan_crossing(kin, task, v, b)
        assert mine.k_sing == theirs.k_sing and mine.q.shape == theirs.q.shape
        assert np.max(np.abs(mine.q - theirs.q)) < 1e-9 and np.max(np.abs(mine.xdd - theirs.xdd)) < 1e-6
    assert speed_ceiling(kin, path, b) == pytest.approx(speed_ceiling(kin, task, b), rel=1e-6)


def test_the_time_optimal_law_along_a_straight_path_is_the_tasks_own(kin, task):
    """toppra and cvxpy along the given path (``planner.timescale.sample_curve``): on the segment's own path,
    the segment's time-optimal plan and ceiling."""
    b = PlanningBounds(method="time-optimal").resolve(DEXTAR)
    path = path_task_of(kin, plan_crossing(kin, task, 1.3, PlanningBounds().resolve(DEXTAR)), "segment")
    mine, theirs = plan_crossing(kin, path, 1.2, b), plan_crossing(kin, task, 1.2, b)
    assert mine.k_sing == theirs.k_sing and mine.q.shape == theirs.q.shape
    assert np.max(np.abs(mine.q - theirs.q)) < 1e-6
    assert speed_ceiling(kin, path, b) == pytest.approx(speed_ceiling(kin, task, b), rel=1e-6)


def test_the_time_optimal_law_along_the_arc_keeps_its_limits(kin):
    arc = problems.arc_task()
    b = PlanningBounds(method="time-optimal").resolve(DEXTAR)
    plan = plan_crossing(kin, arc, 1.2, b)
    assert np.all(np.abs(plan.xdd) <= b.a_peak * (1 + 1e-6))  # the law's bound, below the robot's a_max
    assert np.linalg.norm(plan.xd[plan.k_sing]) == pytest.approx(1.2, rel=1e-6)
    modes = kin.mode_batch(plan.x, plan.q, plan.xi_plan)
    assert modes[0] == -modes[-1] != 0
    assert speed_ceiling(kin, arc, b) > speed_ceiling(kin, arc, PlanningBounds().resolve(DEXTAR))


def test_the_arc_plan_accelerates_within_the_robots_bound_up_to_its_ceiling(kin):
    arc = problems.arc_task()
    b = PlanningBounds().resolve(DEXTAR)
    top = speed_ceiling(kin, arc, b)
    assert 1.3 < top < 1.5  # the bend (radius 0.1 m) limits it below the straight task's 1.96 m/s
    plan = plan_along_path(kin, arc, top, b)
    assert np.all(np.abs(plan.xdd).max(axis=0) <= np.asarray(DEXTAR.a_max))
    # the crossing sample lies on the locus' side change and the planned speed there is the asked one
    modes = kin.mode_batch(plan.x, plan.q, plan.xi_plan)
    assert modes[plan.k_sing - 2] == -modes[plan.k_sing + 2] != 0
    assert np.linalg.norm(plan.xd[plan.k_sing]) == pytest.approx(top, rel=1e-3)


def test_a_curved_path_certifies_and_its_re_timed_plan_certifies_again(kin, imodel, tmp_path):
    """The reported minimal speed re-verified by certifying the re-timed plan written at it."""
    arc = problems.arc_task()
    b = PlanningBounds().resolve(DEXTAR)
    given = plan_along_path(kin, arc, problems.ARC["not_certified"], b)
    cert = certify_path(DEXTAR, given, b, source="arc", v_low=problems.ARC["not_certified"], tol=0.05,
                        monte_carlo_runs=0, refute=False, kin=kin, imodel=imodel)
    assert cert.verdict is Verdict.MODE_CHANGED and cert.v_min <= problems.ARC["certified"]
    path = tmp_path / "retimed.csv"
    p = cert.trajectory
    write_trajectory(path, p.t, p.q, x=p.x)
    again = certify_trajectory(DEXTAR, path, monte_carlo_runs=0, kin=kin, imodel=imodel)
    assert again.verdict is Verdict.MODE_CHANGED and again.v_min == pytest.approx(cert.v_min, rel=1e-3)


def test_cli_retime_prints_the_line_to_act_on_and_writes_the_re_timed_plan(kin, tmp_path, capsys):
    arc = problems.arc_task()
    plan = plan_along_path(kin, arc, problems.ARC["not_certified"], PlanningBounds().resolve(DEXTAR))
    path = tmp_path / "arc.csv"
    write_trajectory(path, plan.t, plan.q, x=plan.x)
    out = tmp_path / "c"
    argv = ["certify", "--plan", str(path), "--retime", "--v-low", str(problems.ARC["not_certified"]), "--tol", "0.1",
            "--monte-carlo", "0", "--no-refute", "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith(f"your plan ({problems.ARC['not_certified']:.3f} m/s at the singularity): not certified")
    assert "; this path certifies from " in first
    report = json.loads((out / "certificate.json").read_text())
    retimed = report["retimed_path"]
    assert retimed["verdict"] == "mode-changed" and retimed["bounce"] is None
    assert (out / f"retimed_plan_{retimed['v_min_mps']:.3f}.csv").is_file()


def test_paths_that_cannot_be_re_timed_are_refused(kin, task):
    b = PlanningBounds().resolve(DEXTAR)
    plan = plan_crossing(kin, task, 1.1, b)
    with pytest.raises(InputError, match="fewer than 4 distinct poses"):
        path_task_of(kin, plan.__class__(**{**_fields(plan), "x": np.repeat(plan.x[:1], len(plan.x), 0)}), "rest")
    with pytest.raises(InputError, match="smoothstep or time-optimal law, not 'dynamic'"):
        plan_crossing(kin, path_task_of(kin, plan, "p"), 1.0, PlanningBounds(method="dynamic", dynamics=object()))


def _fields(plan):
    names = ("t", "q", "qd", "qdd", "x", "xd", "xdd", "t_s", "k_sing", "v_sing", "crossing_point", "xi_plan")
    return {k: getattr(plan, k) for k in names}
