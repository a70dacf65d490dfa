"""The entry point: :func:`generate_crossing` validates a request, solves the NLP, checks and packs the result."""

from __future__ import annotations

import math
import time

import numpy as np

from crosscert.robots.dynamics import LumpedDynamics, LumpedMassModel, uncontrolled_direction
from crosscert.robots.errors import InputError, ModelError, SimulationError
from crosscert.robots.kinematics import KinematicModel

from ..task import CrossingTask, crossing_on_segment, parse_option
from .check import CRITERION_TOL, check_plan
from .nlp import initial_guess, sample, solve_nlp
from .types import GeneratedTrajectory, GenerationLimits, LimitExceeded, Objective

__all__ = ["generate_crossing", "crossing_point_and_joints"]

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


def generate_crossing(kin: KinematicModel, dynamics, task: CrossingTask, v_sing: float, limits: GenerationLimits,
                      *, objective: str = "time", crossing_point=None, duration: float | None = None,
                      duration_factor: float = 1.25, intervals: tuple[int, int] = (40, 40),
                      t_s: float | None = None, t_rest: float = 0.05, t_after: float = 0.05, xi_plan=None,
                      criterion_tol: float = CRITERION_TOL, max_iter: int = 3000, max_cpu_time: float = 60.0,
                      print_level: int = 0) -> GeneratedTrajectory:
    """Generate a rest-to-rest crossing of the Type 2 locus meeting the dynamic crossing criterion.

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
    objective : Objective or {"time", "jerk"}
        Minimise the motion time, or ``integral |jerk|^2 dt`` at the motion
        duration ``duration``.
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
        IPOPT settings.

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
    if not isinstance(kin, KinematicModel):
        raise InputError(f"kin must be a KinematicModel, got {type(kin).__name__}")
    if not isinstance(task, CrossingTask):
        raise InputError(f"task must be a CrossingTask, got {type(task).__name__}")
    if not isinstance(limits, GenerationLimits):
        raise InputError(f"limits must be GenerationLimits, got {type(limits).__name__}")
    dyn = _dynamics(kin, dynamics)
    robot, n = kin.robot, kin.n
    if task.start.shape != (n,):
        raise InputError(f"task poses must have {n} entries")
    try:
        v_sing = float(v_sing)
    except (TypeError, ValueError):
        raise InputError(f"v_sing must be a number, got {v_sing!r}") from None
    if not (math.isfinite(v_sing) and v_sing > 0):
        raise InputError(f"v_sing must be positive and finite, got {v_sing}")
    objective = parse_option(Objective, "objective", objective)
    try:
        NA, NB = (int(v) for v in intervals)
    except (TypeError, ValueError):
        raise InputError(f"intervals must be a pair of integers, got {intervals!r}") from None
    if NA < 2 or NB < 2:
        raise InputError(f"need at least 2 intervals on each side of the crossing, got {intervals}")
    t_s = robot.t_s if t_s is None else float(t_s)
    for name, v in (("t_s", t_s), ("criterion_tol", criterion_tol)):
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"{name} must be positive, got {v}")
    for name, v in (("t_rest", t_rest), ("t_after", t_after)):
        if not (math.isfinite(v) and v >= 0):
            raise InputError(f"{name} must be non-negative, got {v}")
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise InputError(f"duration must be positive, got {duration}")
    if not (math.isfinite(duration_factor) and duration_factor >= 1.0):
        raise InputError(f"duration_factor must be >= 1, got {duration_factor}")
    lim = limits.resolved(n)
    xi = robot.xi_center if xi_plan is None else np.asarray(xi_plan, dtype=float).reshape(-1)
    if xi.shape != (robot.m,):
        raise InputError(f"xi_plan must have {robot.m} entries")

    point, q_point, m0 = crossing_point_and_joints(kin, task, xi, crossing_point)
    t_dir = uncontrolled_direction(kin, point, q_point, xi)
    try:
        guess = initial_guess(kin, task, point, q_point, v_sing, NA, NB, xi)
    except SimulationError as exc:
        raise InputError(f"the straight initial guess is not reachable in the working mode: {exc}") from None
    margin = float(limits.margin)
    common = {"NA": NA, "NB": NB, "xi": xi, "torque": bool(limits.torque), "max_iter": max_iter,
              "max_cpu_time": max_cpu_time, "print_level": print_level}
    pre_time = 0.0
    if objective is Objective.JERK and duration is None:
        tsol = solve_nlp(kin, dyn, task, point, q_point, t_dir, m0, v_sing, lim, objective=Objective.TIME,
                         duration=None, guess=guess, margin=margin, **common)
        pre_time = tsol.solve_time
        duration = duration_factor * (NA * tsol.hA + NB * tsol.hB)
        guess = (tsol.X, tsol.V, tsol.A, tsol.J, tsol.Q, tsol.hA, tsol.hB)
    if objective is Objective.JERK:
        # warm start: the guess (or the minimal-time solution) slowed down to the duration
        X0, V0, A0, J0, Q0, hA0, hB0 = guess
        c = (NA * hA0 + NB * hB0) / duration
        V1 = V0 * c
        V1[NA] = V0[NA]  # keep |v| = v_sing at the crossing
        guess = (X0, V1, A0 * c**2, J0 * c**3, Q0, hA0 / c, hB0 / c)
    solve_time = 0.0
    for attempt in range(_MARGIN_RETRIES + 1):
        sol = solve_nlp(kin, dyn, task, point, q_point, t_dir, m0, v_sing, lim, objective=objective,
                        duration=duration, guess=guess, margin=margin, **common)
        solve_time += sol.solve_time
        sampled = sample(sol, NA, t_s, t_rest, t_after)
        try:
            Q, QD, QDD, tau, crit, modes, peak = check_plan(kin, dyn, task, point, m0, v_sing, lim, bool(limits.torque),
                                                        xi, sampled, sol.Q, criterion_tol)
            break
        except LimitExceeded as exc:
            if attempt == _MARGIN_RETRIES or exc.ratio > _RETRY_RATIO_MAX:
                raise
            # back off further at the nodes by the measured excess, and re-solve from this solution
            margin = 1.0 - (1.0 - margin) / exc.ratio * (1.0 - _RETRY_EXTRA)
            guess = (sol.X, sol.V, sol.A, sol.J, sol.Q, sol.hA, sol.hB)
    t, k_sing = sampled.t, sampled.k_sing
    T_motion = NA * sol.hA + NB * sol.hB
    h = np.concatenate([np.full(NA, sol.hA), np.full(NB, sol.hB)])
    value = T_motion if objective is Objective.TIME else float(np.sum(h * np.sum(sol.J**2, axis=1)))
    stats = {
        "status": sol.status, "iterations": sol.iterations, "solve_time_s": solve_time,
        "presolve_time_s": pre_time, "attempts": attempt + 1, "margin": margin,
        "wall_time_s": time.perf_counter() - wall0, "n_variables": sol.nv, "n_constraints": sol.ng,
        "intervals": (NA, NB),
    }
    return GeneratedTrajectory(
        t=t, t_s=t_s, x=sampled.x, xd=sampled.xd, xdd=sampled.xdd, xddd=sampled.xddd, q=Q, qd=QD, qdd=QDD,
        tau=tau, k_sing=k_sing, v_sing=v_sing, crossing_point=point, xi_plan=xi, criterion_direction=t_dir,
        criterion_residual=crit, objective=objective, objective_value=float(value), duration=float(T_motion),
        t_start=float(sampled.t_start), t_cross=float(t[k_sing]), modes=modes, peak_ratio=peak,
        node_t=sampled.node_t, node_x=sol.X, node_v=sol.V,
        node_a=sol.A, node_q=sol.Q, node_jerk=sol.J, solver_stats=stats,
    )
