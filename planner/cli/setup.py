"""What the commands share: robots from the registry, tasks, tracker settings, progress bars."""

from __future__ import annotations

import sys

import numpy as np

from crosscert.robots import KinematicModel
from crosscert.robots.errors import InputError
from crosscert.robots.registry import get_entry
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.settings import TrackerSettings
from crosscert.verifier.trajfile import parse_number

from ..simulate import random_geometry
from ..task import CrossingTask, benchmark_task

__all__ = ["floats_option", "tracker_setup", "task_setup", "benchmark_setup", "true_geometry", "progress_bar"]


def floats_option(text: str, count: int | None, what: str) -> list[float]:
    """The comma-separated numbers of option ``what`` (``count`` of them, any number when None)."""
    try:
        vals = [parse_number(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{what}: expected comma-separated numbers, got {text!r}") from None
    if count is not None and len(vals) != count:
        raise InputError(f"{what}: expected {count} comma-separated numbers, got {len(vals)}")
    return vals


def tracker_setup(a):
    """Robot, interval model, the settings maker ``t_s -> TrackerSettings`` and the ``--x0`` box (or None)."""
    robot = get_entry(a.robot).robot
    x0 = None
    if a.x0 is not None:
        v = floats_option(a.x0, 2 * robot.n, "--x0")
        x0 = (np.array(v[0::2]), np.array(v[1::2]))

    def settings(t_s):
        return TrackerSettings.for_robot(robot, t_s=t_s, eps_q=a.eps_q, a_max=a.a_max, xd0=a.xd0,
                                         velocity_model=a.velocity_model)

    return robot, IntervalModel(robot), settings, x0


def benchmark_setup(name: str):
    """Registry entry, kinematic model and nominal benchmark crossing of robot ``name``."""
    entry = get_entry(name)
    bench = entry.benchmark_crossing()
    return entry, KinematicModel(entry.robot), bench


def task_setup(a):
    """Registry entry, kinematic model and the task of ``--start``/``--goal`` (default: the benchmark task)."""
    entry, kin, bench = benchmark_setup(a.robot)
    n = entry.robot.n
    task = benchmark_task(entry)
    if a.start is not None or a.goal is not None:
        start = task.start if a.start is None else np.array(floats_option(a.start, n, "--start"))
        goal = task.goal if a.goal is None else np.array(floats_option(a.goal, n, "--goal"))
        task = CrossingTask(start, goal, bench.q_point)
    return entry, kin, task


def true_geometry(robot, seed: int):
    """The true geometry of a simulation: the box centre for seed 0 (None), else a seeded draw in ``[xi]``."""
    if seed == 0:
        return None
    return random_geometry(robot, np.random.default_rng(seed))


def progress_bar(total, enabled: bool, desc: str):
    """A tqdm bar on stderr (``total`` None: open-ended) and its per-sample callback, or ``(None, None)``."""
    if not enabled:
        return None, None
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="step", file=sys.stderr, leave=False)
    return bar, (lambda k: bar.update(1))
