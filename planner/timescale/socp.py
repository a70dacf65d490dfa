"""Minimum-time scaling as a cvxpy second-order cone program, polished and re-checked.

:func:`time_optimal_scaling` minimises ``T = sum_i 2 ds / (sqrt b_i + sqrt b_{i+1})``
under the rows of :mod:`planner.timescale.limits`, the crossing speed and the
crossing criterion; when that is infeasible an LP on the same grid gives the
largest feasible speed at the crossing for the message.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError, SimulationError

from .limits import PathRows, ScalingLimits, interval_matrix, path_rows
from .path import PathSamples, criterion_coeffs, crossing_direction, node_index

__all__ = ["FEAS_RTOL", "TimeScaling", "time_optimal_scaling"]

#: Relative tolerance of the a-posteriori check of every bound on a solved
#: scaling: a row ``A a + B b <= C`` may exceed ``C`` by
#: ``FEAS_RTOL * (|A a| + |B b| + |C|)``.
FEAS_RTOL = 1e-6
#: Clarabel settings, a little tighter than its defaults (1e-8): an error e in b
#: becomes e / (2 ds) in a = (b_{i+1} - b_i) / (2 ds), 5e3 e on a 0.1 mm grid.
#: 1e-10 and tighter often end "optimal_inaccurate" on 700-node paths (five-bar benchmark).
CLARABEL_OPTS = {"tol_gap_abs": 1e-9, "tol_gap_rel": 1e-9, "tol_feas": 1e-9,
                 "tol_infeas_abs": 1e-10, "tol_infeas_rel": 1e-10, "max_iter": 400}
#: cvxpy statuses with a usable solution (an inaccurate one is re-checked against every bound).
SOLVED = ("optimal", "optimal_inaccurate")
#: cvxpy statuses that mean no scaling meets the constraints.
INFEASIBLE = ("infeasible", "infeasible_inaccurate")
#: Floor of the denominators of relative violations: a zero bound or an all-zero
#: ``b`` gives a huge ratio instead of a division by zero.
TINY = 1e-300


@dataclass(frozen=True, eq=False)
class TimeScaling:
    """A solved time scaling on the grid of a :class:`~planner.timescale.PathSamples`.

    Attributes
    ----------
    s : ndarray, shape (N + 1,)
        Grid, m.
    b : ndarray, shape (N + 1,)
        ``sdot^2`` at the nodes, m^2/s^2.
    a : ndarray, shape (N,)
        ``sddot`` on each interval, m/s^2; ``b_{i+1} = b_i + 2 ds a_i`` holds
        to rounding.
    sd : ndarray, shape (N + 1,)
        ``sdot = sqrt(b)``, m/s.
    t : ndarray, shape (N + 1,)
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
    criterion_direction : ndarray, shape (n,), or None
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
    G, h = interval_matrix(rows, ds)
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
    """Solve in place; a solver crash becomes SimulationError, the status is the caller's to read."""
    opts = CLARABEL_OPTS if solver.upper() == "CLARABEL" else {}
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
    if prob.status not in SOLVED:
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


def _violation(b, rows: PathRows, ds) -> float:
    """Largest relative violation of any bound by ``b`` (0 if all hold)."""
    worst = 0.0
    fin = np.isfinite(rows.ub)
    if fin.any():
        worst = max(worst, float(np.max((b[fin] - rows.ub[fin]) / np.maximum(rows.ub[fin], TINY))))
    worst = max(worst, float(np.max(-b)) / max(float(np.max(b)), TINY))
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

    subject to the bounds of ``limits`` (see :mod:`planner.timescale`) and

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
        ``N + 1`` nodes.
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
    criterion_direction : array_like, shape (n,), optional
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
    k_star, v_sing, cdir, crit = _crossing(samples, limits, v_sing, s_star, rest_to_rest,
                                           criterion, criterion_direction)
    rows = path_rows(samples, limits)
    kw = {"k_star": k_star, "crit": crit, "rest_to_rest": rest_to_rest}
    status, b_sol, solve_time = _solve_time_optimal(samples, rows, v_sing, solver, kw)
    b = _polish(b_sol, rows, samples.ds, v_sing=v_sing, **kw)
    viol = _violation(b, rows, samples.ds)
    if viol > FEAS_RTOL:
        raise SimulationError(
            f"time scaling: the {status} solution violates a bound by {viol:.3g} (relative) "
            f"after polishing; the problem is badly scaled or at the edge of feasibility")
    return _scaling(samples, b, k_star=k_star, crit=crit, cdir=cdir, v_sing=v_sing, status=status,
                    solver=solver, solve_time=solve_time, max_violation=viol)


def _crossing(samples, limits, v_sing, s_star, rest_to_rest, criterion, criterion_direction):
    """Check the arguments of :func:`time_optimal_scaling`; the crossing they describe.

    Returns
    -------
    k_star : int or None
        Index of the crossing node ``s_star``.
    v_sing : float or None
        The checked crossing speed, m/s.
    cdir : ndarray, shape (n,), or None
        Unit direction ``c`` of the criterion (None without one).
    crit : (float, float) or None
        Coefficients ``(c . x', c . x'')`` of the criterion at ``k_star`` (None without one).

    Raises
    ------
    InputError
        As :func:`time_optimal_scaling`.
    """
    if not isinstance(samples, PathSamples):
        raise InputError(f"samples must be PathSamples, got {type(samples).__name__}")
    if not isinstance(limits, ScalingLimits):
        raise InputError(f"limits must be ScalingLimits, got {type(limits).__name__}")
    if v_sing is not None:
        v_sing = V.positive("v_sing", v_sing)
        if s_star is None:
            raise InputError("v_sing needs s_star (the crossing arc length)")
    k_star = None if s_star is None else node_index(samples, s_star, exact=True)
    cdir = crit = None
    if k_star is not None and criterion:
        cdir = crossing_direction(samples, k_star, criterion_direction)
        crit = criterion_coeffs(samples, k_star, cdir)
    if rest_to_rest and v_sing is not None and k_star in (0, samples.n_intervals):
        raise InputError("s_star must be an interior node for a rest-to-rest crossing at v_sing > 0")
    return k_star, v_sing, cdir, crit


def _solve_time_optimal(samples, rows, v_sing, solver, kw):
    """Solve the minimum-time SOCP; its status, the solver's ``b`` (m^2/s^2) and the solve time (s).

    ``kw`` holds ``k_star``, ``crit`` and ``rest_to_rest`` of :func:`_problem`.

    Raises
    ------
    SimulationError
        Infeasible (with the largest feasible speed at the crossing, by the
        LP of :func:`_max_speed_lp`), or any other status without a solution.
    """
    k_star = kw["k_star"]
    t0 = time.perf_counter()
    prob, bvar = _problem(samples, rows, v_sing=v_sing, objective="time", **kw)
    _solve(prob, solver)
    solve_time = time.perf_counter() - t0
    if prob.status in INFEASIBLE:
        if k_star is None:
            raise SimulationError("time scaling: no scaling meets the limits (even at rest)")
        vmax = _max_speed_lp(samples, rows, solver=solver, **kw)
        at = f"{vmax:.6g} m/s" if math.isfinite(vmax) else "undefined: no admissible scaling at all"
        raise SimulationError(
            f"no feasible crossing at v_sing = {v_sing:.6g} m/s under the limits (max feasible "
            f"speed at s* = {samples.s[k_star]:.6g} m is {at})")
    if prob.status not in SOLVED or bvar.value is None:
        raise SimulationError(f"time scaling: solver {solver} ended with status {prob.status!r}")
    return prob.status, bvar.value, solve_time


def _scaling(samples, b, *, k_star, crit, cdir, v_sing, status, solver, solve_time,
             max_violation) -> TimeScaling:
    """The :class:`TimeScaling` of the polished ``b`` (m^2/s^2): speeds, times and criterion residual.

    Raises
    ------
    SimulationError
        If the path stops inside (``b = 0`` at both ends of an interval).
    """
    N, ds = samples.n_intervals, samples.ds
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
        s=np.array(samples.s), b=b, a=a, sd=sd, t=t, total_time=float(t[-1]), status=status,
        solver=solver, solve_time=solve_time, v_sing=v_sing,
        s_star=None if k_star is None else float(samples.s[k_star]), k_star=k_star,
        criterion_direction=cdir, criterion_residual=float(res), max_violation=max_violation,
    )
