"""A time scaling sampled at a fixed period: the joint trajectory the tracker and simulator consume.

Named ``resampling`` so that the module does not shadow the function
:func:`resample` re-exported by :mod:`planner.timescale`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from crosscert.robots.assumptions import check_bound
from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError, SimulationError
from crosscert.verifier.trajectory import Trajectory

from ..sampling import ALIGN_TOL
from .path import BRANCH_JUMP, PathSamples
from .reachability import HermitePath
from .socp import TimeScaling

__all__ = ["TimedTrajectory", "resample"]


@dataclass(frozen=True, kw_only=True, eq=False)
class TimedTrajectory(Trajectory):
    """A time scaling sampled at a fixed period: what the tracker and simulator consume.

    ``K`` samples at ``t_k = k t_s``, ``n`` joints and pose coordinates;
    arrays are read-only.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Sample times, s.
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

    s: np.ndarray
    sd: np.ndarray
    sdd: np.ndarray
    t_start: float
    k_star: int | None

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("s", "sd", "sdd"):
            v = V.frozen_array(getattr(self, name))
            if v.shape != self.t.shape:
                raise InputError(f"{name} has shape {v.shape}, expected {self.t.shape} like t")
            object.__setattr__(self, name, v)


def resample(scaling: TimeScaling, samples: PathSamples, t_s: float, *, t_rest: float = 0.0,
             t_rest_end: float = 0.0) -> TimedTrajectory:
    """Sample a time scaling at a fixed period, exactly within its model.

    On interval ``i`` the path acceleration ``a_i`` is constant, so with
    ``tau = t - t_i``: ``s = s_i + sd_i tau + a_i tau^2 / 2`` and
    ``sdot = sd_i + a_i tau`` (piecewise quadratic ``s(t)``).  Then
    ``x = x(s)``, ``xdot = x' sdot``, ``xddot = x' sddot + x'' sdot^2`` (``x' = u``, ``x'' = 0`` on a straight path),
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
        The path the scaling was computed on, ``N + 1`` nodes.
    t_s : float
        Sampling period, s.
    t_rest, t_rest_end : float
        Minimum rest before and after the motion, s (only at ends at rest).

    Returns
    -------
    TimedTrajectory
        ``K`` samples.

    Raises
    ------
    InputError
        Mismatched grid, bad period, rest around a scaling that does not
        start or end at rest.
    SimulationError
        IK fails at a sample.
    """
    t_s, t_rest, t_rest_end = _checked_arguments(scaling, samples, t_s, t_rest, t_rest_end)
    t_anchor, j_lo, j_hi = _sample_range(scaling, t_s, t_rest, t_rest_end)
    j = np.arange(j_lo, j_hi + 1)
    tau = t_anchor + j * t_s
    s, sd, sdd = _evaluate(scaling, tau)
    X, d1, d2 = samples.poses(s)
    XD = d1 * sd[:, None]
    XDD = d1 * sdd[:, None] + d2 * (sd * sd)[:, None]
    if scaling.k_star is not None:  # the crossing sample lies exactly on the node
        X[-j_lo] = samples.x[scaling.k_star]
    Q, QD, QDD = _joints(samples, s, X, XD, XDD)
    return TimedTrajectory(
        t=(j - j_lo) * t_s, s=s, sd=sd, sdd=sdd, x=X, xd=XD, xdd=XDD, q=Q, qd=QD, qdd=QDD,
        t_s=t_s, t_start=float(-(t_anchor + j_lo * t_s)),
        k_star=None if scaling.k_star is None else int(-j_lo),
    )


def _checked_arguments(scaling, samples, t_s, t_rest, t_rest_end) -> tuple[float, float, float]:
    """The arguments of :func:`resample` checked: ``t_s``, ``t_rest`` and ``t_rest_end`` (s) as floats.

    Raises
    ------
    InputError
        As :func:`resample`.
    """
    if not isinstance(scaling, TimeScaling) or not isinstance(samples, PathSamples):
        raise InputError("resample needs a TimeScaling and the PathSamples it was computed on")
    if scaling.s.shape != samples.s.shape or np.any(scaling.s != samples.s):
        raise InputError("the scaling was computed on another grid than these samples")
    t_s = check_bound("t_s", t_s)
    t_rest = V.positive("t_rest", t_rest, allow_zero=True)
    t_rest_end = V.positive("t_rest_end", t_rest_end, allow_zero=True)
    if (t_rest > 0 and scaling.b[0] != 0.0) or (t_rest_end > 0 and scaling.b[-1] != 0.0):
        raise InputError("t_rest/t_rest_end need a scaling that starts/ends at rest")
    return t_s, t_rest, t_rest_end


def _sample_range(scaling: TimeScaling, t_s: float, t_rest: float, t_rest_end: float) -> tuple[float, int, int]:
    """The anchor ``t_anchor`` (s) of the sample clock and the first and last sample indices ``j_lo, j_hi``.

    Samples lie at motion times ``tau_j = t_anchor + j t_s``, ``t_anchor`` the
    crossing instant (0 without one).  At a resting end, samples cover at
    least the requested rest (``t_rest``, ``t_rest_end``, s; held state); at
    a moving end none lies outside ``[0, T]``.
    """
    T = scaling.total_time
    t_anchor = 0.0 if scaling.k_star is None else float(scaling.t[scaling.k_star])
    # (planner.sampling.align_to_samples rounds the end down, so it is not used here.)
    lo, hi = (t_anchor + t_rest) / t_s, (T + t_rest_end - t_anchor) / t_s
    j_lo = -(math.ceil(lo - ALIGN_TOL) if scaling.b[0] == 0.0 else math.floor(lo + ALIGN_TOL))
    j_hi = math.ceil(hi - ALIGN_TOL) if scaling.b[-1] == 0.0 else math.floor(hi + ALIGN_TOL)
    return t_anchor, j_lo, j_hi


def _joints(samples: PathSamples, s: np.ndarray, X: np.ndarray, XD: np.ndarray, XDD: np.ndarray):
    """Joints (rad) by Newton IK at the poses ``X`` (m), started on the samples' branch; their rates (eq. (2)).

    The IK starts from the quintic Hermite interpolation of the samples' joints
    at the arc lengths ``s`` (m); ``XD``, ``XDD`` are the pose's velocity (m/s)
    and acceleration (m/s^2).  Returns ``Q, QD, QDD`` (rad, rad/s, rad/s^2).

    Raises
    ------
    SimulationError
        IK fails at a sample, or lands on another branch.
    """
    n = samples.x.shape[1]
    path = HermitePath(samples.s, samples.q, samples.q_s, samples.q_ss)
    kin = samples.kin
    Qg = path(np.clip(s, 0.0, samples.length), 0).reshape(-1, n)
    Q, ok = kin.ik_batch(X, samples.xi, Qg)
    if not ok.all():
        bad = int(np.nonzero(~ok)[0][0])
        raise SimulationError(f"resample: IK failed at s = {s[bad] * 1e3:.4f} mm")
    if np.max(np.abs(Q - Qg)) > BRANCH_JUMP:
        raise SimulationError("resample: IK left the samples' branch (grid too coarse?)")
    QD = kin.joint_velocity(X, Q, samples.xi, XD)
    QDD = kin.joint_acceleration(X, Q, samples.xi, XD, QD, XDD)
    return Q, QD, QDD


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
