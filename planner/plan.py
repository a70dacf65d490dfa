"""Plans of a crossing: the three time laws along the task's straight segment, or a given path re-timed.

* :func:`plan_crossing` — a rest-to-rest trajectory along the straight segment
  from ``task.start`` to ``task.goal`` that crosses the nominal Type 2 locus at
  speed ``v_sing`` (smoothstep, time-optimal or dynamic time law);
* :func:`speed_ceiling` — the fastest crossing speed a time law allows.

The acceleration bound a certificate of a plan assumes is the bounds' step for
that plan (:meth:`planner.task.ResolvedBounds.for_plan`).
"""

from __future__ import annotations

import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError, SimulationError

from .generate import GenerationLimits, generate_crossing
from .path import (PathTask, joints_along, path_speed_ceiling, plan_along_path, smoothstep_law,
                   time_optimal_along_path, time_optimal_ceiling)
from .simulate import RAMP_PEAK
from .task import (CrossingTask, Method, PlannedTrajectory, PlanningBounds, ResolvedBounds, crossing_on_segment,
                   parse_option, resolved)

__all__ = ["plan_crossing", "speed_ceiling"]

#: Path grid of the time-optimal law, m: fine enough that the cone program's
#: finite differences do not limit the speed at the crossing (~0.1 mm).
TIME_OPTIMAL_GRID_STEP = 1e-4
#: Relative shrink of the speed ceiling, so a plan at the ceiling is feasible
#: despite rounding in the ramp lengths.
CEILING_SHRINK = 1e-6
#: Default joint speed (rad/s) and acceleration (rad/s^2) limits of the
#: dynamic law: a 100 W servo behind a 10:1 gear (3000 rpm ~ 31 rad/s at the joint).
DYNAMIC_QD_MAX = 30.0
DYNAMIC_QDD_MAX = 3000.0


def plan_crossing(kin, task: CrossingTask, v_sing: float, bounds: PlanningBounds | ResolvedBounds,
                  method: str | None = None, limits=None) -> PlannedTrajectory:
    """Plan a rest-to-rest straight crossing at ``v_sing`` (m/s).

    ``bounds``: resolved for ``kin.robot``, or resolved here (:func:`planner.task.resolved`).
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
    b = resolved(bounds, robot)
    v_sing = V.positive("v_sing", v_sing)
    method = b.method if method is None else parse_option(Method, "planning method", method)
    if isinstance(task, PathTask):
        if method is Method.TIME_OPTIMAL:
            return time_optimal_along_path(kin, task, v_sing, b, TIME_OPTIMAL_GRID_STEP)
        if method is not Method.SMOOTHSTEP:
            raise InputError(f"a given path is re-timed with the smoothstep or time-optimal law, not {method.value!r}")
        return plan_along_path(kin, task, v_sing, b)
    xi = robot.xi_center
    c = crossing_on_segment(kin, task, xi)
    s_star, u, L = c.s_star, c.u, c.length
    if method is Method.TIME_OPTIMAL:
        return _plan_time_optimal(kin, task, v_sing, b, xi, s_star, u, L, limits)
    if method is Method.DYNAMIC:
        return _plan_dynamic(kin, task, v_sing, b, xi)
    t, s, v, a, k_event = smoothstep_law(b, v_sing, s_star, L)
    X = task.start[None] + s[:, None] * u[None]
    XD = v[:, None] * u[None]
    XDD = a[:, None] * u[None]
    # the guesses: the segment's scan (0.5 mm apart, on the working branch)
    Q, QD, QDD = joints_along(kin, X, XD, XDD, xi, c.joints_at(s), task.working_guess, "planned path")
    return PlannedTrajectory(t=t, q=Q, qd=QD, qdd=QDD, x=X, xd=XD, xdd=XDD, t_s=b.t_s, k_sing=k_event, v_sing=v_sing,
                             crossing_point=task.start + s_star * u, xi_plan=xi)



def _time_optimal_setup(kin, task, b, xi, s_star, u, L, limits):
    """Path samples (about 0.1 mm apart, the crossing point on a node) and limits of the time-optimal law."""
    from . import timescale as ts_  # cvxpy and toppra load in ~1 s: only when this law is used

    h_target = TIME_OPTIMAL_GRID_STEP
    n1 = max(2, int(round(s_star / h_target)))
    h = s_star / n1
    N = max(n1 + 2, int(round(L / h)))
    samples = ts_.sample_path(kin, task.start, u, N * h, N, task.working_guess, xi)
    if limits is None and (b.qd_max is not None or b.qdd_max is not None):
        limits = ts_.ScalingLimits(qd_max=b.qd_max, qdd_max=b.qdd_max)
    lim = limits or ts_.ScalingLimits()
    lim = ts_.ScalingLimits(qd_max=lim.qd_max, qdd_max=lim.qdd_max, a_max=b.a_peak, extra=lim.extra)
    return ts_, samples, lim


def speed_ceiling(kin, task: CrossingTask, bounds: PlanningBounds | ResolvedBounds) -> float:
    """Fastest ``v_sing`` (m/s) the time law of ``bounds`` allows on ``task``: the upper end of a search.

    ``bounds`` as for :func:`plan_crossing`.

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
    b = resolved(bounds, robot)
    if isinstance(task, PathTask):
        if b.method is Method.TIME_OPTIMAL:
            return time_optimal_ceiling(kin, task, b, TIME_OPTIMAL_GRID_STEP) * (1 - CEILING_SHRINK)
        return path_speed_ceiling(kin, task, b) * (1 - CEILING_SHRINK)
    xi = robot.xi_center
    c = crossing_on_segment(kin, task, xi)
    s_star, u, L = c.s_star, c.u, c.length
    if b.method is Method.TIME_OPTIMAL:
        ts_, samples, lim = _time_optimal_setup(kin, task, b, xi, s_star, u, L, None)
        try:
            top = ts_.max_speed_at(samples, lim, s_star)
        except SimulationError as exc:
            raise InputError(f"no feasible crossing speed: {exc}") from None
    else:
        top = float(np.sqrt(2.0 * b.a_peak * min(s_star, L - s_star) / RAMP_PEAK))
    return top * (1 - CEILING_SHRINK)


def _plan_time_optimal(kin, task, v_sing, b, xi, s_star, u, L, limits):
    ts_, samples, lim = _time_optimal_setup(kin, task, b, xi, s_star, u, L, limits)
    scaling = ts_.time_optimal_scaling(samples, lim, v_sing=v_sing, s_star=s_star)
    tt = ts_.resample(scaling, samples, b.t_s, t_rest=b.t_rest, t_rest_end=b.t_rest)
    return PlannedTrajectory(t=tt.t, q=tt.q, qd=tt.qd, qdd=tt.qdd, x=tt.x, xd=tt.xd, xdd=tt.xdd, t_s=b.t_s,
                             k_sing=tt.k_star, v_sing=v_sing, crossing_point=task.start + s_star * u, xi_plan=xi)


def _plan_dynamic(kin, task, v_sing, b, xi):
    limits = GenerationLimits(qd_max=DYNAMIC_QD_MAX if b.qd_max is None else b.qd_max,
                              qdd_max=DYNAMIC_QDD_MAX if b.qdd_max is None else b.qdd_max, a_max=b.a_peak)
    gen = generate_crossing(kin, b.dynamics, task, v_sing, limits, objective="time", t_s=b.t_s, t_rest=b.t_rest,
                            t_after=b.t_rest, xi_plan=xi)
    return gen.to_planned_trajectory()
