"""The trusted check of a counterexample, independent of the search that produced it.

This is the code to read to trust a counterexample.  It uses numpy and the
robot's numeric kinematics (:class:`~robots.kinematics.KinematicModel`) only:
no optimisation problem is built here and nothing of the NLP is reused, so a
wrong NLP can at worst propose a candidate that this check rejects.

Why the NLP constrains the mode at the samples only: a tracker's verdict is a
statement about the mode *at sample times* (at the step where it certifies).
A motion whose mode equals ``m0`` at every sample refutes every such verdict,
even if it touched or crossed the locus between two samples, provided it is a
real motion: the joints must follow ``x(t)`` continuously on their leg
branches.  :func:`verify_bounce` therefore follows the IK along ``x(t)``
densely between samples, and by default it also requires the mode to stay
``m0`` at every dense point (a genuine bounce, never crossing).  Dense
evaluation at finitely many points is a numerical check, not a proof that the
mode never flips between two of them; it is stricter than the claim needs,
not weaker.

A *crossing* (:func:`verify_crossing`) must be in mode ``m0`` at the first
sample and in ``-m0`` at the last: a tracker's verdict compares those two
modes.  What happens in between is free (by continuity the motion meets the
locus somewhere); the dense check still follows the IK between every two
samples, so the motion is a real one on the measured leg branches.
"""

from __future__ import annotations

import math

import numpy as np

from crosscert.robots.errors import InputError
from crosscert.robots.kinematics import KinematicModel

from .problem import Counterexample, CounterexampleKind, RecordingBounds, integrate_states
from .results import Verification

__all__ = ["BRANCH_TOL", "DENSE_POINTS", "STATE_TOL", "verify_bounce", "verify_counterexample", "verify_crossing"]

#: Largest disagreement (m) between the NLP's sample poses and the trajectory
#: re-integrated from ``x_0, v_0`` and the accelerations (velocities: divided by ``t_s``).
STATE_TOL = 1e-9
#: After IK continuation over one interval, the joints must land within this
#: distance (rad) of the sample's own IK: the leg branches did not switch.
BRANCH_TOL = 1e-7
#: Default points per interval of the dense check: enough to follow the IK
#: continuation of the benchmark crossing; more only costs time.
DENSE_POINTS = 8


def verify_bounce(kin: KinematicModel, ce: Counterexample, rb: RecordingBounds, *, dense: int = DENSE_POINTS,
                  require_dense_mode: bool = True) -> Verification:
    """Check a candidate counterexample independently of the NLP (numpy and the robot's numeric kinematics).

    The motion checked is the piecewise quadratic re-integrated from
    ``ce.x[0]``, ``ce.v[0]`` and ``ce.u`` (so it is C^1 with ``x'' = u_k`` on
    each interval by construction); the candidate's own states must agree with
    it to ``STATE_TOL``.  Then, with no tolerance beyond what is stated:

    0. every value is finite, ``ce.m0`` and ``ce.t_s`` are the recording's,
       ``ce.kind`` is :attr:`CounterexampleKind.BOUNCE`;
    1. ``xi`` lies in ``[xi_lo, xi_hi]`` and ``|u_k,i| <= a_max_i``; ``|v_0| <= v0_max``
       and ``|v_k| <= v_max`` (velocity is linear per interval: samples suffice);
       the sample poses lie in ``[x_lo, x_hi]``;
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
        The robot's kinematics.
    ce : Counterexample
        The candidate: ``xi`` (m,), ``x``, ``v``, ``q`` (K, n), ``u`` (K - 1, n), SI.
    rb : RecordingBounds
        The recording and the bounds the candidate must respect.
    dense : int
        Points per interval for check 4 (``0`` skips it).
    require_dense_mode : bool
        Count dense mode violations as failures.

    Returns
    -------
    Verification
        ``ok`` when every check passed, the failed checks' messages and the figures.

    Raises
    ------
    InputError
        If ``ce`` is not a Counterexample or its arrays do not match the recording's shape.
    """
    return verify_counterexample(kin, ce, rb, CounterexampleKind.BOUNCE, dense=dense, require_dense_mode=require_dense_mode)


def verify_crossing(kin: KinematicModel, ce: Counterexample, rb: RecordingBounds, *,
                    dense: int = DENSE_POINTS) -> Verification:
    """Check a candidate *crossing* independently of the NLP (numpy and the robot's numeric kinematics).

    The same checks as :func:`verify_bounce` (re-integrated piecewise
    quadratic, finite values, geometry in ``[xi]``, ``|u| <= a_max``, velocity
    and workspace bounds, re-solved joints within ``eps_q`` at every sample,
    IK continuation on the same leg branches between samples), except for the
    modes: ``KinematicModel.mode_batch`` must give ``m0`` at the first sample
    and ``-m0`` at the last, both nonzero (``|normalised mode| >=
    robots.kinematics.MODE_RTOL``); ``ce.kind`` must be
    :attr:`CounterexampleKind.CROSSING`.

    Parameters
    ----------
    kin : KinematicModel
        The robot's kinematics.
    ce : Counterexample
        The candidate: ``xi`` (m,), ``x``, ``v``, ``q`` (K, n), ``u`` (K - 1, n), SI.
    rb : RecordingBounds
        The recording and the bounds the candidate must respect.
    dense : int
        IK continuation points per interval (``0`` skips that check).

    Returns
    -------
    Verification
        ``ok`` when every check passed; ``mode_margin`` is
        ``min(m0 n_0, -m0 n_{K-1})`` of the normalised modes ``n_k``;
        ``dense_mode_violations`` is 0 (not counted for a crossing).

    Raises
    ------
    InputError
        If ``ce`` is not a Counterexample or its arrays do not match the recording's shape.
    """
    return verify_counterexample(kin, ce, rb, CounterexampleKind.CROSSING, dense=dense)


def verify_counterexample(kin: KinematicModel, ce: Counterexample, rb: RecordingBounds, kind: CounterexampleKind, *,
           dense: int = DENSE_POINTS, require_dense_mode: bool = True) -> Verification:
    """Check a candidate of either kind: :func:`verify_bounce` or :func:`verify_crossing` by ``kind``.

    Check 3 of :func:`verify_bounce` (the modes at the samples) is the only one
    that depends on ``kind``; for a crossing it is replaced by "mode ``m0`` at
    the first sample and ``-m0`` at the last" and no mode is required between
    samples (``require_dense_mode`` then has no effect).

    Raises
    ------
    InputError
        If ``ce`` is not a Counterexample, its arrays do not match the
        recording's shape, or ``kind`` is not a :class:`CounterexampleKind`.
    """
    kind, (xi, x, v, u, q) = _candidate(kin, ce, rb, kind)
    K = rb.n_samples
    if not all(np.all(np.isfinite(a)) for a in (xi, x, v, u, q)):
        return Verification(False, ("non-finite values",), math.inf, math.inf, math.inf, -math.inf,
                            K * dense, K * dense, math.inf)
    fails: list[str] = []
    if ce.m0 != rb.m0 or abs(ce.t_s - rb.t_s) > 0:
        fails.append("mode or sampling period differs from the recording's")
    if ce.kind is not kind:
        fails.append(f"candidate is a {ce.kind.value}, checked as a {kind.value}")
    xi_excess, accel_ratio, xs, vs, mismatch = _check_bounds(rb, xi, x, v, u, fails)
    q_ik, ok, joint_ratio = _check_joints(kin, rb, xs, xi, q, fails)
    mode_margin = _check_sample_modes(kin, rb, kind, xs, q_ik, xi, fails)
    dense_mode = require_dense_mode and kind is CounterexampleKind.BOUNCE
    dense_mode_bad = dense_ik_bad = 0
    if dense > 0 and ok.all():
        dense_mode_bad, dense_ik_bad = _check_dense(kin, rb, xs, vs, u, q_ik, xi, dense, dense_mode, fails)
    elif dense > 0:
        dense_ik_bad = K - 1
    return Verification(not fails, tuple(fails), joint_ratio, accel_ratio, xi_excess, mode_margin,
                        dense_mode_bad, dense_ik_bad, mismatch)


def _candidate(kin: KinematicModel, ce: Counterexample, rb: RecordingBounds, kind):
    """The checked ``kind`` and the candidate's arrays ``(xi, x, v, u, q)`` as float ndarrays (SI).

    Raises
    ------
    InputError
        If ``kind`` is not a :class:`CounterexampleKind`, ``ce`` is not a
        Counterexample, or its arrays do not match the recording's shape.
    """
    try:
        kind = CounterexampleKind(kind)
    except ValueError:
        raise InputError(f"kind must be one of {[k.value for k in CounterexampleKind]}, got {kind!r}") from None
    if not isinstance(ce, Counterexample):
        raise InputError(f"ce must be a Counterexample, got {type(ce).__name__}")
    K, n = rb.n_samples, kin.n
    xi = np.asarray(ce.xi, dtype=float)
    x, v, u, q = (np.asarray(a, dtype=float) for a in (ce.x, ce.v, ce.u, ce.q))
    if x.shape != (K, n) or v.shape != (K, n) or q.shape != (K, n) or u.shape != (K - 1, n) or xi.shape != (kin.m,):
        raise InputError("counterexample arrays do not match the recording's shape")
    return kind, (xi, x, v, u, q)


def _check_bounds(rb: RecordingBounds, xi, x, v, u, fails: list[str]):
    """Check 1: geometry, acceleration, velocity and workspace bounds, on the re-integrated motion.

    Appends a message to ``fails`` for each failed bound.

    Returns
    -------
    xi_excess : float
        Largest distance (SI) of ``xi`` outside ``[xi_lo, xi_hi]``.
    accel_ratio : float
        ``max |u| / a_max``.
    xs, vs : ndarray, shape (K, n)
        Poses (m) and velocities (m/s) re-integrated from ``x[0]``, ``v[0]`` and ``u``.
    mismatch : float
        Largest disagreement of the candidate's states with them, m.
    """
    xi_excess = float(max(np.max(rb.xi_lo - xi), np.max(xi - rb.xi_hi), 0.0))
    if xi_excess > 0:
        fails.append(f"geometry outside the calibration box by {xi_excess:.3g}")
    accel_ratio = float(np.max(np.abs(u) / rb.a_max))
    if accel_ratio > 1.0:
        fails.append(f"|u| reaches {accel_ratio:.6g} a_max")

    xs, vs = integrate_states(x[0], v[0], u, rb.t_s)
    mismatch = float(max(np.max(np.abs(xs - x)), rb.t_s * np.max(np.abs(vs - v))))
    if mismatch > STATE_TOL:
        fails.append(f"states disagree with the integrated accelerations by {mismatch:.3g} m")
    if rb.v0_max is not None and np.any(np.abs(vs[0]) > rb.v0_max):
        fails.append("initial velocity outside v0_max")
    if rb.v_max is not None and np.any(np.abs(vs) > rb.v_max):
        fails.append("velocity above v_max")
    if rb.x_lo is not None and (np.any(xs < rb.x_lo) or np.any(xs > rb.x_hi)):
        fails.append("pose outside the workspace box at a sample")
    return xi_excess, accel_ratio, xs, vs, mismatch


def _check_joints(kin: KinematicModel, rb: RecordingBounds, xs, xi, q, fails: list[str]):
    """Check 2: the IK of the poses ``xs`` (m), leg branch picked by the measurement, against the intervals.

    Appends a message to ``fails`` for each failed requirement.

    Returns
    -------
    q_ik : ndarray, shape (K, n)
        Re-solved joints, rad.
    ok : ndarray of bool, shape (K,)
        Samples where the IK converged.
    joint_ratio : float
        ``max (|q_ik - q_meas| + |Newton correction|) / eps_q``.
    """
    q_ik, ok = kin.ik_batch(xs, xi, rb.q_meas)
    if not ok.all():
        fails.append(f"IK fails at {int(np.count_nonzero(~ok))} samples")
    jq = kin.jac_q_batch(xs, q_ik, xi)
    resid = kin.f_batch(xs, q_ik, xi)
    with np.errstate(all="ignore"):
        corr = np.abs(np.linalg.solve(jq, resid[..., None])[..., 0])
    joint_ratio = float(np.max((np.abs(q_ik - rb.q_meas) + corr) / rb.eps_q))
    if not joint_ratio <= 1.0:  # also catches NaN
        fails.append(f"re-solved joints leave their intervals: max |q - q_meas| = {joint_ratio:.6g} eps_q")
    q_ratio = float(np.max(np.abs(q - rb.q_meas) / rb.eps_q))
    if q_ratio > 1.0:
        fails.append(f"candidate joints leave their intervals: max |q - q_meas| = {q_ratio:.6g} eps_q")
    if np.max(np.abs(q - q_ik)) > BRANCH_TOL:
        fails.append("candidate joints are not the IK of its poses")
    return q_ik, ok, joint_ratio


def _check_sample_modes(kin: KinematicModel, rb: RecordingBounds, kind: CounterexampleKind, xs, q_ik, xi,
                        fails: list[str]) -> float:
    """Check 3: the modes at the samples, every sample's for a bounce, the first and last for a crossing.

    Appends a message to ``fails`` for each failed requirement; returns the
    mode margin (:attr:`Verification.mode_margin`).
    """
    modes = kin.mode_batch(xs, q_ik, xi)
    signed = rb.m0 * kin.normalised_mode_batch(xs, q_ik, xi)
    if kind is CounterexampleKind.BOUNCE:
        mode_margin = float(np.min(signed))
        if np.any(modes != rb.m0):
            fails.append(f"mode differs from {rb.m0:+d} at {int(np.count_nonzero(modes != rb.m0))} samples")
    else:
        mode_margin = float(min(signed[0], -signed[-1]))
        if modes[0] != rb.m0:
            fails.append(f"mode at the first sample is {int(modes[0]):+d}, not {rb.m0:+d}")
        if modes[-1] != -rb.m0:
            fails.append(f"mode at the last sample is {int(modes[-1]):+d}, not {-rb.m0:+d}")
    return mode_margin


def _check_dense(kin: KinematicModel, rb: RecordingBounds, xs, vs, u, q_ik, xi, dense: int, dense_mode: bool,
                 fails: list[str]) -> tuple[int, int]:
    """Check 4: IK continuation at ``dense`` points per interval, all intervals advancing together.

    Appends a message to ``fails`` for each failed requirement.

    Returns
    -------
    dense_mode_bad : int
        Dense points whose mode is not ``m0`` (counted only if ``dense_mode``).
    dense_ik_bad : int
        Intervals where the continuation failed, left the workspace box or
        switched leg branch.
    """
    K = xs.shape[0]
    dense_mode_bad = 0
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
        if dense_mode and j < dense:
            mj = kin.mode_batch(xd, qc, xi)
            dense_mode_bad += int(np.count_nonzero(live & (mj != rb.m0)))
    live &= np.max(np.abs(qc - q_ik[1:]), axis=1) <= BRANCH_TOL
    dense_ik_bad = int(np.count_nonzero(~live))
    if dense_ik_bad:
        fails.append(f"IK continuation fails or switches branch in {dense_ik_bad} intervals")
    if dense_mode_bad:
        fails.append(f"mode differs from {rb.m0:+d} at {dense_mode_bad} points between samples")
    return dense_mode_bad, dense_ik_bad
