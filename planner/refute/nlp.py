"""Search a counterexample with CasADi's NLP interface and IPOPT.

The whole recording is solved at once, not a window around the crossing: a
counterexample must explain *every* sample (a tracker may certify at any
step), and a few hundred samples of an ``n = 2`` robot give a few thousand
variables, which IPOPT solves in well under a second (the two-joint benchmark crossing of the tests:
K = 250..400 samples, 2000..3200 variables, 0.1..0.4 s to converge,
0.3..1 s to report infeasibility).  To study a window, pass the slice
of the recording; the result then refutes only trackers fed that slice.

One NLP serves both kinds of counterexample
(:class:`~planner.refute.problem.CounterexampleKind`): :func:`search_bounce`
constrains the mode at every sample, :func:`search_crossing` at the first
and the last sample only; everything else is shared.

Non-convergence of IPOPT is never a counterexample; an unverified candidate is
never reported as one: every converged candidate goes through
:func:`~planner.refute.verify.verify_bounce` (or ``verify_crossing``), and only
:attr:`BounceSearch.verified` results count.  SI units throughout (m, rad, s).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError
from crosscert.robots.kinematics import KinematicModel

from ..ipopt import ParametricSolver
from ..lru import LruCache
from .problem import (
    ACCEL_MARGIN,
    JOINT_MARGIN,
    MODE_MARGIN,
    XI_MARGIN,
    Counterexample,
    CounterexampleKind,
    RecordingBounds,
    SearchOutcome,
    ipopt_outcome,
)
from .guess import fk_branch_guess, fk_crossing_guess
from .results import BounceSearch
from .verify import DENSE_POINTS, verify_counterexample

__all__ = ["MAX_CPU_TIME", "MAX_ITER", "nlp_variables", "scaled_cpu_time",
           "search_bounce", "search_counterexample", "search_crossing"]

#: Default IPOPT iteration cap per attempt: on the benchmark crossing IPOPT
#: converges or reports infeasibility within 24..76 iterations.
MAX_ITER = 3000
#: Default IPOPT CPU time cap per attempt, s: a stopped attempt proves nothing, so be generous.
MAX_CPU_TIME = 120.0
#: IPOPT's optimality tolerance; the objective is only a regulariser, so this matters little.
IPOPT_TOL = 1e-9
#: IPOPT's constraint violation tolerance (also the "acceptable" one), in the scaled
#: rows (eps_q- and full-acceleration units): far inside the margins above.
IPOPT_CONSTR_VIOL_TOL = 1e-10
#: Sample counts of the counterexample NLPs are rounded up to a multiple of this (see _build_and_solve).
SAMPLE_BUCKET = 32
def nlp_variables(kin: KinematicModel, n_samples: int) -> int:
    """Number of unknowns of the counterexample NLP of a recording of ``n_samples`` samples.

    ``m + n (4K - 1)`` with ``K`` the sample count rounded up to :data:`SAMPLE_BUCKET`
    (the size IPOPT solves, :func:`search_counterexample`).
    """
    K = -(-int(n_samples) // SAMPLE_BUCKET) * SAMPLE_BUCKET
    return kin.m + kin.n * (4 * K - 1)


def scaled_cpu_time(max_cpu_time: float, n_variables: int, cap_variables: int | None) -> float:
    """The CPU cap (s) of one attempt: ``max_cpu_time``, scaled up in proportion for NLPs above ``cap_variables``.

    IPOPT's cost per iteration grows with the NLP (a sparse factorisation
    per iteration), so one cap in seconds that suits a few thousand unknowns
    stops a larger NLP after a few iterations whatever its difficulty.
    ``cap_variables`` None: ``max_cpu_time`` unchanged.
    """
    if cap_variables is None or n_variables <= cap_variables:
        return float(max_cpu_time)
    return float(max_cpu_time) * n_variables / cap_variables


#: Unknowns above which the NLP is built from matrix symbols (CasADi's MX) with the per-sample function
#: mapped, instead of one expanded scalar graph (SX): on a three-joint plan of 1644 samples (19740 unknowns)
#: 8 CPU-s in all instead of 16, the same solution (docs/planning.md, "The 3-RPR's refutation search");
#: the two-joint benchmark's plans that certification searches stay below.
MX_FROM_VARIABLES = 8000
# --------------------------------------------------------------------- NLP
#: Solvers built in this process, by (robot, samples, kind, IPOPT options): most recently used last.
#: How many solvers :data:`_SOLVERS` keeps: each holds its expression graph and IPOPT's workspace,
#: 30-50 MB for 200-500 samples of a two-joint robot; a bisection asks within one or two sample buckets.
_SOLVER_CACHE_SIZE = 3
_SOLVERS = LruCache(_SOLVER_CACHE_SIZE)


def _counterexample_solver(kin: KinematicModel, K: int, kind: CounterexampleKind, ipopt: dict) -> ParametricSolver:
    """The NLP of ``kind`` on ``K`` samples, built once per process with every datum a parameter.

    Parameters ``p`` (in this order): the readings ``q_meas`` (n x K, column
    by column), ``eps_q`` (n), ``a_max`` (n), ``t_s``, the box centre ``xc``
    and half-width ``xh`` (m each), the residual scales (n) and ``m0``.
    """
    key = (kin.robot, int(K), kind, tuple(sorted(ipopt.items())))
    return _SOLVERS.get_or_build(key, lambda: _build_counterexample_solver(kin, int(K), kind, ipopt))


def _build_counterexample_solver(kin: KinematicModel, K: int, kind: CounterexampleKind, ipopt: dict):
    """The :class:`ParametricSolver` of :func:`_counterexample_solver`, built."""
    n, m = kin.n, kin.m
    # Small NLPs are expanded into one scalar graph (fastest per iteration); above MX_FROM_VARIABLES
    # the per-sample function is mapped over matrix symbols instead: building (and differentiating)
    # the expanded graph then costs more than the solve (25 CPU-s against 3 at 29580 unknowns).
    S = ca.MX if nlp_variables(kin, K) > MX_FROM_VARIABLES else ca.SX
    qm, eps, amax = S.sym("qm", n, K), S.sym("eps", n), S.sym("amax", n)
    ts, xc, xh = S.sym("ts"), S.sym("xc", m), S.sym("xh", m)
    fs, m0 = S.sym("fscale", n), S.sym("m0")
    p = ca.vertcat(ca.vec(qm), eps, amax, ts, xc, xh, fs, m0)

    # Decision vector, all scaled to O(1): xi = xc + xh*s, u = amax*w, q = qm + eps*dq.
    s = S.sym("s", m)
    Xs = S.sym("x", n, K)
    Vs = S.sym("v", n, K)
    Ws = S.sym("w", n, K - 1)
    Ds = S.sym("dq", n, K)
    xi = xc + xh * s
    U = ca.repmat(amax, 1, K - 1) * Ws
    Q = qm + ca.repmat(eps, 1, K) * Ds

    fs_in = fs if S is ca.SX else ca.SX.sym("fscale", n)  # the per-sample function is scalar either way
    point = ca.Function("point", [kin.sx_x, kin.sx_q, kin.sx_xi, fs_in],
                        [kin.sx_f / fs_in, kin.sx_mode / kin.sx_hadamard])
    F, M = point.map(K)(Xs, Q, ca.repmat(xi, 1, K), ca.repmat(fs, 1, K))
    M = m0 * M
    dyn_x = ((Xs[:, 1:] - Xs[:, :-1] - ts * Vs[:, :-1] - 0.5 * ts * ts * U)
             / ca.repmat(0.5 * ts * ts * amax, 1, K - 1))
    dyn_v = (Vs[:, 1:] - Vs[:, :-1] - ts * U) / ca.repmat(ts * amax, 1, K - 1)
    # The only difference between the kinds: which samples' modes are constrained.
    # A bounce keeps m0 at every sample; a crossing starts in m0 and ends in -m0
    # (M is already multiplied by m0, so the last row is -M >= margin).
    if kind is CounterexampleKind.BOUNCE:
        mode_rows = ca.vec(M)
    else:
        mode_rows = ca.vertcat(M[0], -M[K - 1])
    g = ca.vertcat(ca.vec(dyn_x), ca.vec(dyn_v), ca.vec(F), mode_rows)
    z = ca.vertcat(s, ca.vec(Xs), ca.vec(Vs), ca.vec(Ws), ca.vec(Ds))
    # Feasibility problem; the small smoothness objective picks a regular point.
    obj = ca.sumsqr(Ws) / (n * (K - 1))
    return ParametricSolver(kind.value, z, p, obj, g, ipopt=ipopt)


def _mapped_start(warm: Counterexample, qm: np.ndarray, ts: float):
    """A neighbouring recording's counterexample carried to the readings ``qm``: ``(X, V, U, Q)``.

    The two recordings follow one path at different speeds, so samples are
    matched by the arc length of the joints along each (the
    counterexample's own joints stand for its readings: they lie within
    ``eps_q`` of them); velocities are rescaled by the local rate of that
    match and the accelerations are their differences.
    """
    def arc(Q):
        return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(Q, axis=0), axis=1))])

    so, sn = arc(warm.q), arc(qm)
    so = so + 1e-15 * np.arange(so.size)  # strictly increasing over rests, for np.interp
    j = np.interp(sn, so, np.arange(so.size, dtype=float))
    rate = np.gradient(j) * ts / warm.t_s  # old samples per new sample, in time

    def at(a):
        idx = np.arange(a.shape[0], dtype=float)
        return np.stack([np.interp(j, idx, a[:, c]) for c in range(a.shape[1])], axis=1)

    X, V, Q = at(warm.x), at(warm.v) * rate[:, None], at(warm.q)
    U = np.diff(V, axis=0) / ts
    return X, V, U, Q


def _build_and_solve(kin: KinematicModel, rb: RecordingBounds, xi_start: np.ndarray, kind: CounterexampleKind, *,
                     max_iter: int, max_cpu_time: float, print_level: int, warm: Counterexample | None = None):
    """Solve the NLP of ``kind`` from ``xi_start``; returns (Counterexample or None, status, iters, time, nv, ng)."""
    K0, n, m = rb.n_samples, kin.n, kin.m
    ts, eps, amax = rb.t_s, rb.eps_q, rb.a_max
    xc, xh = 0.5 * (rb.xi_lo + rb.xi_hi), 0.5 * (rb.xi_hi - rb.xi_lo)
    # Solvers are built per sample count: the recording is extended to the next multiple of
    # SAMPLE_BUCKET by repeating its last reading (the robot rests there), so recordings of
    # nearby lengths share one.  Only the first K0 samples of a solution are kept: every
    # constraint holds sample by sample, so they explain the original recording (the trusted
    # check judges them against it).
    K = -(-K0 // SAMPLE_BUCKET) * SAMPLE_BUCKET
    qm = np.vstack([rb.q_meas, np.repeat(rb.q_meas[-1:], K - K0, axis=0)])

    # Initial guess: the FK of the samples with the starting geometry, in mode
    # m0 (bounce), or in m0 then -m0 (crossing); or a neighbour's counterexample
    # carried to these readings (xi_start is then its geometry).
    Dq0 = np.zeros((K, n))
    if warm is not None:
        X0, V0, U0, Q0 = _mapped_start(warm, qm, ts)
        U0 = np.clip(U0, -amax, amax)
        Dq0 = (Q0 - qm) / eps[None, :]
    elif kind is CounterexampleKind.BOUNCE:
        X0, _solved = fk_branch_guess(kin, qm, xi_start, rb.m0)
    else:
        X0, _k = fk_crossing_guess(kin, qm, xi_start, rb.m0)
    if warm is None:
        V0 = np.gradient(X0, ts, axis=0)
        U0 = np.clip(np.diff(V0, axis=0) / ts, -amax, amax)
    # Scales: f in "eps_q-equivalents" (row norm of J_q times eps_q), the
    # dynamics in units of one full-acceleration step; IPOPT then sees O(1) rows.
    jq = kin.jac_q_batch(X0, qm, xi_start)
    fscale = np.median(np.linalg.norm(jq * eps[None, None, :], axis=2), axis=0)
    fscale = np.where(fscale > 0, fscale, 1.0)
    solver = _counterexample_solver(kin, K, kind, {
        "print_level": print_level, "max_iter": max_iter, "max_cpu_time": max_cpu_time, "tol": IPOPT_TOL,
        "constr_viol_tol": IPOPT_CONSTR_VIOL_TOL, "acceptable_constr_viol_tol": IPOPT_CONSTR_VIOL_TOL})

    def vecF(a):  # CasADi's vec() is column-major
        return np.asarray(a, dtype=float).reshape(-1, order="F")

    p = np.concatenate([vecF(qm.T), eps, amax, [ts], xc, xh, fscale, [float(rb.m0)]])
    n_mode = K if kind is CounterexampleKind.BOUNCE else 2
    n_eq = 2 * n * (K - 1) + n * K
    lbg = np.concatenate([np.zeros(n_eq), np.full(n_mode, MODE_MARGIN)])
    ubg = np.concatenate([np.zeros(n_eq), np.full(n_mode, np.inf)])

    inf = np.inf
    x_lo = np.full((n, K), -inf) if rb.x_lo is None else np.repeat(rb.x_lo[:, None], K, axis=1)
    x_hi = np.full((n, K), inf) if rb.x_hi is None else np.repeat(rb.x_hi[:, None], K, axis=1)
    vb = np.full((n, K), inf) if rb.v_max is None else np.repeat((1 - ACCEL_MARGIN) * rb.v_max[:, None], K, axis=1)
    if rb.v0_max is not None:
        vb[:, 0] = np.minimum(vb[:, 0], (1 - ACCEL_MARGIN) * rb.v0_max)
    sb = np.full(m, 1 - XI_MARGIN)
    wb = np.full((n, K - 1), 1 - ACCEL_MARGIN)
    db = np.full((n, K), 1 - JOINT_MARGIN)

    lbx = np.concatenate([-sb, vecF(x_lo), vecF(-vb), vecF(-wb), vecF(-db)])
    ubx = np.concatenate([sb, vecF(x_hi), vecF(vb), vecF(wb), vecF(db)])
    s0 = np.divide(xi_start - xc, xh, out=np.zeros(m), where=xh > 0)
    X0c = np.clip(X0.T, x_lo, x_hi)
    z0 = np.concatenate([np.clip(s0, -sb, sb), vecF(X0c), vecF(np.clip(V0.T, -vb, vb)),
                         vecF(U0.T / amax[:, None]), vecF(np.clip(Dq0.T, -db, db))])
    run = solver.solve(p=p, z0=z0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    sol, stats, status, elapsed = run.solution, run.stats, run.status, run.elapsed_s
    iters = int(stats.get("iter_count", -1))
    nv, ng = solver.n_variables, solver.n_constraints
    if ipopt_outcome(status) is not SearchOutcome.CONVERGED:
        return None, status, iters, elapsed, nv, ng
    zs = np.asarray(sol["x"], dtype=float).reshape(-1)
    s_v, xv, vv, wv, dv = np.split(zs, np.cumsum([m, n * K, n * K, n * (K - 1)]))
    Xv, Vv, Dv = (a.reshape((n, K), order="F").T[:K0] for a in (xv, vv, dv))
    Wv = wv.reshape((n, K - 1), order="F").T[:K0 - 1]
    ce = Counterexample(xi=xc + xh * s_v, x=Xv, v=Vv, u=amax[None, :] * Wv,
                        q=qm[:K0] + eps[None, :] * Dv, t_s=ts, m0=rb.m0, kind=kind)
    return ce, status, iters, elapsed, nv, ng


def search_counterexample(kin: KinematicModel, rb: RecordingBounds, kind: CounterexampleKind, *, xi_start=None,
           max_iter: int = MAX_ITER, max_cpu_time: float = MAX_CPU_TIME, print_level: int = 0,
           dense: int = DENSE_POINTS, warm: Counterexample | None = None) -> BounceSearch:
    """Search one counterexample of ``kind`` from one starting geometry, and verify it.

    :func:`search_bounce` and :func:`search_crossing` are this function with
    ``kind`` fixed; their docstrings describe the NLP.

    ``warm``, a counterexample of a neighbouring recording (e.g. at the
    next speed of a bisection), replaces ``xi_start`` and the FK guess:
    the NLP starts from it, carried to these readings sample by sample
    (matched by the joints' arc length along each recording).  Only the
    start changes: the candidate is verified as any other.

    Raises
    ------
    InputError
        If ``rb`` does not match ``kin``, ``xi_start`` lies outside the box or
        ``kind`` is not a :class:`CounterexampleKind`.
    SimulationError
        If no sample has an FK solution of the required mode(s) with ``xi_start``.
    """
    if not isinstance(kin, KinematicModel):
        raise InputError(f"kin must be a KinematicModel, got {type(kin).__name__}")
    if not isinstance(rb, RecordingBounds):
        raise InputError(f"rb must be RecordingBounds, got {type(rb).__name__}")
    try:
        kind = CounterexampleKind(kind)
    except ValueError:
        raise InputError(f"kind must be one of {[k.value for k in CounterexampleKind]}, got {kind!r}") from None
    if rb.q_meas.shape[1] != kin.n or rb.xi_lo.shape != (kin.m,):
        raise InputError(f"recording has {rb.q_meas.shape[1]} joints and {rb.xi_lo.size} parameters; "
                         f"{kin.robot.name} needs {kin.n} and {kin.m}")
    if warm is not None:
        if xi_start is not None or not isinstance(warm, Counterexample) or warm.q.shape[1:] != (kin.n,):
            raise InputError("warm must be a Counterexample of this robot, given instead of xi_start")
        xs = np.clip(warm.xi, rb.xi_lo, rb.xi_hi)
    else:
        xs = 0.5 * (rb.xi_lo + rb.xi_hi) if xi_start is None else V.vector("xi_start", xi_start, kin.m, broadcast=True)
    if np.any(xs < rb.xi_lo) or np.any(xs > rb.xi_hi):
        raise InputError(f"xi_start = {xs.tolist()} lies outside the calibration box")
    ce, status, iters, elapsed, nv, ng = _build_and_solve(
        kin, rb, xs, kind, max_iter=max_iter, max_cpu_time=max_cpu_time, print_level=print_level, warm=warm)
    if ce is None:
        return BounceSearch(False, False, status, iters, elapsed, nv, ng, xs, kind=kind)
    ver = verify_counterexample(kin, ce, rb, kind, dense=dense)
    return BounceSearch(True, ver.ok, status, iters, elapsed, nv, ng, xs, ce, ver, kind=kind)


def search_bounce(kin: KinematicModel, rb: RecordingBounds, *, xi_start=None, max_iter: int = MAX_ITER,
                  max_cpu_time: float = MAX_CPU_TIME, print_level: int = 0,
                  dense: int = DENSE_POINTS) -> BounceSearch:
    """Search one counterexample with IPOPT from one starting geometry, and verify it.

    Unknowns: one geometry ``xi`` (m,), the pose ``x_k`` and velocity ``v_k`` at
    every sample, a constant acceleration ``u_k`` per interval and the joints
    ``q_k``: ``(m + n (4K - 1))`` variables.  Constraints: exact
    piecewise-quadratic dynamics, ``f(x_k, q_k, xi) = 0``, and the mode
    ``m0`` at every sample (normalised ``det J_x >= MODE_MARGIN``); bounds:
    the measurement intervals, ``a_max``, ``[xi]``, each shrunk by a small
    margin (``JOINT_MARGIN``, ``ACCEL_MARGIN``, ``XI_MARGIN``) so that an
    accepted solution is strictly feasible.  See :mod:`planner.refute.verify`
    for why the mode is constrained at the samples only.

    Parameters
    ----------
    kin : KinematicModel
        The robot's kinematics (its CasADi expressions build the NLP).
    rb : RecordingBounds
        The recording and the bounds.
    xi_start : array_like, shape (m,), optional
        Starting geometry (default: centre of the box); it only seeds the
        initial guess (the mode-``m0`` FK of the samples with it), ``xi`` is free.
    max_iter : int
        IPOPT iteration cap.
    max_cpu_time : float
        IPOPT time cap, s.
    print_level : int
        IPOPT verbosity (0 silent).
    dense : int
        Sub-samples per interval of the verification (:func:`verify_bounce`).

    Returns
    -------
    BounceSearch
        ``found=False`` with IPOPT's status when it did not converge (this is
        no counterexample, and no proof that none exists); otherwise the
        candidate and its verification.  ``outcome`` is
        :attr:`SearchOutcome.FOUND` only for a verified counterexample.

    Raises
    ------
    InputError
        If ``rb`` does not match ``kin`` or ``xi_start`` lies outside the box.
    SimulationError
        If no sample has an FK solution of mode ``m0`` with ``xi_start``.
    """
    return search_counterexample(kin, rb, CounterexampleKind.BOUNCE, xi_start=xi_start, max_iter=max_iter,
                  max_cpu_time=max_cpu_time, print_level=print_level, dense=dense)


def search_crossing(kin: KinematicModel, rb: RecordingBounds, *, xi_start=None, max_iter: int = MAX_ITER,
                    max_cpu_time: float = MAX_CPU_TIME, print_level: int = 0,
                    dense: int = DENSE_POINTS) -> BounceSearch:
    """Search one *crossing* counterexample with IPOPT from one starting geometry, and verify it.

    The NLP of :func:`search_bounce` (same unknowns, dynamics, joint
    intervals, ``a_max``, ``[xi]``, velocity and workspace bounds, margins)
    with the mode constrained at two samples only: ``m0`` at the first and
    ``-m0`` at the last (normalised ``m0 det J_x >= MODE_MARGIN`` and
    ``<= -MODE_MARGIN``), so ``m + n (4K - 1)`` variables and
    ``2 n (K - 1) + n K + 2`` constraints.  A verified solution explains the
    readings by a motion that changed the assembly mode: no sound tracker may
    certify ``mode-unchanged`` on them.

    Parameters
    ----------
    kin : KinematicModel
        The robot's kinematics (its CasADi expressions build the NLP).
    rb : RecordingBounds
        The recording (e.g. a bounce) and the bounds; ``rb.m0`` is the initial mode.
    xi_start : array_like, shape (m,), optional
        Starting geometry (default: centre of the box); it only seeds the
        initial guess (:func:`fk_crossing_guess` with it), ``xi`` is free.
    max_iter : int
        IPOPT iteration cap.
    max_cpu_time : float
        IPOPT time cap, s.
    print_level : int
        IPOPT verbosity (0 silent).
    dense : int
        IK continuation points per interval of the verification (:func:`verify_crossing`).

    Returns
    -------
    BounceSearch
        ``kind`` :attr:`CounterexampleKind.CROSSING`; ``outcome`` is
        :attr:`SearchOutcome.FOUND` only for a verified counterexample, and
        no other outcome means that none exists.

    Raises
    ------
    InputError
        If ``rb`` does not match ``kin`` or ``xi_start`` lies outside the box.
    SimulationError
        If no sample has an FK solution of mode ``m0``, or none of mode ``-m0``, with ``xi_start``.
    """
    return search_counterexample(kin, rb, CounterexampleKind.CROSSING, xi_start=xi_start, max_iter=max_iter,
                  max_cpu_time=max_cpu_time, print_level=print_level, dense=dense)
