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

import threading
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..ipopt import ParametricSolver
from ..lru import LruCache
from ..sampling import align_to_samples
from .types import NotConverged, Objective, Samples

__all__ = ["CrossingNlp", "CrossingSite", "CrossingSolver", "IpoptSettings", "NlpSolution", "Transcription",
           "initial_guess", "sample", "solve_nlp"]

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


@dataclass(frozen=True, eq=False)
class CrossingSite:
    """Where the motion crosses: the point (m), its joints (rad), the uncontrolled direction there (unit),
    the start mode (+1 or -1) and the planning geometry ``xi`` (SI)."""

    point: np.ndarray
    q_point: np.ndarray
    t_dir: np.ndarray
    m0: int
    xi: np.ndarray

    def key(self) -> tuple:
        """Hashable value of the site (the arrays' bytes)."""
        return (*(np.asarray(a, float).tobytes() for a in (self.point, self.q_point, self.t_dir, self.xi)), self.m0)


@dataclass(frozen=True)
class Transcription:
    """The NLP's shape: ``NA``, ``NB`` intervals before and after the crossing node, the objective, and
    whether the actuator torque limits are imposed."""

    NA: int
    NB: int
    objective: Objective
    torque: bool


@dataclass(frozen=True)
class IpoptSettings:
    """IPOPT's caps and verbosity for the crossing NLP: iterations, CPU time (s), print level (0 silent)."""

    max_iter: int = 3000
    max_cpu_time: float = 60.0
    print_level: int = 0

    def options(self) -> dict:
        """IPOPT options of a solve (tolerances of this module and these caps)."""
        return {"print_level": self.print_level, "max_iter": self.max_iter, "max_cpu_time": self.max_cpu_time,
                "tol": _IPOPT_TOL, "constr_viol_tol": _IPOPT_CONSTR_VIOL_TOL, "acceptable_iter": 0}


@dataclass(frozen=True, eq=False)
class CrossingNlp:
    """What one crossing NLP is built from: the models, the task, the site, the limits, its shape and IPOPT's
    settings (everything but the speed, the back-off and the duration, which are its parameters).

    Parameters
    ----------
    kin, dyn : KinematicModel, LumpedDynamics
    task : CrossingTask
    site : CrossingSite
    lim : dict
        :meth:`GenerationLimits.resolved` arrays.
    shape : Transcription
    ipopt : IpoptSettings
    """

    kin: object
    dyn: object
    task: object
    site: CrossingSite
    lim: dict
    shape: Transcription
    ipopt: IpoptSettings

    def key(self) -> tuple:
        """Hashable value of these data: equal keys build the same solver."""
        lim = tuple((k, None if v is None else np.asarray(v, float).tobytes()) for k, v in sorted(self.lim.items()))
        ends = tuple(np.asarray(a, float).tobytes() for a in (self.task.start, self.task.goal))
        return (self.kin.robot, self.dyn.model, ends, self.site.key(), lim, self.shape, self.ipopt)

    def solver(self) -> CrossingSolver:
        """The :class:`CrossingSolver` of these data, built on first use and kept (:data:`_SOLVERS`)."""
        return _SOLVERS.get_or_build(self.key(), lambda: CrossingSolver(self))


class CrossingSolver:
    """The crossing NLP of one :class:`CrossingNlp`, built once.

    The speed at the crossing ``v_sing``, the back-off ``1 - margin`` and the
    scaled duration are CasADi parameters: with the variables scaled by
    ``|goal - start|`` and ``v_sing`` (module docstring), the interval maps,
    bounds and fixed nodes do not depend on the speed, so one ``nlpsol``
    serves every speed of a speed search and every margin re-solve.  Each
    converged solution is kept (by speed) as the starting point of the
    nearest speed asked next, in scaled units.

    Only the primal point is carried over.  IPOPT uses given multipliers
    only with ``warm_start_init_point``, an option fixed when the solver is
    built, and with it a cold start (no multipliers yet) is far slower: on
    the benchmark task 60 iterations and 10 CPU-s instead of 24 and 1.2;
    with the multipliers a warm solve takes 5-13 iterations instead of
    12-22, about 0.05 CPU-s less, which does not pay for a second solver.

    Parameters
    ----------
    nlp : CrossingNlp
    """

    def __init__(self, nlp: CrossingNlp):
        task, site, shape = nlp.task, nlp.site, nlp.shape
        self.n, self.shape = nlp.kin.n, shape
        self.L = float(np.linalg.norm(task.goal - task.start))
        z, p, obj, g, self._lbg, self._ubg = _transcribe(nlp.kin, nlp.dyn, self.L, site, nlp.lim, shape)
        self._lbx, self._ubx = _variable_bounds(nlp.kin.robot, task, site, self.L, shape)
        self._solver = ParametricSolver("crossing", z, p, obj, g, ipopt=nlp.ipopt.options())
        self._solutions: dict[float, np.ndarray] = {}
        self._lock = threading.Lock()  # one solve at a time: plans may come from two threads (a CasADi solver is not shared)
        # nodes fixed by bounds, restored exactly after a solve (undo the rounding of the scaling)
        self._fixed = ((0, task.start), (shape.NA, site.point), (shape.NA + shape.NB, task.goal)), site.q_point

    def has_solutions(self) -> bool:
        """A converged solution is kept (a warm start for any speed)."""
        return bool(self._solutions)

    def solve(self, v_sing: float, margin: float, duration: float | None, guess: tuple | None) -> NlpSolution:
        """Solve at ``v_sing`` (m/s) with the back-off ``margin`` from ``guess`` (SI tuple of the module
        docstring) or, when None, from the kept solution of the nearest speed; NotConverged unless success."""
        Vs = float(v_sing)
        T0 = self.L / Vs
        dur = 0.0 if duration is None else float(duration) / T0
        with self._lock:
            if guess is None:
                z0 = self._solutions[min(self._solutions, key=lambda v: abs(v - Vs))]
            else:
                z0 = _scaled(guess, self.L, Vs)
            run = self._solver.solve(p=[Vs, 1.0 - margin, dur], z0=np.clip(z0, self._lbx, self._ubx),
                                     lbx=self._lbx, ubx=self._ubx, lbg=self._lbg, ubg=self._ubg)
            if run.status != _SUCCESS:
                raise NotConverged(run.status)
            zs = np.asarray(run.solution["x"], dtype=float).reshape(-1)
            self._solutions[Vs] = zs
        X, V, A, J, Q, hA, hB = _unscaled(zs, self.n, self.shape, self.L, Vs)
        nodes, Q[self.shape.NA] = self._fixed
        for k, x in nodes:
            X[k] = x
        return NlpSolution(X, V, A, J, Q, hA, hB, run.status, int(run.stats.get("iter_count", -1)), run.elapsed_s,
                           self._solver.n_variables, self._solver.n_constraints)


#: Crossing solvers built in this process, by the value of what they are built from; most recently used last.
#: How many :data:`_SOLVERS` are kept (a speed search plans one task with one objective at a time).
_SOLVER_CACHE_SIZE = 4
_SOLVERS = LruCache(_SOLVER_CACHE_SIZE)


def solve_nlp(nlp: CrossingNlp, *, v_sing: float, margin: float, duration: float | None,
              guess: tuple | None) -> NlpSolution:
    """Solve the NLP of the module docstring at ``v_sing`` (m/s); NotConverged unless IPOPT reports success.

    ``guess`` is the SI tuple of the module docstring, or None to start from
    the solution of the nearest speed already solved on the same solver
    (:meth:`CrossingNlp.solver`; one must exist).  ``margin`` is the relative
    back-off of every limit at the nodes, ``duration`` the motion time (s)
    of ``Objective.JERK`` (None for ``Objective.TIME``).
    """
    return nlp.solver().solve(v_sing, margin, duration, guess)


def _scaled(guess: tuple, L: float, Vs: float) -> np.ndarray:
    """The SI guess tuple as the scaled decision vector (lengths by L, speeds by Vs, times by L / Vs)."""
    X0, V0, A0, J0, Q0, hA0, hB0 = guess
    T0 = L / Vs
    As, Js = Vs / T0, Vs / T0**2
    return np.concatenate([_vec(X0.T / L), _vec(V0.T / Vs), _vec(A0.T / As), _vec(J0.T / Js), _vec(Q0.T),
                           [hA0 / T0, hB0 / T0]])


def _unscaled(zs: np.ndarray, n: int, shape: Transcription, L: float, Vs: float) -> tuple:
    """The scaled decision vector as the SI tuple ``(X, V, A, J, Q, h_A, h_B)``."""
    N = shape.NA + shape.NB
    T0 = L / Vs
    sizes = [n * (N + 1)] * 3 + [n * N, n * (N + 1)]
    X, V, A, J, Q = (part.reshape((n, -1), order="F").T for part in np.split(zs[:-2], np.cumsum(sizes)[:-1]))
    return X * L, V * Vs, A * (Vs / T0), J * (Vs / T0**2), Q.copy(), float(zs[-2] * T0), float(zs[-1] * T0)


def _vec(a) -> np.ndarray:
    """CasADi's ``vec`` (column-major) of an array."""
    return np.asarray(a, dtype=float).reshape(-1, order="F")


def _variable_bounds(robot, task, site: CrossingSite, L: float, shape: Transcription):
    """Bounds of the scaled decision vector: workspace and joint boxes, rest at both ends, the fixed nodes
    (start, crossing point and its joints, goal) and the interval lengths; independent of the speed."""
    n, NA, NB = robot.n, shape.NA, shape.NB
    N, inf = NA + NB, np.inf
    xlo = np.repeat((robot.x_lo_array / L)[:, None], N + 1, axis=1)
    xhi = np.repeat((robot.x_hi_array / L)[:, None], N + 1, axis=1)
    for k, p in ((0, task.start), (NA, site.point), (N, task.goal)):
        xlo[:, k] = xhi[:, k] = p / L
    vlo, vhi = np.full((n, N + 1), -inf), np.full((n, N + 1), inf)
    for k in (0, N):
        vlo[:, k] = vhi[:, k] = 0.0
    qlo = np.repeat(robot.q_lo_array[:, None], N + 1, axis=1)
    qhi = np.repeat(robot.q_hi_array[:, None], N + 1, axis=1)
    qlo[:, NA] = qhi[:, NA] = site.q_point
    h_lo, h_hi = _H_MIN_REL / max(NA, NB), _H_MAX_SCALED / min(NA, NB)
    free = np.full(n * N, inf)
    lbx = np.concatenate([_vec(xlo), _vec(vlo), _vec(vlo), -free, _vec(qlo), [h_lo, h_lo]])
    ubx = np.concatenate([_vec(xhi), _vec(vhi), _vec(vhi), free, _vec(qhi), [h_hi, h_hi]])
    return lbx, ubx


def _transcribe(kin, dyn, L: float, site: CrossingSite, lim: dict, shape: Transcription):
    """The scaled NLP of the module docstring: ``(z, p, obj, g, lbg, ubg)`` with ``p = (v_sing, back, dur)``.

    ``back = 1 - margin`` divides every limit row (so ``lbg``, ``ubg`` do not
    depend on it) and ``dur`` is the motion time of ``Objective.JERK`` over
    ``L / v_sing``.  Every constraint row is divided by its natural scale.
    """
    n, NA, NB = kin.n, shape.NA, shape.NB
    N, ks = NA + NB, NA
    Vs, back, dur = ca.SX.sym("v_sing"), ca.SX.sym("back"), ca.SX.sym("duration")
    T0 = L / Vs
    As, Js = Vs / T0, Vs / T0**2
    Fs = dyn.model.total_mass * As  # force scale, N
    xs, vs, as_ = ca.SX.sym("x", n, N + 1), ca.SX.sym("v", n, N + 1), ca.SX.sym("a", n, N + 1)
    js, qv, hs = ca.SX.sym("j", n, N), ca.SX.sym("q", n, N + 1), ca.SX.sym("h", 2)
    Xe, Ve, Ae, Je = L * xs, Vs * vs, As * as_, Js * js
    xi_dm = ca.DM(site.xi)
    rows = _Rows()
    # --- interval maps (exact cubic): in scaled units they do not depend on the speed
    for i0, i1, h in ((0, NA, hs[0]), (NA, N, hs[1])):
        x0, v0, a0, j0 = xs[:, i0:i1], vs[:, i0:i1], as_[:, i0:i1], js[:, i0:i1]
        rows.add(xs[:, i0 + 1:i1 + 1] - (x0 + h * v0 + h**2 / 2 * a0 + h**3 / 6 * j0), 0.0, 0.0)
        rows.add(vs[:, i0 + 1:i1 + 1] - (v0 + h * a0 + h**2 / 2 * j0), 0.0, 0.0)
        rows.add(as_[:, i0 + 1:i1 + 1] - (a0 + h * j0), 0.0, 0.0)
        # no jump to another IK branch: |q_{k+1} - q_k| <= h qd_max
        dq = qv[:, i0 + 1:i1 + 1] - qv[:, i0:i1]
        qdm = ca.repmat(ca.DM(lim["qd_max"]), 1, i1 - i0)
        rows.add(dq / qdm - T0 * h, -np.inf, 0.0)
        rows.add(-dq / qdm - T0 * h, -np.inf, 0.0)
    _node_rows(rows, kin, dyn, site, lim, shape, (Xe, Ve, Ae, Je, qv), back, xi_dm)
    # --- the crossing
    rows.add(ca.sumsqr(vs[:, ks]) - 1.0, 0.0, 0.0)  # |v| = v_sing (scaled)
    w_x, _w_q = dyn.reduced_wrench_fun(Xe[:, ks], qv[:, ks], Ve[:, ks], Ae[:, ks], xi_dm)
    rows.add(ca.dot(ca.DM(site.t_dir), w_x) / Fs, 0.0, 0.0)  # the criterion
    rows.add(js[:, ks - 1] - js[:, ks], 0.0, 0.0)  # continuous jerk at the singular instant
    T_total = NA * hs[0] + NB * hs[1]  # in units of T0
    if shape.objective is Objective.TIME:
        obj = T_total
    else:
        rows.add(T_total - dur, 0.0, 0.0)
        obj = (hs[0] * ca.sumsqr(js[:, :NA]) + hs[1] * ca.sumsqr(js[:, NA:])) / N
    z = ca.vertcat(ca.vec(xs), ca.vec(vs), ca.vec(as_), ca.vec(js), ca.vec(qv), hs)
    g, lbg, ubg = rows.stacked()
    return z, ca.vertcat(Vs, back, dur), obj, g, lbg, ubg


def _node_rows(rows, kin, dyn, site: CrossingSite, lim: dict, shape: Transcription, states, back, xi_dm) -> None:
    """Rows at every node: loop closure, modes, no Type 1 singularity, the limits (each over ``back``)."""
    Xe, Ve, Ae, Je, qv = states
    n, N, ks, m0 = kin.n, shape.NA + shape.NB, shape.NA, site.m0
    xsym, qsym, vsym, asym = kin.sx_x, kin.sx_q, ca.SX.sym("v", n), ca.SX.sym("a", n)
    jq_point = kin.jac_q_batch(site.point[None], site.q_point[None], site.xi)[0]
    jq_row = np.linalg.norm(jq_point, axis=1)
    fscale = ca.DM(np.where(jq_row > 0, jq_row, 1.0))
    jx, jq = kin.sx_jx, kin.sx_jq
    had_x = had_q = 1
    for i in range(n):
        had_x = had_x * ca.norm_2(jx[i, :])
        had_q = had_q * ca.norm_2(jq[i, :])
    qd_e, qdd_e = dyn.rates_fun(xsym, qsym, vsym, asym, xi_dm)
    node = [kin.sx_f / fscale, kin.robot.mode_sign * kin.sx_det / had_x, ca.det(jq) / had_q,
            qd_e / ca.DM(lim["qd_max"]), qdd_e / ca.DM(lim["qdd_max"])]
    node_f = ca.Function("node", [xsym, qsym, vsym, asym], [ca.substitute(r, kin.sx_xi, xi_dm) for r in node])
    F, MODE, DETQ, QD, QDD = node_f.map(N + 1)(Xe, qv, Ve, Ae)
    rows.add(F, 0.0, 0.0)
    rows.add(m0 * MODE[:, list(range(1, ks))], 0.0, np.inf)
    rows.add(-m0 * MODE[:, list(range(ks + 1, N))], 0.0, np.inf)
    rows.add(float(np.sign(np.linalg.det(jq_point))) * DETQ, 0.0, np.inf)
    rows.add(QD / back, -1.0, 1.0)
    rows.add(QDD / back, -1.0, 1.0)
    if lim["a_max"] is not None:
        rows.add(Ae / ca.repmat(ca.DM(lim["a_max"]), 1, N + 1) / back, -1.0, 1.0)
    if lim["jerk_max"] is not None:
        rows.add(Je / ca.repmat(ca.DM(lim["jerk_max"]), 1, N) / back, -1.0, 1.0)
    if shape.torque:
        tmax = ca.DM(dyn.model.tau_max)
        regular = [k for k in range(N + 1) if k != ks]
        tau_f = ca.Function("tau", [xsym, qsym, vsym, asym], [dyn.torque_fun(xsym, qsym, vsym, asym, xi_dm) / tmax])
        rows.add(tau_f.map(len(regular))(Xe[:, regular], qv[:, regular], Ve[:, regular], Ae[:, regular]) / back,
                 -1.0, 1.0)
        tau_s, _lam = dyn.singular_torque_fun(Xe[:, ks], qv[:, ks], Ve[:, ks], Ae[:, ks], Je[:, ks], xi_dm,
                                              ca.DM(site.t_dir))
        rows.add(tau_s / tmax / back, -1.0, 1.0)


class _Rows:
    """Constraint rows and their bounds, stacked in the order added."""

    def __init__(self):
        self._g, self._lb, self._ub = [], [], []

    def add(self, expr, lo: float, hi: float) -> None:
        expr = ca.vec(expr)
        self._g.append(expr)
        self._lb.append(np.full(expr.numel(), lo))
        self._ub.append(np.full(expr.numel(), hi))

    def stacked(self):
        return ca.vertcat(*self._g), np.concatenate(self._lb), np.concatenate(self._ub)


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
