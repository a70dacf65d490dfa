"""Independent check of a generated crossing, on the samples, with numpy only.

The NLP solution is trusted for nothing but the sampled poses: the joints are
recomputed by IK continuation along them (not taken from the NLP), the rates
by the kinematics, the torques by the dynamics and the uncontrolled direction
by an SVD of ``J_x``; then every requirement is re-checked on the samples:
loop closure, modes, branch, speed and position at the crossing sample, the
criterion residual (<= ``criterion_tol`` N) and every limit (relative
tolerance :data:`LIMIT_RTOL`).  Any failure raises :class:`CheckFailed`
(:class:`LimitExceeded` for a limit).

This module does not depend on the NLP (:mod:`.nlp`): it reads samples.
"""

from __future__ import annotations

import numpy as np

from crosscert.robots.errors import SimulationError

from .types import CheckFailed, LimitExceeded, Samples

__all__ = ["CRITERION_TOL", "LIMIT_RTOL", "check_plan"]

#: Relative tolerance of the a-posteriori limit check on the samples.
LIMIT_RTOL = 1e-6
#: Default bound on the criterion residual ``|t_s^T w_x|`` at the crossing sample, N.
CRITERION_TOL = 1e-8
#: Largest loop-closure residual ``|f(x, q, xi)|`` of the IK continuation (Newton converges far below).
_LOOP_CLOSURE_TOL = 1e-10
#: Start sample vs ``task.start``, m: the first node is fixed exactly, so only rounding is allowed.
_START_ATOL = 1e-12
#: Last sample vs ``task.goal``, m: the goal node is fixed, the sample may be reached through the last cubic.
_GOAL_ATOL = 1e-9
#: Relative error of ``|xd|`` at the crossing sample vs ``v_sing``: IPOPT meets the equality far tighter.
_SPEED_RTOL = 1e-6
#: Slack of the branch test of the NLP joints, rad (rounding of the bound ``qd_max * dt``).
_BRANCH_SLACK = 1e-9


def _check(cond: bool, what: str) -> None:
    if not cond:
        raise CheckFailed(what)


def check_plan(kin, dyn, task, point, m0, v_sing, lim, torque, xi, samples: Samples, node_q, criterion_tol):
    """Recompute joints, rates, torques and the criterion on the samples; raise on any failure.

    Parameters
    ----------
    kin, dyn : KinematicModel, LumpedDynamics
    task : CrossingTask
    point : ndarray, shape (n,)
        Crossing point, m.
    m0 : int
        Assembly mode before the crossing (+1 or -1).
    v_sing : float
        Prescribed speed at the crossing, m/s.
    lim : dict
        :meth:`GenerationLimits.resolved` arrays.
    torque : bool
        Check the actuator torque limits.
    xi : ndarray, shape (m,)
        Planning geometry.
    samples : Samples
        The sampled solution (K samples).
    node_q : ndarray, shape (N+1, n)
        NLP joints at the nodes, rad (checked to lie on the continuation's branch).
    criterion_tol : float
        Largest accepted ``|t_s^T w_x|`` at the crossing sample, N.

    Returns
    -------
    Q, QD, QDD, tau : ndarray, shape (K, n)
        Joints (rad), rates (rad/s, rad/s^2), torques (N m).
    crit : float
        Criterion residual at the crossing sample, N.
    modes : (int, int)
        Assembly modes at the first and last sample.
    peak : dict
        Largest ``|value| / limit`` of every imposed limit.

    Raises
    ------
    CheckFailed
        On any failed requirement; :class:`LimitExceeded` when a limit is
        exceeded by more than :data:`LIMIT_RTOL`.
    """
    t, X, XD, XDD, XDDD, k_sing = samples.t, samples.x, samples.xd, samples.xdd, samples.xddd, samples.k_sing
    Q, QD, QDD = _joints(kin, task, xi, X, XD, XDD)
    modes = _check_motion(kin, task, point, m0, v_sing, xi, samples, Q)
    _check_branch(t, samples.node_t, node_q, Q, lim["qd_max"])
    # t_s recomputed from the sampled configuration (SVD of J_x), not taken from the NLP
    crit = float(dyn.criterion_residual(X[k_sing], Q[k_sing], XD[k_sing], XDD[k_sing], xi)[0])
    _check(abs(crit) <= criterion_tol, f"criterion residual {crit:.3g} N > {criterion_tol:.3g} N")
    tau = np.empty_like(QD)
    reg = np.arange(t.size) != k_sing
    tau[reg] = dyn.torques(X[reg], Q[reg], XD[reg], XDD[reg], xi)
    tau[k_sing] = dyn.singular_torques(X[k_sing], Q[k_sing], XD[k_sing], XDD[k_sing], XDDD[k_sing], xi)
    _check(np.all(np.isfinite(tau)), "torques finite")
    peak = _peaks(dyn, lim, torque, QD, QDD, tau, XDD, XDDD)
    return Q, QD, QDD, tau, crit, (int(modes[0]), int(modes[-1])), peak


def _joints(kin, task, xi, X, XD, XDD):
    """Joints (rad) by IK continuation along the sampled poses ``X`` (m), and their rates (rad/s, rad/s^2).

    Raises
    ------
    CheckFailed
        If the IK continuation fails.
    """
    try:
        Q = kin.ik_path(X, xi, task.working_guess)
    except SimulationError as exc:
        raise CheckFailed("IK continuation", f"generated trajectory failed the independent check: {exc}") from None
    QD = kin.joint_velocity(X, Q, xi, XD)
    QDD = kin.joint_acceleration(X, Q, xi, XD, QD, XDD)
    return Q, QD, QDD


def _check_motion(kin, task, point, m0, v_sing, xi, samples: Samples, Q) -> np.ndarray:
    """Check loop closure, start and goal at rest, the crossing sample's pose and speed, the modes and Type 1.

    Returns the assembly modes at the samples; raises :class:`CheckFailed` on
    the first failed requirement.
    """
    X, XD, k_sing = samples.x, samples.xd, samples.k_sing
    _check(np.abs(kin.f_batch(X, Q, xi)).max() <= _LOOP_CLOSURE_TOL, "loop closure")
    _check(np.allclose(X[0], task.start, atol=_START_ATOL, rtol=0)
           and np.allclose(X[-1], task.goal, atol=_GOAL_ATOL, rtol=0), "start/goal poses")
    _check(np.all(XD[[0, -1]] == 0.0), "rest at start and goal")
    _check(np.array_equal(X[k_sing], point), "crossing point at the crossing sample")
    speed = float(np.linalg.norm(XD[k_sing]))
    _check(abs(speed - v_sing) <= _SPEED_RTOL * v_sing, f"|xd| = {speed} m/s at the crossing, v_sing = {v_sing}")
    modes = kin.mode_batch(X, Q, xi)
    _check(np.all(modes[:k_sing] == m0) and np.all(modes[k_sing + 1:] == -m0),
           f"assembly mode {m0:+d} before and {-m0:+d} after the crossing sample")
    detq = np.linalg.det(kin.jac_q_batch(X, Q, xi))
    _check(np.all(np.sign(detq) == np.sign(detq[0])) and np.all(detq != 0), "working mode of the legs (Type 1)")
    return modes


def _check_branch(t, node_t, node_q, Q, qd_max) -> None:
    """Check the NLP joints ``node_q`` (rad) at times ``node_t`` (s) lie on the continuation's branch ``Q``.

    Each must be within one sample of motion at ``qd_max`` (rad/s) of the
    continuation's joints at the nearest sample, else :class:`CheckFailed`.
    """
    idx = np.clip(np.searchsorted(t, node_t), 0, t.size - 1)
    step = float(t[1] - t[0]) if t.size > 1 else 0.0
    reach = qd_max * (step + np.abs(t[idx] - node_t))[:, None] + _BRANCH_SLACK
    _check(np.all(np.abs(node_q - Q[idx]) <= reach), "NLP joints off the IK-continuation branch")


def _peaks(dyn, lim, torque, QD, QDD, tau, XDD, XDDD) -> dict:
    """Largest ``|value| / limit`` of every imposed limit; :class:`LimitExceeded` above ``1 + LIMIT_RTOL``."""
    peak = {"qd": float(np.max(np.abs(QD) / lim["qd_max"])), "qdd": float(np.max(np.abs(QDD) / lim["qdd_max"]))}
    if torque:
        peak["tau"] = float(np.max(np.abs(tau) / dyn.model.tau_max_array))
    if lim["a_max"] is not None:
        peak["xdd"] = float(np.max(np.abs(XDD) / lim["a_max"]))
    if lim["jerk_max"] is not None:
        peak["jerk"] = float(np.max(np.abs(XDDD) / lim["jerk_max"]))
    worst = max(peak, key=peak.get)
    if peak[worst] > 1.0 + LIMIT_RTOL:
        raise LimitExceeded(worst, peak[worst])
    return peak
