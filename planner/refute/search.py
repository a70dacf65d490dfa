"""The refutation bound: counterexample searches over a family of recordings indexed by speed."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from robots.errors import InputError
from robots.kinematics import KinematicModel

from .nlp import MAX_CPU_TIME, MAX_ITER, search_bounce
from .problem import RecordingBounds
from .results import RefutationBound, SpeedRefutation, deciding_attempt
from .verify import DENSE_POINTS

__all__ = ["refutation_bound"]


def refutation_bound(kin: KinematicModel, make_recording: Callable[[float], tuple], speeds: Sequence[float], *,
                     m0: int = 1, xi_starts: Sequence | None = None, bounds: dict | None = None,
                     max_iter: int = MAX_ITER, max_cpu_time: float = MAX_CPU_TIME, dense: int = DENSE_POINTS,
                     progress: Callable[[SpeedRefutation], None] | None = None) -> RefutationBound:
    """Counterexample search at several speeds; the largest refuted speed bounds certification from below.

    Parameters
    ----------
    kin : KinematicModel
        The robot's kinematics.
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
        Passed to :func:`search_bounce` (per attempt; ``max_cpu_time`` in s).
    progress : callable, optional
        Called with each :class:`SpeedRefutation` as it completes.

    Returns
    -------
    RefutationBound
        One row per speed; a speed whose outcome is not ``FOUND`` is not
        refuted by this search, which does not mean it cannot be.

    Raises
    ------
    InputError
        If ``kin`` is not a KinematicModel, ``make_recording`` is not callable
        or a recording does not fit the robot.
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
        dec = deciding_attempt(attempts)
        ver = dec.verification
        row = SpeedRefutation(
            speed=float(speed), n_samples=rb.n_samples, found=any(a.found for a in attempts),
            verified=dec.verified,
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
