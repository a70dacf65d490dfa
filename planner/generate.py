"""Trajectory generation through a Type 2 singularity with the dynamic crossing criterion (CasADi + IPOPT).

:func:`generate_crossing` computes a rest-to-rest motion of the end-effector
from ``task.start`` (one assembly mode) to ``task.goal`` (the other) that
passes a given point of the Type 2 locus at a prescribed speed ``v_sing``,
satisfies there the crossing criterion of Briot and Arakelian (Section III-B
of the paper, ref. [11] there; :mod:`robots.dynamics`, eq. (2)), and respects
joint speed, joint acceleration and actuator torque limits, minimising either
the motion time or the integral of the squared jerk.

Transcription (multiple shooting with exact integration)
--------------------------------------------------------
The pose is piecewise cubic in time: ``N = N_A + N_B`` intervals, ``N_A`` of
length ``h_A`` before the crossing node ``k* = N_A`` and ``N_B`` of length
``h_B`` after it, a constant jerk ``j_k`` on each.  States at the nodes are
the pose ``x_k``, velocity ``v_k`` and acceleration ``a_k``; the interval
maps are exact,

    ``x_{k+1} = x_k + h v_k + h^2/2 a_k + h^3/6 j_k``,
    ``v_{k+1} = v_k + h a_k + h^2/2 j_k``,  ``a_{k+1} = a_k + h j_k``,

so the motion is ``C^2`` and the path is free (not restricted to the straight
segment).  The joints ``q_k`` are decision variables tied to the pose by the
loop-closure equations ``f(x_k, q_k, xi_plan) = 0`` (no explicit IK); a joint
step larger than ``h qd_max`` is forbidden (it would be a jump to another IK
branch) and ``det J_q`` keeps its sign (no Type 1 singularity).

Constraints: rest (``v = a = 0``) at start and goal; ``x_{k*}`` the crossing
point, ``|v_{k*}| = v_sing``; the crossing criterion ``t_s^T w_x = 0`` at
``k*`` (``t_s`` the uncontrolled direction there); the jerk continuous at
``k*`` (so that the torques of the singular instant, eq. (3) of
:mod:`robots.dynamics`, are defined); the assembly mode ``m0`` before ``k*``
and ``-m0`` after (normalised ``det J_x`` of the right sign at every node);
``|qd|``, ``|qdd|``, ``|tau|`` and optionally ``|xdd|``, ``|j|`` below their
limits at every node (torques by eq. (1) away from ``k*``, by eq. (3) at
it), each backed off by ``limits.margin`` so that the limits also hold
between the nodes; the poses inside ``robot.x_bounds`` and the joints inside
``[q_lo, q_hi]``.

Objectives: ``"time"`` minimises ``N_A h_A + N_B h_B``; ``"jerk"`` minimises
``sum_k h_k |j_k|^2`` (m^2/s^5) at a fixed motion duration.

Independent check
-----------------
IPOPT must report ``Solve_Succeeded``; the solution is then sampled at
``t_s`` (the crossing instant on a sample, rests before and after), the
joints recomputed by IK continuation along the sampled poses (not taken from
the NLP), and every requirement re-checked with numpy on the samples: loop
closure, modes, branch, speed and position at the crossing sample, the
criterion residual (<= ``criterion_tol`` N), every limit (relative tolerance
:data:`LIMIT_RTOL`).  Any failure raises :class:`~robots.errors.SimulationError`;
an unconverged or unverified solution is never returned.

SI units throughout (m, rad, s, N, N m).  ``planner`` never names a robot:
the robot and its dynamic data come from :mod:`robots`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from robots.dynamics import LumpedDynamics, LumpedMassModel, uncontrolled_direction
from robots.kinematics import KinematicModel
from robots.errors import InputError, ModelError, SimulationError

from .task import CrossingTask, PlannedTrajectory, crossing_on_segment

__all__ = [
    "LIMIT_RTOL",
    "CRITERION_TOL",
    "GenerationLimits",
    "GeneratedTrajectory",
    "generate_crossing",
]

#: Relative tolerance of the a-posteriori limit check on the samples.
LIMIT_RTOL = 1e-6
#: Default bound on the criterion residual ``|t_s^T w_x|`` at the crossing sample, N.
CRITERION_TOL = 1e-8
#: ``|mode value| / Hadamard bound`` below which a given crossing point is on the locus.
_LOCUS_RTOL = 1e-8
_OBJECTIVES = ("time", "jerk")
#: Re-solves with a larger back-off when a limit met at the nodes is exceeded between them.
_MARGIN_RETRIES = 2


def _limit_vec(name: str, v, n: int, *, required: bool) -> np.ndarray | None:
    if v is None:
        if required:
            raise InputError(f"{name} is required")
        return None
    try:
        arr = np.array(v, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a number or a vector of numbers, got {v!r}") from exc
    if arr.size == 1:
        arr = np.full(n, float(arr[0]))
    if arr.size != n or not np.all(np.isfinite(arr)) or not np.all(arr > 0):
        raise InputError(f"{name} must be positive and finite with 1 or {n} entries, got {v!r}")
    return arr


@dataclass(frozen=True)
class GenerationLimits:
    """Limits of a generated crossing; the torque limits come from the dynamic model.

    Parameters
    ----------
    qd_max : float or array_like (n,)
        Joint speed bound ``|qd_i| <= qd_max_i``, rad/s.
    qdd_max : float or array_like (n,)
        Joint acceleration bound, rad/s^2.
    a_max : float or array_like (n,), optional
        End-effector acceleration bound ``|xdd_i| <= a_max_i``, m/s^2 (the
        tracker's ``[a_max]``: a certified plan needs one).
    jerk_max : float or array_like (n,), optional
        End-effector jerk bound, m/s^3.
    torque : bool
        Impose ``|tau_i| <= tau_max_i`` of the dynamic model.
    margin : float
        Relative back-off of every limit at the NLP nodes (``[0, 0.5)``):
        the limits are checked between the nodes (on the samples) without it.
    """

    qd_max: object
    qdd_max: object
    a_max: object = None
    jerk_max: object = None
    torque: bool = True
    margin: float = 0.02

    def resolved(self, n: int) -> dict:
        """The limits as ``(n,)`` arrays (``None`` where unbounded)."""
        m = float(self.margin)
        if not (0.0 <= m < 0.5):
            raise InputError(f"margin must be in [0, 0.5), got {self.margin}")
        return {
            "qd_max": _limit_vec("qd_max", self.qd_max, n, required=True),
            "qdd_max": _limit_vec("qdd_max", self.qdd_max, n, required=True),
            "a_max": _limit_vec("a_max", self.a_max, n, required=False),
            "jerk_max": _limit_vec("jerk_max", self.jerk_max, n, required=False),
        }


@dataclass(frozen=True, eq=False)
class GeneratedTrajectory:
    """A generated, independently checked crossing sampled at ``t_s`` (read-only arrays).

    Attributes
    ----------
    t : ndarray, shape (K,)
        Sample times, s (``t[k] = k t_s``).
    x, xd, xdd, xddd : ndarray, shape (K, n)
        Pose (m), velocity (m/s), acceleration (m/s^2), jerk (m/s^3; the
        jerk of the interval starting at or containing the sample).
    q, qd, qdd : ndarray, shape (K, n)
        Joints by IK continuation along ``x`` (rad), rates by eq. (2) and its
        derivative (rad/s, rad/s^2).
    tau : ndarray, shape (K, n)
        Actuator torques, N m (eq. (1); eq. (3) at ``k_sing``).
    k_sing : int
        Sample of the crossing instant (``x[k_sing] == crossing_point``).
    v_sing : float
        Prescribed ``|xd[k_sing]|``, m/s.
    crossing_point : ndarray, shape (n,)
        Point of the Type 2 locus crossed, m.
    xi_plan : ndarray, shape (m,)
        Planning geometry.
    criterion_direction : ndarray, shape (n,)
        Uncontrolled direction ``t_s`` at the crossing point (unit).
    criterion_residual : float
        ``t_s^T w_x`` at ``k_sing``, N (signed; ``|.| <= criterion_tol``).
    objective : str
        ``"time"`` or ``"jerk"``.
    objective_value : float
        Motion time start -> goal (s) or ``integral |jerk|^2 dt`` (m^2/s^5).
    duration : float
        Motion time from leaving the start to reaching the goal, s.
    t_start, t_cross : float
        Times the motion leaves the start and crosses the locus, s.
    modes : tuple of int
        Assembly modes at the first and last sample.
    peak_ratio : dict
        Largest ``|value| / limit`` over the samples for every imposed limit
        (``<= 1 + LIMIT_RTOL``).
    node_t : ndarray, shape (N+1,)
        NLP node times, s (same clock as ``t``).
    node_x, node_v, node_a, node_q : ndarray, shape (N+1, n)
        NLP states at the nodes.
    node_jerk : ndarray, shape (N, n)
        Jerk on each interval, m/s^3.
    solver_stats : dict
        ``status``, ``iterations``, ``solve_time_s`` (IPOPT), ``wall_time_s``
        (whole call, including a minimum-time pre-solve for ``"jerk"``),
        ``n_variables``, ``n_constraints``, ``intervals``.
    """

    t: np.ndarray
    x: np.ndarray
    xd: np.ndarray
    xdd: np.ndarray
    xddd: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    k_sing: int
    v_sing: float
    crossing_point: np.ndarray
    xi_plan: np.ndarray
    criterion_direction: np.ndarray
    criterion_residual: float
    objective: str
    objective_value: float
    duration: float
    t_start: float
    t_cross: float
    modes: tuple
    peak_ratio: dict
    node_t: np.ndarray = field(repr=False)
    node_x: np.ndarray = field(repr=False)
    node_v: np.ndarray = field(repr=False)
    node_a: np.ndarray = field(repr=False)
    node_q: np.ndarray = field(repr=False)
    node_jerk: np.ndarray = field(repr=False)
    solver_stats: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("t", "x", "xd", "xdd", "xddd", "q", "qd", "qdd", "tau", "crossing_point", "xi_plan",
                     "criterion_direction", "node_t", "node_x", "node_v", "node_a", "node_q", "node_jerk"):
            arr = np.array(getattr(self, name), dtype=float)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def to_planned_trajectory(self) -> PlannedTrajectory:
        """The trajectory as a :class:`~planner.certify.PlannedTrajectory` (for :func:`~planner.certify.certify_plan`)."""
        return PlannedTrajectory(t=self.t, q=self.q, qd=self.qd, qdd=self.qdd, x=self.x, xd=self.xd, xdd=self.xdd,
                                 k_sing=self.k_sing, v_sing=self.v_sing, crossing_point=self.crossing_point,
                                 xi_plan=self.xi_plan)


# ------------------------------------------------------------------ set-up
def _dynamics(kin: KinematicModel, dynamics) -> LumpedDynamics:
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


def _crossing(kin: KinematicModel, task: CrossingTask, xi, crossing_point):
    """Crossing point, joints there, start mode; InputError on a bad request."""
    if crossing_point is None:
        c = crossing_on_segment(kin, task, xi)
        s_star, u, m0 = c.s_star, c.u, c.m0
        point = task.start + s_star * u
        q_point = kin.ik(point, xi, kin.ik_path(task.start[None] + np.linspace(0, s_star, 200)[:, None] * u[None],
                                                xi, task.working_guess)[-1])
        return point, q_point, m0
    point = np.asarray(crossing_point, dtype=float).reshape(-1)
    if point.shape != task.start.shape or not np.all(np.isfinite(point)):
        raise InputError(f"crossing_point must be a finite ({task.start.size},) vector, got {crossing_point!r}")

    def seg(a, b):  # points every <= 0.5 mm from a to b, for IK continuation
        k = max(8, int(np.ceil(np.linalg.norm(b - a) / 5e-4)) + 1)
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


def _quintic_profile(L: float, v_end: float, T: float, tau: np.ndarray):
    """Rest-to-speed profile s(t) on [0, T]: s, s' s'' zero at 0; s = L, s' = v_end, s'' = 0 at T."""
    M = np.array([[1, 1, 1], [3, 4, 5], [6, 12, 20]], dtype=float)
    c3, c4, c5 = np.linalg.solve(M, [L, v_end * T, 0.0])
    p = c3 * tau**3 + c4 * tau**4 + c5 * tau**5
    dp = (3 * c3 * tau**2 + 4 * c4 * tau**3 + 5 * c5 * tau**4) / T
    ddp = (6 * c3 * tau + 12 * c4 * tau**2 + 20 * c5 * tau**3) / T**2
    return p, dp, ddp


def _initial_guess(kin, task, point, q_point, v_sing, NA, NB, xi):
    """Straight start -> point -> goal with quintic speed profiles; joints by IK continuation."""
    La = float(np.linalg.norm(point - task.start))
    Lb = float(np.linalg.norm(task.goal - point))
    ua = (point - task.start) / La
    ub = (task.goal - point) / Lb
    d = ua + ub
    d = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-9 else ub
    Ta, Tb = 2.0 * La / v_sing, 2.0 * Lb / v_sing
    tau = np.linspace(0.0, 1.0, NA + 1)
    sa, va, aa = _quintic_profile(La, v_sing, Ta, tau)
    tb = np.linspace(0.0, 1.0, NB + 1)
    sb, vb, ab = _quintic_profile(Lb, v_sing, Tb, tb)  # time-reversed below
    sb, vb, ab = Lb - sb[::-1], vb[::-1], -ab[::-1]
    X = np.vstack([task.start + sa[:, None] * ua, (point + sb[:, None] * ub)[1:]])
    V = np.vstack([va[:, None] * ua, (vb[:, None] * ub)[1:]])
    V[NA] = v_sing * d
    A = np.vstack([aa[:, None] * ua, (ab[:, None] * ub)[1:]])
    Q = np.vstack([kin.ik_path(X[: NA + 1], xi, task.working_guess), kin.ik_path(X[NA:], xi, q_point)[1:]])
    h = np.concatenate([np.full(NA, Ta / NA), np.full(NB, Tb / NB)])
    J = np.diff(A, axis=0) / h[:, None]
    return X, V, A, J, Q, Ta / NA, Tb / NB


# ------------------------------------------------------------------ NLP
@dataclass
class _Solved:
    """An IPOPT solution in SI units: node states (N+1, n), jerks (N, n), interval lengths (s), stats."""

    X: np.ndarray
    V: np.ndarray
    A: np.ndarray
    J: np.ndarray
    Q: np.ndarray
    hA: float
    hB: float
    status: str
    iterations: int
    solve_time: float
    nv: int
    ng: int


def _solve_nlp(kin, dyn, task, point, q_point, t_dir, m0, v_sing, lim, *, objective, duration, NA, NB, xi,
               guess, margin, torque, max_iter, max_cpu_time, print_level) -> _Solved:
    """Build and solve the NLP of the module docstring; SimulationError unless IPOPT reports success.

    Decision variables are scaled to O(1) (lengths by ``|goal - start|``,
    speeds by ``v_sing``, times by their ratio); every constraint row is
    divided by its natural scale (limit, force scale, ...).
    """
    n = kin.n
    N = NA + NB
    ks = NA
    X0, V0, A0, J0, Q0, hA0, hB0 = guess
    # Scales: length L, speed v_sing, time T0 = L / v_sing.
    L = float(np.linalg.norm(task.goal - task.start))
    Vs = float(v_sing)
    T0 = L / Vs
    As, Js = Vs / T0, Vs / T0**2
    Fs = dyn.model.total_mass * As  # force scale, N
    robot = kin.robot
    back = 1.0 - margin

    xs = ca.SX.sym("x", n, N + 1)
    vs = ca.SX.sym("v", n, N + 1)
    as_ = ca.SX.sym("a", n, N + 1)
    js = ca.SX.sym("j", n, N)
    qv = ca.SX.sym("q", n, N + 1)
    hs = ca.SX.sym("h", 2)
    Xe, Ve, Ae, Je = L * xs, Vs * vs, As * as_, Js * js
    hA, hB = T0 * hs[0], T0 * hs[1]
    xi_dm = ca.DM(xi)

    # --- interval maps (exact cubic), scaled per state
    g_list, lb, ub = [], [], []

    def add(expr, lo, hi):
        expr = ca.vec(expr)
        g_list.append(expr)
        k = expr.numel()
        lb.append(np.broadcast_to(np.asarray(lo, float), (k,)).copy() if np.ndim(lo) == 0 else np.asarray(lo, float))
        ub.append(np.broadcast_to(np.asarray(hi, float), (k,)).copy() if np.ndim(hi) == 0 else np.asarray(hi, float))

    for sl, h in ((slice(0, NA), hA), (slice(NA, N), hB)):
        i0, i1 = sl.start, sl.stop
        x0, v0, a0, j0 = Xe[:, i0:i1], Ve[:, i0:i1], Ae[:, i0:i1], Je[:, i0:i1]
        add((Xe[:, i0 + 1:i1 + 1] - (x0 + h * v0 + h**2 / 2 * a0 + h**3 / 6 * j0)) / L, 0.0, 0.0)
        add((Ve[:, i0 + 1:i1 + 1] - (v0 + h * a0 + h**2 / 2 * j0)) / Vs, 0.0, 0.0)
        add((Ae[:, i0 + 1:i1 + 1] - (a0 + h * j0)) / As, 0.0, 0.0)
        # no jump to another IK branch: |q_{k+1} - q_k| <= h qd_max
        dq = qv[:, i0 + 1:i1 + 1] - qv[:, i0:i1]
        qdm = ca.repmat(ca.DM(lim["qd_max"]), 1, i1 - i0)
        add(dq / qdm - h, -np.inf, 0.0)
        add(-dq / qdm - h, -np.inf, 0.0)

    # --- node constraints (mapped over the nodes)
    xsym, qsym, vsym, asym = kin.sx_x, kin.sx_q, ca.SX.sym("v", n), ca.SX.sym("a", n)
    jq_row = np.linalg.norm(kin.jac_q_batch(point[None], q_point[None], xi)[0], axis=1)
    fscale = ca.DM(np.where(jq_row > 0, jq_row, 1.0))
    jx, jq = kin.sx_jx, kin.sx_jq
    had_x = 1
    had_q = 1
    for i in range(n):
        had_x = had_x * ca.norm_2(jx[i, :])
        had_q = had_q * ca.norm_2(jq[i, :])
    mode_n = robot.mode_sign * kin.sx_det / had_x
    detq_n = ca.det(jq) / had_q
    qd_e, qdd_e = dyn.rates_fun(xsym, qsym, vsym, asym, xi_dm)
    rows = [ca.substitute(kin.sx_f, kin.sx_xi, xi_dm) / fscale, mode_n, detq_n,
            qd_e / ca.DM(lim["qd_max"]), qdd_e / ca.DM(lim["qdd_max"])]
    node_f = ca.Function("node", [xsym, qsym, vsym, asym], [ca.substitute(r, kin.sx_xi, xi_dm) for r in rows])
    F, MODE, DETQ, QD, QDD = node_f.map(N + 1)(Xe, qv, Ve, Ae)
    add(F, 0.0, 0.0)
    before = np.arange(1, ks)
    after = np.arange(ks + 1, N)
    add(m0 * MODE[:, before.tolist()], 0.0, np.inf)
    add(-m0 * MODE[:, after.tolist()], 0.0, np.inf)
    sq = float(np.sign(np.linalg.det(kin.jac_q_batch(point[None], q_point[None], xi)[0])))
    add(sq * DETQ, 0.0, np.inf)
    add(QD, -back, back)
    add(QDD, -back, back)
    if lim["a_max"] is not None:
        add(Ae / ca.repmat(ca.DM(lim["a_max"]), 1, N + 1), -back, back)
    if lim["jerk_max"] is not None:
        add(Je / ca.repmat(ca.DM(lim["jerk_max"]), 1, N), -back, back)
    tmax = ca.DM(dyn.model.tau_max)
    if torque:
        regular = [k for k in range(N + 1) if k != ks]
        tau_f = ca.Function("tau", [xsym, qsym, vsym, asym], [dyn.torque_fun(xsym, qsym, vsym, asym, xi_dm) / tmax])
        TAU = tau_f.map(len(regular))(Xe[:, regular], qv[:, regular], Ve[:, regular], Ae[:, regular])
        add(TAU, -back, back)
        tau_s, _lam = dyn.singular_torque_fun(Xe[:, ks], qv[:, ks], Ve[:, ks], Ae[:, ks], Je[:, ks], xi_dm,
                                              ca.DM(t_dir))
        add(tau_s / tmax, -back, back)

    # --- the crossing
    add(ca.sumsqr(vs[:, ks]) - 1.0, 0.0, 0.0)  # |v| = v_sing (scaled)
    w_x, _w_q = dyn.reduced_wrench_fun(Xe[:, ks], qv[:, ks], Ve[:, ks], Ae[:, ks], xi_dm)
    add(ca.dot(ca.DM(t_dir), w_x) / Fs, 0.0, 0.0)  # the criterion
    add(js[:, ks - 1] - js[:, ks], 0.0, 0.0)  # continuous jerk at the singular instant

    T_total = NA * hA + NB * hB
    if objective == "time":
        obj = T_total / T0
    else:
        add(T_total / T0 - duration / T0, 0.0, 0.0)
        obj = (hA * ca.sumsqr(js[:, :NA]) + hB * ca.sumsqr(js[:, NA:])) / T0 / N

    # --- bounds
    inf = np.inf
    xlo = np.repeat((robot.x_lo_array / L)[:, None], N + 1, axis=1)
    xhi = np.repeat((robot.x_hi_array / L)[:, None], N + 1, axis=1)
    for k, p in ((0, task.start), (ks, point), (N, task.goal)):
        xlo[:, k] = xhi[:, k] = p / L
    vlo, vhi = np.full((n, N + 1), -inf), np.full((n, N + 1), inf)
    alo, ahi = np.full((n, N + 1), -inf), np.full((n, N + 1), inf)
    for k in (0, N):
        vlo[:, k] = vhi[:, k] = 0.0
        alo[:, k] = ahi[:, k] = 0.0
    qlo = np.repeat(robot.q_lo_array[:, None], N + 1, axis=1)
    qhi = np.repeat(robot.q_hi_array[:, None], N + 1, axis=1)
    qlo[:, ks] = qhi[:, ks] = q_point
    h_lo, h_hi = 1e-6 * T0 / max(NA, NB) / T0, 50.0 / min(NA, NB)

    def F_(a):
        return np.asarray(a, dtype=float).reshape(-1, order="F")

    z = ca.vertcat(ca.vec(xs), ca.vec(vs), ca.vec(as_), ca.vec(js), ca.vec(qv), hs)
    lbx = np.concatenate([F_(xlo), F_(vlo), F_(alo), np.full(n * N, -inf), F_(qlo), [h_lo, h_lo]])
    ubx = np.concatenate([F_(xhi), F_(vhi), F_(ahi), np.full(n * N, inf), F_(qhi), [h_hi, h_hi]])
    z0 = np.concatenate([F_(X0.T / L), F_(V0.T / Vs), F_(A0.T / As), F_(J0.T / Js), F_(Q0.T), [hA0 / T0, hB0 / T0]])
    z0 = np.clip(z0, lbx, ubx)
    g = ca.vertcat(*g_list)
    lbg, ubg = np.concatenate(lb), np.concatenate(ub)
    opts = {
        "ipopt": {
            "print_level": print_level, "max_iter": max_iter, "max_cpu_time": max_cpu_time,
            "tol": 1e-10, "constr_viol_tol": 1e-11, "acceptable_iter": 0,
            "bound_relax_factor": 0.0, "honor_original_bounds": "yes",
            "mu_strategy": "adaptive", "sb": "yes",
        },
        "print_time": False,
    }
    solver = ca.nlpsol("crossing", "ipopt", {"x": z, "f": obj, "g": g}, opts)
    t0 = time.perf_counter()
    sol = solver(x0=z0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    elapsed = time.perf_counter() - t0
    stats = solver.stats()
    status = str(stats.get("return_status", "unknown"))
    if status != "Solve_Succeeded":
        raise SimulationError(f"trajectory generation did not converge: {status}")
    zs = np.asarray(sol["x"], dtype=float).reshape(-1)
    o = 0

    def take(rows, cols, scale):
        nonlocal o
        out = zs[o:o + rows * cols].reshape((rows, cols), order="F").T * scale
        o += rows * cols
        return out

    X, V, A = take(n, N + 1, L), take(n, N + 1, Vs), take(n, N + 1, As)
    J, Q = take(n, N, Js), take(n, N + 1, 1.0)
    hAv, hBv = zs[o] * T0, zs[o + 1] * T0
    # fixed variables, exactly (undo the rounding of the scaling)
    X[0], X[ks], X[N], Q[ks] = task.start, point, task.goal, q_point
    return _Solved(X, V, A, J, Q, float(hAv), float(hBv), status, int(stats.get("iter_count", -1)), elapsed,
                   int(z.numel()), int(g.numel()))


# ------------------------------------------------------------------ sampling and check
def _sample(sol: _Solved, NA: int, t_s: float, t_rest: float, t_after: float):
    """Sample the piecewise-cubic solution at t_s with the crossing node on a sample."""
    N = sol.J.shape[0]
    T_A, T_B = NA * sol.hA, (N - NA) * sol.hB
    k_sing = math.ceil((t_rest + T_A) / t_s - 1e-9)
    t_start = k_sing * t_s - T_A
    t_end = t_start + T_A + T_B
    K = math.floor((t_end + t_after) / t_s + 1e-9) + 1
    t = np.arange(K) * t_s
    node_t = t_start + np.concatenate([np.arange(NA + 1) * sol.hA, T_A + np.arange(1, N - NA + 1) * sol.hB])
    n = sol.X.shape[1]
    X, XD, XDD, XDDD = (np.empty((K, n)) for _ in range(4))
    for k, tk in enumerate(t):
        if k == k_sing:  # exactly the crossing node
            i, dt = NA, 0.0
        elif tk <= t_start:
            X[k], XD[k], XDD[k], XDDD[k] = sol.X[0], 0.0, 0.0, 0.0
            continue
        elif tk >= t_end:
            X[k], XD[k], XDD[k], XDDD[k] = sol.X[-1], 0.0, 0.0, 0.0
            continue
        elif tk < node_t[NA]:
            i = min(int((tk - t_start) / sol.hA), NA - 1)
            dt = tk - node_t[i]
        else:
            i = min(NA + int((tk - node_t[NA]) / sol.hB), N - 1)
            dt = tk - node_t[i]
        x0, v0, a0, j0 = sol.X[i], sol.V[i], sol.A[i], sol.J[i]
        X[k] = x0 + dt * v0 + dt**2 / 2 * a0 + dt**3 / 6 * j0
        XD[k] = v0 + dt * a0 + dt**2 / 2 * j0
        XDD[k] = a0 + dt * j0
        XDDD[k] = j0
    return t, X, XD, XDD, XDDD, k_sing, t_start, node_t


def _check(cond: bool, what: str) -> None:
    if not cond:
        raise SimulationError(f"generated trajectory failed the independent check: {what}")


class _BetweenNodes(SimulationError):
    """A limit met at the nodes is exceeded between them (``ratio`` = worst |value| / limit)."""

    def __init__(self, message: str, ratio: float) -> None:
        super().__init__(message)
        self.ratio = ratio


def _verify(kin, dyn, task, point, m0, v_sing, lim, torque, xi, sampled, sol, criterion_tol):
    """Recompute joints, rates, torques and the criterion on the samples; raise on any failure."""
    t, X, XD, XDD, XDDD, k_sing, _t_start, _node_t = sampled
    try:
        Q = kin.ik_path(X, xi, task.working_guess)
    except SimulationError as exc:
        raise SimulationError(f"generated trajectory failed the independent check: {exc}") from None
    QD = kin.joint_velocity(X, Q, xi, XD)
    QDD = kin.joint_acceleration(X, Q, xi, XD, QD, XDD)
    _check(np.abs(kin.f_batch(X, Q, xi)).max() <= 1e-10, "loop closure")
    _check(np.allclose(X[0], task.start, atol=1e-12, rtol=0) and np.allclose(X[-1], task.goal, atol=1e-9, rtol=0),
           "start/goal poses")
    _check(np.all(XD[[0, -1]] == 0.0), "rest at start and goal")
    _check(np.array_equal(X[k_sing], point), "crossing point at the crossing sample")
    speed = float(np.linalg.norm(XD[k_sing]))
    _check(abs(speed - v_sing) <= 1e-6 * v_sing, f"|xd| = {speed} m/s at the crossing, v_sing = {v_sing}")
    modes = kin.mode_batch(X, Q, xi)
    _check(np.all(modes[:k_sing] == m0) and np.all(modes[k_sing + 1:] == -m0),
           f"assembly mode {m0:+d} before and {-m0:+d} after the crossing sample")
    detq = np.linalg.det(kin.jac_q_batch(X, Q, xi))
    _check(np.all(np.sign(detq) == np.sign(detq[0])) and np.all(detq != 0), "working mode of the legs (Type 1)")
    # NLP joints on the same branch as the continuation (within one sample of motion)
    idx = np.clip(np.searchsorted(t, _node_t), 0, t.size - 1)
    step = float(t[1] - t[0]) if t.size > 1 else 0.0
    _check(np.all(np.abs(sol.Q - Q[idx]) <= lim["qd_max"] * (step + np.abs(t[idx] - _node_t))[:, None] + 1e-9),
           "NLP joints off the IK-continuation branch")
    # t_s recomputed from the sampled configuration (SVD of J_x), not taken from the NLP
    crit = float(dyn.criterion_residual(X[k_sing], Q[k_sing], XD[k_sing], XDD[k_sing], xi)[0])
    _check(abs(crit) <= criterion_tol, f"criterion residual {crit:.3g} N > {criterion_tol:.3g} N")
    tau = np.empty_like(QD)
    reg = np.arange(t.size) != k_sing
    tau[reg] = dyn.torques(X[reg], Q[reg], XD[reg], XDD[reg], xi)
    tau[k_sing] = dyn.singular_torques(X[k_sing], Q[k_sing], XD[k_sing], XDD[k_sing], XDDD[k_sing], xi)
    _check(np.all(np.isfinite(tau)), "torques finite")
    peak = {"qd": float(np.max(np.abs(QD) / lim["qd_max"])), "qdd": float(np.max(np.abs(QDD) / lim["qdd_max"]))}
    if torque:
        peak["tau"] = float(np.max(np.abs(tau) / dyn.model.tau_max_array))
    if lim["a_max"] is not None:
        peak["xdd"] = float(np.max(np.abs(XDD) / lim["a_max"]))
    if lim["jerk_max"] is not None:
        peak["jerk"] = float(np.max(np.abs(XDDD) / lim["jerk_max"]))
    worst = max(peak, key=peak.get)
    if peak[worst] > 1.0 + LIMIT_RTOL:
        raise _BetweenNodes(f"generated trajectory failed the independent check: {worst} reaches "
                            f"{peak[worst]:.9g} of its limit between the nodes (use more intervals or a larger "
                            "margin)", peak[worst])
    return Q, QD, QDD, tau, crit, (int(modes[0]), int(modes[-1])), peak


# ------------------------------------------------------------------ API
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
    objective : {"time", "jerk"}
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
    SimulationError
        ``"trajectory generation did not converge: <IPOPT status>"`` (e.g.
        ``Infeasible_Problem_Detected`` when the limits do not allow
        ``v_sing``), or a converged solution that fails the independent check.
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
    if objective not in _OBJECTIVES:
        raise InputError(f"unknown objective {objective!r}; use one of {_OBJECTIVES}")
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

    point, q_point, m0 = _crossing(kin, task, xi, crossing_point)
    t_dir = uncontrolled_direction(kin, point, q_point, xi)
    try:
        guess = _initial_guess(kin, task, point, q_point, v_sing, NA, NB, xi)
    except SimulationError as exc:
        raise InputError(f"the straight initial guess is not reachable in the working mode: {exc}") from None
    margin = float(limits.margin)
    common = dict(NA=NA, NB=NB, xi=xi, torque=bool(limits.torque), max_iter=max_iter, max_cpu_time=max_cpu_time,
                  print_level=print_level)
    pre_time = 0.0
    if objective == "jerk" and duration is None:
        tsol = _solve_nlp(kin, dyn, task, point, q_point, t_dir, m0, v_sing, lim, objective="time", duration=None,
                          guess=guess, margin=margin, **common)
        pre_time = tsol.solve_time
        duration = duration_factor * (NA * tsol.hA + NB * tsol.hB)
        guess = (tsol.X, tsol.V, tsol.A, tsol.J, tsol.Q, tsol.hA, tsol.hB)
    if objective == "jerk":
        # warm start: the guess (or the minimal-time solution) slowed down to the duration
        X0, V0, A0, J0, Q0, hA0, hB0 = guess
        c = (NA * hA0 + NB * hB0) / duration
        V1 = V0 * c
        V1[NA] = V0[NA]  # keep |v| = v_sing at the crossing
        guess = (X0, V1, A0 * c**2, J0 * c**3, Q0, hA0 / c, hB0 / c)
    solve_time = 0.0
    for attempt in range(_MARGIN_RETRIES + 1):
        sol = _solve_nlp(kin, dyn, task, point, q_point, t_dir, m0, v_sing, lim, objective=objective,
                         duration=duration, guess=guess, margin=margin, **common)
        solve_time += sol.solve_time
        sampled = _sample(sol, NA, t_s, t_rest, t_after)
        try:
            Q, QD, QDD, tau, crit, modes, peak = _verify(kin, dyn, task, point, m0, v_sing, lim,
                                                         bool(limits.torque), xi, sampled, sol, criterion_tol)
            break
        except _BetweenNodes as exc:
            if attempt == _MARGIN_RETRIES or exc.ratio > 1.5:
                raise SimulationError(str(exc)) from None
            # back off further at the nodes by the measured excess, and re-solve from this solution
            margin = 1.0 - (1.0 - margin) / exc.ratio * (1.0 - 1e-3)
            guess = (sol.X, sol.V, sol.A, sol.J, sol.Q, sol.hA, sol.hB)
    t, X, XD, XDD, XDDD, k_sing, t_start, node_t = sampled
    T_motion = NA * sol.hA + NB * sol.hB
    h = np.concatenate([np.full(NA, sol.hA), np.full(NB, sol.hB)])
    value = T_motion if objective == "time" else float(np.sum(h * np.sum(sol.J**2, axis=1)))
    stats = {
        "status": sol.status, "iterations": sol.iterations, "solve_time_s": solve_time,
        "presolve_time_s": pre_time, "attempts": attempt + 1, "margin": margin,
        "wall_time_s": time.perf_counter() - wall0, "n_variables": sol.nv, "n_constraints": sol.ng, "intervals": (NA, NB),
    }
    return GeneratedTrajectory(
        t=t, x=X, xd=XD, xdd=XDD, xddd=XDDD, q=Q, qd=QD, qdd=QDD, tau=tau, k_sing=k_sing, v_sing=v_sing,
        crossing_point=point, xi_plan=xi, criterion_direction=t_dir, criterion_residual=crit, objective=objective,
        objective_value=float(value), duration=float(T_motion), t_start=float(t_start),
        t_cross=float(t[k_sing]), modes=modes, peak_ratio=peak, node_t=node_t, node_x=sol.X, node_v=sol.V,
        node_a=sol.A, node_q=sol.Q, node_jerk=sol.J, solver_stats=stats,
    )
