"""Planning-time certification of a Type 2 singularity crossing.

Before a crossing is executed, answer: how fast must the robot cross for the
assembly-mode change to be certified from its encoders, and prove it.

* :func:`plan_crossing` — a rest-to-rest trajectory along the straight segment
  from ``task.start`` to ``task.goal`` that crosses the nominal Type 2 locus at
  speed ``v_sing`` with zero acceleration there (the crossing criterion for a
  path along the uncontrolled direction), smoothstep speed ramps peaking at
  ``a_peak``;
* :func:`certify_plan` — the tracker run on inputs that cover every admissible
  execution (see *What a certificate guarantees* below);
* :func:`minimal_v_sing` — batched search of the smallest certified speed;
* :func:`monte_carlo_confirmation` — simulated executions with random true
  geometries and encoder quantisations, tracked as the robot would at run time;
* :func:`certify_crossing` — all of it, returning a frozen certificate.

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
every admissible execution ends in the other assembly mode.

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

import importlib.metadata as md
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from robots.errors import InputError, SimulationError
from verifier.model import IntervalModel
from verifier.tracker import TrackerSettings, TrackResult, Verdict, initial_box_from_mode, track, track_batch

from . import execution as ex_
from .simulate import TimeLaw, ramp_length
from .task import CrossingTask, Method, PlannedTrajectory, PlanningBounds, crossing_on_segment

__all__ = [
    "CrossingTask",
    "PlanningBounds",
    "PlannedTrajectory",
    "SpeedTrial",
    "CrossingCertificate",
    "plan_crossing",
    "certify_plan",
    "execution_class",
    "speed_ceiling",
    "minimal_v_sing",
    "monte_carlo_confirmation",
    "certify_crossing",
]


@dataclass(frozen=True)
class SpeedTrial:
    """One tried speed: the paper's Table II columns."""

    v_sing: float
    verdict: Verdict
    max_width_pose: float  # m
    max_width_velocity: float  # m/s
    certified_at_step: int


@dataclass(frozen=True)
class CrossingCertificate:
    """Result of :func:`certify_crossing` (frozen).

    ``verdict`` is ``MODE_CHANGED`` when ``v_min`` exists (the change is
    certified for every admissible execution at ``v_min``), ``UNKNOWN`` when
    no tried speed certifies.  ``refutation_bound`` (m/s, or None when not
    computed / no counterexample) is the largest speed at which a verified
    counterexample exists: no sound tracker can certify at or below it.
    ``execution`` is the class of admissible executions the certificate
    covers (:mod:`planner.execution`); ``timings_s`` the wall time of each
    phase, s (``setup``, ``search``, ``certificate``, ``monte_carlo``, and
    ``refutation``: the wait for the background searches left after the
    Monte Carlo run).
    """

    verdict: Verdict
    v_min: float | None
    refutation_bound: float | None
    trials: tuple
    trajectory: PlannedTrajectory | None
    enclosures: TrackResult | None
    bounds: PlanningBounds
    a_max_used: tuple | None
    monte_carlo: dict | None
    versions: dict
    elapsed_s: float
    refutation: tuple = field(default=(), repr=False)
    execution: ex_.ExecutionClass | None = None
    timings_s: dict = field(default_factory=dict)

    @property
    def certified_below_v_min(self) -> list:
        """Tried speeds below ``v_min`` that certified (m/s): where certification was not monotone in the speed."""
        if self.v_min is None:
            return [t.v_sing for t in self.trials if t.verdict is Verdict.MODE_CHANGED]
        return [t.v_sing for t in self.trials if t.verdict is Verdict.MODE_CHANGED and t.v_sing < self.v_min]

    @property
    def v_min_at_lower_end(self) -> bool:
        """``v_min`` is the slowest speed tried: a smaller one may certify too (lower ``v_low``)."""
        return self.v_min is not None and self.v_min <= min(t.v_sing for t in self.trials)

    def summary(self) -> dict:
        """JSON-ready summary."""
        return {
            "verdict": self.verdict.value,
            "v_min_mps": self.v_min,
            "refutation_bound_mps": self.refutation_bound,
            "gap_mps": None if self.v_min is None or self.refutation_bound is None else self.v_min - self.refutation_bound,
            "certified_below_v_min_mps": self.certified_below_v_min,
            "v_min_at_lower_end": self.v_min_at_lower_end,
            "a_max_mps2": None if self.a_max_used is None else list(self.a_max_used),
            "eps_q_rad": self.bounds.eps_q,
            "tracking_error_rad": self.bounds.tracking_error,
            "t_s": self.bounds.t_s,
            "xi_splits": None if self.bounds.xi_splits is None else list(self.bounds.xi_splits),
            "execution": None if self.execution is None else self.execution.summary(),
            "trials": [
                {"v_sing_mps": r.v_sing, "verdict": r.verdict.value, "max_width_pose_m": r.max_width_pose,
                 "max_width_velocity_mps": r.max_width_velocity,
                 "certified_at_step": None if r.certified_at_step < 0 else r.certified_at_step}
                for r in self.trials
            ],
            "refutation": [
                {"v_sing_mps": r.speed, "counterexample": bool(r.verified), "status": r.status,
                 "geometry": None if r.geometry is None else list(map(float, r.geometry))}
                for r in self.refutation
            ],
            "monte_carlo": self.monte_carlo,
            "versions": self.versions,
            "elapsed_s": self.elapsed_s,
            "timings_s": self.timings_s,
        }


# ------------------------------------------------------------------ planning
def plan_crossing(kin, task: CrossingTask, v_sing: float, bounds: PlanningBounds,
                  method: str | None = None, limits=None) -> PlannedTrajectory:
    """Plan a rest-to-rest straight crossing at ``v_sing`` (m/s).

    ``method`` defaults to ``bounds.method``.  ``"smoothstep"``: rest ``t_rest``; smoothstep speed ramp
    to ``v_sing`` (peak ``a_peak``); constant speed through the crossing point
    (zero acceleration there: the crossing criterion); ramp to rest at
    ``goal``; rest ``t_rest``.

    ``"dynamic"``: the CasADi + IPOPT generator
    (:func:`planner.generate.generate_crossing`, minimal time) with the
    dynamic model ``bounds.dynamics``: free path, torque limits, the dynamic
    crossing criterion at the singular instant, ``|xdd| <= a_peak``.

    ``method="time-optimal"``: the minimal-time scaling of the same segment
    (:func:`planner.timescale.time_optimal_scaling`, cvxpy) with
    ``|xdd| <= a_peak``, the joint limits of ``limits``
    (:class:`planner.timescale.ScalingLimits`, optional), speed ``v_sing``
    and the criterion at the crossing point; the segment is gridded at about
    0.1 mm with the crossing point on a node, so the goal may move by less
    than one grid step along the segment.

    Raises
    ------
    InputError
        Infeasible speed (the ramps do not fit between start, crossing point
        and goal: the message gives the largest feasible speed), bad task.
    """
    robot = kin.robot
    b = bounds.resolved(robot)
    if not (np.isfinite(v_sing) and v_sing > 0):
        raise InputError(f"v_sing must be positive, got {v_sing}")
    xi = robot.xi_center
    c = crossing_on_segment(kin, task, xi)
    s_star, u, L = c.s_star, c.u, c.length
    method = b.method if method is None else method
    if method == "time-optimal":
        return _plan_time_optimal(kin, task, v_sing, b, xi, s_star, u, L, limits)
    if method == "dynamic":
        return _plan_dynamic(kin, task, v_sing, b, xi)
    if method != "smoothstep":
        raise InputError(f"unknown planning method {method!r}; use 'smoothstep', 'time-optimal' or 'dynamic'")
    T, D = ramp_length(v_sing, b.a_peak)
    room = min(s_star, L - s_star)
    if D > room:
        v_max = float(np.sqrt(2.0 * b.a_peak * room / 1.875))
        raise InputError(
            f"no feasible crossing at v_sing = {v_sing} m/s: its speed ramps need {1e3 * D:.1f} mm but the crossing "
            f"point is {1e3 * s_star:.1f} mm from the start and {1e3 * (L - s_star):.1f} mm from the goal; "
            f"v_sing <= {v_max:.3f} m/s at a_peak = {b.a_peak} m/s^2"
        )
    law = TimeLaw.build(0.0, [
        (b.t_rest, 0.0, 0.0),
        (T, 0.0, v_sing),
        ((s_star - D) / v_sing, v_sing, v_sing),
        ((L - s_star - D) / v_sing, v_sing, v_sing),
        (T, v_sing, 0.0),
        (b.t_rest, 0.0, 0.0),
    ])
    t_cross = b.t_rest + T + (s_star - D) / v_sing
    # put the crossing instant on a sample (shift the initial rest by < t_s)
    shift = (np.ceil(t_cross / b.t_s - 1e-9) * b.t_s) - t_cross
    K = int(np.floor((law.duration + shift) / b.t_s + 1e-9)) + 1
    t = np.arange(K) * b.t_s
    s, v, a = law.evaluate(t - shift)
    X = task.start[None] + s[:, None] * u[None]
    XD = v[:, None] * u[None]
    XDD = a[:, None] * u[None]
    try:
        Q = kin.ik_path(X, xi, task.working_guess)
    except SimulationError as exc:
        raise InputError(f"planned path left the working mode: {exc}") from None
    QD = kin.joint_velocity(X, Q, xi, XD)
    QDD = kin.joint_acceleration(X, Q, xi, XD, QD, XDD)
    k_sing = int(round((t_cross + shift) / b.t_s))
    for arr in (t, Q, QD, QDD, X, XD, XDD):
        arr.setflags(write=False)
    return PlannedTrajectory(t=t, q=Q, qd=QD, qdd=QDD, x=X, xd=XD, xdd=XDD, t_s=b.t_s, k_sing=k_sing, v_sing=v_sing,
                             crossing_point=task.start + s_star * u, xi_plan=xi)


def _time_optimal_setup(kin, task, b, xi, s_star, u, L, limits):
    """Path samples (about 0.1 mm apart, the crossing point on a node) and limits of the time-optimal law."""
    from . import timescale as ts_

    h_target = 1e-4  # m, grid step
    n1 = max(2, int(round(s_star / h_target)))
    h = s_star / n1
    N = max(n1 + 2, int(round(L / h)))
    samples = ts_.sample_path(kin, task.start, u, N * h, N, task.working_guess, xi)
    if limits is None and (b.qd_max is not None or b.qdd_max is not None):
        limits = ts_.ScalingLimits(qd_max=b.qd_max, qdd_max=b.qdd_max)
    lim = limits or ts_.ScalingLimits()
    lim = ts_.ScalingLimits(qd_max=lim.qd_max, qdd_max=lim.qdd_max, a_max=b.a_peak, extra=lim.extra)
    return ts_, samples, lim


def speed_ceiling(kin, task: CrossingTask, bounds: PlanningBounds) -> float:
    """Fastest ``v_sing`` (m/s) the time law of ``bounds`` allows on ``task``: the upper end of a search.

    ``smoothstep`` and ``dynamic``: both speed ramps (length ``1.875 v^2 / (2
    a_peak)``) must fit between the start, the crossing point and the goal.
    ``time-optimal``: toppra's controllable and reachable sets at the
    crossing point (:func:`planner.timescale.max_speed_at`) under the same
    limits as the plans, the criterion included.  Shrunk by 1e-6 relative so
    that a plan at the ceiling is feasible.

    Raises
    ------
    InputError
        No admissible time law reaches the crossing point.
    """
    robot = kin.robot
    b = bounds.resolved(robot)
    xi = robot.xi_center
    c = crossing_on_segment(kin, task, xi)
    s_star, u, L = c.s_star, c.u, c.length
    if b.method == "time-optimal":
        ts_, samples, lim = _time_optimal_setup(kin, task, b, xi, s_star, u, L, None)
        try:
            top = ts_.max_speed_at(samples, lim, s_star)
        except SimulationError as exc:
            raise InputError(f"no feasible crossing speed: {exc}") from None
    else:
        top = float(np.sqrt(2.0 * b.a_peak * min(s_star, L - s_star) / 1.875))
    return top * (1 - 1e-6)


def _plan_time_optimal(kin, task, v_sing, b, xi, s_star, u, L, limits):
    ts_, samples, lim = _time_optimal_setup(kin, task, b, xi, s_star, u, L, limits)
    scaling = ts_.time_optimal_scaling(samples, lim, v_sing=v_sing, s_star=s_star)
    tt = ts_.resample(scaling, samples, b.t_s, t_rest=b.t_rest, t_rest_end=b.t_rest)
    return PlannedTrajectory(t=tt.t, q=tt.q, qd=tt.qd, qdd=tt.qdd, x=tt.x, xd=tt.xd, xdd=tt.xdd, t_s=b.t_s,
                             k_sing=tt.k_star, v_sing=v_sing, crossing_point=task.start + s_star * u, xi_plan=xi)


def _plan_dynamic(kin, task, v_sing, b, xi):
    from .generate import GenerationLimits, generate_crossing

    limits = GenerationLimits(qd_max=30.0 if b.qd_max is None else b.qd_max,
                              qdd_max=3000.0 if b.qdd_max is None else b.qdd_max, a_max=b.a_peak)
    gen = generate_crossing(kin, b.dynamics, task, v_sing, limits, objective="time", t_s=b.t_s, t_rest=b.t_rest,
                            t_after=b.t_rest, xi_plan=xi)
    return gen.to_planned_trajectory()


def _a_max_for(plan: PlannedTrajectory, b: PlanningBounds):
    peak = np.max(np.abs(plan.xdd), axis=0)
    if b.a_max is None:
        # an axis the plan does not accelerate still gets a_margin * the largest
        # planned acceleration: room for tracking errors, an assumption stated in a_max
        return tuple(float(v) for v in np.maximum(peak * (1.0 + b.a_margin), b.a_margin * peak.max()))
    if np.any(np.asarray(b.a_max) < peak):
        raise InputError(
            f"bounds contradict the plan: a_max = {list(b.a_max)} m/s^2 is below the planned peak acceleration "
            f"{peak.tolist()} m/s^2"
        )
    return tuple(float(v) for v in b.a_max)


def _settings(robot, b: PlanningBounds, a_max, cls: ex_.ExecutionClass):
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
    if b.execution == "joint":
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
    the box.  ``MODE_CHANGED`` certifies every admissible execution.
    """
    robot = imodel.robot
    b = bounds.resolved(robot)
    if execution is None:
        from robots import KinematicModel

        execution = execution_class(kin if kin is not None else KinematicModel(robot), plan, b)
    s = _settings(robot, b, _a_max_for(plan, b), execution)
    return track(imodel, plan.q, s, initial_mode=initial_mode, xi_box=execution.xi_box)


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
    if not (0 < v_low < v_high):
        raise InputError(f"need 0 < v_low < v_high, got [{v_low}, {v_high}]")
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
    a_max = np.max([_a_max_for(p, b) for p in plans], axis=0)
    # one class for the batch: the union of the plans' paths (a superset of
    # each plan's own class; the certificate re-runs its speed alone)
    cls = execution_class(kin, plans, b)
    s = _settings(robot, b, a_max, cls)
    K = max(len(p.t) for p in plans)
    q = np.stack([np.vstack([p.q, np.repeat(p.q[-1:], K - len(p.t), axis=0)]) for p in plans])
    m0 = int(kin.mode(plans[0].x[0], plans[0].q[0], plans[0].xi_plan))
    boxes = [initial_box_from_mode(imodel, p.q[0], m0, s, xi_box=cls.xi_box) for p in plans]
    x0 = (np.array([bx[0] for bx in boxes]), np.array([bx[1] for bx in boxes]))
    res = track_batch(imodel, q, s, x0, xi_box=cls.xi_box, progress=progress)
    return [
        SpeedTrial(float(v), res.verdict[i], float(res.max_width_pose[i]), float(res.max_width_velocity[i]),
                   int(res.certified_at_step[i]))
        for i, v in enumerate(speeds)
    ]


def monte_carlo_confirmation(kin, imodel, plan: PlannedTrajectory, bounds: PlanningBounds, *, runs=50, seed=0,
                             a_max=None, progress=None, execution: ex_.ExecutionClass | None = None) -> dict:
    """Execute ``plan``'s Cartesian motion with random true geometries and quantisations.

    Each execution: geometry uniform in ``[xi]`` (every 5th at a random corner),
    joints by the true IK, readings quantised (floor, round or a uniform
    random error within ``eps_q``), tracked by the run-time tracker (robot
    defaults, ``a_max`` of the certificate).  Each execution is checked
    against the certificate's class ``execution`` (derived from ``bounds``
    when not given).

    Returns
    -------
    dict
        ``runs``, ``seed``, ``detected`` (verdict ``mode-changed``),
        ``in_class`` (admissible executions) and ``detected_in_class``, and the
        lists ``outside_class`` (run indices), ``containment_failures`` (run
        indices whose boxes missed the truth), ``wrong_verdicts`` and
        ``not_detected`` (dicts with the run, verdict and geometry).
    """
    from .simulate import random_geometry

    robot = kin.robot
    b = bounds.resolved(robot)
    a_max = _a_max_for(plan, b) if a_max is None else a_max
    cls = execution_class(kin, plan, b) if execution is None else execution
    s = TrackerSettings.for_robot(robot, t_s=b.t_s, eps_q=b.eps_q, a_max=a_max, xi_splits=b.xi_splits)
    rng = np.random.default_rng(seed)
    qs, truths = [], []
    for r in range(runs):
        xi = random_geometry(robot, rng, corners=(r % 5 == 4))
        q_true = kin.ik_path(plan.x, xi, plan.q[0])
        kind = ("floor", "round", "uniform")[r % 3]
        if kind == "floor":
            q_read = b.eps_q * np.floor(q_true / b.eps_q)
        elif kind == "round":
            q_read = (0.5 * b.eps_q) * np.round(q_true / (0.5 * b.eps_q))
        else:
            q_read = q_true + rng.uniform(-b.eps_q, b.eps_q, q_true.shape)
        q_read = np.clip(q_read, q_true - b.eps_q, q_true + b.eps_q)
        modes = kin.mode_batch(plan.x, q_true, xi)
        qs.append(q_read)
        truths.append((xi, modes, ex_.in_class(cls, robot, q_true, plan.q, xi, plan.xi_plan, b.eps_q,
                                               b.tracking_error)))
    q = np.stack(qs)
    m0 = int(truths[0][1][0])
    boxes = [initial_box_from_mode(imodel, q[r, 0], m0, s) for r in range(runs)]
    x0 = (np.array([bx[0] for bx in boxes]), np.array([bx[1] for bx in boxes]))
    res, rec = track_batch(imodel, q, s, x0, record=True, progress=progress)
    misses, failures, wrong = [], [], []
    for r in range(runs):
        inside = (np.all(rec["x_lo"][r] <= plan.x) and np.all(plan.x <= rec["x_hi"][r])
                  and np.all(rec["xd_lo"][r, 1:] <= plan.xd[1:]) and np.all(plan.xd[1:] <= rec["xd_hi"][r, 1:]))
        if not inside:
            misses.append(r)
        modes = truths[r][1]
        certified = rec["mode"][r] != 0
        true_changed = modes[-1] != modes[0]
        bad_mode = bool(np.any(rec["mode"][r][certified] != modes[certified]))
        if bad_mode or (res.verdict[r] is Verdict.MODE_CHANGED and not true_changed):
            wrong.append({"run": r, "verdict": res.verdict[r].value, "xi": truths[r][0].tolist()})
        elif res.verdict[r] is not Verdict.MODE_CHANGED:
            failures.append({"run": r, "verdict": res.verdict[r].value, "xi": truths[r][0].tolist()})
    admissible = [r for r in range(runs) if truths[r][2]]
    return {
        "runs": runs,
        "seed": seed,
        "detected": int(sum(v is Verdict.MODE_CHANGED for v in res.verdict)),
        "in_class": len(admissible),
        "detected_in_class": int(sum(res.verdict[r] is Verdict.MODE_CHANGED for r in admissible)),
        "outside_class": [r for r in range(runs) if not truths[r][2]],
        "containment_failures": misses,
        "wrong_verdicts": wrong,
        "not_detected": failures,
    }


def _versions():
    out = {}
    for pkg in ("crosscert", "numpy", "casadi", "scipy"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = None
    return out


def certify_crossing(robot, task: CrossingTask, bounds: PlanningBounds | None = None, *, v_low=0.6, v_high=None,
                     tol=0.01, monte_carlo_runs=50, refute=True, refute_speeds=None, refute_in_background=True,
                     seed=0, progress=None, kin=None, imodel=None) -> CrossingCertificate:
    """Minimal certified crossing speed for ``task``, its proof and its refutation bound.

    Parameters
    ----------
    robot : robots.Robot
    task : CrossingTask
    bounds : PlanningBounds, optional
    v_low, v_high : float
        Speed bracket, m/s; ``v_high`` defaults to (and is capped at)
        :func:`speed_ceiling`: the fastest crossing the time law allows.
    tol : float
        Resolution of ``v_min``, m/s.
    monte_carlo_runs : int
        Executions simulated at ``v_min`` (0 to skip).
    refute : bool
        Search verified counterexamples (planner.refute) below ``v_min``.
    refute_speeds : sequence of float, optional
        Speeds of the coarse counterexample scan (default every 0.1 m/s from 0.3).
    refute_in_background : bool
        Run the counterexample searches in one worker process while the
        speed search and the Monte Carlo run go on (the same searches, with
        the same 2 s CPU cap per attempt; ``False`` runs them here,
        afterwards).
    seed : int
        Seed of the Monte Carlo executions and of the counterexample starts.
    progress : callable, optional
        ``progress(k)`` after each tracked sample of every batch.
    """
    from robots import KinematicModel

    from .simulate import random_geometry

    t0 = time.perf_counter()
    kin = KinematicModel(robot) if kin is None else kin
    imodel = IntervalModel(robot) if imodel is None else imodel
    b = (bounds or PlanningBounds()).resolved(robot)
    m0 = crossing_on_segment(kin, task, robot.xi_center).m0
    v_feasible = speed_ceiling(kin, task, b)
    v_high = v_feasible if v_high is None else min(float(v_high), v_feasible)
    if v_high <= v_low:
        raise InputError(f"no feasible crossing speed above v_low = {v_low} m/s: the {b.method} time law allows "
                         f"at most {v_feasible:.3f} m/s on this task")
    refuter = None
    if refute:
        # starting geometries of the (non-convex) searches: the box centre and a seeded corner
        starts = [robot.xi_center, random_geometry(robot, np.random.default_rng(seed), corners=True)]
        scan = refute_speeds if refute_speeds is not None else np.arange(0.3, v_high, 0.1)
        try:
            scan = sorted({round(float(v), 6) for v in scan})
        except (TypeError, ValueError):
            raise InputError(f"refute_speeds must be numbers (m/s), got {refute_speeds!r}") from None
        refuter = _Refuter(robot, task, b, m0, starts, kin, refute_in_background)
        refuter.submit(scan)
    # wall time of each phase (the refutation's is the wait left after the Monte Carlo run)
    clock = {"setup": time.perf_counter() - t0}

    def lap(name, since):
        clock[name] = time.perf_counter() - since
        return time.perf_counter()

    try:
        t1 = time.perf_counter()
        v_min, trials = minimal_v_sing(kin, imodel, task, b, v_low, v_high, tol=tol, progress=progress)
        t1 = lap("search", t1)
        plan = enc = mc = a_used = cls = None
        # the batched search pads shorter plans with rest samples: re-certify the
        # candidate alone, on its own samples; if it fails, try the next faster
        # certified speed (the certificate's verdict is this run's verdict)
        for cand in ([t.v_sing for t in trials if t.verdict is Verdict.MODE_CHANGED and t.v_sing >= v_min]
                     if v_min is not None else []):
            plan = plan_crossing(kin, task, cand, b)
            cls = execution_class(kin, plan, b)
            enc = certify_plan(imodel, plan, b, m0, execution=cls)
            if enc.verdict is Verdict.MODE_CHANGED:
                v_min = cand
                a_used = _a_max_for(plan, b)
                break
        else:
            v_min = plan = enc = cls = None
        t1 = lap("certificate", t1)
        top = v_min if v_min is not None else max(t.v_sing for t in trials)
        ref_job = None
        if refuter is not None:
            refuter.drop_from(top)
            if refute_in_background:
                # the bisection mostly waits on the worker: let it wait beside the Monte Carlo run
                helper = ThreadPoolExecutor(max_workers=1)
                ref_job = helper.submit(_refutation, refuter, top, tol)
                helper.shutdown(wait=False)
        if v_min is not None and monte_carlo_runs:
            mc = monte_carlo_confirmation(kin, imodel, plan, b, runs=monte_carlo_runs, seed=seed, progress=progress,
                                          execution=cls)
        t1 = lap("monte_carlo", t1)
        if ref_job is not None:
            ref_bound, ref = ref_job.result()
        elif refuter is not None:
            ref_bound, ref = _refutation(refuter, top, tol)
        else:
            ref_bound = ref = None
        lap("refutation", t1)
    finally:
        if refuter is not None:
            refuter.close()
    return CrossingCertificate(
        verdict=enc.verdict if enc is not None else Verdict.UNKNOWN,
        v_min=v_min,
        refutation_bound=ref_bound,
        trials=tuple(trials),
        trajectory=plan,
        enclosures=enc,
        bounds=b,
        a_max_used=a_used,
        monte_carlo=mc,
        versions=_versions(),
        elapsed_s=time.perf_counter() - t0,
        refutation=tuple(ref or ()),
        execution=cls,
        timings_s=clock,
    )


_WORKER_KIN: dict = {}
# IPOPT time cap per counterexample attempt, s.  On the benchmark task of
# docs/planning.md every verified counterexample took <= 0.2 s (<= 60
# iterations); attempts near the
# bound can wander for 10-25 s before declaring infeasibility, and a stopped
# attempt proves nothing either way (it only costs bound tightness).
REFUTE_CPU_TIME = 2.0


def _refute_speed(robot, task, b, m0, starts, v, kin=None):
    """Counterexample search on the planned readings at speed ``v``, with that plan's own ``a_max``.

    Module-level so that a worker process can run it; builds (and keeps) the
    robot's ``KinematicModel`` there.  A speed the planner cannot plan gives
    a row with no counterexample and the planner's message as status.
    """
    from robots import KinematicModel

    from . import refute

    if kin is None:
        # keyed by the robot's value (a frozen dataclass): variants of one robot differ in their boxes
        kin = _WORKER_KIN.get(robot)
        if kin is None:
            kin = _WORKER_KIN[robot] = KinematicModel(robot)
    try:
        plan = plan_crossing(kin, task, v, b)
    except (InputError, SimulationError) as exc:
        nan = float("nan")
        return refute.SpeedRefutation(float(v), 0, False, False, None, nan, nan, nan, f"no plan: {exc}", 0.0, ())
    a_max = b.a_max if b.a_max is not None else _a_max_for(plan, b)
    overrides = {"eps_q": b.eps_q + b.tracking_error, "a_max": np.asarray(a_max, float)}
    return refute.refutation_bound(kin, lambda _v: (plan.q, b.t_s), [v], m0=m0, xi_starts=starts,
                                   bounds=overrides, max_cpu_time=REFUTE_CPU_TIME).rows[0]


class _Refuter:
    """Counterexample searches by speed: in a background worker process, or here when asked."""

    def __init__(self, robot, task, b, m0, starts, kin, background):
        from ._worker import BackgroundCalls

        self._args = (robot, task, b, m0, starts)
        self._kin = kin
        self._speeds: set = set()
        self._rows: dict = {}
        self._bg = BackgroundCalls(__name__, "_refute_speed", self._args) if background else None

    def submit(self, speeds):
        self._speeds.update(speeds)
        if self._bg is not None:
            self._bg.submit(speeds)

    def drop_from(self, v_top):
        """Forget the speeds at or above ``v_top`` (not started ones are never run)."""
        self._speeds = {v for v in self._speeds if v < v_top}
        if self._bg is not None:
            self._bg.drop(lambda v: v >= v_top)

    def speeds(self):
        return sorted(self._speeds)

    def result(self, v):
        self._speeds.add(v)
        if v not in self._rows:
            row = None
            if self._bg is not None:
                try:
                    row = self._bg.result(v)
                except Exception:
                    # e.g. a robot defined in a script the worker cannot import: go on here
                    # (a genuine error of the search is raised again by the run here),
                    # possibly on the helper thread, so with a model of its own (CasADi
                    # functions are not to be called from two threads at once)
                    self._bg.close()
                    self._bg = None
                    self._kin = None
            self._rows[v] = row if row is not None else _refute_speed(*self._args, v, kin=self._kin)
        return self._rows[v]

    def close(self):
        if self._bg is not None:
            self._bg.close()


def _refutation(refuter: _Refuter, v_top, tol):
    """Refutation bound below ``v_top``: the largest speed with a verified counterexample.

    The coarse scan submitted to ``refuter`` (0.1 m/s from 0.3 m/s, or the
    caller's speeds) below ``v_top``, then bisection between the fastest
    refuted and the slowest non-refuted speed above it, to ``tol``.  Each
    speed is searched against its own plan's readings and ``a_max`` (the
    bounds its certificate would use); a failed search proves nothing (the
    NLP is non-convex).

    Returns
    -------
    bound : float or None
    rows : list of planner.refute.SpeedRefutation (sorted by speed)
    """
    rows = {v: refuter.result(v) for v in refuter.speeds() if v < v_top}
    while True:
        ordered = sorted(rows)
        refuted = [v for v in ordered if rows[v].verified]
        if not refuted:
            return None, [rows[v] for v in ordered]
        v_ok = max(refuted)
        above = [v for v in ordered if v > v_ok]
        v_no = min(above) if above else v_top
        if v_no - v_ok <= tol:
            return v_ok, [rows[v] for v in ordered]
        mid = round(0.5 * (v_ok + v_no), 6)
        rows[mid] = refuter.result(mid)
