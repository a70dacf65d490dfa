"""The subprocess executor (planner.worker) and the refutation searches of the pipeline on executors."""

import concurrent.futures as cf
import dataclasses
import operator
import os
import tempfile

import numpy as np
import pytest

from crosscert.planner import CrossingTask, PlanningBounds, certify_crossing, execution_class, plan_crossing
from crosscert.planner.execution import in_class
from crosscert.planner.refute.orchestrate import Refuter, refute_speed
from crosscert.planner.simulate import random_geometry
from crosscert.planner.worker import SubprocessExecutor, WorkerStopped
from problems import interval_model, kinematics
from crosscert.robots import DEXTAR, KinematicModel
from crosscert.robots.dextar import benchmark_crossing
from crosscert.robots.dextar import dextar_loop_closure
from crosscert.verifier.tracker import Verdict


def test_calls_run_in_order_and_errors_come_back():
    with SubprocessExecutor() as ex:
        futures = [ex.submit(operator.truediv, 6.0, k) for k in (1.0, 2.0, 3.0)]
        assert [f.result() for f in futures] == [6.0, 3.0, 2.0]
        with pytest.raises(ZeroDivisionError):
            ex.submit(operator.truediv, 6.0, 0.0).result()
        assert ex.submit(operator.truediv, 6.0, 12.0).result() == 0.5  # the worker survives an exception
        assert ex.submit(divmod, 7, b=2).exception() is not None  # keyword arguments reach the call


def test_cancelled_calls_never_run():
    with SubprocessExecutor() as ex:
        slow = ex.submit(pow, 2, 10)
        later = [ex.submit(pow, 3, k) for k in range(50)]
        cancelled = [f for f in later[25:] if f.cancel()]
        assert slow.result() == 1024
        assert all(f.result() == 3**k for k, f in enumerate(later[:25]))
        assert all(f.cancelled() for f in cancelled)


def test_unpicklable_requests_and_answers_come_back_as_errors():
    with SubprocessExecutor() as ex:
        with pytest.raises(Exception, match="pickle|lambda"):
            ex.submit(operator.add, lambda: 0, 1).result()  # the request cannot be pickled
        assert ex.submit(operator.add, 1, 2).result() == 3  # only that call failed
        with pytest.raises(RuntimeError, match="could not be sent back"):
            ex.submit(tempfile.TemporaryFile, "w").result()  # a file object cannot be sent back
        with pytest.raises(RuntimeError, match="could not be sent back"):
            ex.submit(tempfile.TemporaryFile, "w+b").result()  # the worker survived


def test_a_dying_worker_is_reported_not_waited_for():
    ex = SubprocessExecutor()
    try:
        with pytest.raises(WorkerStopped, match="worker stopped"):
            ex.submit(os._exit, 3).result(timeout=60)
        with pytest.raises(WorkerStopped):
            ex.submit(operator.add, 1, 2).result(timeout=60)
    finally:
        ex.shutdown(wait=False)


def local_closure(x, q, xi):
    """A loop closure the worker process cannot import (tests/ is not on its path)."""
    return dextar_loop_closure(x, q, xi)


def _task():
    b = benchmark_crossing()
    return CrossingTask(b.point - 0.06 * b.direction, b.point + 0.06 * b.direction, b.q_point)


def test_refutation_falls_back_to_this_process():
    robot = dataclasses.replace(DEXTAR, loop_closure=local_closure)
    ref = Refuter(robot, _task(), PlanningBounds().resolve(robot), 1, [robot.xi_center], kinematics(),
                  SubprocessExecutor(), own_executor=True)
    try:
        row = ref.result(0.5)
    finally:
        ref.close()
    assert row.speed == 0.5 and row.verified


def test_any_executor_gives_the_rows_of_this_process():
    """A thread pool (any concurrent.futures executor) gives the same search rows as a call here."""
    b = PlanningBounds().resolve(DEXTAR)
    args = (DEXTAR, _task(), b, 1, [DEXTAR.xi_center])
    with cf.ThreadPoolExecutor(max_workers=1) as pool:
        ref = Refuter(*args, None, pool)
        ref.submit([0.5])
        row = ref.result(0.5)
    here = refute_speed(*args, 0.5, kin=KinematicModel(DEXTAR))
    assert row.verified == here.verified and row.speed == here.speed


def test_cartesian_class_with_a_joint_without_offset():
    """Only joint 1 declares an offset: joint 2's whole deviation is drift; path-following executions belong."""
    robot = dataclasses.replace(DEXTAR, joint_offsets=(5, None))
    kin = KinematicModel(robot)
    plan = plan_crossing(kin, _task(), 1.3, PlanningBounds())
    cls = execution_class(kin, plan, PlanningBounds())
    rng = np.random.default_rng(5)
    for r in range(20):
        xi = random_geometry(robot, rng, corners=(r % 2 == 0))
        q = kin.ik_path(plan.x, xi, plan.q[0])
        assert in_class(cls, robot, q, plan.q, xi, plan.xi_plan, robot.eps_q), r


def test_certify_crossing_with_background_refutation():
    """End to end on a narrow bracket: v_min, refutation bound below it, Monte Carlo, JSON summary."""
    cert = certify_crossing(DEXTAR, _task(), PlanningBounds(), v_low=0.9, v_high=1.3, tol=0.1, monte_carlo_runs=4,
                            refute_speeds=[0.5, 0.8], kin=kinematics(), imodel=interval_model(), bounce=False)
    assert cert.verdict is Verdict.MODE_CHANGED and 0.9 < cert.v_min <= 1.3
    # bisected up from the scan's 0.8 m/s towards v_min (to tol / 10): a verified bounce up to 0.93 m/s at a_max
    assert cert.refutation_bound is not None and 0.8 <= cert.refutation_bound < cert.v_min
    assert cert.summary()["bounce"] is None  # tests/test_bounce.py covers the bounce gap
    speeds = [r.speed for r in cert.refutation]
    assert speeds == sorted(speeds) and {0.5, 0.8} <= set(speeds) and max(speeds) < cert.v_min
    assert all(r.speed <= cert.refutation_bound for r in cert.refutation if r.verified)
    mc = cert.monte_carlo
    assert mc.in_class == 4 and mc.detected_in_class == 4 and mc.containment_failures == ()
    summary = cert.summary()
    assert summary["execution"]["kind"] == "cartesian"
    assert np.isfinite(summary["gap_mps"]) and summary["gap_mps"] > 0
    # self-describing: what was certified, under which bounds, in our words
    assert summary["schema"] == "crosscert-certificate/4" and summary["robot"] == "dextar"
    assert summary["task"]["start"] == list(_task().start) and summary["method"] == "smoothstep"
    assert summary["bounds"]["a_peak_mps2"] == 60.0 and summary["bounds"]["eps_q"] == DEXTAR.eps_q
    assert list(summary["execution"]["xi_lo"]) == list(DEXTAR.param_names)
    found = [r for r in summary["refutation"] if r["counterexample"]]
    assert found and all(r["outcome"] == "counterexample-found" for r in found)
    assert all(set(r["geometry"]) == set(DEXTAR.param_names) for r in found)


class _FailingExecutor(cf.Executor):
    """An executor whose every call fails, as a dead background worker's do."""

    def submit(self, fn, /, *args, **kwargs):
        future = cf.Future()
        future.set_exception(WorkerStopped("the background worker stopped"))
        return future


def test_monte_carlo_beside_a_worker_counts_the_same_executions():
    """Executions split between a worker and this process: the serial counts, lists and order; and the same
    when the worker fails (its executions run here)."""
    from crosscert.planner import monte_carlo_confirmation

    kin, im = kinematics(), interval_model()
    b = PlanningBounds()
    plan = plan_crossing(kin, _task(), 1.3, b)
    cls = execution_class(kin, plan, b)
    serial = monte_carlo_confirmation(kin, im, plan, b, runs=6, seed=3, execution=cls, parallel=False)
    with cf.ThreadPoolExecutor(max_workers=1) as pool:
        split = monte_carlo_confirmation(kin, im, plan, b, runs=6, seed=3, execution=cls, parallel=False,
                                         beside=pool)
    failed = monte_carlo_confirmation(kin, im, plan, b, runs=6, seed=3, execution=cls, parallel=False,
                                      beside=_FailingExecutor())
    assert serial.runs == serial.in_class == 6
    assert split.summary() == serial.summary() and failed.summary() == serial.summary()


class _SlowThere:
    """``there`` of :func:`planner.montecarlo._shared`: each chunk after ``delay`` s on a thread of its own,
    recording what it ran; fails from chunk ``fail_from`` on."""

    def __init__(self, delay: float, fail_from: int | None = None):
        self.delay, self.fail_from, self.ran = delay, fail_from, []
        self.pool = cf.ThreadPoolExecutor(max_workers=1)

    def __call__(self, start, stop):
        def run():
            import time

            time.sleep(self.delay)
            if self.fail_from is not None and start >= self.fail_from:
                raise WorkerStopped("the background worker stopped")
            self.ran.append((start, stop))
            return ("there", start, stop)

        return self.pool.submit(run)


@pytest.mark.parametrize("delay, chunk", [(0.0, 1), (0.02, 1), (0.02, 3), (0.5, 2)])
def test_shared_executions_run_once_each_in_order_from_both_ends(delay, chunk):
    """Every chunk runs exactly once, results come back in execution order whoever ran them, the worker
    takes from the front and this thread from the back, and progress counts every execution once."""
    from crosscert.planner.montecarlo import _shared

    there, here_ran, ticks = _SlowThere(delay), [], []

    def here(start, stop):
        here_ran.append((start, stop))
        return ("here", start, stop)

    out = _shared(there, here, 10, chunk, progress=lambda done=1: ticks.append(done))
    bounds = [(s, min(10, s + chunk)) for s in range(0, 10, chunk)]
    assert [(a, b) for _, a, b in out] == bounds
    assert sorted(there.ran + here_ran) == bounds and not set(there.ran) & set(here_ran)
    assert there.ran == bounds[:len(there.ran)]  # the front
    assert here_ran == bounds[::-1][:len(here_ran)]  # the back
    assert len(ticks) == 10
    if delay >= 0.5:  # a slow worker still takes its first chunk, this thread the rest
        assert there.ran == bounds[:1]


def test_shared_executions_the_worker_failed_on_run_here():
    """A worker that fails from some chunk on: that chunk and those after it run here, once each, in order."""
    from crosscert.planner.montecarlo import _shared

    there, here_ran = _SlowThere(0.05, fail_from=2), []

    def here(start, stop):
        import time

        time.sleep(0.03)
        here_ran.append((start, stop))
        return ("here", start, stop)

    out = _shared(there, here, 8, 1)
    assert [(a, b) for _, a, b in out] == [(i, i + 1) for i in range(8)]
    assert there.ran and all(start < 2 for start, _ in there.ran)  # it failed at chunk 2, if it got there
    assert sorted(there.ran + here_ran) == [(i, i + 1) for i in range(8)]


def test_an_error_here_stops_the_worker_taking_shares():
    """An execution failing in this process: the error comes out, and the worker takes no share after it."""
    from crosscert.planner.montecarlo import _shared

    there = _SlowThere(0.05)

    def here(start, stop):
        raise ValueError("boom")

    import time

    with pytest.raises(ValueError, match="boom"):
        _shared(there, here, 20, 1)
    time.sleep(0.4)  # a feeder still taking shares would have run several by now
    assert len(there.ran) <= 1


def test_the_worker_draws_the_certificate_figure_as_this_process_does(tmp_path):
    """`crosscert certify` hands the figure to the worker while the second certification runs: its
    arguments reach the worker, and the file is the one this process draws, byte for byte."""
    from pathlib import Path

    from crosscert.planner.cli.planning import _figure

    cert = certify_crossing(DEXTAR, _task(), PlanningBounds(), v_low=1.2, v_high=1.3, tol=0.1, monte_carlo_runs=0,
                            refute=False, kin=kinematics(), imodel=interval_model(), bounce=False)
    png, (fn, *args, kwargs) = _figure(cert, DEXTAR, PlanningBounds(), tmp_path / "here", "rad")
    png.parent.mkdir()
    fn(*args, **kwargs)
    there = tmp_path / "there" / png.name
    there.parent.mkdir()
    pool = SubprocessExecutor()
    try:
        pool.submit(fn, there, *args[1:], **kwargs).result()
    finally:
        pool.shutdown()
    assert Path(png).stat().st_size > 10_000 and there.read_bytes() == Path(png).read_bytes()
