"""Refutation bound: search for "bounce" motions that explain a crossing's encoder data.

A sound tracker may certify that a recording changed the assembly mode only if
*no* motion compatible with its assumptions explains the same data without a
mode change.  This module searches for such a motion, a counterexample, with
CasADi's NLP interface and IPOPT, and checks every candidate independently:

* one constant geometry ``xi`` inside the calibration box ``[xi_lo, xi_hi]``;
* a pose ``x(t)`` that is exactly C^1 and piecewise quadratic on the sample
  grid ``t_k = k t_s``: on ``[t_k, t_k+1]`` the acceleration is the constant
  ``u_k`` with ``|u_k,i| <= a_max_i``, so ``x_k+1 = x_k + t_s v_k + t_s^2/2 u_k``
  and ``v_k+1 = v_k + t_s u_k`` hold exactly (not a discretisation);
* joints ``q_k`` with ``f(x_k, q_k, xi) = 0`` and ``|q_k - q_meas[k]| <= eps_q``
  at every sample;
* the assembly mode (``KinematicModel.mode``, i.e. ``mode_sign * sign det J_x``)
  equal to the initial mode ``m0`` at every sample;
* optionally ``|x'(0)| <= v0_max``, ``|x'(t)| <= v_max``, ``x(t)`` in the
  robot's workspace box (the tracker's other assumptions).

Why the mode is constrained at the samples only: a tracker's verdict is a
statement about the mode *at sample times* (at the step where it certifies).
A motion whose mode equals ``m0`` at every sample refutes every such verdict,
even if it touched or crossed the locus between two samples, provided it is a
real motion: the joints must follow ``x(t)`` continuously on their leg
branches.  The verification step (:func:`verify_bounce`) therefore follows the
IK along ``x(t)`` densely between samples, and by default it also requires the
mode to stay ``m0`` at every dense point (a genuine bounce, never crossing).
Dense evaluation at finitely many points is a numerical check, not a proof
that the mode never flips between two of them; it is stricter than the claim
needs, not weaker.

The whole recording is solved at once, not a window around the crossing: a
counterexample must explain *every* sample (a tracker may certify at any
step), and a few hundred samples of an ``n = 2`` robot give a few thousand
variables, which IPOPT solves in well under a second (the two-joint benchmark crossing of the tests:
K = 250..400 samples, 2000..3200 variables, 0.1..0.4 s to converge,
0.3..1 s to report infeasibility).  To study a window, pass the slice
of the recording; the result then refutes only trackers fed that slice.

Non-convergence of IPOPT is never a counterexample; an unverified candidate is
never reported as one.  Only :attr:`BounceSearch.verified` results count.
SI units throughout (m, rad, s).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import casadi as ca
import numpy as np

from robots.kinematics import KinematicModel
from robots.errors import InputError, SimulationError

__all__ = [
    "RecordingBounds",
    "Counterexample",
    "Verification",
    "BounceSearch",
    "SpeedRefutation",
    "RefutationBound",
    "fk_branch_guess",
    "search_bounce",
    "verify_bounce",
    "refutation_bound",
]

#: The NLP's joint intervals are ``q_meas +- (1 - JOINT_MARGIN) eps_q``, so the
#: verified joints lie strictly inside ``q_meas +- eps_q`` despite IPOPT's
#: constraint tolerance and the re-solved IK (both ~1e-10 of eps_q).
JOINT_MARGIN = 1e-4
#: The NLP's bounds on ``|u|`` are ``(1 - ACCEL_MARGIN) a_max`` (also for v0_max, v_max).
ACCEL_MARGIN = 1e-6
#: The NLP's geometry box is shrunk by this fraction of its half-width.
XI_MARGIN = 1e-6
#: The NLP requires ``m0 * mode_sign * det J_x >= MODE_MARGIN * prod_i |row_i J_x|``
#: (Hadamard's bound); the verification's threshold is ``robots.kinematics.MODE_RTOL`` = 1e-10.
MODE_MARGIN = 1e-6
#: Largest disagreement (m) between the NLP's sample poses and the trajectory
#: re-integrated from ``x_0, v_0`` and the accelerations (velocities: divided by ``t_s``).
STATE_TOL = 1e-9
#: After IK continuation over one interval, the joints must land within this
#: distance (rad) of the sample's own IK: the leg branches did not switch.
BRANCH_TOL = 1e-7


# ------------------------------------------------------------------ inputs
def _vector(name: str, value, n: int, *, positive: bool = False) -> np.ndarray:
    try:
        a = np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a number or a vector of length {n}, got {value!r}") from exc
    if not np.all(np.isfinite(a)) or (positive and np.any(a <= 0)):
        raise InputError(f"{name} must be finite{' and positive' if positive else ''}, got {value!r}")
    return a


@dataclass(frozen=True)
class RecordingBounds:
    """Measurement intervals of one recording and the assumptions a tracker makes about it.

    Parameters
    ----------
    q_meas : ndarray, shape (K, n)
        Encoder samples, rad; the true joints at ``t_k = k t_s`` lie in
        ``q_meas[k] +- eps_q``.
    t_s : float
        Sampling period, s.
    eps_q : ndarray, shape (n,)
        Encoder error bounds, rad.
    a_max : ndarray, shape (n,)
        Componentwise bound on ``|x''|``, m/s^2.
    xi_lo, xi_hi : ndarray, shape (m,)
        Calibration box of the geometry, SI.
    m0 : int
        Initial assembly mode, +1 or -1 (``KinematicModel.mode`` convention).
    v0_max : ndarray, shape (n,), optional
        Bound on ``|x'(0)|``, m/s (the tracker's initial velocity box); none if ``None``.
    v_max : ndarray, shape (n,), optional
        Bound on ``|x'(t)|``, m/s; none if ``None``.
    x_lo, x_hi : ndarray, shape (n,), optional
        Box the pose stays in, m; none if ``None``.

    Raises
    ------
    InputError
        On wrong shapes, non-finite or non-positive bounds, an empty box or ``m0`` not +-1.
    """

    q_meas: np.ndarray
    t_s: float
    eps_q: np.ndarray
    a_max: np.ndarray
    xi_lo: np.ndarray
    xi_hi: np.ndarray
    m0: int
    v0_max: np.ndarray | None = None
    v_max: np.ndarray | None = None
    x_lo: np.ndarray | None = None
    x_hi: np.ndarray | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__  # frozen: normalise once
        try:
            q = np.array(self.q_meas, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InputError("q_meas must be a numeric (K, n) array") from exc
        if q.ndim != 2 or q.shape[0] < 2 or q.shape[1] < 1 or not np.all(np.isfinite(q)):
            raise InputError(f"q_meas must be a finite (K, n) array with K >= 2, got shape {q.shape}")
        n = q.shape[1]
        q.setflags(write=False)
        set_(self, "q_meas", q)
        try:
            ts = float(self.t_s)
        except (TypeError, ValueError) as exc:
            raise InputError(f"t_s must be a number, got {self.t_s!r}") from exc
        if not (math.isfinite(ts) and ts > 0):
            raise InputError(f"t_s must be positive and finite, got {self.t_s!r}")
        set_(self, "t_s", ts)
        set_(self, "eps_q", _vector("eps_q", self.eps_q, n, positive=True))
        set_(self, "a_max", _vector("a_max", self.a_max, n, positive=True))
        lo = np.array(self.xi_lo, dtype=float).reshape(-1)
        hi = np.array(self.xi_hi, dtype=float).reshape(-1)
        if lo.shape != hi.shape or lo.size == 0 or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise InputError("xi_lo and xi_hi must be finite vectors of the same length")
        if np.any(lo > hi):
            raise InputError(f"calibration box is empty: xi_lo = {lo.tolist()}, xi_hi = {hi.tolist()}")
        set_(self, "xi_lo", lo)
        set_(self, "xi_hi", hi)
        if self.m0 not in (1, -1):
            raise InputError(f"m0 must be +1 or -1, got {self.m0!r}")
        set_(self, "m0", int(self.m0))
        for nm in ("v0_max", "v_max"):
            if getattr(self, nm) is not None:
                set_(self, nm, _vector(nm, getattr(self, nm), n, positive=True))
        if (self.x_lo is None) != (self.x_hi is None):
            raise InputError("give both x_lo and x_hi, or neither")
        if self.x_lo is not None:
            xl, xh = _vector("x_lo", self.x_lo, n), _vector("x_hi", self.x_hi, n)
            if np.any(xl >= xh):
                raise InputError(f"need x_lo < x_hi, got {xl.tolist()}, {xh.tolist()}")
            set_(self, "x_lo", xl)
            set_(self, "x_hi", xh)
        for nm in ("eps_q", "a_max", "xi_lo", "xi_hi", "v0_max", "v_max", "x_lo", "x_hi"):
            a = getattr(self, nm)
            if a is not None:
                a.setflags(write=False)

    @classmethod
    def for_model(cls, kin: KinematicModel, q_meas, t_s: float | None = None, m0: int = 1,
                  **overrides) -> "RecordingBounds":
        """The robot's defaults (``t_s``, ``eps_q``, ``a_max``, calibration box,
        ``xd0`` as ``v0_max``, ``x_bounds``), with keyword overrides (``None`` ignored).

        Parameters
        ----------
        kin : KinematicModel
        q_meas : array_like, shape (K, n)
            Encoder samples, rad.
        t_s : float, optional
            Sampling period, s (default ``robot.t_s``).
        m0 : int
            Initial assembly mode, +1 or -1.
        **overrides
            Any other field of :class:`RecordingBounds`.
        """
        if not isinstance(kin, KinematicModel):
            raise InputError(f"kin must be a KinematicModel, got {type(kin).__name__}")
        r = kin.robot
        args = dict(t_s=r.t_s if t_s is None else t_s, eps_q=r.eps_q, a_max=r.a_max_array,
                    xi_lo=r.xi_lo_array, xi_hi=r.xi_hi_array, m0=m0, v0_max=np.array(r.xd0),
                    x_lo=r.x_lo_array, x_hi=r.x_hi_array)
        args.update({k: v for k, v in overrides.items() if v is not None})
        out = cls(q_meas=q_meas, **args)
        if out.q_meas.shape[1] != kin.n or out.xi_lo.shape != (kin.m,):
            raise InputError(f"q_meas must have {kin.n} columns and the box {kin.m} parameters")
        return out

    @property
    def n_samples(self) -> int:
        """Number of samples K."""
        return int(self.q_meas.shape[0])


# ------------------------------------------------------------------ results
@dataclass(frozen=True)
class Counterexample:
    """A candidate bounce: one geometry and a piecewise-quadratic pose with its joints.

    Attributes
    ----------
    xi : ndarray (m,)
        Geometry, SI.
    x, v : ndarray (K, n)
        Pose (m) and velocity (m/s) at the samples.
    u : ndarray (K - 1, n)
        Constant acceleration on ``[t_k, t_k+1]``, m/s^2.
    q : ndarray (K, n)
        Joints at the samples, rad.
    t_s : float
        Sampling period, s.
    m0 : int
        The assembly mode kept throughout.
    """

    xi: np.ndarray
    x: np.ndarray
    v: np.ndarray
    u: np.ndarray
    q: np.ndarray
    t_s: float
    m0: int

    def __post_init__(self) -> None:
        for nm in ("xi", "x", "v", "u", "q"):
            a = np.array(getattr(self, nm), dtype=float)  # own copy, read-only
            a.setflags(write=False)
            object.__setattr__(self, nm, a)

    def trajectory(self, t) -> np.ndarray:
        """Pose ``x(t)`` (m), shape ``(len(t), n)``, of the piecewise quadratic re-integrated
        from ``x[0], v[0]`` and ``u`` (the definition :func:`verify_bounce` checks);
        ``t`` in ``[0, (K - 1) t_s]`` s."""
        xs, vs = _integrate(self.x[0], self.v[0], self.u, self.t_s)
        t = np.atleast_1d(np.asarray(t, dtype=float))
        k = np.clip(np.floor(t / self.t_s).astype(int), 0, self.u.shape[0] - 1)
        tau = (t - k * self.t_s)[:, None]
        return xs[k] + tau * vs[k] + 0.5 * tau**2 * self.u[k]


@dataclass(frozen=True)
class Verification:
    """Outcome of the independent check of a :class:`Counterexample`.

    Attributes
    ----------
    ok : bool
        Every check passed.
    failures : tuple of str
        One message per failed check (empty when ``ok``).
    joint_ratio : float
        ``max_k,i (|q_ik - q_meas| + |Newton correction|) / eps_q`` with ``q_ik``
        the IK of the re-integrated pose; ``<= 1`` required.
    accel_ratio : float
        ``max |u_k,i| / a_max_i``; ``<= 1`` required.
    xi_excess : float
        Largest distance (SI) of ``xi`` outside the box; ``0`` required.
    mode_margin : float
        ``min_k m0 * mode_sign * det J_x / prod |rows of J_x|`` at the samples; ``> 0`` required.
    dense_mode_violations : int
        Dense points (between samples) whose mode is not ``m0``.
    dense_ik_failures : int
        Dense points where the IK continuation failed, left the workspace box,
        or landed on another leg branch at the next sample.
    state_mismatch : float
        ``max |x_k - x_hat_k|`` (m) and ``t_s |v_k - v_hat_k|`` between the
        candidate's states and the re-integrated ones.
    """

    ok: bool
    failures: tuple[str, ...]
    joint_ratio: float
    accel_ratio: float
    xi_excess: float
    mode_margin: float
    dense_mode_violations: int
    dense_ik_failures: int
    state_mismatch: float


@dataclass(frozen=True)
class BounceSearch:
    """One NLP solve from one starting geometry, and the verification of its result.

    Attributes
    ----------
    found : bool
        IPOPT reported success (``Solve_Succeeded`` or ``Solved_To_Acceptable_Level``).
    verified : bool
        ``found`` and :func:`verify_bounce` accepted the candidate: a counterexample.
    status : str
        IPOPT's return status.
    iterations : int
    solve_time : float
        Wall time of the solve (s), building excluded.
    n_variables, n_constraints : int
        NLP size.
    xi_start : ndarray (m,)
        Starting geometry.
    counterexample : Counterexample or None
        The candidate (``None`` unless ``found``).
    verification : Verification or None
        Its check (``None`` unless ``found``).
    """

    found: bool
    verified: bool
    status: str
    iterations: int
    solve_time: float
    n_variables: int
    n_constraints: int
    xi_start: np.ndarray
    counterexample: Counterexample | None = field(default=None, repr=False)
    verification: Verification | None = None


@dataclass(frozen=True)
class SpeedRefutation:
    """Search result for one recording (one speed).

    Attributes
    ----------
    speed : float
        The speed passed to ``make_recording``, m/s.
    n_samples : int
        Samples of the recording.
    found : bool
        Some start converged.
    verified : bool
        Some start gave a verified counterexample.
    geometry : ndarray (m,) or None
        Geometry of the verified counterexample (else of the last converged candidate, else ``None``).
    joint_ratio, accel_ratio, mode_margin : float
        The counterexample's :class:`Verification` figures (``nan`` if none converged).
    status : str
        Status of the deciding attempt (the verified one, else the last).
    solve_time : float
        Total solver wall time over the attempts, s.
    attempts : tuple of BounceSearch
    """

    speed: float
    n_samples: int
    found: bool
    verified: bool
    geometry: np.ndarray | None
    joint_ratio: float
    accel_ratio: float
    mode_margin: float
    status: str
    solve_time: float
    attempts: tuple[BounceSearch, ...] = field(repr=False)


@dataclass(frozen=True)
class RefutationBound:
    """Counterexample search over speeds.

    Attributes
    ----------
    rows : tuple of SpeedRefutation
        One per speed, in the order given.
    bound : float or None
        Largest speed with a verified counterexample (m/s), ``None`` if none.
        That recording cannot be certified "mode changed" by any sound tracker
        under the same bounds, so the slowest certifiable crossing (of this
        family of recordings) is faster than ``bound``, or the family is not
        monotone in speed — :attr:`rows` shows which speeds were refuted.
    """

    rows: tuple[SpeedRefutation, ...]
    bound: float | None


# ------------------------------------------------------------ helpers
def _integrate(x0, v0, u, t_s) -> tuple[np.ndarray, np.ndarray]:
    """Sample states of the piecewise-quadratic pose from ``x0, v0`` and accelerations ``u`` (K-1, n)."""
    K = u.shape[0] + 1
    x = np.empty((K, u.shape[1]))
    v = np.empty_like(x)
    x[0], v[0] = x0, v0
    for k in range(K - 1):
        x[k + 1] = x[k] + t_s * v[k] + 0.5 * t_s * t_s * u[k]
        v[k + 1] = v[k] + t_s * u[k]
    return x, v


def fk_branch_guess(kin: KinematicModel, q_meas, xi, m0: int) -> tuple[np.ndarray, np.ndarray]:
    """The forward kinematics of every sample in assembly mode ``m0``, by continuation.

    For a crossing this is the recording's own path before the locus and its
    reflection (the other FK solution) after it: the "bounce" the NLP starts
    from.  Samples with no mode-``m0`` solution (near the locus, where the two
    solutions merge and vanish for this ``xi``) are linearly interpolated.

    Parameters
    ----------
    kin : KinematicModel
    q_meas : array_like, shape (K, n)
        Joints, rad.
    xi : array_like, shape (m,)
        Geometry, SI.
    m0 : int
        Assembly mode, +1 or -1.

    Returns
    -------
    X : ndarray, shape (K, n)
        Poses, m.
    solved : ndarray of bool, shape (K,)
        Samples where an FK solution of mode ``m0`` was found (others interpolated).

    Raises
    ------
    SimulationError
        If no sample has an FK solution of mode ``m0``.
    """
    Q = np.asarray(q_meas, dtype=float)
    K = Q.shape[0]
    X = np.full((K, kin.n), np.nan)
    solved = np.zeros(K, dtype=bool)
    prev = None
    for k in range(K):
        x = None
        if prev is not None:
            Xk, ok = kin.fk_batch(Q[k:k + 1], xi, prev[None, :])
            if ok[0] and kin.mode(Xk[0], Q[k], xi) == m0:
                x = Xk[0]
        if x is None:  # no continuation (first sample, or it fell into the other mode)
            sols = kin.fk_all(Q[k], xi)
            mine = [s for s in sols if kin.mode(s, Q[k], xi) == m0]
            if mine:
                # Nearest to the last pose keeps the branch; the first sample takes
                # the lexicographically first solution of its mode.
                x = mine[0] if prev is None else min(mine, key=lambda s: float(np.max(np.abs(s - prev))))
        if x is not None:
            X[k], solved[k], prev = x, True, x
    if not solved.any():
        raise SimulationError(f"{kin.robot.name}: no sample has a forward-kinematics solution in mode {m0:+d}")
    idx = np.nonzero(solved)[0]
    for j in range(kin.n):
        X[:, j] = np.interp(np.arange(K), idx, X[idx, j])
    return X, solved


# --------------------------------------------------------------------- NLP
def _build_and_solve(kin: KinematicModel, rb: RecordingBounds, xi_start: np.ndarray, *,
                     max_iter: int, max_cpu_time: float, print_level: int):
    """Set up and solve the bounce NLP; returns (Counterexample or None, status, iters, time, nv, ng)."""
    K, n, m = rb.n_samples, kin.n, kin.m
    ts, qm, eps, amax = rb.t_s, rb.q_meas, rb.eps_q, rb.a_max
    xc, xh = 0.5 * (rb.xi_lo + rb.xi_hi), 0.5 * (rb.xi_hi - rb.xi_lo)

    # Initial guess: mode-m0 FK of the samples with the starting geometry.
    X0, _solved = fk_branch_guess(kin, qm, xi_start, rb.m0)
    V0 = np.gradient(X0, ts, axis=0)
    U0 = np.clip(np.diff(V0, axis=0) / ts, -amax, amax)
    # Scales: f in "eps_q-equivalents" (row norm of J_q times eps_q), the
    # dynamics in units of one full-acceleration step; IPOPT then sees O(1) rows.
    jq = kin.jac_q_batch(X0, qm, xi_start)
    fscale = np.median(np.linalg.norm(jq * eps[None, None, :], axis=2), axis=0)
    fscale = np.where(fscale > 0, fscale, 1.0)

    # Decision vector, all scaled to O(1): xi = xc + xh*s, u = amax*w, q = qm + eps*dq.
    s = ca.SX.sym("s", m)
    Xs = ca.SX.sym("x", n, K)
    Vs = ca.SX.sym("v", n, K)
    Ws = ca.SX.sym("w", n, K - 1)
    Ds = ca.SX.sym("dq", n, K)
    xi = ca.DM(xc) + ca.DM(xh) * s
    U = ca.repmat(ca.DM(amax), 1, K - 1) * Ws
    Q = ca.DM(qm.T) + ca.repmat(ca.DM(eps), 1, K) * Ds

    point = ca.Function("point", [kin.sx_x, kin.sx_q, kin.sx_xi],
                        [kin.sx_f / ca.DM(fscale), rb.m0 * kin.sx_mode / kin.sx_hadamard])
    F, M = point.map(K)(Xs, Q, ca.repmat(xi, 1, K))
    dyn_x = (Xs[:, 1:] - Xs[:, :-1] - ts * Vs[:, :-1] - 0.5 * ts * ts * U) / ca.repmat(ca.DM(0.5 * ts * ts * amax), 1, K - 1)
    dyn_v = (Vs[:, 1:] - Vs[:, :-1] - ts * U) / ca.repmat(ca.DM(ts * amax), 1, K - 1)
    g = ca.vertcat(ca.vec(dyn_x), ca.vec(dyn_v), ca.vec(F), ca.vec(M))
    z = ca.vertcat(s, ca.vec(Xs), ca.vec(Vs), ca.vec(Ws), ca.vec(Ds))
    n_eq = 2 * n * (K - 1) + n * K
    lbg = np.concatenate([np.zeros(n_eq), np.full(K, MODE_MARGIN)])
    ubg = np.concatenate([np.zeros(n_eq), np.full(K, np.inf)])

    inf = np.inf
    x_lo = np.full((n, K), -inf) if rb.x_lo is None else np.repeat(rb.x_lo[:, None], K, axis=1)
    x_hi = np.full((n, K), inf) if rb.x_hi is None else np.repeat(rb.x_hi[:, None], K, axis=1)
    vb = np.full((n, K), inf) if rb.v_max is None else np.repeat((1 - ACCEL_MARGIN) * rb.v_max[:, None], K, axis=1)
    if rb.v0_max is not None:
        vb[:, 0] = np.minimum(vb[:, 0], (1 - ACCEL_MARGIN) * rb.v0_max)
    sb = np.full(m, 1 - XI_MARGIN)
    wb = np.full((n, K - 1), 1 - ACCEL_MARGIN)
    db = np.full((n, K), 1 - JOINT_MARGIN)

    def vecF(a):  # CasADi's vec() is column-major
        return np.asarray(a, dtype=float).reshape(-1, order="F")

    lbx = np.concatenate([-sb, vecF(x_lo), vecF(-vb), vecF(-wb), vecF(-db)])
    ubx = np.concatenate([sb, vecF(x_hi), vecF(vb), vecF(wb), vecF(db)])
    s0 = np.divide(xi_start - xc, xh, out=np.zeros(m), where=xh > 0)
    X0c = np.clip(X0.T, x_lo, x_hi)
    z0 = np.concatenate([np.clip(s0, -sb, sb), vecF(X0c), vecF(np.clip(V0.T, -vb, vb)),
                         vecF(U0.T / amax[:, None]), np.zeros(n * K)])

    # Feasibility problem; the small smoothness objective picks a regular point.
    obj = ca.sumsqr(Ws) / (n * (K - 1))
    opts = {
        "ipopt": {
            "print_level": print_level, "max_iter": max_iter, "max_cpu_time": max_cpu_time,
            "tol": 1e-9, "constr_viol_tol": 1e-10, "acceptable_constr_viol_tol": 1e-10,
            # Bounds are the measurement intervals: never relax them.
            "bound_relax_factor": 0.0, "honor_original_bounds": "yes",
            "mu_strategy": "adaptive", "sb": "yes",
        },
        "print_time": False,
    }
    solver = ca.nlpsol("bounce", "ipopt", {"x": z, "f": obj, "g": g}, opts)
    t0 = time.perf_counter()
    sol = solver(x0=z0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    elapsed = time.perf_counter() - t0
    stats = solver.stats()
    status = str(stats.get("return_status", "unknown"))
    iters = int(stats.get("iter_count", -1))
    nv, ng = int(z.numel()), int(g.numel())
    if status not in ("Solve_Succeeded", "Solved_To_Acceptable_Level"):
        return None, status, iters, elapsed, nv, ng
    zs = np.asarray(sol["x"], dtype=float).reshape(-1)
    o = 0
    s_v = zs[o:o + m]; o += m
    Xv = zs[o:o + n * K].reshape((n, K), order="F").T; o += n * K
    Vv = zs[o:o + n * K].reshape((n, K), order="F").T; o += n * K
    Wv = zs[o:o + n * (K - 1)].reshape((n, K - 1), order="F").T; o += n * (K - 1)
    Dv = zs[o:o + n * K].reshape((n, K), order="F").T
    ce = Counterexample(xi=xc + xh * s_v, x=Xv, v=Vv, u=amax[None, :] * Wv,
                        q=qm + eps[None, :] * Dv, t_s=ts, m0=rb.m0)
    return ce, status, iters, elapsed, nv, ng


def search_bounce(kin: KinematicModel, rb: RecordingBounds, *, xi_start=None, max_iter: int = 3000,
                  max_cpu_time: float = 120.0, print_level: int = 0, dense: int = 8) -> BounceSearch:
    """Search one counterexample with IPOPT from one starting geometry, and verify it.

    Unknowns: one geometry ``xi`` (m,), the pose ``x_k`` and velocity ``v_k`` at
    every sample, a constant acceleration ``u_k`` per interval and the joints
    ``q_k``: ``(m + n (4K - 1))`` variables.  Constraints: exact
    piecewise-quadratic dynamics, ``f(x_k, q_k, xi) = 0``, and the mode
    ``m0`` at every sample (normalised ``det J_x >= MODE_MARGIN``); bounds:
    the measurement intervals, ``a_max``, ``[xi]``, each shrunk by a small
    margin (``JOINT_MARGIN``, ``ACCEL_MARGIN``, ``XI_MARGIN``) so that an
    accepted solution is strictly feasible.  See the module docstring for why
    the mode is constrained at the samples only.

    Parameters
    ----------
    kin : KinematicModel
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
        no counterexample); otherwise the candidate and its verification.

    Raises
    ------
    InputError
        If ``rb`` does not match ``kin`` or ``xi_start`` lies outside the box.
    SimulationError
        If no sample has an FK solution of mode ``m0`` with ``xi_start``.
    """
    if not isinstance(kin, KinematicModel):
        raise InputError(f"kin must be a KinematicModel, got {type(kin).__name__}")
    if not isinstance(rb, RecordingBounds):
        raise InputError(f"rb must be RecordingBounds, got {type(rb).__name__}")
    if rb.q_meas.shape[1] != kin.n or rb.xi_lo.shape != (kin.m,):
        raise InputError(f"recording has {rb.q_meas.shape[1]} joints and {rb.xi_lo.size} parameters; "
                         f"{kin.robot.name} needs {kin.n} and {kin.m}")
    xs = 0.5 * (rb.xi_lo + rb.xi_hi) if xi_start is None else _vector("xi_start", xi_start, kin.m)
    if np.any(xs < rb.xi_lo) or np.any(xs > rb.xi_hi):
        raise InputError(f"xi_start = {xs.tolist()} lies outside the calibration box")
    ce, status, iters, elapsed, nv, ng = _build_and_solve(
        kin, rb, xs, max_iter=max_iter, max_cpu_time=max_cpu_time, print_level=print_level)
    if ce is None:
        return BounceSearch(False, False, status, iters, elapsed, nv, ng, xs)
    ver = verify_bounce(kin, ce, rb, dense=dense)
    return BounceSearch(True, ver.ok, status, iters, elapsed, nv, ng, xs, ce, ver)


# ----------------------------------------------------------- verification
def verify_bounce(kin: KinematicModel, ce: Counterexample, rb: RecordingBounds, *, dense: int = 8,
                  require_dense_mode: bool = True) -> Verification:
    """Check a candidate counterexample independently of the NLP (numpy and the robot's numeric kinematics).

    The motion checked is the piecewise quadratic re-integrated from
    ``ce.x[0]``, ``ce.v[0]`` and ``ce.u`` (so it is C^1 with ``x'' = u_k`` on
    each interval by construction); the candidate's own states must agree with
    it to ``STATE_TOL``.  Then, with no tolerance beyond what is stated:

    1. ``xi`` lies in ``[xi_lo, xi_hi]`` and ``|u_k,i| <= a_max_i``; ``|v_0| <= v0_max``
       and ``|v_k| <= v_max`` (velocity is linear per interval: samples suffice);
    2. at every sample the joints ``q_ik`` re-solved by the robot's IK (Newton
       from ``q_meas[k]``, which selects the leg branch) satisfy
       ``|q_ik - q_meas| + |d| <= eps_q``, ``d = J_q^{-1} f`` the remaining
       Newton correction (bounds the IK's own error); ``ce.q`` lies in the
       intervals and within ``BRANCH_TOL`` of ``q_ik``;
    3. the mode is ``m0`` at every sample (``KinematicModel.mode_batch``, nonzero);
    4. between samples, at ``dense`` points per interval, the IK continues from
       ``q_ik[k]`` without failure, stays in the workspace box, lands within
       ``BRANCH_TOL`` of ``q_ik[k+1]`` (same leg branches), and, if
       ``require_dense_mode``, the mode stays ``m0`` (stricter than the claim
       needs; a numerical check at finitely many points, not a proof).

    Parameters
    ----------
    kin : KinematicModel
    ce : Counterexample
    rb : RecordingBounds
    dense : int
        Points per interval for check 4 (``0`` skips it).
    require_dense_mode : bool
        Count dense mode violations as failures.

    Returns
    -------
    Verification
    """
    if not isinstance(ce, Counterexample):
        raise InputError(f"ce must be a Counterexample, got {type(ce).__name__}")
    K, n = rb.n_samples, kin.n
    fails: list[str] = []
    xi = np.asarray(ce.xi, dtype=float)
    x, v, u, q = (np.asarray(a, dtype=float) for a in (ce.x, ce.v, ce.u, ce.q))
    if x.shape != (K, n) or v.shape != (K, n) or q.shape != (K, n) or u.shape != (K - 1, n) or xi.shape != (kin.m,):
        raise InputError("counterexample arrays do not match the recording's shape")
    if not all(np.all(np.isfinite(a)) for a in (xi, x, v, u, q)):
        return Verification(False, ("non-finite values",), math.inf, math.inf, math.inf, -math.inf, K * dense, K * dense, math.inf)
    if ce.m0 != rb.m0 or abs(ce.t_s - rb.t_s) > 0:
        fails.append("mode or sampling period differs from the recording's")

    xi_excess = float(max(np.max(rb.xi_lo - xi), np.max(xi - rb.xi_hi), 0.0))
    if xi_excess > 0:
        fails.append(f"geometry outside the calibration box by {xi_excess:.3g}")
    accel_ratio = float(np.max(np.abs(u) / rb.a_max))
    if accel_ratio > 1.0:
        fails.append(f"|u| reaches {accel_ratio:.6g} a_max")

    xs, vs = _integrate(x[0], v[0], u, rb.t_s)
    mismatch = float(max(np.max(np.abs(xs - x)), rb.t_s * np.max(np.abs(vs - v))))
    if mismatch > STATE_TOL:
        fails.append(f"states disagree with the integrated accelerations by {mismatch:.3g} m")
    if rb.v0_max is not None and np.any(np.abs(vs[0]) > rb.v0_max):
        fails.append("initial velocity outside v0_max")
    if rb.v_max is not None and np.any(np.abs(vs) > rb.v_max):
        fails.append("velocity above v_max")
    if rb.x_lo is not None and (np.any(xs < rb.x_lo) or np.any(xs > rb.x_hi)):
        fails.append("pose outside the workspace box at a sample")

    # 2. joints: IK of the integrated poses, branch picked by the measurement.
    q_ik, ok = kin.ik_batch(xs, xi, rb.q_meas)
    if not ok.all():
        fails.append(f"IK fails at {int(np.count_nonzero(~ok))} samples")
    jq = kin.jac_q_batch(xs, q_ik, xi)
    resid = kin.f_batch(xs, q_ik, xi)
    with np.errstate(all="ignore"):
        corr = np.abs(np.linalg.solve(jq, resid[..., None])[..., 0])
    joint_ratio = float(np.max((np.abs(q_ik - rb.q_meas) + corr) / rb.eps_q))
    if not joint_ratio <= 1.0:
        fails.append(f"re-solved joints leave their intervals: max |q - q_meas| = {joint_ratio:.6g} eps_q")
    q_ratio = float(np.max(np.abs(q - rb.q_meas) / rb.eps_q))
    if q_ratio > 1.0:
        fails.append(f"candidate joints leave their intervals: max |q - q_meas| = {q_ratio:.6g} eps_q")
    if np.max(np.abs(q - q_ik)) > BRANCH_TOL:
        fails.append("candidate joints are not the IK of its poses")

    # 3. mode at the samples.
    modes = kin.mode_batch(xs, q_ik, xi)
    mode_margin = float(np.min(rb.m0 * kin.normalised_mode_batch(xs, q_ik, xi)))
    if np.any(modes != rb.m0):
        fails.append(f"mode differs from {rb.m0:+d} at {int(np.count_nonzero(modes != rb.m0))} samples")

    # 4. dense continuation between samples (all intervals advance together).
    dense_mode_bad = dense_ik_bad = 0
    if dense > 0 and ok.all():
        qc = q_ik[:-1].copy()
        live = np.ones(K - 1, dtype=bool)
        for j in range(1, dense + 1):
            tau = rb.t_s * j / dense
            xd = xs[:-1] + tau * vs[:-1] + 0.5 * tau * tau * u
            qn, okj = kin.ik_batch(xd, xi, qc)
            if rb.x_lo is not None:
                okj &= np.all((xd >= rb.x_lo) & (xd <= rb.x_hi), axis=1)
            live &= okj
            qc = np.where(okj[:, None], qn, qc)
            if j < dense:
                mj = kin.mode_batch(xd, qc, xi)
                dense_mode_bad += int(np.count_nonzero(live & (mj != rb.m0)))
        live &= np.max(np.abs(qc - q_ik[1:]), axis=1) <= BRANCH_TOL
        dense_ik_bad = int(np.count_nonzero(~live))
        if dense_ik_bad:
            fails.append(f"IK continuation fails or switches branch in {dense_ik_bad} intervals")
        if require_dense_mode and dense_mode_bad:
            fails.append(f"mode differs from {rb.m0:+d} at {dense_mode_bad} points between samples")
    elif dense > 0:
        dense_ik_bad = K - 1
    return Verification(not fails, tuple(fails), joint_ratio, accel_ratio, xi_excess, mode_margin,
                        dense_mode_bad, dense_ik_bad, mismatch)


# ------------------------------------------------------------------ sweep
def refutation_bound(kin: KinematicModel, make_recording: Callable[[float], tuple], speeds: Sequence[float], *,
                     m0: int = 1, xi_starts: Sequence | None = None, bounds: dict | None = None,
                     max_iter: int = 3000, max_cpu_time: float = 120.0, dense: int = 8,
                     progress: Callable[[SpeedRefutation], None] | None = None) -> RefutationBound:
    """Counterexample search at several speeds; the largest refuted speed bounds certification from below.

    Parameters
    ----------
    kin : KinematicModel
    make_recording : callable
        ``make_recording(speed) -> (q_meas, t_s)``: the recording at that speed
        (e.g. a simulated crossing), ``q_meas`` (K, n) rad, ``t_s`` s.
    speeds : sequence of float
        Speeds to try, m/s (any order).
    m0 : int
        Initial assembly mode, +1 or -1.
    xi_starts : sequence of array_like (m,), optional
        Starting geometries tried in order until one gives a verified
        counterexample (the NLP is non-convex).  Default: the box centre.
    bounds : dict, optional
        Overrides of :meth:`RecordingBounds.for_model` (``eps_q``, ``a_max``,
        ``xi_lo``, ``xi_hi``, ``v0_max``, ``v_max``, ``x_lo``, ``x_hi``).
    max_iter, max_cpu_time, dense
        Passed to :func:`search_bounce` (per attempt).
    progress : callable, optional
        Called with each :class:`SpeedRefutation` as it completes.

    Returns
    -------
    RefutationBound
    """
    if not isinstance(kin, KinematicModel):
        raise InputError(f"kin must be a KinematicModel, got {type(kin).__name__}")
    if not callable(make_recording):
        raise InputError("make_recording must be callable: speed -> (q_meas, t_s)")
    rows = []
    for speed in speeds:
        q_meas, t_s = make_recording(speed)
        rb = RecordingBounds.for_model(kin, q_meas, t_s, m0, **(bounds or {}))
        starts = [None] if not xi_starts else list(xi_starts)
        attempts = []
        for xs in starts:
            att = search_bounce(kin, rb, xi_start=xs, max_iter=max_iter, max_cpu_time=max_cpu_time, dense=dense)
            attempts.append(att)
            if att.verified:
                break
        best = next((a for a in attempts if a.verified), None)
        conv = [a for a in attempts if a.found]
        dec = best or (conv[-1] if conv else attempts[-1])
        ver = dec.verification
        row = SpeedRefutation(
            speed=float(speed), n_samples=rb.n_samples, found=bool(conv), verified=best is not None,
            geometry=None if dec.counterexample is None else dec.counterexample.xi.copy(),
            joint_ratio=math.nan if ver is None else ver.joint_ratio,
            accel_ratio=math.nan if ver is None else ver.accel_ratio,
            mode_margin=math.nan if ver is None else ver.mode_margin,
            status=dec.status, solve_time=float(sum(a.solve_time for a in attempts)),
            attempts=tuple(attempts),
        )
        rows.append(row)
        if progress is not None:
            progress(row)
    refuted = [r.speed for r in rows if r.verified]
    return RefutationBound(tuple(rows), max(refuted) if refuted else None)
