"""Named reference problems shared by the tests (simulated DexTAR runs).

Each problem is a simulated encoder recording with its ground truth and the
answer a sound tracker must give (or must never give).  Simulations are
cached per process.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from planner.simulate import random_geometry, simulate_bounce, simulate_crossing
from planner.sweep import cruise_for
from robots import DEXTAR, KinematicModel, benchmark_crossing
from verifier.model import IntervalModel
from verifier.tracker import TrackerSettings, Verdict

T_REST = 0.05  # s: enough for the boxes to settle (they settle in a few samples)
# every run starts at least 35 mm before the locus (planner.sweep.cruise_for)


@dataclass(frozen=True)
class Problem:
    name: str
    v_sing: float
    bounce: bool
    seed: int
    expected: frozenset  # acceptable verdicts


CATALOGUE = {
    p.name: p
    for p in (
        # the paper's fastest Table II speed: a sound tracker must certify it
        Problem("crossing_1458", 1.458, False, 0, frozenset({Verdict.MODE_CHANGED})),
        # the paper's slowest detection (with its unsound model): certified soundly
        # with the robot's default partition of the angular offsets
        Problem("crossing_1264", 1.264, False, 0, frozenset({Verdict.MODE_CHANGED})),
        # far below the refutation floor (~0.8 m/s): certifying would be wrong
        Problem("crossing_0500", 0.5, False, 0, frozenset({Verdict.UNKNOWN})),
        # failed crossings: never "mode-changed"
        Problem("bounce_1458", 1.458, True, 0, frozenset({Verdict.MODE_UNCHANGED, Verdict.UNKNOWN})),
        Problem("bounce_0800", 0.8, True, 3, frozenset({Verdict.MODE_UNCHANGED, Verdict.UNKNOWN})),
    )
}


@lru_cache(maxsize=None)
def kinematics():
    return KinematicModel(DEXTAR)


@lru_cache(maxsize=None)
def interval_model():
    return IntervalModel(DEXTAR)


def default_settings(**kw):
    return TrackerSettings.for_robot(DEXTAR, **kw)


@lru_cache(maxsize=None)
def simulate(v_sing: float, bounce: bool, seed: int, quantisation: str = "floor"):
    """A simulated run; ``seed`` 0 uses the centre of the calibration box."""
    bench = benchmark_crossing()
    xi = None if seed == 0 else random_geometry(DEXTAR, np.random.default_rng(seed))
    fn = simulate_bounce if bounce else simulate_crossing
    return fn(kinematics(), bench.point, bench.direction, v_sing, xi_true=xi, t_rest=T_REST,
              working_guess=bench.q_point, seed=seed, quantisation=quantisation,
              cruise=cruise_for(v_sing))


def run_of(problem: Problem):
    return simulate(problem.v_sing, problem.bounce, problem.seed)
