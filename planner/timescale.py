"""Time scaling of a straight crossing path under kinematic limits (planning-time certification).

The end-effector follows the straight pose segment ``x(s) = p0 + s u``,
``s in [0, L]`` (m), ``u`` a unit vector, through a point of the Type 2
singular locus at ``s = s*``.  A time scaling ``s(t)`` is described on a grid
``s_0 = 0 < ... < s_N = L`` of step ``ds`` by

* ``b_i = sdot(s_i)^2`` (m^2/s^2), the squared path speed at the nodes, and
* ``a_i = sddot`` (m/s^2), constant on ``[s_i, s_{i+1}]``, so that
  ``b_{i+1} = b_i + 2 ds a_i`` exactly and ``s(t)`` is piecewise quadratic in
  time (the classic TOPP discretisation).

Every bound below is linear in ``(a, b)`` because, by the chain rule,

* ``qdot = q' sdot``            -> ``q'^2 b <= qd_max^2``,
* ``qddot = q' a + q'' b``      -> ``|q' a + q'' b| <= qdd_max``,
* ``xddot = x' a + x'' b``      -> ``|x' a + x'' b| <= a_max``,

with ``'`` the derivative with respect to ``s``.  The joint path derivatives
``q'``, ``q''`` are exact (eq. (2) of the paper and its derivative, through
:meth:`~robots.kinematics.KinematicModel.joint_velocity` and
:meth:`~robots.kinematics.KinematicModel.joint_acceleration`), never finite
differences; ``q'`` stays finite on the Type 2 locus since only ``J_q`` is
inverted.

Discretisation of the acceleration-level bounds: on interval ``i`` the path
acceleration ``a_i`` is applied with the data of *both* end nodes,
``A_i a_i + B_i b_i <= C_i`` and ``A_{i+1} a_i + B_{i+1} b_{i+1} <= C_{i+1}``
(toppra's "interpolation" scheme), so every node's bound holds for both
one-sided accelerations.  Between nodes the end-effector bound holds exactly
on a straight path (``x'' = 0``: ``xddot = u a_i`` is constant); joint bounds
hold up to the ``O(ds^2)`` curvature of ``q'(s)``, ``q''(s)``.

Two solvers answer two questions:

* :func:`time_optimal_scaling` (cvxpy, second-order cone program): the
  minimum-time scaling that crosses ``s*`` at a prescribed speed ``v_sing``
  while satisfying the crossing criterion of Section III-B of the paper;
* :func:`max_speed_at` (toppra, reachability analysis): the largest speed
  at ``s*`` of any admissible scaling, the upper end of a ``v_sing`` search.

Both use the same discretisation, so they agree up to solver tolerances.
:func:`resample` turns a scaling into the fixed-period joint trajectory that
the tracker and the simulator consume.  SI units throughout (m, rad, s).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import cvxpy as cp
import numpy as np
import scipy.sparse as sp
import toppra
from scipy.interpolate import BPoly
from toppra.constraint import (
    DiscretizationType,
    JointAccelerationConstraint,
    JointVelocityConstraint,
    LinearConstraint,
    canlinear_colloc_to_interpolate,
)

from robots.kinematics import KinematicModel
from .simulate import _vec  # one validator of numeric vectors for planner/
from robots.errors import InputError, SimulationError

__all__ = [
    "FEAS_RTOL",
    "PathSamples",
    "sample_path",
    "LinearPathConstraint",
    "ScalingLimits",
    "TimeScaling",
    "time_optimal_scaling",
    "max_speed_at",
    "TimedTrajectory",
    "resample",
]

#: Relative tolerance of the a-posteriori check of every bound on a solved
#: scaling: a row ``A a + B b <= C`` may exceed ``C`` by
#: ``FEAS_RTOL * (|A a| + |B b| + |C|)``.
FEAS_RTOL = 1e-6
#: A continuation step whose joints differ from the first-order prediction
#: ``q_k + q'_k ds`` by more than this (rad) is a jump to another leg branch.
_BRANCH_JUMP = 0.1
#: Clarabel settings, a little tighter than its defaults (1e-8): an error e in b
#: becomes e / (2 ds) in a = (b_{i+1} - b_i) / (2 ds), 5e3 e on a 0.1 mm grid.
#: 1e-10 and tighter often end "optimal_inaccurate" on 700-node paths (five-bar benchmark).
_CLARABEL_OPTS = dict(tol_gap_abs=1e-9, tol_gap_rel=1e-9, tol_feas=1e-9,
                      tol_infeas_abs=1e-10, tol_infeas_rel=1e-10, max_iter=400)
_SOLVED = ("optimal", "optimal_inaccurate")
_INFEASIBLE = ("infeasible", "infeasible_inaccurate")


# ------------------------------------------------------------------ path samples
@dataclass(frozen=True, eq=False)
class PathSamples:
    """A straight pose path and its joint path sampled on a uniform grid.

    ``N + 1`` nodes, ``n`` pose/joint coordinates; subscript ``_s`` denotes a
    derivative with respect to the path parameter ``s`` (m).  Arrays are
    read-only.

    Attributes
    ----------
    s : ndarray, shape (N+1,)
        Grid ``s_i = i L / N``, m.
    x, x_s, x_ss : ndarray, shape (N+1, n)
        Poses ``p0 + s u`` (m), ``x' = u`` (1), ``x'' = 0`` (1/m).
    q, q_s, q_ss : ndarray, shape (N+1, n)
        Joints (rad), ``q'`` (rad/m), ``q''`` (rad/m^2) from the kinematics.
    p0, u : ndarray, shape (n,)
        Start pose (m) and unit direction.
    length : float
        ``L``, m.
    xi : ndarray, shape (m,)
        Geometry used for the IK (the planner's view, usually nominal).
    kin : KinematicModel
        The model (used by :func:`resample` for exact IK between nodes and by
        the default crossing criterion).
    """

    s: np.ndarray
    x: np.ndarray
    x_s: np.ndarray
    x_ss: np.ndarray
    q: np.ndarray
    q_s: np.ndarray
    q_ss: np.ndarray
    p0: np.ndarray
    u: np.ndarray
    length: float
    xi: np.ndarray
    kin: KinematicModel = field(repr=False)

    def __post_init__(self) -> None:
        for name in ("s", "x", "x_s", "x_ss", "q", "q_s", "q_ss", "p0", "u", "xi"):
            getattr(self, name).setflags(write=False)

    @property
    def n_intervals(self) -> int:
        """Number of grid intervals ``N``."""
        return int(self.s.shape[0]) - 1

    @property
    def ds(self) -> float:
        """Grid step ``L / N``, m."""
        return self.length / self.n_intervals


def sample_path(kin: KinematicModel, p0, u, L: float, N: int, working_guess, xi=None) -> PathSamples:
    """Sample the straight path ``x(s) = p0 + s u``, ``s in [0, L]``, and its IK.

    The joints follow the working branch of the legs by continuation: Newton
    from ``working_guess`` at ``p0``, then from the first-order prediction
    ``q_k + q'_k ds`` at each next node.  ``q'`` and ``q''`` are exact (eq. (2)
    and its derivative with ``x' = u``, ``x'' = 0``).

    Parameters
    ----------
    kin : KinematicModel
    p0 : array_like, shape (n,)
        Start pose, m.
    u : array_like, shape (n,)
        Direction (normalised here, so ``s`` is the arc length in m).
    L : float
        Path length, m (> 0).
    N : int
        Number of grid intervals (>= 2); step ``ds = L / N``.  To impose the
        crossing at ``s*`` choose ``N`` so that ``s*`` is a node.
    working_guess : array_like, shape (n,)
        Joints on the working branch near ``p0``, rad.
    xi : array_like, shape (m,), optional
        Geometry, SI; default the robot's nominal parameters.

    Returns
    -------
    PathSamples

    Raises
    ------
    InputError
        Malformed arguments.
    SimulationError
        IK fails (unreachable pose, ``J_q`` singular), a pose leaves
        ``robot.x_bounds``, joints leave their limits, or the continuation
        jumps to another branch; the message gives the arc length.
    """
    if not isinstance(kin, KinematicModel):
        raise InputError(f"kin must be a KinematicModel, got {type(kin).__name__}")
    n, r = kin.n, kin.robot
    p0 = _vec("p0", p0, n)
    u = _vec("u", u, n)
    nu = float(np.linalg.norm(u))
    if nu == 0.0:
        raise InputError("u must be non-zero")
    u = u / nu
    L = _positive("L", L)
    if isinstance(N, bool) or not isinstance(N, (int, np.integer)) or N < 2:
        raise InputError(f"N must be an integer >= 2, got {N!r}")
    N = int(N)
    qg = _vec("working_guess", working_guess, n)
    xi = r.xi_nominal_array if xi is None else _vec("xi", xi, r.m)

    s = L * np.arange(N + 1) / N
    s[-1] = L
    ds = L / N
    X = p0 + s[:, None] * u
    XS = np.tile(u, (N + 1, 1))
    Q = np.empty((N + 1, n))
    QS = np.empty((N + 1, n))
    guess = qg
    for k in range(N + 1):
        Qk, ok = kin.ik_batch(X[k:k + 1], xi, guess[None, :])
        if not ok[0]:
            raise SimulationError(
                f"{r.name}: IK failed at s = {s[k] * 1e3:.4f} mm (x = {X[k].tolist()}): pose "
                "unreachable or J_q singular; shorten the path")
        if k > 0 and np.max(np.abs(Qk[0] - guess)) > _BRANCH_JUMP:
            raise SimulationError(
                f"{r.name}: IK continuation jumped to another branch at s = {s[k] * 1e3:.4f} mm; "
                "refine the grid (larger N)")
        Q[k] = Qk[0]
        QS[k] = kin.joint_velocity(X[k:k + 1], Q[k:k + 1], xi, XS[k:k + 1])[0]
        guess = Q[k] + ds * QS[k]  # tangent predictor keeps Newton on the branch
    inside = np.all((X >= r.x_lo_array) & (X <= r.x_hi_array), axis=1)
    in_lim = np.all((Q >= r.q_lo_array) & (Q <= r.q_hi_array), axis=1)
    bad = np.nonzero(~(inside & in_lim))[0]
    if bad.size:
        k = int(bad[0])
        what = "outside x_bounds" if not inside[k] else "beyond the joint limits"
        raise SimulationError(f"{r.name}: the path is {what} at s = {s[k] * 1e3:.4f} mm; shorten it")
    XSS = np.zeros_like(X)  # straight path
    QSS = kin.joint_acceleration(X, Q, xi, XS, QS, XSS)
    return PathSamples(s=s, x=X, x_s=XS, x_ss=XSS, q=Q, q_s=QS, q_ss=QSS, p0=p0, u=u,
                       length=L, xi=np.array(xi, dtype=float), kin=kin)


# ------------------------------------------------------------------ limits
@dataclass(frozen=True, eq=False)
class LinearPathConstraint:
    """Extra node-wise bound ``A_i a + B_i b_i <= C_i`` (e.g. torques of a dynamic model).

    Imposed at every node ``i`` for both one-sided path accelerations (of the
    intervals on either side), like the built-in acceleration bounds.

    Attributes
    ----------
    A : ndarray, shape (N+1, k)
        Coefficients of the path acceleration ``a`` (units of C per m/s^2).
    B : ndarray, shape (N+1, k)
        Coefficients of ``b = sdot^2`` (units of C per m^2/s^2).
    C : ndarray, shape (N+1, k)
        Bounds (any unit, e.g. N m).
    name : str
        Shown in error messages.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    name: str = "extra"

    def __post_init__(self) -> None:
        arrs = []
        for nm in ("A", "B", "C"):
            try:
                v = np.array(getattr(self, nm), dtype=float)
            except (TypeError, ValueError) as exc:
                raise InputError(f"LinearPathConstraint {self.name}: {nm} must be numeric") from exc
            if v.ndim == 1:
                v = v[:, None]
            if v.ndim != 2 or not np.all(np.isfinite(v)):
                raise InputError(f"LinearPathConstraint {self.name}: {nm} must be a finite (N+1, k) array")
            v.setflags(write=False)
            object.__setattr__(self, nm, v)
            arrs.append(v)
        if not arrs[0].shape == arrs[1].shape == arrs[2].shape:
            raise InputError(f"LinearPathConstraint {self.name}: A, B, C shapes differ: "
                             f"{[a.shape for a in arrs]}")


@dataclass(frozen=True, eq=False)
class ScalingLimits:
    """Kinematic limits of a time scaling; ``None`` leaves a quantity unbounded.

    Attributes
    ----------
    qd_max : float or array_like (n,), optional
        Componentwise joint speed bound ``|qdot| <= qd_max``, rad/s.
    qdd_max : float or array_like (n,), optional
        Componentwise joint acceleration bound, rad/s^2.
    a_max : float or array_like (n,), optional
        Componentwise end-effector acceleration bound ``|xddot| <= a_max``,
        m/s^2 (the tracker's ``[a_max]``).
    extra : tuple of LinearPathConstraint
        Further linear bounds on the same grid (e.g. actuator torques).
    """

    qd_max: object = None
    qdd_max: object = None
    a_max: object = None
    extra: tuple = ()

    def __post_init__(self) -> None:
        for nm in ("qd_max", "qdd_max", "a_max"):
            v = getattr(self, nm)
            if v is None:
                continue
            try:
                arr = np.array(v, dtype=float).reshape(-1)
            except (TypeError, ValueError) as exc:
                raise InputError(f"{nm} must be a number or a vector of numbers, got {v!r}") from exc
            if arr.size == 0 or not np.all(arr > 0) or np.any(np.isnan(arr)):
                raise InputError(f"{nm} must be positive, got {v!r}")
            arr.setflags(write=False)
            object.__setattr__(self, nm, arr)
        extra = tuple(self.extra)
        if not all(isinstance(e, LinearPathConstraint) for e in extra):
            raise InputError("extra must be a tuple of LinearPathConstraint")
        object.__setattr__(self, "extra", extra)


def _bound(v, n: int, name: str) -> np.ndarray | None:
    if v is None:
        return None
    if v.size == 1:
        return np.full(n, float(v[0]))
    if v.size != n:
        raise InputError(f"{name} must be a scalar or have {n} entries, got {v.size}")
    return np.asarray(v, dtype=float)


@dataclass(frozen=True)
class _Rows:
    """All bounds on the grid: ``b <= ub`` and normalised rows ``A a + B b <= C``."""

    ub: np.ndarray  # (N+1,), m^2/s^2, inf where unbounded
    A: np.ndarray  # (N+1, k)
    B: np.ndarray  # (N+1, k)
    C: np.ndarray  # (N+1, k)


def _rows(samples: PathSamples, limits: ScalingLimits) -> _Rows:
    n, N1 = samples.q.shape[1], samples.s.shape[0]
    qd = _bound(limits.qd_max, n, "qd_max")
    qdd = _bound(limits.qdd_max, n, "qdd_max")
    am = _bound(limits.a_max, n, "a_max")
    ub = np.full(N1, np.inf)
    if qd is not None:
        with np.errstate(divide="ignore"):
            ub = np.min((qd / np.abs(samples.q_s)) ** 2, axis=1)  # q'=0 gives inf
    As, Bs, Cs = [], [], []
    # Rows are divided by their bound so all are O(1) for the solver.
    for lim, d1, d2 in ((qdd, samples.q_s, samples.q_ss), (am, samples.x_s, samples.x_ss)):
        if lim is None:
            continue
        keep = np.any(d1 != 0, axis=0) | np.any(d2 != 0, axis=0)  # drop 0 <= lim rows
        for sgn in (1.0, -1.0):
            As.append(sgn * d1[:, keep] / lim[keep])
            Bs.append(sgn * d2[:, keep] / lim[keep])
            Cs.append(np.ones((N1, int(keep.sum()))))
    for e in limits.extra:
        if e.A.shape[0] != N1:
            raise InputError(f"LinearPathConstraint {e.name} has {e.A.shape[0]} nodes, the path {N1}")
        scale = np.maximum(np.maximum(np.abs(e.A), np.abs(e.B)), np.abs(e.C))
        scale[scale == 0.0] = 1.0
        As.append(e.A / scale)
        Bs.append(e.B / scale)
        Cs.append(e.C / scale)
    if As:
        A, B, C = np.hstack(As), np.hstack(Bs), np.hstack(Cs)
    else:
        A = B = C = np.zeros((N1, 0))
    return _Rows(ub=ub, A=A, B=B, C=C)


def _row_matrix(rows: _Rows, ds: float) -> tuple[sp.csr_matrix, np.ndarray]:
    """``G b <= h`` for both ends of every interval, with ``a_i = (b_{i+1} - b_i) / (2 ds)``."""
    N1, k = rows.A.shape
    N = N1 - 1
    i = np.arange(N)
    rows_i = np.concatenate([i, i])
    cols = np.concatenate([i, i + 1])  # b_i, b_{i+1}
    blocks, rhs = [], []
    for j in range(k):
        for m, right in ((i, False), (i + 1, True)):  # node of the bound: left or right end
            # A_m (b_{i+1} - b_i) / (2 ds) + B_m b_m <= C_m
            Am, Bm = rows.A[m, j] / (2.0 * ds), rows.B[m, j]
            coef_i = -Am + (0.0 if right else Bm)
            coef_i1 = Am + (Bm if right else 0.0)
            blocks.append(sp.csr_matrix((np.concatenate([coef_i, coef_i1]), (rows_i, cols)),
                                        shape=(N, N1)))
            rhs.append(rows.C[m, j])
    if not blocks:
        return sp.csr_matrix((0, N1)), np.zeros(0)
    return sp.vstack(blocks).tocsr(), np.concatenate(rhs)


# ------------------------------------------------------------------ crossing data
def _node_index(samples: PathSamples, s_star, *, exact: bool) -> int:
    s_star = _finite("s_star", s_star)
    ds = samples.ds
    k = int(round(s_star / ds))
    if not 0 <= k <= samples.n_intervals:
        raise InputError(f"s_star = {s_star} m lies outside the path [0, {samples.length}] m")
    if exact and abs(samples.s[k] - s_star) > 1e-6 * ds:
        raise InputError(
            f"s_star = {s_star} m is not a grid node (nearest {samples.s[k]} m, step {ds} m); "
            "choose L and N so that s_star = k L / N")
    return k


def _criterion_dir(samples: PathSamples, k: int, direction) -> np.ndarray:
    """Criterion direction at node k: given, or the kernel of J_x (uncontrolled motion)."""
    n = samples.x.shape[1]
    if direction is not None:
        c = _vec("criterion_direction", direction, n)
        if not np.any(c):
            raise InputError("criterion_direction must be non-zero")
        return c / np.linalg.norm(c)
    jx = samples.kin.jac_x_batch(samples.x[k:k + 1], samples.q[k:k + 1], samples.xi)[0]
    return np.linalg.svd(jx)[2][-1]  # right singular vector of the smallest singular value


def _criterion_coeffs(samples: PathSamples, k: int, c: np.ndarray) -> tuple[float, float]:
    """``(c.x', c.x'')`` at node k: the criterion reads ``cx a + cxx b = 0``."""
    cx = float(c @ samples.x_s[k])
    cxx = float(c @ samples.x_ss[k])
    if abs(cx) <= 1e-9 * np.linalg.norm(samples.x_s[k]):
        raise InputError(
            "the criterion direction is normal to the path at s_star: c.xddot = 0 does not "
            "involve the path acceleration there (the path does not cross along it)")
    return cx, cxx


# ------------------------------------------------------------------ cvxpy scaling
@dataclass(frozen=True)
class TimeScaling:
    """A solved time scaling on the grid of a :class:`PathSamples`.

    Attributes
    ----------
    s : ndarray, shape (N+1,)
        Grid, m.
    b : ndarray, shape (N+1,)
        ``sdot^2`` at the nodes, m^2/s^2.
    a : ndarray, shape (N,)
        ``sddot`` on each interval, m/s^2; ``b_{i+1} = b_i + 2 ds a_i`` holds
        to rounding.
    sd : ndarray, shape (N+1,)
        ``sdot = sqrt(b)``, m/s.
    t : ndarray, shape (N+1,)
        Time at each node, s (``t[0] = 0``).
    total_time : float
        ``t[-1]``, s; within about 1e-6 (relative) of the optimum of the
        discrete problem (interior-point tolerance; TOPP-RA on the same grid
        agrees to that level).
    status : str
        cvxpy status (``"optimal"`` or ``"optimal_inaccurate"``; the solution
        passed the a-posteriori check of every bound either way).
    solver : str
    solve_time : float
        Wall-clock time of building and solving the problem, s.
    v_sing : float or None
        Prescribed speed at ``s_star``, m/s.
    s_star : float or None
        Crossing node, m.
    k_star : int or None
        Its index.
    criterion_direction : ndarray (n,) or None
        Unit vector ``c`` of the criterion ``c . xddot = 0`` at ``s_star``.
    criterion_residual : float
        ``max |c . (x' a + x'' b)|`` over both one-sided accelerations at
        ``s_star``, m/s^2 (0 when no criterion).
    max_violation : float
        Largest violation of a bound after polishing, relative to the bound
        (<= ``FEAS_RTOL``).
    """

    s: np.ndarray
    b: np.ndarray
    a: np.ndarray
    sd: np.ndarray
    t: np.ndarray
    total_time: float
    status: str
    solver: str
    solve_time: float
    v_sing: float | None
    s_star: float | None
    k_star: int | None
    criterion_direction: np.ndarray | None
    criterion_residual: float
    max_violation: float

    def __post_init__(self) -> None:
        for name in ("s", "b", "a", "sd", "t"):
            getattr(self, name).setflags(write=False)


def _problem(samples, rows, *, k_star, v_sing, crit, rest_to_rest, objective):
    """Build the cvxpy problem; ``objective`` is ``"time"`` (SOCP) or ``"speed"`` (LP, max b_k*)."""
    N, ds = samples.n_intervals, samples.ds
    b = cp.Variable(N + 1, nonneg=True, name="b")
    cons = []
    fin = np.isfinite(rows.ub)
    if fin.any():
        cons.append(b[fin] <= rows.ub[fin])
    G, h = _row_matrix(rows, ds)
    if G.shape[0]:
        cons.append(G @ b <= h)
    if rest_to_rest:
        cons += [b[0] == 0.0, b[N] == 0.0]
    if v_sing is not None:
        cons.append(b[k_star] == v_sing**2)
    if crit is not None:
        cx, cxx = crit
        # c.(x' a + x'' b_k*) = 0 for the accelerations of both adjacent intervals.
        if k_star < N:
            cons.append(cx * (b[k_star + 1] - b[k_star]) / (2.0 * ds) + cxx * b[k_star] == 0.0)
        if k_star > 0:
            cons.append(cx * (b[k_star] - b[k_star - 1]) / (2.0 * ds) + cxx * b[k_star] == 0.0)
    if objective == "speed":
        return cp.Problem(cp.Maximize(b[k_star]), cons), b
    # T = sum 2 ds / (sqrt b_i + sqrt b_{i+1}) is convex in b but not DCP as
    # written; with c_i <= sqrt(b_i) (hypograph of the concave sqrt) and
    # tau_i >= 2 / (c_i + c_{i+1}) (epigraph of a convex decreasing function)
    # minimising ds sum tau is equivalent, both sets being second-order cones:
    #   c^2 <= b          <=>  ||(2c, b - 1)||          <= b + 1,
    #   tau w >= 2, w >= 0 <=>  ||(2 sqrt 2, tau - w)||  <= tau + w.
    c = cp.Variable(N + 1, nonneg=True, name="c")
    tau = cp.Variable(N, nonneg=True, name="tau")  # interval time / ds, s/m
    w = c[:-1] + c[1:]
    cons.append(cp.SOC(b + 1.0, cp.vstack([2.0 * c, b - 1.0]), axis=0))
    cons.append(cp.SOC(tau + w, cp.vstack([np.full(N, 2.0 * math.sqrt(2.0)), tau - w]), axis=0))
    return cp.Problem(cp.Minimize(cp.sum(tau)), cons), b


def _solve(prob: cp.Problem, solver: str) -> None:
    opts = _CLARABEL_OPTS if solver.upper() == "CLARABEL" else {}
    try:
        with warnings.catch_warnings():
            # "optimal_inaccurate" is reported in the status and re-checked by the caller.
            warnings.simplefilter("ignore", UserWarning)
            prob.solve(solver=solver, **opts)
    except cp.error.SolverError as exc:
        raise SimulationError(f"time scaling: solver {solver} failed: {exc}") from exc


def _max_speed_lp(samples, rows, *, k_star, crit, rest_to_rest, solver) -> float:
    """Largest sqrt(b_k*) of the same discretisation (LP), m/s; NaN if none."""
    prob, b = _problem(samples, rows, k_star=k_star, v_sing=None, crit=crit,
                       rest_to_rest=rest_to_rest, objective="speed")
    _solve(prob, solver)
    if prob.status not in _SOLVED:
        return math.nan
    return math.sqrt(max(float(b.value[k_star]), 0.0))


def _polish(b_sol, rows, ds, *, k_star, v_sing, crit, rest_to_rest) -> np.ndarray:
    """Make the equality constraints hold exactly (solvers meet them to ~1e-10)."""
    b = np.maximum(np.asarray(b_sol, dtype=float), 0.0)
    b = np.minimum(b, rows.ub)
    N = b.size - 1
    if rest_to_rest:
        b[0] = b[N] = 0.0
    if v_sing is not None:
        b[k_star] = v_sing**2
    if crit is not None:
        cx, cxx = crit
        a_c = -cxx * b[k_star] / cx  # the one path acceleration meeting the criterion
        if k_star < N:
            b[k_star + 1] = b[k_star] + 2.0 * ds * a_c
        if k_star > 0:
            b[k_star - 1] = b[k_star] - 2.0 * ds * a_c
    return b


def _violation(b, rows, ds) -> float:
    """Largest relative violation of any bound by ``b`` (0 if all hold)."""
    worst = 0.0
    fin = np.isfinite(rows.ub)
    if fin.any():
        worst = max(worst, float(np.max((b[fin] - rows.ub[fin]) / np.maximum(rows.ub[fin], 1e-300))))
    worst = max(worst, float(np.max(-b)) / max(float(np.max(b)), 1e-300))
    if rows.A.shape[1]:
        a = np.diff(b) / (2.0 * ds)
        for node, bb in ((slice(0, -1), b[:-1]), (slice(1, None), b[1:])):
            la = rows.A[node] * a[:, None]
            lb = rows.B[node] * bb[:, None]
            C = rows.C[node]
            scale = np.abs(la) + np.abs(lb) + np.abs(C)
            scale[scale == 0.0] = 1.0
            worst = max(worst, float(np.max((la + lb - C) / scale)))
    return max(worst, 0.0)


def time_optimal_scaling(samples: PathSamples, limits: ScalingLimits, v_sing: float | None = None,
                         s_star: float | None = None, rest_to_rest: bool = True, *,
                         criterion: bool = True, criterion_direction=None,
                         solver: str = "CLARABEL") -> TimeScaling:
    """Minimum-time scaling of a path under the limits, crossing ``s_star`` at ``v_sing``.

    Solves, over ``b_i = sdot^2(s_i) >= 0`` and ``a_i = (b_{i+1} - b_i) / (2 ds)``
    (so the TOPP relation ``b_{i+1} = b_i + 2 ds a_i`` holds by construction),

        minimise ``T = sum_i 2 ds / (sqrt(b_i) + sqrt(b_{i+1}))``

    subject to the bounds of ``limits`` (see the module docstring) and

    * rest to rest: ``b_0 = b_N = 0``;
    * crossing speed: ``b_k* = v_sing^2`` at the node ``s_k* = s_star``;
    * crossing criterion (Section III-B of the paper, ref. [11] there, Briot
      and Arakelian 2008): on
      the Type 2 locus the inverse dynamic model stays consistent only if the
      end-effector acceleration is normal to the direction ``c`` of the
      uncontrolled motion, ``c . xddot = c . (x' a + x'' b) = 0`` at ``s*``,
      imposed for the accelerations of both adjacent intervals.  ``c`` is by
      default the kernel of ``J_x`` at ``s*`` (the motion the locked actuators
      do not control).  For a straight path crossing along that direction
      (``x' = u = +-c``, ``x'' = 0``) it reads ``sddot = 0``: constant speed
      ``v_sing`` over ``[s* - ds, s* + ds]``.

    The objective is made a second-order cone program with epigraph
    variables ``c_i <= sqrt(b_i)`` and ``tau_i >= 2 / (c_i + c_{i+1})`` (both
    second-order cones; at the optimum they are tight), ``T = ds sum tau``.
    The solution is then polished so the equalities hold exactly (``v_sing``,
    rest, criterion) and re-checked against every bound with relative
    tolerance :data:`FEAS_RTOL`; times are recomputed from the polished ``b``.

    Parameters
    ----------
    samples : PathSamples
    limits : ScalingLimits
    v_sing : float, optional
        Speed at ``s_star``, m/s (> 0).  ``None``: free.
    s_star : float, optional
        Crossing arc length, m; must be a grid node (``k L / N``).  Required
        with ``v_sing`` or ``criterion``.
    rest_to_rest : bool
        ``b_0 = b_N = 0``; otherwise the end speeds are free.
    criterion : bool
        Impose the crossing criterion at ``s_star`` (when given).
    criterion_direction : array_like (n,), optional
        ``c`` of the criterion; default the kernel of ``J_x`` at ``s_star``.
    solver : str
        cvxpy conic solver (default Clarabel, with tightened tolerances).

    Returns
    -------
    TimeScaling

    Raises
    ------
    InputError
        Malformed arguments; ``s_star`` not a node; ``v_sing <= 0``; a
        criterion direction normal to the path.
    SimulationError
        No scaling meets the limits at ``v_sing``: the message gives the
        largest feasible speed at ``s*`` (same discretisation, by an LP);
        solver failure; a solution that fails the a-posteriori check.
    """
    if not isinstance(samples, PathSamples):
        raise InputError(f"samples must be PathSamples, got {type(samples).__name__}")
    if not isinstance(limits, ScalingLimits):
        raise InputError(f"limits must be ScalingLimits, got {type(limits).__name__}")
    if v_sing is not None:
        v_sing = _positive("v_sing", v_sing)
        if s_star is None:
            raise InputError("v_sing needs s_star (the crossing arc length)")
    k_star = None if s_star is None else _node_index(samples, s_star, exact=True)
    cdir = crit = None
    if k_star is not None and criterion:
        cdir = _criterion_dir(samples, k_star, criterion_direction)
        crit = _criterion_coeffs(samples, k_star, cdir)
    N, ds = samples.n_intervals, samples.ds
    if rest_to_rest and v_sing is not None and k_star in (0, N):
        raise InputError("s_star must be an interior node for a rest-to-rest crossing at v_sing > 0")
    rows = _rows(samples, limits)
    kw = dict(k_star=k_star, crit=crit, rest_to_rest=rest_to_rest)

    t0 = time.perf_counter()
    prob, bvar = _problem(samples, rows, v_sing=v_sing, objective="time", **kw)
    _solve(prob, solver)
    solve_time = time.perf_counter() - t0
    if prob.status in _INFEASIBLE:
        if k_star is None:
            raise SimulationError("time scaling: no scaling meets the limits (even at rest)")
        vmax = _max_speed_lp(samples, rows, solver=solver, **kw)
        at = f"{vmax:.6g} m/s" if math.isfinite(vmax) else "undefined: no admissible scaling at all"
        raise SimulationError(
            f"no feasible crossing at v_sing = {v_sing:.6g} m/s under the limits (max feasible "
            f"speed at s* = {samples.s[k_star]:.6g} m is {at})")
    if prob.status not in _SOLVED or bvar.value is None:
        raise SimulationError(f"time scaling: solver {solver} ended with status {prob.status!r}")

    b = _polish(bvar.value, rows, ds, v_sing=v_sing, **kw)
    viol = _violation(b, rows, ds)
    if viol > FEAS_RTOL:
        raise SimulationError(
            f"time scaling: the {prob.status} solution violates a bound by {viol:.3g} (relative) "
            f"after polishing; the problem is badly scaled or at the edge of feasibility")
    sd = np.sqrt(b)
    den = sd[:-1] + sd[1:]
    if np.any(den <= 0.0):
        raise SimulationError("time scaling: the path stops inside (b = 0 on a whole interval)")
    t = np.concatenate([[0.0], np.cumsum(2.0 * ds / den)])
    a = np.diff(b) / (2.0 * ds)
    res = 0.0
    if crit is not None:
        cx, cxx = crit
        adj = [a[j] for j in (k_star - 1, k_star) if 0 <= j < N]
        res = max(abs(cx * aj + cxx * b[k_star]) for aj in adj)
    return TimeScaling(
        s=np.array(samples.s), b=b, a=a, sd=sd, t=t, total_time=float(t[-1]), status=prob.status,
        solver=solver, solve_time=solve_time, v_sing=v_sing,
        s_star=None if k_star is None else float(samples.s[k_star]), k_star=k_star,
        criterion_direction=cdir, criterion_residual=float(res), max_violation=viol,
    )


# ------------------------------------------------------------------ toppra
class _HermitePath(toppra.interpolator.AbstractGeometricPath):
    """C^2 joint path through exact ``(q, q', q'')`` at the nodes (quintic Hermite).

    toppra evaluates the path only at the grid nodes here, so its constraint
    coefficients are the exact kinematic derivatives, as in the cvxpy problem
    (a cubic spline through ``q`` alone would differ by its interpolation error).
    """

    def __init__(self, s: np.ndarray, q: np.ndarray, q_s: np.ndarray, q_ss: np.ndarray):
        self._s = s
        self._polys = [BPoly.from_derivatives(s, np.stack([q[:, j], q_s[:, j], q_ss[:, j]], axis=1))
                       for j in range(q.shape[1])]
        self._d = [[p, p.derivative(1), p.derivative(2)] for p in self._polys]

    def __call__(self, path_positions, order=0):
        if order not in (0, 1, 2):
            raise ValueError(f"order must be 0, 1 or 2, got {order}")
        return np.stack([d[order](path_positions) for d in self._d], axis=-1)

    @property
    def dof(self) -> int:
        return len(self._polys)

    @property
    def path_interval(self):
        return np.array([self._s[0], self._s[-1]])


class _GridConstraint(LinearConstraint):
    """toppra canonical linear constraint ``F (a_i u + b_i x + c_i) <= g`` from node arrays."""

    def __init__(self, s, a, b, c, F, g, *, interpolate: bool):
        super().__init__()
        self._s, self._a, self._b, self._c, self._F, self._g = s, a, b, c, F, g
        self.identical = F.ndim == 2
        self.dof = -1  # path-independent: the data are given on the grid
        self.set_discretization_type(DiscretizationType.Interpolation if interpolate
                                     else DiscretizationType.Collocation)

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
        if gridpoints.shape != self._s.shape or np.any(gridpoints != self._s):
            raise ValueError("this constraint is defined on the samples' grid only")
        if self.discretization_type == DiscretizationType.Collocation:
            return self._a, self._b, self._c, self._F, self._g, None, None
        return canlinear_colloc_to_interpolate(self._a, self._b, self._c, self._F, self._g, None,
                                               None, gridpoints, identical=self.identical)


def max_speed_at(samples: PathSamples, limits: ScalingLimits, s_star: float, *,
                 rest_to_rest: bool = True, criterion: bool = True,
                 criterion_direction=None) -> float:
    """Largest speed at ``s_star`` of any admissible scaling (toppra reachability), m/s.

    toppra's controllable sets ``K_i`` (states from which the end can be
    reached within the limits) and reachable sets ``L_i`` (states reachable
    from the start) are computed on the samples' grid; the speeds at node
    ``i`` lying on a complete admissible scaling are exactly ``K_i ∩ L_i``,
    so the answer is ``sqrt(min(max K_k, max L_k))`` at the node ``k`` nearest
    ``s_star``.  Constraints: :class:`toppra.constraint.JointVelocityConstraint`,
    :class:`toppra.constraint.JointAccelerationConstraint` on a joint path
    with the exact derivatives at the nodes, and canonical linear constraints
    (interpolation scheme, like :func:`time_optimal_scaling`) for the
    end-effector acceleration and ``limits.extra``; the crossing criterion at
    ``s*`` (see :func:`time_optimal_scaling`) as an equality on the two
    adjacent stages.  This is the upper end of a ``v_sing`` search.

    Parameters
    ----------
    samples : PathSamples
    limits : ScalingLimits
    s_star : float
        Arc length of the crossing, m (the nearest node is used).
    rest_to_rest : bool
        Start and end at rest; otherwise the end speeds are free.
    criterion : bool
        Impose the crossing criterion at the node.
    criterion_direction : array_like (n,), optional
        As in :func:`time_optimal_scaling`.

    Returns
    -------
    float
        m/s.

    Raises
    ------
    InputError
        Malformed arguments.
    SimulationError
        No admissible scaling reaches the node (toppra's sets are empty).
    """
    if not isinstance(samples, PathSamples):
        raise InputError(f"samples must be PathSamples, got {type(samples).__name__}")
    if not isinstance(limits, ScalingLimits):
        raise InputError(f"limits must be ScalingLimits, got {type(limits).__name__}")
    k = _node_index(samples, s_star, exact=False)
    n, N, ds, s = samples.q.shape[1], samples.n_intervals, samples.ds, samples.s
    path = _HermitePath(s, samples.q, samples.q_s, samples.q_ss)
    cons = []
    qd = _bound(limits.qd_max, n, "qd_max")
    qdd = _bound(limits.qdd_max, n, "qdd_max")
    am = _bound(limits.a_max, n, "a_max")
    if qd is not None:
        cons.append(JointVelocityConstraint(qd))
    if qdd is not None:
        cons.append(JointAccelerationConstraint(qdd))
    if am is not None:
        F = np.vstack([np.eye(n), -np.eye(n)])
        cons.append(_GridConstraint(s, samples.x_s, samples.x_ss, np.zeros((N + 1, n)), F,
                                    np.concatenate([am, am]), interpolate=True))
    for e in limits.extra:
        if e.A.shape[0] != N + 1:
            raise InputError(f"LinearPathConstraint {e.name} has {e.A.shape[0]} nodes, the path {N + 1}")
        kk = e.A.shape[1]
        F = np.broadcast_to(np.eye(kk), (N + 1, kk, kk)).copy()
        cons.append(_GridConstraint(s, e.A, e.B, np.zeros_like(e.A), F, np.array(e.C), interpolate=True))
    if criterion:
        cx, cxx = _criterion_coeffs(samples, k, _criterion_dir(samples, k, criterion_direction))
        ca_, cb_ = np.zeros((N + 1, 1)), np.zeros((N + 1, 1))
        if k < N:  # stage k: cx u_k + cxx x_k = 0
            ca_[k, 0], cb_[k, 0] = cx, cxx
        if k > 0:  # stage k-1, written on x_k = x_{k-1} + 2 ds u_{k-1}
            ca_[k - 1, 0], cb_[k - 1, 0] = cx + 2.0 * ds * cxx, cxx
        cons.append(_GridConstraint(s, ca_, cb_, np.zeros((N + 1, 1)), np.array([[1.0], [-1.0]]),
                                    np.zeros(2), interpolate=False))
    if not cons:
        raise InputError("max_speed_at needs at least one limit")
    algo = toppra.algorithm.TOPPRA(cons, path, gridpoints=np.array(s), solver_wrapper="seidel")
    if rest_to_rest:
        K = algo.compute_controllable_sets(0.0, 0.0)
        Lr = algo.compute_reachable_sets(0.0, 0.0)
    else:
        X = algo.compute_feasible_sets()
        K = algo.compute_controllable_sets(0.0, math.sqrt(max(X[N, 1], 0.0)))
        Lr = algo.compute_reachable_sets(0.0, math.sqrt(max(X[0, 1], 0.0)))
    top = min(K[k, 1], Lr[k, 1])
    if not (np.isfinite(top) and K[k, 0] <= K[k, 1] and Lr[k, 0] <= Lr[k, 1]):
        raise SimulationError(
            f"no admissible scaling of the path reaches s* = {s[k]:.6g} m under the limits")
    return math.sqrt(max(float(top), 0.0))


# ------------------------------------------------------------------ resampling
@dataclass(frozen=True)
class TimedTrajectory:
    """A time scaling sampled at a fixed period: what the tracker and simulator consume.

    ``K`` samples at ``t_k = k t_s``; arrays are read-only.

    Attributes
    ----------
    t : ndarray, shape (K,)
        s.
    s, sd, sdd : ndarray, shape (K,)
        Arc length (m), speed (m/s), path acceleration (m/s^2; the value of
        the interval the sample starts, right-continuous).
    x, xd, xdd : ndarray, shape (K, n)
        Pose (m), velocity (m/s), acceleration (m/s^2).
    q, qd, qdd : ndarray, shape (K, n)
        Joints (rad, exact IK on the samples' geometry and branch), joint
        velocities (rad/s) and accelerations (rad/s^2) from eq. (2).
    t_s : float
        Period, s.
    t_start : float
        Time at which the motion leaves ``s = 0``, s (after the initial rest;
        negative when the scaling does not start at rest and the first sample
        lies inside the motion).
    k_star : int or None
        Sample at the crossing node (``t[k_star]`` is exactly the crossing
        instant), if the scaling has one.
    """

    t: np.ndarray
    s: np.ndarray
    sd: np.ndarray
    sdd: np.ndarray
    x: np.ndarray
    xd: np.ndarray
    xdd: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    t_s: float
    t_start: float
    k_star: int | None

    def __post_init__(self) -> None:
        for name in ("t", "s", "sd", "sdd", "x", "xd", "xdd", "q", "qd", "qdd"):
            getattr(self, name).setflags(write=False)


def resample(scaling: TimeScaling, samples: PathSamples, t_s: float, *, t_rest: float = 0.0,
             t_rest_end: float = 0.0) -> TimedTrajectory:
    """Sample a time scaling at a fixed period, exactly within its model.

    On interval ``i`` the path acceleration ``a_i`` is constant, so with
    ``tau = t - t_i``: ``s = s_i + sd_i tau + a_i tau^2 / 2`` and
    ``sdot = sd_i + a_i tau`` (piecewise quadratic ``s(t)``).  Then
    ``x = p0 + s u``, ``xdot = u sdot``, ``xddot = u sddot`` (straight path),
    ``q`` by Newton IK started from the quintic Hermite interpolation of the
    samples (so on their branch), ``qdot``, ``qddot`` from eq. (2).

    The clock is shifted (the initial rest lengthened by less than ``t_s``)
    so that the crossing instant is a sample time ``t[k_star]``; then ``s``
    and ``sdot`` there are exactly ``s*`` and ``v_sing``.  A resting end is
    held for at least ``t_rest`` (``t_rest_end``); a moving end (scaling not
    rest to rest) is cut at the last sample inside the motion.

    Parameters
    ----------
    scaling : TimeScaling
    samples : PathSamples
        The path the scaling was computed on.
    t_s : float
        Sampling period, s.
    t_rest, t_rest_end : float
        Minimum rest before and after the motion, s (only at ends at rest).

    Returns
    -------
    TimedTrajectory

    Raises
    ------
    InputError
        Mismatched grid, bad period, rest around a scaling that does not
        start or end at rest.
    SimulationError
        IK fails at a sample.
    """
    if not isinstance(scaling, TimeScaling) or not isinstance(samples, PathSamples):
        raise InputError("resample needs a TimeScaling and the PathSamples it was computed on")
    if scaling.s.shape != samples.s.shape or np.any(scaling.s != samples.s):
        raise InputError("the scaling was computed on another grid than these samples")
    t_s = _positive("t_s", t_s)
    t_rest = _nonneg("t_rest", t_rest)
    t_rest_end = _nonneg("t_rest_end", t_rest_end)
    if (t_rest > 0 and scaling.b[0] != 0.0) or (t_rest_end > 0 and scaling.b[-1] != 0.0):
        raise InputError("t_rest/t_rest_end need a scaling that starts/ends at rest")
    T = scaling.total_time
    t_anchor = 0.0 if scaling.k_star is None else float(scaling.t[scaling.k_star])
    # Motion time tau_j = t_anchor + j t_s.  At a resting end, samples cover at
    # least the requested rest (held state); at a moving end none lies outside [0, T].
    lo, hi = (t_anchor + t_rest) / t_s, (T + t_rest_end - t_anchor) / t_s
    j_lo = -(math.ceil(lo - 1e-9) if scaling.b[0] == 0.0 else math.floor(lo + 1e-9))
    j_hi = math.ceil(hi - 1e-9) if scaling.b[-1] == 0.0 else math.floor(hi + 1e-9)
    j = np.arange(j_lo, j_hi + 1)
    tau = t_anchor + j * t_s
    s, sd, sdd = _evaluate(scaling, tau)
    n = samples.x.shape[1]
    X = samples.p0 + s[:, None] * samples.u
    XD = sd[:, None] * samples.u
    XDD = sdd[:, None] * samples.u
    if scaling.k_star is not None:  # the crossing sample lies exactly on the node
        X[-j_lo] = samples.x[scaling.k_star]
    path = _HermitePath(samples.s, samples.q, samples.q_s, samples.q_ss)
    kin = samples.kin
    Qg = path(np.clip(s, 0.0, samples.length), 0).reshape(-1, n)
    Q, ok = kin.ik_batch(X, samples.xi, Qg)
    if not ok.all():
        bad = int(np.nonzero(~ok)[0][0])
        raise SimulationError(f"resample: IK failed at s = {s[bad] * 1e3:.4f} mm")
    if np.max(np.abs(Q - Qg)) > _BRANCH_JUMP:
        raise SimulationError("resample: IK left the samples' branch (grid too coarse?)")
    QD = kin.joint_velocity(X, Q, samples.xi, XD)
    QDD = kin.joint_acceleration(X, Q, samples.xi, XD, QD, XDD)
    return TimedTrajectory(
        t=(j - j_lo) * t_s, s=s, sd=sd, sdd=sdd, x=X, xd=XD, xdd=XDD, q=Q, qd=QD, qdd=QDD,
        t_s=t_s, t_start=float(-(t_anchor + j_lo * t_s)),
        k_star=None if scaling.k_star is None else int(-j_lo),
    )


def _evaluate(scaling: TimeScaling, tau: np.ndarray):
    """``s, sdot, sddot`` at motion times ``tau`` (s); held at the ends outside ``[0, T]``."""
    t, s, sd, a = scaling.t, scaling.s, scaling.sd, scaling.a
    N = a.size
    i = np.clip(np.searchsorted(t, tau, side="right") - 1, 0, N - 1)
    dt = np.clip(tau - t[i], 0.0, t[i + 1] - t[i])
    out_s = s[i] + sd[i] * dt + 0.5 * a[i] * dt**2
    out_sd = sd[i] + a[i] * dt
    out_sdd = a[i].copy()
    before, after = tau < 0.0, tau > t[-1]
    out_sdd[before | after] = 0.0
    out_s[after], out_sd[after] = s[-1], sd[-1]
    # Exactly at nodes (e.g. the crossing instant) keep the node values.
    at = dt == 0.0
    out_s[at], out_sd[at] = s[i[at]], sd[i[at]]
    return np.minimum(out_s, s[-1]), np.maximum(out_sd, 0.0), out_sdd


# ------------------------------------------------------------------ checks


def _finite(name: str, v) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a number, got {v!r}") from exc
    if not math.isfinite(f):
        raise InputError(f"{name} must be finite, got {v!r}")
    return f


def _positive(name: str, v) -> float:
    f = _finite(name, v)
    if f <= 0.0:
        raise InputError(f"{name} must be > 0, got {v!r}")
    return f


def _nonneg(name: str, v) -> float:
    f = _finite(name, v)
    if f < 0.0:
        raise InputError(f"{name} must be >= 0, got {v!r}")
    return f
