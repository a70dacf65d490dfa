"""The background worker process (planner._worker) and its use by certify_crossing."""

import numpy as np
import pytest

from planner._worker import BackgroundCalls, WorkerStopped
from planner.certify import CrossingTask, PlanningBounds, _Refuter, certify_crossing
from planner.execution import in_class
from planner.simulate import random_geometry
from problems import interval_model, kinematics
from robots import DEXTAR, benchmark_crossing
from robots.dextar import dextar_loop_closure
from verifier.tracker import Verdict


def test_calls_run_in_order_and_errors_come_back():
    bg = BackgroundCalls("operator", "truediv", (6.0,))
    try:
        bg.submit([1.0, 2.0, 3.0])
        assert [bg.result(k) for k in (3.0, 1.0, 2.0)] == [2.0, 6.0, 3.0]
        assert bg.result(4.0) == 1.5  # queued on demand
        with pytest.raises(ZeroDivisionError):
            bg.result(0.0)
        assert bg.result(12.0) == 0.5  # the worker survives an exception
        bg.submit([5.0, 7.0])
        bg.drop(lambda k: k > 6.0)
        assert bg.result(5.0) == 1.2
    finally:
        bg.close()


def test_unpicklable_requests_and_answers_come_back_as_errors():
    bg = BackgroundCalls("operator", "add", (lambda: 0,))  # the request cannot be pickled
    try:
        with pytest.raises(WorkerStopped):
            bg.result(1)
    finally:
        bg.close()
    bg = BackgroundCalls("tempfile", "TemporaryFile", ())  # a file object cannot be sent back
    try:
        with pytest.raises(RuntimeError, match="could not be sent back"):
            bg.result("w")
        with pytest.raises(RuntimeError, match="could not be sent back"):
            bg.result("w+b")  # the worker survived
    finally:
        bg.close()


def local_closure(x, q, xi):
    """A loop closure the worker process cannot import (tests/ is not on its path)."""
    return dextar_loop_closure(x, q, xi)


def test_refutation_falls_back_to_this_process():
    import dataclasses

    robot = dataclasses.replace(DEXTAR, loop_closure=local_closure)
    b = benchmark_crossing()
    task = CrossingTask(b.point - 0.06 * b.direction, b.point + 0.06 * b.direction, b.q_point)
    ref = _Refuter(robot, task, PlanningBounds().resolved(robot), 1, [robot.xi_center], kinematics(), True)
    try:
        row = ref.result(0.5)
    finally:
        ref.close()
    assert row.speed == 0.5 and row.verified


def test_cartesian_class_with_a_joint_without_offset():
    """Only joint 1 declares an offset: joint 2's whole deviation is drift; path-following executions belong."""
    import dataclasses

    from planner.certify import execution_class, plan_crossing
    from robots import KinematicModel

    robot = dataclasses.replace(DEXTAR, joint_offsets=(5, None))
    kin = KinematicModel(robot)
    b = benchmark_crossing()
    task = CrossingTask(b.point - 0.06 * b.direction, b.point + 0.06 * b.direction, b.q_point)
    plan = plan_crossing(kin, task, 1.3, PlanningBounds())
    cls = execution_class(kin, plan, PlanningBounds())
    rng = np.random.default_rng(5)
    for r in range(20):
        xi = random_geometry(robot, rng, corners=(r % 2 == 0))
        q = kin.ik_path(plan.x, xi, plan.q[0])
        assert in_class(cls, robot, q, plan.q, xi, plan.xi_plan, robot.eps_q), r


def test_a_dying_worker_is_reported_not_waited_for():
    bg = BackgroundCalls("os", "_exit", ())
    try:
        with pytest.raises(WorkerStopped, match="worker stopped"):
            bg.result(3)
        with pytest.raises(WorkerStopped):
            bg.result(4)
    finally:
        bg.close()


def test_certify_crossing_with_background_refutation():
    """End to end on a narrow bracket: v_min, refutation bound below it, Monte Carlo, JSON summary."""
    b = benchmark_crossing()
    task = CrossingTask(b.point - 0.06 * b.direction, b.point + 0.06 * b.direction, b.q_point)
    cert = certify_crossing(DEXTAR, task, PlanningBounds(), v_low=1.0, v_high=1.4, tol=0.1, monte_carlo_runs=4,
                            refute_speeds=[0.5, 1.0], kin=kinematics(), imodel=interval_model())
    assert cert.verdict is Verdict.MODE_CHANGED and 1.0 < cert.v_min <= 1.4
    assert cert.refutation_bound is not None and 0.7 <= cert.refutation_bound < 1.0
    speeds = [r.speed for r in cert.refutation]
    assert speeds == sorted(speeds) and {0.5, 1.0} <= set(speeds) and max(speeds) < cert.v_min
    assert all(r.speed <= cert.refutation_bound for r in cert.refutation if r.verified)
    mc = cert.monte_carlo
    assert mc["in_class"] == 4 and mc["detected_in_class"] == 4 and mc["containment_failures"] == []
    summary = cert.summary()
    assert summary["execution"]["kind"] == "cartesian"
    assert np.isfinite(summary["gap_mps"]) and summary["gap_mps"] > 0
