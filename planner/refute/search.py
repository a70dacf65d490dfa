"""Counterexample searches over a family of recordings.

* :func:`refutation_bound` — crossings indexed by speed, searched for bounces:
  the largest refuted speed bounds from below the speed at which any sound
  tracker can certify ``mode-changed``;
* :func:`crossing_floor` — bounces indexed by how far before the locus they
  turn back, searched for crossings: the largest refuted distance bounds from
  below the distance at which any sound tracker can certify ``mode-unchanged``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError
from crosscert.robots.kinematics import KinematicModel

from .nlp import MAX_CPU_TIME, MAX_ITER, nlp_variables, scaled_cpu_time, search_counterexample
from .problem import Counterexample, CounterexampleKind, RecordingBounds
from .results import BounceSearch, CrossingFloor, RecordingRefutation, RefutationBound, SpeedRefutation, deciding_attempt
from .verify import DENSE_POINTS

__all__ = ["crossing_floor", "refutation_bound", "verified_counterexample"]


def _search_recording(kin, make_recording, value, kind, *, m0, xi_starts, bounds, max_iter, max_cpu_time,
                      dense, warm=None, cap_variables=None) -> dict:
    """Search the recording ``make_recording(value)`` from each start until one is verified.

    ``warm``, a verified counterexample of a neighbouring recording, takes
    the place of the first start (:func:`search_counterexample`).  Returns
    the fields the row records share (:class:`SpeedRefutation`,
    :class:`RecordingRefutation`), the parameter excepted.
    """
    q_meas, t_s = make_recording(value)
    rb = RecordingBounds.for_model(kin, q_meas, t_s, m0, **(bounds or {}))
    max_cpu_time = scaled_cpu_time(max_cpu_time, nlp_variables(kin, rb.n_samples), cap_variables)
    starts = [None] if not xi_starts else list(xi_starts)
    plan = [(xs, None) for xs in starts] if warm is None else [(None, warm)] + [(xs, None) for xs in starts[1:]]
    attempts: list[BounceSearch] = []
    for xs, ce in plan:
        att = search_counterexample(kin, rb, kind, xi_start=xs, max_iter=max_iter, max_cpu_time=max_cpu_time,
                                    dense=dense, warm=ce)
        attempts.append(att)
        if att.verified:
            break
    dec = deciding_attempt(attempts)
    ver = dec.verification
    return {
        "n_samples": rb.n_samples, "found": any(a.found for a in attempts), "verified": dec.verified,
        "geometry": None if dec.counterexample is None else dec.counterexample.xi.copy(),
        "joint_ratio": math.nan if ver is None else ver.joint_ratio,
        "accel_ratio": math.nan if ver is None else ver.accel_ratio,
        "mode_margin": math.nan if ver is None else ver.mode_margin,
        "status": dec.status, "solve_time": float(sum(a.solve_time for a in attempts)),
        "attempts": tuple(attempts),
    }


def verified_counterexample(row) -> Counterexample | None:
    """The verified counterexample of a row (:class:`SpeedRefutation`, :class:`RecordingRefutation`), or None."""
    return next((a.counterexample for a in row.attempts if a.verified), None)


def _check(kin, make_recording, what: str) -> None:
    if not isinstance(kin, KinematicModel):
        raise InputError(f"kin must be a KinematicModel, got {type(kin).__name__}")
    if not callable(make_recording):
        raise InputError(f"make_recording must be callable: {what} -> (q_meas, t_s)")


def refutation_bound(kin: KinematicModel, make_recording: Callable[[float], tuple], speeds: Sequence[float], *,
                     m0: int = 1, xi_starts: Sequence | None = None, bounds: dict | None = None,
                     max_iter: int = MAX_ITER, max_cpu_time: float = MAX_CPU_TIME, dense: int = DENSE_POINTS,
                     progress: Callable[[SpeedRefutation], None] | None = None,
                     warm: Counterexample | None = None, cap_variables: int | None = None) -> RefutationBound:
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
    warm : Counterexample, optional
        A verified counterexample at a neighbouring speed: every speed's
        first attempt starts from it (:func:`search_counterexample`) instead
        of the first of ``xi_starts``.
    cap_variables : int, optional
        An attempt whose NLP has more unknowns than this gets ``max_cpu_time``
        scaled by its size (:func:`~planner.refute.nlp.scaled_cpu_time`);
        None: ``max_cpu_time`` for every size.

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
    _check(kin, make_recording, "speed")
    rows = []
    for speed in speeds:
        row = SpeedRefutation(speed=float(speed), **_search_recording(
            kin, make_recording, speed, CounterexampleKind.BOUNCE, m0=m0, xi_starts=xi_starts, bounds=bounds,
            max_iter=max_iter, max_cpu_time=max_cpu_time, dense=dense, warm=warm, cap_variables=cap_variables))
        rows.append(row)
        if progress is not None:
            progress(row)
    refuted = [r.speed for r in rows if r.verified]
    return RefutationBound(tuple(rows), max(refuted) if refuted else None)


def crossing_floor(kin: KinematicModel, make_recording: Callable[[float], tuple], distances: Sequence[float], *,
                   tol: float | None = None, m0: int = 1, xi_starts: Sequence | None = None,
                   bounds: dict | None = None, max_iter: int = MAX_ITER, max_cpu_time: float = MAX_CPU_TIME,
                   dense: int = DENSE_POINTS, upper: float | None = None,
                   progress: Callable[[RecordingRefutation], None] | None = None) -> CrossingFloor:
    """Crossing-counterexample search on bounces turning back at several distances before the locus.

    The mirror of :func:`refutation_bound`: each recording is a bounce (the
    mode never changes) that turns back ``d`` metres before the singular
    locus, and :func:`~planner.refute.search_crossing` looks for a motion that
    changed mode yet explains its readings.  The largest distance with a
    verified one is the *crossing floor*: no sound tracker can certify
    ``mode-unchanged`` for a bounce of this family turning back at or closer
    than that (if the family is monotone in ``d``).

    Parameters
    ----------
    kin : KinematicModel
        The robot's kinematics.
    make_recording : callable
        ``make_recording(d) -> (q_meas, t_s)``: the bounce turning back ``d``
        (m) before the locus (e.g. ``simulate_bounce(..., short=d)``),
        ``q_meas`` (K, n) rad, ``t_s`` s.
    distances : sequence of float
        Turn-back distances to try, m (any order, >= 0).
    tol : float, optional
        If given (m), then bisect between the largest refuted distance and the
        smallest non-refuted one above it until they are ``tol`` apart (needs a
        non-refuted distance above a refuted one among ``distances``).
    m0 : int
        Initial assembly mode, +1 or -1.
    xi_starts : sequence of array_like (m,), optional
        Starting geometries tried in order until one gives a verified
        counterexample (the NLP is non-convex).  Default: the box centre.
    bounds : dict, optional
        Overrides of :meth:`RecordingBounds.for_model` (``eps_q``, ``a_max``,
        ``xi_lo``, ``xi_hi``, ``v0_max``, ``v_max``, ``x_lo``, ``x_hi``).
    max_iter, max_cpu_time, dense
        Passed to :func:`~planner.refute.search_crossing` (per attempt; ``max_cpu_time`` in s).
    upper : float, optional
        A distance (m) known to have no crossing counterexample (e.g. one
        whose bounce a sound tracker certified ``mode-unchanged``): with
        ``tol``, the bisection's upper end when no tried distance above the
        largest refuted one is unrefuted.  It is not searched itself.
    progress : callable, optional
        Called with each :class:`RecordingRefutation` as it completes.

    Returns
    -------
    CrossingFloor
        One row per distance tried (``parameter`` in m), sorted by distance;
        a distance whose outcome is not ``FOUND`` is not refuted by this
        search, which does not mean it cannot be.

    Raises
    ------
    InputError
        If ``kin`` is not a KinematicModel, ``make_recording`` is not callable,
        a distance or ``upper`` is negative, ``tol`` is not positive (all
        checked before any search), or a recording does not fit the robot.
    """
    _check(kin, make_recording, "distance")
    ds = [V.positive("distance", d, allow_zero=True) for d in distances]
    if tol is not None:
        tol = V.positive("tol", tol)
    if upper is not None:  # checked with the others, before any search
        upper = V.positive("upper", upper, allow_zero=True)
    rows: dict[float, RecordingRefutation] = {}
    search = {"m0": m0, "xi_starts": xi_starts, "bounds": bounds, "max_iter": max_iter,
              "max_cpu_time": max_cpu_time, "dense": dense}
    for d in ds:
        if d not in rows:
            rows[d] = _floor_row(kin, make_recording, d, search, progress)
    if tol is not None:
        _bisect_floor(rows, lambda d: _floor_row(kin, make_recording, d, search, progress), tol, upper)
    refuted = [d for d in rows if rows[d].verified]
    return CrossingFloor(tuple(rows[d] for d in sorted(rows)), max(refuted) if refuted else None)


def _floor_row(kin, make_recording, d: float, search: dict, progress) -> RecordingRefutation:
    """The crossing search on the bounce turning back ``d`` (m) before the locus, passed to ``progress``.

    ``search`` holds the keyword arguments of :func:`_search_recording`
    (``m0``, ``xi_starts``, ``bounds``, ``max_iter``, ``max_cpu_time``, ``dense``).
    """
    row = RecordingRefutation(parameter=d, unit="m", kind=CounterexampleKind.CROSSING, **_search_recording(
        kin, make_recording, d, CounterexampleKind.CROSSING, **search))
    if progress is not None:
        progress(row)
    return row


def _bisect_floor(rows: dict, row_at: Callable[[float], RecordingRefutation], tol: float,
                  upper: float | None) -> None:
    """Bisect between the largest refuted distance and the smallest unrefuted one above it (m).

    ``rows`` (by distance) gets the row ``row_at(d)`` of each midpoint ``d``
    until the two ends are ``tol`` (m) apart.  ``upper`` (m), known
    unrefuted, serves as the upper end when no tried distance above the
    largest refuted one is unrefuted.  Nothing runs while no distance is refuted.
    """
    while True:
        refuted = [d for d in rows if rows[d].verified]
        above = [d for d in rows if refuted and d > max(refuted) and not rows[d].verified]
        if upper is not None and refuted and upper > max(refuted):
            above.append(upper)
        if not refuted or not above or min(above) - max(refuted) <= tol:
            break
        d = 0.5 * (max(refuted) + min(above))
        rows[d] = row_at(d)
