"""A given path to re-time: the crossing task of a user's plan, its path kept, its time law chosen here.

:class:`PathTask` holds the poses of a plan (a curve through the Type 2
locus, not only a straight segment) as a function of a path parameter ``s``
(m: the arc length of its translational axes, along the plan's samples);
:func:`plan_along_path` times it with the ``smoothstep`` law of
:func:`smoothstep_law` (the segment's own law) at a chosen speed at the singularity, so
that every certification step made for a task (the speed search, the
counterexample searches, the Monte Carlo run) runs on the user's path.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq

from crosscert.robots.errors import InputError, SimulationError

from .locus import sign_changes
from .sampling import align_to_samples
from .simulate import RAMP_PEAK, TimeLaw, ramp_length
from .task import CrossingTask, PlannedTrajectory

__all__ = ["PathTask", "path_task_of", "path_task_from_poses", "plan_along_path", "smoothstep_law", "path_speed_ceiling",
           "time_optimal_along_path", "time_optimal_ceiling", "joints_along", "PATH_KNOT_SPACING", "SCAN_NEIGHBOURHOOD"]

#: Smallest spacing of the path's knots, m: a plan's rest samples (the same pose repeated) and samples closer
#: than this are dropped, so that the spline's parameter increases strictly and its derivatives stay tame.
PATH_KNOT_SPACING = 1e-5


@dataclass(frozen=True, eq=False)
class PathTask(CrossingTask):
    """A crossing along a given path ``x(s)``, ``s`` in ``[0, length]`` (m), from ``start`` to ``goal``.

    Attributes
    ----------
    s_knots : ndarray (N,)
        Path parameter of the knots, m, strictly increasing from 0.
    x_knots, q_knots : ndarray (N, n)
        Poses (SI) and joints (rad) at the knots (the given plan's samples).
    s_star : float
        Where the path meets the nominal Type 2 locus, m.
    m0 : int
        Assembly mode at the start (+1 or -1).
    source : str
        What the path comes from (a file name), for messages.
    """

    s_knots: np.ndarray = field(default=None, repr=False)
    x_knots: np.ndarray = field(default=None, repr=False)
    q_knots: np.ndarray = field(default=None, repr=False)
    s_star: float = 0.0
    m0: int = 1
    source: str = "<path>"

    def __post_init__(self) -> None:
        super().__post_init__()
        spline = CubicSpline(self.s_knots, self.x_knots, axis=0)
        object.__setattr__(self, "_spline", spline)
        object.__setattr__(self, "_d1", spline.derivative(1))
        object.__setattr__(self, "_d2", spline.derivative(2))

    @property
    def length(self) -> float:
        """Path length, m."""
        return float(self.s_knots[-1])

    def poses(self, s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``x(s)``, ``x'(s)``, ``x''(s)`` at the path parameters ``s`` (K,): three (K, n) arrays, SI per m, m^2."""
        s = np.clip(np.asarray(s, float), 0.0, self.length)
        return self._spline(s), self._d1(s), self._d2(s)

    def joints_at(self, s) -> np.ndarray:
        """Newton guesses of the joints at ``s`` (K,): the knots' joints interpolated, (K, n)."""
        s = np.asarray(s, float)
        return np.stack([np.interp(s, self.s_knots, self.q_knots[:, j]) for j in range(self.q_knots.shape[1])], axis=1)


def _lengths(robot) -> list:
    """The pose axes whose unit is the metre (all axes when none is)."""
    return [i for i, u in enumerate(robot.pose_units) if u.value == "m"] or list(range(robot.n))


def path_task_of(kin, plan: PlannedTrajectory, source: str = "<path>") -> PathTask:
    """The path of a (given) plan as a :class:`PathTask`: its poses in order, its rests and repeats dropped.

    Raises
    ------
    InputError
        The path is too short to re-time, or the locus is not met between two of its knots.
    """
    robot = kin.robot
    x, q = np.asarray(plan.x, float), np.asarray(plan.q, float)
    ax = _lengths(robot)
    step = np.linalg.norm(np.diff(x[:, ax], axis=0), axis=1)
    keep = [0]
    run = 0.0
    for k in range(1, len(x)):
        run += step[k - 1]
        if run >= PATH_KNOT_SPACING:
            keep.append(k)
            run = 0.0
    if keep[-1] != len(x) - 1 and np.linalg.norm(x[-1, ax] - x[keep[-1], ax]) > 0.0:
        keep[-1] = len(x) - 1
    keep = np.asarray(keep)
    if keep.size < 4:
        raise InputError(f"{source}: the path moves through fewer than 4 distinct poses: nothing to re-time")
    return _path_task(kin, x[keep], q[keep], plan.xi_plan, source)


def path_task_from_poses(kin, X, working_guess, source: str = "<path>") -> PathTask:
    """A :class:`PathTask` through the poses ``X`` (N, n; SI, in order, distinct), their joints by IK
    continuation from ``working_guess`` (rad) at the centre of the calibration box."""
    X = np.asarray(X, float)
    xi = kin.robot.xi_center
    try:
        Q = kin.ik_path(X, xi, np.asarray(working_guess, float))
    except SimulationError as exc:
        raise InputError(f"{source}: the path is not reachable in the working mode: {exc}") from None
    return _path_task(kin, X, Q, xi, source)


def _path_task(kin, xk, qk, xi, source: str) -> PathTask:
    """The task of the knots ``xk``, ``qk`` (N, n): parameter, crossing and start mode."""
    xk, qk = np.array(xk, float), np.array(qk, float)
    ax = _lengths(kin.robot)
    sk = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xk[:, ax], axis=0), axis=1))])
    if not np.all(np.diff(sk) > 0.0):
        raise InputError(f"{source}: the path's poses must be distinct and in order")
    nm = kin.normalised_mode_batch(xk, qk, xi)
    sign = np.sign(nm)
    m0 = int(kin.mode(xk[0], qk[0], xi))
    ka, kb = sign_changes(sign)  # a knot on the locus up to rounding is bracketed by its neighbours
    if ka.size != 1 or m0 == 0:
        raise InputError(f"{source}: the path must meet the Type 2 locus once, it does {ka.size} times")
    j, j1 = int(ka[0]), int(kb[0])
    task = PathTask(start=xk[0], goal=xk[-1], working_guess=qk[0], s_knots=sk, x_knots=xk, q_knots=qk, s_star=0.0,
                    m0=m0, source=source)

    def g(s):
        X, _d1, _d2 = task.poses(np.array([s]))
        Q = kin.ik(X[0], xi, task.joints_at(np.array([s]))[0])
        return float(kin.normalised_mode_batch(X, Q[None], xi)[0])

    try:
        s_star = brentq(g, sk[j], sk[j1], xtol=1e-12)
    except (SimulationError, ValueError) as exc:
        raise InputError(f"{source}: could not locate the crossing on the path between knots {j} and {j1}: "
                         f"{exc}") from None
    object.__setattr__(task, "s_star", float(s_star))
    for a in (sk, xk, qk):
        a.setflags(write=False)
    return task


#: Largest joint change (rad; m for a prismatic joint) between a planned pose's IK and its guess (the scan or
#: the knots, interpolated) that keeps the working branch; beyond it the joints come from a continuation instead.
SCAN_NEIGHBOURHOOD = 0.05


def joints_along(kin, X, XD, XDD, xi, guess, working_guess, what: str):
    """Joints (rad), rates and accelerations (K, n) of the planned poses ``X`` and their rates (SI): one batched
    Newton from ``guess`` (on the working branch), the continuation from ``working_guess`` along the path where
    a pose does not converge within :data:`SCAN_NEIGHBOURHOOD` of it.

    Raises
    ------
    InputError
        The continuation fails (``what`` names the path in the message).
    """
    Q, ok = kin.ik_batch(X, xi, guess)
    if not ok.all() or np.max(np.abs(Q - guess)) > SCAN_NEIGHBOURHOOD:
        try:
            Q = kin.ik_path(X, xi, working_guess)
        except SimulationError as exc:
            raise InputError(f"{what} left the working mode: {exc}") from None
    QD = kin.joint_velocity(X, Q, xi, XD)
    return Q, QD, kin.joint_acceleration(X, Q, xi, XD, QD, XDD)


def _tangent_scale(task: PathTask, robot) -> float:
    """``|x'(s*)|`` over the length axes: path parameter speed times it is the speed at the singularity."""
    _x, d1, _d2 = task.poses(np.array([task.s_star]))
    return float(np.linalg.norm(d1[0, _lengths(robot)]))


def path_speed_ceiling(kin, task: PathTask, b) -> float:
    """Fastest speed at the singularity (m/s) the smoothstep law allows on the path within the robot's ``a_max``:
    the ramps fit (as on a segment), and ``a_peak |x'| + v^2 |x''|`` stays within ``a_max`` on every axis."""
    robot = kin.robot
    scale = _tangent_scale(task, robot)
    room = min(task.s_star, task.length - task.s_star)
    top = float(np.sqrt(2.0 * b.a_peak * room / RAMP_PEAK)) * scale
    s = np.linspace(0.0, task.length, 2001)
    _x, d1, d2 = task.poses(s)
    a_max = np.asarray(robot.a_max, float)
    left = a_max - b.a_peak * np.max(np.abs(d1), axis=0)
    curv = np.max(np.abs(d2), axis=0)
    if np.any(left <= 0.0):
        raise InputError(f"{task.source}: a_peak = {b.a_peak:g} m/s^2 along this path exceeds the robot's a_max on "
                         "some axis; lower a_peak")
    with np.errstate(divide="ignore"):
        bend = np.min(np.where(curv > 0.0, np.sqrt(left / np.where(curv > 0.0, curv, 1.0)), np.inf))
    return min(top, float(bend) * scale)


def smoothstep_law(b, v_sing: float, s_star: float, L: float):
    """The ``smoothstep`` time law of a path of length ``L`` (m) crossing at ``s_star`` (m) at ``v_sing`` (m/s).

    Rest ``b.t_rest``, a smoothstep ramp to ``v_sing`` (peak ``b.a_peak``), constant speed through
    ``s_star``, a ramp to rest at ``L``, rest; sampled at ``b.t_s`` with the crossing on a sample.
    Returns ``(t, s, sdot, sddot, k_event)``: times (s), path parameter (m) and its rates, crossing sample.

    Raises
    ------
    InputError
        The ramps do not fit between the start, ``s_star`` and the end (the message gives the fastest speed).
    """
    T, D = ramp_length(v_sing, b.a_peak)
    room = min(s_star, L - s_star)
    if D > room:
        v_max = float(np.sqrt(2.0 * b.a_peak * room / RAMP_PEAK))
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
    # put the crossing instant on a sample (the initial rest grows by < t_s)
    at = align_to_samples(b.t_rest + T + (s_star - D) / v_sing, law.duration, b.t_s)
    t = np.arange(at.samples) * b.t_s
    s, v, a = law.evaluate(t - at.shift)
    return t, s, v, a, at.k_event


def _curve_samples(kin, task: PathTask, b, grid_step: float):
    """The path sampled for the time-optimal law: about ``grid_step`` m apart with ``s*`` on a node (the end
    may move back by less than one step), and the law's limits (``|x''| <= a_peak`` per axis, the bounds'
    joint limits)."""
    from . import timescale as ts_  # cvxpy and toppra load in ~1 s: only when this law is used

    n1 = max(2, int(round(task.s_star / grid_step)))
    h = task.s_star / n1
    N = max(n1 + 2, int(np.floor(task.length / h)))
    try:
        samples = ts_.sample_curve(kin, task.poses, N * h, N, task.joints_at, kin.robot.xi_center)
    except SimulationError as exc:
        raise InputError(f"{task.source}: {exc}") from None
    lim = ts_.ScalingLimits(qd_max=b.qd_max, qdd_max=b.qdd_max, a_max=b.a_peak)
    return ts_, samples, lim


def time_optimal_along_path(kin, task: PathTask, v_sing: float, b, grid_step: float) -> PlannedTrajectory:
    """The path timed by the minimal-time scaling (cvxpy) through the locus at ``v_sing`` (m/s) under the
    crossing criterion, ``|x''| <= a_peak`` per axis and the bounds' joint limits, rest to rest."""
    robot = kin.robot
    ts_, samples, lim = _curve_samples(kin, task, b, grid_step)
    scale = _tangent_scale(task, robot)
    try:
        scaling = ts_.time_optimal_scaling(samples, lim, v_sing=v_sing / scale, s_star=task.s_star)
        tt = ts_.resample(scaling, samples, b.t_s, t_rest=b.t_rest, t_rest_end=b.t_rest)
    except SimulationError as exc:
        raise InputError(f"{task.source}: no time-optimal timing at {v_sing} m/s: {exc}") from None
    point = task.poses(np.array([task.s_star]))[0][0]
    return PlannedTrajectory(t=tt.t, q=tt.q, qd=tt.qd, qdd=tt.qdd, x=tt.x, xd=tt.xd, xdd=tt.xdd, t_s=b.t_s,
                             k_sing=tt.k_star, v_sing=float(v_sing), crossing_point=point, xi_plan=robot.xi_center)


def time_optimal_ceiling(kin, task: PathTask, b, grid_step: float) -> float:
    """The fastest speed at the singularity (m/s) a timing of the path reaches under the time-optimal law's
    limits (toppra's controllable and reachable sets at ``s*``, the criterion included)."""
    ts_, samples, lim = _curve_samples(kin, task, b, grid_step)
    try:
        return float(ts_.max_speed_at(samples, lim, task.s_star)) * _tangent_scale(task, kin.robot)
    except SimulationError as exc:
        raise InputError(f"{task.source}: no feasible crossing speed: {exc}") from None


def plan_along_path(kin, task: PathTask, v_sing: float, b) -> PlannedTrajectory:
    """The path timed by the smoothstep law crossing the locus at ``v_sing`` (m/s), rest to rest.

    The law runs on the path parameter at ``v_sing / |x'(s*)|`` (so the planned speed at the singularity is
    ``v_sing``); poses and their rates come from the path's spline (``xd = x' sd``, ``xdd = x' sdd + x'' sd^2``),
    joints from IK on the working branch.
    """
    robot = kin.robot
    xi = robot.xi_center
    scale = _tangent_scale(task, robot)
    t, s, sd, sdd, k_event = smoothstep_law(b, v_sing / scale, task.s_star, task.length)
    X, d1, d2 = task.poses(s)
    XD = d1 * sd[:, None]
    XDD = d1 * sdd[:, None] + d2 * (sd * sd)[:, None]
    Q, QD, QDD = joints_along(kin, X, XD, XDD, xi, task.joints_at(s), task.working_guess,
                              f"{task.source}: the re-timed path")
    point = task.poses(np.array([task.s_star]))[0][0]
    return PlannedTrajectory(t=t, q=Q, qd=QD, qdd=QDD, x=X, xd=XD, xdd=XDD, t_s=b.t_s, k_sing=k_event,
                             v_sing=float(v_sing), crossing_point=point, xi_plan=xi)
