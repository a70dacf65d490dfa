"""The crossing NLP: initial guess, transcription, IPOPT solve, sampling of the solution.

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

A guess or solution is passed around as the tuple ``(X, V, A, J, Q, h_A, h_B)``
(node states (N+1, n), jerks (N, n), interval lengths in s).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..ipopt import solve_with_ipopt
from ..sampling import align_to_samples
from .types import NotConverged, Objective, Samples

__all__ = ["NlpSolution", "initial_guess", "sample", "solve_nlp"]

#: Each leg of the initial guess lasts this many ``length / v_sing``: a quintic
#: from rest to ``v_sing`` has mean speed ``v_sing / 2``.
_GUESS_TIME_FACTOR = 2.0
#: Below this norm (of a sum of unit vectors) the guess's direction at the
#: crossing falls back to the outgoing leg: the path reverses there.
_DIRECTION_EPS = 1e-9
#: Lower bound of the interval lengths relative to ``T0 / max(N_A, N_B)``:
#: keeps every ``h`` positive without constraining any real motion.
_H_MIN_REL = 1e-6
#: Upper bound of ``N h / T0`` on either side: a leg 50 times slower than
#: ``|goal - start| / v_sing`` is no crossing worth solving for.
_H_MAX_SCALED = 50.0
#: IPOPT's overall and constraint-violation tolerances (scaled units): tight
#: enough that the criterion residual passes the independent check at 1e-8 N.
_IPOPT_TOL = 1e-10
_IPOPT_CONSTR_VIOL_TOL = 1e-11
#: Accepted IPOPT return status; anything else raises :class:`NotConverged`.
_SUCCESS = "Solve_Succeeded"


def _quintic_profile(L: float, v_end: float, T: float, tau: np.ndarray):
    """Rest-to-speed profile s(t) on [0, T]: s, s' s'' zero at 0; s = L, s' = v_end, s'' = 0 at T."""
    M = np.array([[1, 1, 1], [3, 4, 5], [6, 12, 20]], dtype=float)
    c3, c4, c5 = np.linalg.solve(M, [L, v_end * T, 0.0])
    p = c3 * tau**3 + c4 * tau**4 + c5 * tau**5
    dp = (3 * c3 * tau**2 + 4 * c4 * tau**3 + 5 * c5 * tau**4) / T
    ddp = (6 * c3 * tau + 12 * c4 * tau**2 + 20 * c5 * tau**3) / T**2
    return p, dp, ddp


def initial_guess(kin, task, point, q_point, v_sing, NA, NB, xi) -> tuple:
    """Straight start -> point -> goal with quintic speed profiles; joints by IK continuation.

    Returns the guess tuple ``(X, V, A, J, Q, h_A, h_B)`` with ``N_A`` and ``N_B``
    intervals; raises SimulationError when the IK continuation fails.
    """
    La = float(np.linalg.norm(point - task.start))
    Lb = float(np.linalg.norm(task.goal - point))
    ua = (point - task.start) / La
    ub = (task.goal - point) / Lb
    d = ua + ub
    d = d / np.linalg.norm(d) if np.linalg.norm(d) > _DIRECTION_EPS else ub
    Ta, Tb = _GUESS_TIME_FACTOR * La / v_sing, _GUESS_TIME_FACTOR * Lb / v_sing
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
@dataclass(eq=False)
class NlpSolution:
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


def solve_nlp(kin, dyn, task, point, q_point, t_dir, m0, v_sing, lim, *, objective, duration, NA, NB, xi,
              guess, margin, torque, max_iter, max_cpu_time, print_level) -> NlpSolution:
    """Build and solve the NLP of the module docstring; NotConverged unless IPOPT reports success.

    Decision variables are scaled to O(1) (lengths by ``|goal - start|``,
    speeds by ``v_sing``, times by their ratio); every constraint row is
    divided by its natural scale (limit, force scale, ...).

    Parameters
    ----------
    kin, dyn : KinematicModel, LumpedDynamics
    task : CrossingTask
    point, q_point : ndarray, shape (n,)
        Crossing point (m) and the joints there (rad).
    t_dir : ndarray, shape (n,)
        Uncontrolled direction at the crossing point (unit).
    m0 : int
        Assembly mode before the crossing (+1 or -1).
    v_sing : float
        Speed at the crossing, m/s.
    lim : dict
        :meth:`GenerationLimits.resolved` arrays.
    objective : Objective
    duration : float or None
        Motion time for ``Objective.JERK``, s.
    NA, NB : int
        Intervals before and after the crossing node.
    xi : ndarray, shape (m,)
        Planning geometry.
    guess : tuple
        ``(X, V, A, J, Q, h_A, h_B)``, SI.
    margin : float
        Relative back-off of every limit at the nodes.
    torque : bool
        Impose the actuator torque limits.
    max_iter, max_cpu_time, print_level
        IPOPT settings.
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
    if objective is Objective.TIME:
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
    h_lo, h_hi = _H_MIN_REL * T0 / max(NA, NB) / T0, _H_MAX_SCALED / min(NA, NB)

    def F_(a):
        return np.asarray(a, dtype=float).reshape(-1, order="F")

    z = ca.vertcat(ca.vec(xs), ca.vec(vs), ca.vec(as_), ca.vec(js), ca.vec(qv), hs)
    lbx = np.concatenate([F_(xlo), F_(vlo), F_(alo), np.full(n * N, -inf), F_(qlo), [h_lo, h_lo]])
    ubx = np.concatenate([F_(xhi), F_(vhi), F_(ahi), np.full(n * N, inf), F_(qhi), [h_hi, h_hi]])
    z0 = np.concatenate([F_(X0.T / L), F_(V0.T / Vs), F_(A0.T / As), F_(J0.T / Js), F_(Q0.T), [hA0 / T0, hB0 / T0]])
    z0 = np.clip(z0, lbx, ubx)
    g = ca.vertcat(*g_list)
    lbg, ubg = np.concatenate(lb), np.concatenate(ub)
    run = solve_with_ipopt("crossing", z, obj, g, z0=z0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg,
                           ipopt={"print_level": print_level, "max_iter": max_iter, "max_cpu_time": max_cpu_time,
                                  "tol": _IPOPT_TOL, "constr_viol_tol": _IPOPT_CONSTR_VIOL_TOL, "acceptable_iter": 0})
    sol, stats, status, elapsed = run.solution, run.stats, run.status, run.elapsed_s
    if status != _SUCCESS:
        raise NotConverged(status)
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
    return NlpSolution(X, V, A, J, Q, float(hAv), float(hBv), status, int(stats.get("iter_count", -1)), elapsed,
                       int(z.numel()), int(g.numel()))


# ------------------------------------------------------------------ sampling
def sample(sol: NlpSolution, NA: int, t_s: float, t_rest: float, t_after: float) -> Samples:
    """Sample the piecewise-cubic solution at ``t_s`` (s) with the crossing node on a sample.

    ``t_rest`` (at least; the start is delayed by less than ``t_s``) and
    ``t_after`` (s) of rest are added before and after the motion.
    """
    N = sol.J.shape[0]
    T_A, T_B = NA * sol.hA, (N - NA) * sol.hB
    grid = align_to_samples(t_rest + T_A, t_rest + T_A + T_B + t_after, t_s)
    k_sing = grid.k_event
    t_start = k_sing * t_s - T_A
    t_end = t_start + T_A + T_B
    K = grid.samples
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
    return Samples(t=t, x=X, xd=XD, xdd=XDD, xddd=XDDD, k_sing=k_sing, t_start=t_start, node_t=node_t)
