"""The entry point: :func:`generate_crossing` validates a request, solves the NLP, checks and packs the result."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields, replace

import numpy as np

from crosscert.robots.dynamics import LumpedDynamics, LumpedMassModel, uncontrolled_direction
from crosscert.robots.errors import InputError, ModelError, SimulationError
from crosscert.robots.kinematics import KinematicModel

from ..task import CrossingTask, crossing_on_segment, parse_option
from .check import CRITERION_TOL, check_plan
from .nlp import CrossingNlp, CrossingSite, IpoptSettings, Transcription, initial_guess, sample, solve_nlp
from .types import GeneratedTrajectory, GenerationLimits, LimitExceeded, Objective

__all__ = ["GenerationOptions", "generate_crossing", "crossing_point_and_joints"]

#: ``|mode value| / Hadamard bound`` below which a given crossing point is on the locus.
_LOCUS_RTOL = 1e-8
#: Re-solves with a larger back-off when a limit met at the nodes is exceeded between them.
_MARGIN_RETRIES = 2
#: No re-solve past this overshoot between the nodes: the intervals are too coarse for a back-off to help.
_RETRY_RATIO_MAX = 1.5
#: Extra relative back-off of a re-solve beyond the measured overshoot, so it lands strictly inside.
_RETRY_EXTRA = 1e-3
#: Samples of the IK continuation from the start to the crossing point on the straight segment.
_SEGMENT_IK_SAMPLES = 200
#: IK continuation step to and from a given crossing point, m (Newton stays on the working branch).
_IK_STEP = 5e-4
#: Fewest samples of such a continuation.
_IK_MIN_SAMPLES = 8


def _dynamics(kin: KinematicModel, dynamics) -> LumpedDynamics:
    """The dynamics of ``kin``'s robot from a model or a built LumpedDynamics; InputError otherwise."""
    if isinstance(dynamics, LumpedDynamics):
        if dynamics.kin is not kin and dynamics.kin.robot is not kin.robot:
            raise InputError("the LumpedDynamics was built for another robot")
        return dynamics
    if isinstance(dynamics, LumpedMassModel):
        try:
            return LumpedDynamics(kin, dynamics)
        except ModelError as exc:
            raise InputError(f"unusable dynamic model: {exc}") from exc
    raise InputError(f"dynamics must be a LumpedMassModel or LumpedDynamics, got {type(dynamics).__name__}")


def crossing_point_and_joints(kin: KinematicModel, task: CrossingTask, xi, crossing_point=None):
    """Where ``task`` crosses the locus of ``xi`` (``crossing_point``, m, when given; else where its straight
    segment does), the joints there (rad) and the start mode; InputError on a bad request."""
    if crossing_point is None:
        c = crossing_on_segment(kin, task, xi)
        s_star, u, m0 = c.s_star, c.u, c.m0
        point = task.start + s_star * u
        along = task.start[None] + np.linspace(0, s_star, _SEGMENT_IK_SAMPLES)[:, None] * u[None]
        q_point = kin.ik(point, xi, kin.ik_path(along, xi, task.working_guess)[-1])
        return point, q_point, m0
    point = np.asarray(crossing_point, dtype=float).reshape(-1)
    if point.shape != task.start.shape or not np.all(np.isfinite(point)):
        raise InputError(f"crossing_point must be a finite ({task.start.size},) vector, got {crossing_point!r}")

    def seg(a, b):  # points every <= _IK_STEP (m) from a to b, for IK continuation
        k = max(_IK_MIN_SAMPLES, int(np.ceil(np.linalg.norm(b - a) / _IK_STEP)) + 1)
        return a[None] + np.linspace(0.0, 1.0, k)[:, None] * (b - a)[None]

    try:
        Qa = kin.ik_path(seg(task.start, point), xi, task.working_guess)
        Qb = kin.ik_path(seg(point, task.goal), xi, Qa[-1])
    except SimulationError as exc:
        raise InputError(f"start -> crossing point -> goal is not reachable in the working mode: {exc}") from None
    q_point = Qa[-1]
    mv = kin.normalised_mode_batch(point[None], q_point[None], xi)[0]
    if abs(mv) > _LOCUS_RTOL:
        raise InputError(f"crossing_point {point.tolist()} is not on the Type 2 locus (normalised det J_x = {mv:.3g})")
    m0 = kin.mode(task.start, Qa[0], xi)
    m1 = kin.mode(task.goal, Qb[-1], xi)
    if m0 == 0 or m1 == 0:
        raise InputError("start or goal lies on the Type 2 locus; move it off the locus")
    if m0 == m1:
        raise InputError(f"goal is in the same assembly mode ({m0:+d}) as the start: there is nothing to cross")
    return point, q_point, int(m0)


@dataclass(frozen=True, eq=False)
class GenerationOptions:
    """How :func:`generate_crossing` transcribes and solves a request; validated at construction.

    Parameters
    ----------
    objective : Objective or {"time", "jerk"}
        Minimise the motion time, or ``integral |jerk|^2 dt`` at the motion duration ``duration``.
    crossing_point : array_like (n,), optional
        Point of the Type 2 locus to cross (m; on the locus of ``xi_plan`` to
        a normalised ``|det J_x|`` of 1e-8).  Default: where the straight
        segment start -> goal meets the locus.
    duration : float, optional
        Motion time for ``"jerk"``, s.  Default: ``duration_factor`` times the
        minimal time (solved first, and used as the initial guess).
    duration_factor : float
        See ``duration`` (>= 1).
    intervals : (int, int)
        Intervals before and after the crossing instant (>= 2 each).
    t_s : float, optional
        Sampling period of the result, s (robot default).
    t_rest, t_after : float
        Rest before the motion (at least; the start is delayed by less than
        ``t_s`` so that the crossing falls on a sample) and after it, s.
    xi_plan : array_like (m,), optional
        Planning geometry (default the centre of the calibration box, as
        :func:`~planner.certify.plan_crossing`).
    criterion_tol : float
        Largest accepted ``|t_s^T w_x|`` at the crossing sample, N.
    max_iter, max_cpu_time, print_level
        IPOPT settings (:class:`~planner.generate.nlp.IpoptSettings`; ``max_cpu_time`` in s).
    """

    objective: Objective = Objective.TIME
    crossing_point: np.ndarray | None = None
    duration: float | None = None
    duration_factor: float = 1.25
    intervals: tuple[int, int] = (40, 40)
    t_s: float | None = None
    t_rest: float = 0.05
    t_after: float = 0.05
    xi_plan: np.ndarray | None = None
    criterion_tol: float = CRITERION_TOL
    max_iter: int = 3000
    max_cpu_time: float = 60.0
    print_level: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "objective", parse_option(Objective, "objective", self.objective))
        try:
            NA, NB = (int(v) for v in self.intervals)
        except (TypeError, ValueError):
            raise InputError(f"intervals must be a pair of integers, got {self.intervals!r}") from None
        if NA < 2 or NB < 2:
            raise InputError(f"need at least 2 intervals on each side of the crossing, got {self.intervals}")
        object.__setattr__(self, "intervals", (NA, NB))
        for name in ("t_s", "duration", "criterion_tol", "max_cpu_time"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise InputError(f"{name} must be positive, got {v}")
        for name in ("t_rest", "t_after"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise InputError(f"{name} must be non-negative, got {getattr(self, name)}")
        if not (math.isfinite(self.duration_factor) and self.duration_factor >= 1.0):
            raise InputError(f"duration_factor must be >= 1, got {self.duration_factor}")

    @property
    def ipopt(self) -> IpoptSettings:
        """The IPOPT settings."""
        return IpoptSettings(int(self.max_iter), float(self.max_cpu_time), int(self.print_level))

    def geometry(self, robot) -> np.ndarray:
        """The planning geometry ``xi_plan`` (default the centre of ``robot``'s calibration box); InputError
        when it has not ``robot.m`` entries."""
        xi = robot.xi_center if self.xi_plan is None else np.asarray(self.xi_plan, dtype=float).reshape(-1)
        if xi.shape != (robot.m,):
            raise InputError(f"xi_plan must have {robot.m} entries")
        return xi


def generate_crossing(kin: KinematicModel, dynamics, task: CrossingTask, v_sing: float, limits: GenerationLimits,
                      options: GenerationOptions | None = None, **overrides) -> GeneratedTrajectory:
    """Generate a rest-to-rest crossing of the Type 2 locus meeting the dynamic crossing criterion.

    The NLP of a (robot, task, crossing point, limits, objective) is built
    once per process with the speed as a parameter and solved from the
    solution of the nearest speed already generated (its primal point);
    every solution passes the independent check (:mod:`.check`).

    Parameters
    ----------
    kin : KinematicModel
    dynamics : LumpedMassModel or LumpedDynamics
        The robot's dynamic model (masses, inertias, gravity, ``tau_max``).
    task : CrossingTask
        ``start`` (at rest, one assembly mode), ``goal`` (at rest, the other),
        ``working_guess`` (joints near ``start``: selects the legs' branch).
    v_sing : float
        Speed ``|xd|`` at the crossing instant, m/s (> 0).
    limits : GenerationLimits
    options : GenerationOptions, optional
        Objective, crossing point, intervals, sampling, IPOPT settings.
    **overrides
        Fields of :class:`GenerationOptions` replacing those of ``options``
        (e.g. ``objective="jerk"``, ``intervals=(20, 20)``).

    Returns
    -------
    GeneratedTrajectory

    Raises
    ------
    InputError
        Malformed arguments; start and goal in the same assembly mode; start,
        goal or crossing point unreachable; crossing point off the locus.
    NotConverged
        IPOPT did not succeed; ``.status`` holds its status (e.g.
        ``"Infeasible_Problem_Detected"`` when the limits do not allow ``v_sing``).
    CheckFailed
        A converged solution failed the independent check (``.check`` names
        the requirement); :class:`LimitExceeded` (``.limit``, ``.ratio``) when
        a limit is still exceeded between the nodes after the re-solves.
        All three are :class:`~robots.errors.SimulationError`.
    """
    wall0 = time.perf_counter()
    dyn, v_sing = _checked_request(kin, dynamics, task, v_sing, limits)
    opts = _options(options, overrides)
    lim, xi = limits.resolved(kin.n), opts.geometry(kin.robot)
    point, q_point, m0 = crossing_point_and_joints(kin, task, xi, opts.crossing_point)
    site = CrossingSite(point, q_point, uncontrolled_direction(kin, point, q_point, xi), m0, xi)
    NA, NB = opts.intervals
    run = _Run(kin, dyn, task, site, lim, v_sing, opts, bool(limits.torque))
    duration, guess, pre_time = _duration_and_guess(run, float(limits.margin))
    sol, sampled, checked, margin, attempts, solve_time = _solve_and_check(run, duration, guess, float(limits.margin))
    stats = {
        "status": sol.status, "iterations": sol.iterations, "solve_time_s": solve_time, "presolve_time_s": pre_time,
        "attempts": attempts, "margin": margin, "wall_time_s": time.perf_counter() - wall0,
        "n_variables": sol.nv, "n_constraints": sol.ng, "intervals": (NA, NB),
    }
    return _packed(run, sol, sampled, checked, stats)


def _checked_request(kin, dynamics, task, v_sing, limits) -> tuple[LumpedDynamics, float]:
    """The dynamics and the speed (m/s) of a request, after checking the arguments' types and sizes."""
    if not isinstance(kin, KinematicModel):
        raise InputError(f"kin must be a KinematicModel, got {type(kin).__name__}")
    if not isinstance(task, CrossingTask):
        raise InputError(f"task must be a CrossingTask, got {type(task).__name__}")
    if not isinstance(limits, GenerationLimits):
        raise InputError(f"limits must be GenerationLimits, got {type(limits).__name__}")
    dyn = _dynamics(kin, dynamics)
    if task.start.shape != (kin.n,):
        raise InputError(f"task poses must have {kin.n} entries")
    try:
        v_sing = float(v_sing)
    except (TypeError, ValueError):
        raise InputError(f"v_sing must be a number, got {v_sing!r}") from None
    if not (math.isfinite(v_sing) and v_sing > 0):
        raise InputError(f"v_sing must be positive and finite, got {v_sing}")
    return dyn, v_sing


def _options(options: GenerationOptions | None, overrides: dict) -> GenerationOptions:
    """``options`` (default :class:`GenerationOptions`) with ``overrides`` replacing its fields."""
    if options is not None and not isinstance(options, GenerationOptions):
        raise InputError(f"options must be GenerationOptions, got {type(options).__name__}")
    unknown = set(overrides) - {f.name for f in fields(GenerationOptions)}
    if unknown:
        raise InputError(f"unknown generation options {sorted(unknown)}; see GenerationOptions")
    return replace(options or GenerationOptions(), **overrides)


@dataclass(frozen=True, eq=False)
class _Run:
    """One generation request, resolved: what every step needs."""

    kin: KinematicModel
    dyn: LumpedDynamics
    task: CrossingTask
    site: CrossingSite
    lim: dict
    v_sing: float
    opts: GenerationOptions
    torque: bool

    def nlp(self, objective: Objective) -> CrossingNlp:
        """The NLP of this request with ``objective``."""
        return CrossingNlp(self.kin, self.dyn, self.task, self.site, self.lim,
                           Transcription(*self.opts.intervals, objective, self.torque), self.opts.ipopt)

    def solve(self, objective: Objective, duration, guess, margin: float):
        """:func:`solve_nlp` of this request with ``objective``; ``guess`` None: from the nearest speed solved."""
        return solve_nlp(self.nlp(objective), v_sing=self.v_sing, margin=margin, duration=duration, guess=guess)

    def cold_guess(self) -> tuple:
        """The straight initial guess (InputError when its IK continuation fails)."""
        try:
            return initial_guess(self.kin, self.task, self.site.point, self.site.q_point, self.v_sing,
                                 *self.opts.intervals, self.site.xi)
        except SimulationError as exc:
            raise InputError(f"the straight initial guess is not reachable in the working mode: {exc}") from None

    def start(self, objective: Objective) -> tuple | None:
        """None (warm: the nearest speed's solution) when this objective's solver has one, else the cold guess."""
        return None if self.nlp(objective).solver().has_solutions() else self.cold_guess()


def _duration_and_guess(run: _Run, margin: float) -> tuple:
    """``(duration, guess, presolve time)``: for ``"jerk"`` without a duration, the minimal time is solved
    first and its solution, slowed down to the duration, is the guess."""
    opts, (NA, NB) = run.opts, run.opts.intervals
    if opts.objective is Objective.TIME:
        return None, run.start(Objective.TIME), 0.0
    duration, guess, pre_time = opts.duration, None, 0.0
    if duration is None:
        tsol = run.solve(Objective.TIME, None, run.start(Objective.TIME), margin)
        pre_time = tsol.solve_time
        duration = opts.duration_factor * (NA * tsol.hA + NB * tsol.hB)
        guess = (tsol.X, tsol.V, tsol.A, tsol.J, tsol.Q, tsol.hA, tsol.hB)
    X0, V0, A0, J0, Q0, hA0, hB0 = guess if guess is not None else run.cold_guess()
    c = (NA * hA0 + NB * hB0) / duration
    V1 = V0 * c
    V1[NA] = V0[NA]  # keep |v| = v_sing at the crossing
    return duration, (X0, V1, A0 * c**2, J0 * c**3, Q0, hA0 / c, hB0 / c), pre_time


def _solve_and_check(run: _Run, duration, guess, margin: float) -> tuple:
    """Solve and check; on a limit exceeded between the nodes back off by the measured excess and re-solve
    from this solution.  Returns ``(solution, samples, checked, margin, attempts, solve time)``."""
    solve_time = 0.0
    opts = run.opts
    for attempt in range(_MARGIN_RETRIES + 1):
        sol = run.solve(opts.objective, duration, guess, margin)
        solve_time += sol.solve_time
        sampled = sample(sol, opts.intervals[0], _t_s(run), opts.t_rest, opts.t_after)
        try:
            checked = check_plan(run.kin, run.dyn, run.task, run.site.point, run.site.m0, run.v_sing, run.lim, run.torque,
                             run.site.xi, sampled, sol.Q, opts.criterion_tol)
            return sol, sampled, checked, margin, attempt + 1, solve_time
        except LimitExceeded as exc:
            if attempt == _MARGIN_RETRIES or exc.ratio > _RETRY_RATIO_MAX:
                raise
            margin = 1.0 - (1.0 - margin) / exc.ratio * (1.0 - _RETRY_EXTRA)
            guess = None  # from this speed's own solution (primal point)


def _t_s(run: _Run) -> float:
    return run.kin.robot.t_s if run.opts.t_s is None else float(run.opts.t_s)


def _packed(run: _Run, sol, sampled, checked, stats: dict) -> GeneratedTrajectory:
    """The checked solution as a :class:`GeneratedTrajectory`."""
    Q, QD, QDD, tau, crit, modes, peak = checked
    NA, NB = run.opts.intervals
    t, k_sing, objective = sampled.t, sampled.k_sing, run.opts.objective
    T_motion = NA * sol.hA + NB * sol.hB
    h = np.concatenate([np.full(NA, sol.hA), np.full(NB, sol.hB)])
    value = T_motion if objective is Objective.TIME else float(np.sum(h * np.sum(sol.J**2, axis=1)))
    site = run.site
    return GeneratedTrajectory(
        t=t, t_s=_t_s(run), x=sampled.x, xd=sampled.xd, xdd=sampled.xdd, xddd=sampled.xddd, q=Q, qd=QD, qdd=QDD,
        tau=tau, k_sing=k_sing, v_sing=run.v_sing, crossing_point=site.point, xi_plan=site.xi,
        criterion_direction=site.t_dir, criterion_residual=crit, objective=objective, objective_value=float(value),
        duration=float(T_motion), t_start=float(sampled.t_start), t_cross=float(t[k_sing]), modes=modes,
        peak_ratio=peak, node_t=sampled.node_t, node_x=sol.X, node_v=sol.V, node_a=sol.A, node_q=sol.Q,
        node_jerk=sol.J, solver_stats=stats,
    )
