"""Planning-time certification of a Type 2 singularity crossing.

Before a crossing is executed, answer: how fast must the robot cross for the
assembly-mode change to be certified from its encoders, and prove it.

* :func:`certify_plan` — the tracker run on inputs that cover every admissible
  execution of a plan (see *What a certificate guarantees* below);
* :func:`minimal_v_sing` — batched search of the smallest certified speed;

Plans come from :mod:`planner.plan`, the Monte Carlo confirmation from
:mod:`planner.montecarlo`, the whole pipeline from :mod:`planner.pipeline`.

What a certificate guarantees
-----------------------------
Let ``q_plan(t_k)`` be the planned joints (computed with the planning
geometry, the centre of ``[xi]``).  An *admissible execution* is any motion
with (i) one constant true geometry, (ii) ``|xdd_i(t)| <= a_max_i`` at all
times, (iii) joints in the execution class of :mod:`planner.execution` —
``cartesian`` (default): the lengths in ``[xi]`` and effective angles
``q(t_k) + delta = q_plan(t_k) + c + w_k`` with one constant ``c`` in the
derived box ``C``, ``|w_k| <=`` the class's reading error and ``w`` changing
by at most the class's drift per sample (this holds for
every execution that follows the planned path, whatever its geometry in
``[xi]``: the encoders absorb the offsets); ``joint``: true joints within
``eps_q + tracking_error`` of ``q_plan(t_k)``, geometry in ``[xi]`` —, (iv) a
start at rest up to the robot's ``xd0`` and in the plan's initial assembly
mode, with the pose inside the robot's ``x_bounds``, (v) samples exactly
``t_s`` apart.  The certifying run feeds the tracker the readings
``q_plan(t_k)`` with the class's reading error and geometry box: by the
tracker's soundness (docs/soundness.md) its boxes contain the pose and
velocity of every admissible execution, so when it reports ``mode-changed``
every admissible execution ends in the other assembly mode.  With ``window``
reasoning (``PlanningBounds.reasoning``, the default) a speed the tracker
leaves undecided is decided by window passes on the same inputs
(:func:`verifier.window.track_window`): they refute "the run ends in the
initial mode" only if no motion satisfying the same assumptions does, so
the guarantee is the same.

The midpoint-preconditioned Newton step and the fixpoint thresholds are not
inclusion-monotone: re-running the tracker on one execution's (narrower)
readings is not guaranteed to certify whenever the planning run did.  The
certificate therefore never relies on such a re-run: it is a statement about
every admissible execution, proved by the planning run itself.  Whether the
run-time tracker (robot's own ``[xi]``, readings within ``eps_q``) detects
the change on each execution is what the Monte Carlo confirmation measures,
on executions checked to be admissible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robots import KinematicModel
from robots import validators as V
from robots.errors import InputError
from verifier.model import IntervalModel
from verifier.tracker import TrackerSettings, TrackResult, Verdict, initial_box_from_mode, track, track_batch
from verifier.window import Reasoning, WindowResult, track_window

from . import execution as ex_
from .plan import derived_a_max, plan_crossing
from .task import ExecutionKind, PlannedTrajectory, PlanningBounds

__all__ = [
    "SpeedTrial",
    "certify_plan",
    "certify_plan_window",
    "CERTIFY_WINDOW_GEOMETRIES",
    "execution_class",
    "tracker_settings",
    "minimal_v_sing",
]


@dataclass(frozen=True)
class SpeedTrial:
    """One tried speed: the paper's Table II columns (widths of the forward tracker's boxes),
    the verdict and the forward tracker's own verdict (they differ where window passes decided)."""

    v_sing: float
    verdict: Verdict
    max_width_pose: float  # m
    max_width_velocity: float  # m/s
    certified_at_step: int | None  # first sample of the forward tracker's certified streak; None: not certified
    forward_verdict: Verdict


#: Geometry sub-boxes per final-mode hypothesis in the window passes of a certification
#: (the robot's partition halved up to this count; docs/tracker.md, "Window reasoning").
CERTIFY_WINDOW_GEOMETRIES = 16


# ------------------------------------------------------------------ planning
def tracker_settings(robot, b: PlanningBounds, a_max, cls: ex_.ExecutionClass) -> TrackerSettings:
    """Tracker settings of a certifying run: the class's reading error and drift, ``a_max`` (m/s^2)."""
    drift = {}
    if cls.drift_per_sample is not None:
        # d per sample as a rate, rounded up so that j t_s rate >= j d
        drift = dict(eps_q_fast=cls.fast_error, drift_rate=float(np.nextafter(cls.drift_per_sample / b.t_s, np.inf)))
    return TrackerSettings.for_robot(robot, t_s=b.t_s, eps_q=cls.reading_error, a_max=a_max, xi_splits=b.xi_splits,
                                     **drift)


def execution_class(kin, plans, bounds: PlanningBounds) -> ex_.ExecutionClass:
    """The admissible executions of one plan or a list of plans (union of their paths) under ``bounds``.

    See :mod:`planner.execution`; ``cartesian`` classes are derived from the
    planned poses and joints (seeded, deterministic).
    """
    robot = kin.robot
    b = bounds.resolved(robot)
    if b.execution is ExecutionKind.JOINT:
        return ex_.joint_class(robot, b.eps_q, b.tracking_error)
    plans = [plans] if isinstance(plans, PlannedTrajectory) else list(plans)
    return ex_.cartesian_class(kin, [p.x for p in plans], [p.q for p in plans], plans[0].xi_plan, b.eps_q,
                               b.tracking_error)


def certify_plan(imodel: IntervalModel, plan: PlannedTrajectory, bounds: PlanningBounds, initial_mode: int, *,
                 execution: ex_.ExecutionClass | None = None, kin=None) -> TrackResult:
    """Run the tracker on inputs covering every admissible execution of ``plan``.

    Readings ``q_plan`` with the class's reading error and geometry box
    (``execution``, derived with :func:`execution_class` when not given; ``kin``
    is then the robot's ``KinematicModel``, built when absent); the initial box
    encloses every start pose of mode ``initial_mode`` for every geometry of
    the box.  ``MODE_CHANGED`` certifies every admissible execution.  The
    forward tracker's run; :func:`certify_plan_window` adds the window passes.
    """
    robot = imodel.robot
    b = bounds.resolved(robot)
    if execution is None:
        execution = execution_class(kin if kin is not None else KinematicModel(robot), plan, b)
    s = tracker_settings(robot, b, derived_a_max(plan, b), execution)
    return track(imodel, plan.q, s, initial_mode=initial_mode, xi_box=execution.xi_box)


def certify_plan_window(imodel: IntervalModel, plan: PlannedTrajectory, bounds: PlanningBounds, initial_mode: int,
                        *, execution: ex_.ExecutionClass | None = None, kin=None, a_max=None,
                        max_geometries: int = CERTIFY_WINDOW_GEOMETRIES) -> WindowResult:
    """:func:`certify_plan` with window passes (:func:`verifier.window.track_window`) on the same inputs.

    ``a_max`` (m/s^2) defaults to the plan's derived bound.  ``MODE_CHANGED``
    certifies every admissible execution, as for :func:`certify_plan`.
    """
    robot = imodel.robot
    b = bounds.resolved(robot)
    if execution is None:
        execution = execution_class(kin if kin is not None else KinematicModel(robot), plan, b)
    s = tracker_settings(robot, b, derived_a_max(plan, b) if a_max is None else a_max, execution)
    return track_window(imodel, plan.q, s, initial_mode=initial_mode, xi_box=execution.xi_box,
                        max_geometries=max_geometries)


def minimal_v_sing(kin, imodel, task, bounds, v_low, v_high, *, tol=0.01, grid=6, progress=None):
    """Smallest certified ``v_sing`` in ``[v_low, v_high]`` to ``tol`` (m/s).

    The first round plans ``grid`` speeds spread over ``[v_low, v_high]``, each
    later round at least ``grid - 2`` interior speeds of the current bracket
    (more, up to three times that, when it saves a round), certified in one
    batch per round; the bracket shrinks to the interval between
    the fastest uncertified speed below the slowest certified one and that
    certified speed.  Certification need not be monotone in the speed: the
    table of every trial is returned, and the result is the slowest speed
    certified such that every tried speed above it was certified too.

    Returns
    -------
    v_min : float or None
        ``None`` when no tried speed certifies, or when the fastest one does not.
    trials : list of SpeedTrial (sorted by speed)
    """
    robot = kin.robot
    b = bounds.resolved(robot)
    v_low, v_high = V.positive("v_low", v_low), V.positive("v_high", v_high)
    if not v_low < v_high:
        raise InputError(f"need v_low < v_high, got [{v_low}, {v_high}]")
    trials: dict[float, SpeedTrial] = {}
    lo, hi = float(v_low), float(v_high)
    speeds = list(np.linspace(lo, hi, grid))
    while True:
        speeds = [round(v, 6) for v in speeds if round(v, 6) not in trials]
        if speeds:
            for v, trial in zip(speeds, _certify_speeds(kin, imodel, task, b, speeds, progress)):
                trials[v] = trial
        ordered = sorted(trials)
        ok = [trials[v].verdict is Verdict.MODE_CHANGED for v in ordered]
        if not ok[-1]:
            # the fastest tried speed is not certified: no speed has every
            # faster trial certified (a non-monotone table is left to the user)
            return None, [trials[v] for v in ordered]
        # slowest speed from which every faster trial certifies
        i = len(ordered) - 1
        while i > 0 and ok[i - 1]:
            i -= 1
        v_cert = ordered[i]
        v_fail = ordered[i - 1] if i > 0 else None
        if v_fail is None:
            return v_cert, [trials[v] for v in ordered]
        if v_cert - v_fail <= tol:
            return v_cert, [trials[v] for v in ordered]
        # enough interior speeds to reach tol in two more rounds when up to
        # three times the base grid allows it (one round costs about as much
        # as one tracked run: the batch is vectorised)
        interior = int(np.clip(np.ceil(np.sqrt((v_cert - v_fail) / tol)) - 1, grid - 2, 3 * (grid - 2)))
        speeds = list(np.linspace(v_fail, v_cert, interior + 2)[1:-1])


def _certify_speeds(kin, imodel, task, b, speeds, progress):
    robot = kin.robot
    plans = [plan_crossing(kin, task, v, b) for v in speeds]
    a_max = np.max([derived_a_max(p, b) for p in plans], axis=0)
    # one class for the batch: the union of the plans' paths (a superset of
    # each plan's own class; the certificate re-runs its speed alone)
    cls = execution_class(kin, plans, b)
    s = tracker_settings(robot, b, a_max, cls)
    K = max(len(p.t) for p in plans)
    q = np.stack([np.vstack([p.q, np.repeat(p.q[-1:], K - len(p.t), axis=0)]) for p in plans])
    m0 = int(kin.mode(plans[0].x[0], plans[0].q[0], plans[0].xi_plan))
    boxes = [initial_box_from_mode(imodel, p.q[0], m0, s, xi_box=cls.xi_box) for p in plans]
    x0 = (np.array([bx[0] for bx in boxes]), np.array([bx[1] for bx in boxes]))
    res = track_batch(imodel, q, s, x0, xi_box=cls.xi_box, progress=progress)
    verdicts = list(res.verdict)
    if b.reasoning is Reasoning.WINDOW:
        for i, p in enumerate(plans):
            if verdicts[i] is Verdict.UNKNOWN:
                verdicts[i] = track_window(imodel, p.q, s, x0=(x0[0][i], x0[1][i]), xi_box=cls.xi_box,
                                           max_geometries=CERTIFY_WINDOW_GEOMETRIES).verdict
    return [
        SpeedTrial(float(v), verdicts[i], float(res.max_width_pose[i]), float(res.max_width_velocity[i]),
                   None if res.certified_at_step[i] < 0 else int(res.certified_at_step[i]), res.verdict[i])
        for i, v in enumerate(speeds)
    ]
