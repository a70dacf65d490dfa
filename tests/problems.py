"""Named reference problems shared by the tests, and the checks they share.

* :data:`CATALOGUE` — simulated DexTAR encoder recordings with their ground
  truth and the verdicts a sound tracker may give (:class:`Problem`);
* :data:`PLANNING` — the benchmark planning task of every registered robot
  with the expected result of the default certification
  (:class:`PlanningProblem`, :class:`CertificationExpectation`);
* ``check_*`` — assertions used by several test files: the truth inside
  every box, a verdict against a problem, a plan against its limits, a
  certified speed against the expected one and the refutation bound.

Simulations and tasks are cached per process.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit

from crosscert.planner.simulate import random_geometry, simulate_bounce, simulate_crossing
from crosscert.planner.sweep import cruise_for
from crosscert.planner.task import CrossingTask, Method, benchmark_task
from crosscert.robots import DEXTAR, KinematicModel, available_robots, get_entry
from crosscert.robots.dextar import benchmark_crossing
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.tracker import TrackerSettings, Verdict

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


# ------------------------------------------------------------ planning tasks
@dataclass(frozen=True)
class CertificationExpectation:
    """What the default certification of a task gives (``certify_crossing(robot, task)``).

    Attributes
    ----------
    v_min : float
        Minimal certified speed at the singularity, m/s (default ``window`` reasoning).
    v_min_forward : float
        The same with ``forward`` reasoning (the tracker alone), m/s.
    v_min_tol : float
        How far a re-run may land from ``v_min``, m/s (the search's own
        resolution is 0.01 m/s).
    refutation_bound : float or None
        Largest speed with a verified counterexample, m/s: no sound tracker
        certifies at or below it, so no test may ever see a certified speed
        there.
    measured : str
        Where and when the numbers were measured.
    """

    v_min: float
    v_min_forward: float
    v_min_tol: float
    refutation_bound: float | None
    measured: str


@dataclass(frozen=True)
class PlanningProblem:
    """A registered robot's benchmark task, planned with ``method``, and what certifying it gives."""

    name: str
    robot: str
    method: Method
    expected: CertificationExpectation | None  # None: not measured

    def task(self) -> CrossingTask:
        """The task (``planner.task.benchmark_task`` of the robot's registry entry), cached."""
        return _benchmark_task(self.robot)


@lru_cache(maxsize=None)
def _benchmark_task(robot: str) -> CrossingTask:
    return benchmark_task(get_entry(robot))


#: Default certification (smoothstep plans, ``PlanningBounds()`` defaults: the robot's a_max on every axis;
#: ``certify_crossing``'s defaults: v_low 0.6 m/s, tol 0.01 m/s, 50 Monte Carlo runs, refutation on) of each
#: robot's benchmark task: what ``crosscert certify`` prints.  About 25 s warm on 2 cores, so only
#: ``pytest -m slow`` runs it (tests/test_certify.py::test_default_certification_of_the_benchmark_task).
DEFAULT_CERTIFICATION = {
    # DexTAR at a_max (80, 80) m/s^2 (docs/planning.md, "Measured on the DexTAR benchmark task"): 1.0247 m/s
    # (1.0194 m/s fails), refutation bound 0.9375 m/s (bisected to a tenth of tol), ratio 1.093, Monte Carlo
    # 50/50, bounces certified from 10.0 mm (floor 9.50 mm); the forward tracker alone 1.3114 m/s.
    "dextar": CertificationExpectation(v_min=1.0247, v_min_forward=1.3114, v_min_tol=0.01, refutation_bound=0.9375,
                                       measured="crosscert certify, robot a_max on both axes"),
}

#: A curved DexTAR path (named reference problem of the re-timing of a given path): a circular arc of radius
#: ``radius`` m through the benchmark crossing point, its tangent there at ``angle_deg`` from the benchmark
#: direction, ``half_angle`` rad either side (0.06 m of arc).  Its smoothstep timing certifies from about 1.39 m/s
#: under the robot's a_max (1.026 m/s on the straight benchmark task); a counterexample exists at 1.11 m/s.
ARC = {"radius": 0.1, "angle_deg": 30.0, "half_angle": 0.6, "knots": 601, "certified": 1.45, "not_certified": 1.2}


@lru_cache(maxsize=None)
def arc_task():
    """The :data:`ARC` path as a ``planner.path.PathTask`` (cached)."""
    from crosscert.planner.path import path_task_from_poses

    kin = kinematics()
    b = benchmark_crossing()
    a = math.radians(ARC["angle_deg"])
    u = np.asarray(b.direction, float)
    t = np.array([math.cos(a) * u[0] - math.sin(a) * u[1], math.sin(a) * u[0] + math.cos(a) * u[1]])
    normal = np.array([-t[1], t[0]])
    phi = np.linspace(-ARC["half_angle"], ARC["half_angle"], ARC["knots"])
    R = ARC["radius"]
    X = b.point + R * np.sin(phi)[:, None] * t + R * (1.0 - np.cos(phi))[:, None] * normal
    q_start = kin.ik_path(np.linspace(b.point, X[0], 50), DEXTAR.xi_center, b.q_point)[-1]
    return path_task_from_poses(kin, X, q_start, "arc")


#: Linear systems ``A z <= b``, ``lo <= z <= hi`` (``A`` dense, one variable here) with multipliers ``y``, for the
#: Farkas certificate of :func:`verifier.one_motion.prove_infeasible`.  ``float_only``: feasible (``z = 5.2``
#: satisfies both rows exactly: each ``b`` is ``a z`` rounded up), yet ``yᵀ(A z - b)`` evaluated in round to
#: nearest is ``+3.6e-15 > 0`` (exactly ``-1.3e-16``): a certificate that holds only in float arithmetic.
#: ``infeasible``: ``z <= 0.4`` and ``z >= 0.6``.  (Found by a seeded search, 2026-12-02.)
FARKAS = {
    "float_only": (np.array([[5.8], [-4.4]]), np.array([30.16, -22.880000000000003]), np.array([5.2]),
                   np.array([5.2]), np.array([1.0, 1.3181818181818181])),
    "infeasible": (np.array([[1.0], [-1.0]]), np.array([0.4, -0.6]), np.array([0.0]), np.array([1.0]),
                   np.array([1.0, 1.0])),
}

#: The relative tracking margin (``PlanningBounds.a_margin``) under which the plans of :data:`ONE_MOTION_PLAN`
#: and the window tests were measured: y within the plan's peak + 10 % (66 m/s^2), x within the robot's
#: 80 m/s^2.  The mechanisms those tests guard (one-motion refutation and narrowing, the acceleration bound
#: between samples) decide those plans only under that bound; the default is the robot's a_max on both axes.
MARGIN = 0.1

#: :data:`MARGIN`'s certification of the DexTAR benchmark task (``crosscert certify --a-margin 0.1``): v_min
#: 0.9292 m/s (0.9238 m/s fails), refutation bound 0.8484 m/s, Monte Carlo 49/50.
MARGIN_CERTIFICATION = {"v_min": 0.9292, "refutation_bound": 0.8484}

#: ``crosscert certify --a-margin 0.1``'s plan speeds (m/s) around the one-motion refutation (verifier.one_motion, 2026-12-02):
#: undecided without it (the bounce hypothesis survives with 10 sub-boxes), certified with it; and the
#: refutation bound, where a verified bounce exists (the bounce hypothesis must survive).
#: ``contracted``: undecided by the refutation alone, certified once the one-motion relaxation also narrows the
#: rows' sub-boxes (2026-12-02, issue 20).
ONE_MOTION_PLAN = {"certified": 0.9557, "contracted": 0.9300, "floor": 0.8438}

#: The 3-RPR benchmark task's counterexample searches on ``crosscert certify``'s own plans and bounds (issue 20,
#: 2026-12-02; docs/robots.md, "The 3-RPR"): a verified bounce at ``refuted`` m/s from the box centre, and at
#: ``refuted_warm`` m/s started from that one (as certify's bisection does); none found at ``not_refuted``
#: (IPOPT: locally infeasible).  ``guess`` m/s: the plan on which the mode-``m0`` branch of certify's corner
#: start (seed 0) vanishes for 46 samples, where the guess once jumped to the other assembly (phi = 0.46 rad).
RPR3_REFUTATION = {"robot": "3rpr", "refuted": 0.05, "refuted_warm": 0.075, "not_refuted": 0.0875, "guess": 0.1}

#: Planning problems by name: ``<robot>_benchmark`` for every registered robot with a benchmark crossing.
PLANNING = {
    f"{name}_benchmark": PlanningProblem(f"{name}_benchmark", name, Method.SMOOTHSTEP,
                                         DEFAULT_CERTIFICATION.get(name))
    for name in available_robots()
    if get_entry(name).benchmark is not None
}


# -------------------------------------------------------------------- checks
def first_outside(lo, hi, truth):
    """Index of the first sample whose truth leaves its box (NaN bounds count as outside), or None.

    ``lo, hi, truth`` have shape ``(K, n)`` (or broadcast to it).
    """
    lo, hi, truth = np.broadcast_arrays(np.asarray(lo, float), np.asarray(hi, float), np.asarray(truth, float))
    ok = ((lo <= truth) & (truth <= hi)).reshape(len(truth), -1).all(axis=1)
    bad = np.flatnonzero(~ok)
    return int(bad[0]) if bad.size else None


def check_contains(lo, hi, truth, what="box", start=0):
    """Assert ``lo[k] <= truth[k] <= hi[k]`` componentwise for every sample ``k >= start``."""
    lo, hi, truth = (np.asarray(a, float)[start:] for a in (lo, hi, truth))
    k = first_outside(lo, hi, truth)
    assert k is None, (f"{what}: truth outside the box at sample {k + start}: "
                       f"truth {truth[k]}, box {lo[k]} .. {hi[k]}")


def check_run_contains(res, run, what="run"):
    """The tracker's pose boxes hold the true pose at every sample, its velocity boxes from sample 1 on.

    (At sample 0 the velocity box is the assumed ``[-xd0, xd0]``.)
    """
    check_contains(res.x_lo, res.x_hi, run.x_true, f"{what}: pose")
    check_contains(res.xd_lo, res.xd_hi, run.xd_true, f"{what}: velocity", start=1)


def check_verdict(res, problem: Problem, run):
    """The verdict is one ``problem`` allows, and a certified change is the true one, certified after the crossing."""
    assert res.verdict in problem.expected, (problem.name, res.summary())
    if res.verdict is Verdict.MODE_CHANGED:
        assert res.initial_mode == run.mode_true[0], (problem.name, res.initial_mode)
        assert res.final_mode == run.mode_true[-1] != run.mode_true[0], (problem.name, res.final_mode)
        assert res.certified_at_step > run.k_sing, (problem.name, res.certified_at_step, run.k_sing)


def check_plan_limits(plan, task: CrossingTask, v_sing, a_peak=60.0, *, v_rtol=1e-9, a_rtol=1e-9,
                      criterion_tol=1e-8):
    """A planned crossing meets its request: speed ``v_sing`` at the crossing sample, no acceleration
    along the task's segment there (the crossing criterion), ``|xdd| <= a_peak`` componentwise,
    rest to rest."""
    u = (task.goal - task.start) / np.linalg.norm(task.goal - task.start)
    k = plan.k_sing
    assert abs(np.linalg.norm(plan.xd[k]) - v_sing) <= v_rtol * v_sing, (np.linalg.norm(plan.xd[k]), v_sing)
    assert abs(plan.xdd[k] @ u) <= criterion_tol, plan.xdd[k]
    assert np.abs(plan.xdd).max() <= a_peak * (1 + a_rtol), np.abs(plan.xdd).max()
    assert np.all(plan.xd[0] == 0) and np.all(plan.xd[-1] == 0), (plan.xd[0], plan.xd[-1])


def check_certified_speed(v, expected: CertificationExpectation, tol=None, *, forward=False):
    """A speed some run certified: above the refutation bound (always), and within ``tol``
    (default the expectation's) of the expected minimal certified speed."""
    if expected.refutation_bound is not None:
        assert v > expected.refutation_bound, (f"certified at {v} m/s, at or below the refutation bound "
                                               f"{expected.refutation_bound} m/s: unsound")
    tol = expected.v_min_tol if tol is None else tol
    want = expected.v_min_forward if forward else expected.v_min
    assert abs(v - want) <= tol, (f"v_min = {v} m/s, expected {want} +- {tol} m/s "
                                            f"(measured in {expected.measured})")


@njit(cache=False)
def libm_trig(x, cosine):
    """sin (or cos) of every entry of ``x`` as the compiled core computes a point value: numba's
    ``math.sin``/``math.cos`` call libm, which may differ from numpy's by an ulp."""
    out = np.empty_like(x)
    for i in range(x.size):
        out[i] = math.cos(x[i]) if cosine else math.sin(x[i])
    return out
