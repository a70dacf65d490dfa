"""Data types hold values: arrays read-only, equality that never raises, options as enums."""

import dataclasses
import importlib
import inspect
import pkgutil

import numpy as np
import pytest

from crosscert import planner
from crosscert import robots
from crosscert import verifier
from crosscert.planner import Method, PlannedTrajectory, PlanningBounds, plan_crossing
from crosscert.planner.execution import ExecutionKind
from crosscert.planner.task import CrossingTask
from crosscert.robots.errors import InputError


def _dataclasses():
    seen = {}
    for pkg in (robots, verifier, planner):
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            if info.name.endswith("__main__"):
                continue
            mod = importlib.import_module(info.name)
            for obj in vars(mod).values():
                if inspect.isclass(obj) and dataclasses.is_dataclass(obj) and obj.__module__ == mod.__name__:
                    seen[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return seen


DATACLASSES = _dataclasses()


@pytest.mark.parametrize("name", sorted(DATACLASSES))
def test_array_fields_do_not_make_equality_raise(name):
    """A dataclass holding arrays compares by identity (``eq=False``): ``==`` on arrays would raise."""
    cls = DATACLASSES[name]
    arrays = [f.name for f in dataclasses.fields(cls) if "ndarray" in str(f.type)]
    if arrays:
        assert not cls.__dataclass_params__.eq or "__eq__" in vars(cls), f"{name} compares {arrays} with =="


def test_the_scan_sees_the_data_types():
    assert "crosscert.planner.task.CrossingTask" in DATACLASSES and "crosscert.verifier.trajectory.Trajectory" in DATACLASSES


def test_task_and_plan_arrays_are_read_only(task, kin):
    with pytest.raises(ValueError, match="read-only"):
        task.start[0] = 5.0
    plan = plan_crossing(kin, task, 1.3, PlanningBounds())
    assert isinstance(plan, PlannedTrajectory)
    for name in ("t", "q", "qd", "qdd", "x", "xd", "xdd", "crossing_point", "xi_plan"):
        assert not getattr(plan, name).flags.writeable, name
    assert plan == plan and plan != plan_crossing(kin, task, 1.3, PlanningBounds())


def test_task_copies_what_it_is_given():
    start = np.array([0.0, 0.14])
    task = CrossingTask(start, np.array([0.0, 0.03]), np.array([1.9, 1.2]))
    start[0] = 1.0
    assert task.start[0] == 0.0


def test_options_are_enums_and_bad_ones_list_the_choices():
    b = PlanningBounds(method="time-optimal", execution="joint").resolve(robots.DEXTAR)
    assert b.method is Method.TIME_OPTIMAL and b.execution is ExecutionKind.JOINT
    with pytest.raises(InputError, match="'smoothstep', 'time-optimal', 'dynamic'"):
        PlanningBounds(method="fast").resolve(robots.DEXTAR)
    with pytest.raises(InputError, match="'cartesian', 'joint'"):
        PlanningBounds(execution="loose").resolve(robots.DEXTAR)


def test_a_sweep_row_not_certified_has_no_certified_step(kin, bench):
    """SweepRow.certified_at_step is None where the tracker certified no final mode (not a -1 sentinel)."""
    from crosscert.planner.sweep import SweepRow, sweep
    from crosscert.verifier.settings import VelocityModel, Verdict

    rows, _ = sweep(kin.robot, kin, bench, [0.3, 1.458], models=(VelocityModel.SOUND,))
    by_speed = {r.v_sing: r for r in rows}
    slow, fast = by_speed[0.3], by_speed[1.458]
    assert slow.verdict is not Verdict.MODE_CHANGED and slow.certified_at_step is None, slow
    assert fast.verdict is Verdict.MODE_CHANGED and isinstance(fast.certified_at_step, int), fast
    assert fast.certified_at_step > fast.k_sing and isinstance(rows[0], SweepRow)
