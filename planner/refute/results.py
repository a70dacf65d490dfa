"""The records a counterexample search returns: a check, one attempt, one speed, a sweep.

Each result carries an ``outcome`` (:class:`~planner.refute.problem.SearchOutcome`)
derived from its other fields, next to IPOPT's raw ``status`` kept for
diagnostics.  Only ``SearchOutcome.FOUND`` is a counterexample; no other
outcome means that none exists.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from .problem import Counterexample, CounterexampleKind, SearchOutcome, ipopt_outcome

__all__ = ["BounceSearch", "CrossingFloor", "RecordingRefutation", "RefutationBound", "SpeedRefutation", "Verification",
           "SearchCompleteness", "completeness", "deciding_attempt"]

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
        ``min_k m0 * mode_sign * det J_x / prod |rows of J_x|`` over the
        samples whose mode is constrained (a bounce: all, ``m0`` each; a
        crossing: the first, ``m0``, and the last, ``-m0``, so the sign of
        the last term flips); ``> 0`` required.
    dense_mode_violations : int
        Dense points (between samples) whose mode is not ``m0`` (a bounce; 0 for a crossing).
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


@dataclass(frozen=True, eq=False)
class BounceSearch:
    """One NLP solve from one starting geometry, and the verification of its result.

    The record of both kinds of search (:func:`~planner.refute.search_bounce`,
    :func:`~planner.refute.search_crossing`); ``kind`` says which.

    Attributes
    ----------
    found : bool
        IPOPT converged (its status maps to :attr:`SearchOutcome.CONVERGED`).
    verified : bool
        ``found`` and the independent check (:func:`~planner.refute.verify_bounce`
        or :func:`~planner.refute.verify_crossing`) accepted the candidate: a counterexample.
    status : str
        IPOPT's raw return status, for diagnostics.
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
    kind : CounterexampleKind
        The kind of counterexample searched (default: a bounce).
    outcome : SearchOutcome
        Derived from ``status`` and ``verification``: FOUND or REJECTED once a
        converged candidate has been checked, else :func:`ipopt_outcome` of the status.
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
    kind: CounterexampleKind = CounterexampleKind.BOUNCE
    outcome: SearchOutcome = field(init=False)

    def __post_init__(self) -> None:
        out = ipopt_outcome(self.status)
        if out is SearchOutcome.CONVERGED and self.verification is not None:
            out = SearchOutcome.FOUND if self.verified else SearchOutcome.REJECTED
        object.__setattr__(self, "outcome", out)


def deciding_attempt(attempts: Sequence[BounceSearch]) -> BounceSearch | None:
    """The attempt a speed's result reports: the verified one, else the last converged, else the last (None if none)."""
    for a in attempts:
        if a.verified:
            return a
    converged = [a for a in attempts if a.found]
    if converged:
        return converged[-1]
    return attempts[-1] if attempts else None


#: Outcomes of an attempt that ended on its own (a local conclusion); a time or iteration cap, a solver error
#: or no solve at all says nothing about the neighbourhood the attempt started in.
_ENDED = (SearchOutcome.INFEASIBLE, SearchOutcome.REJECTED, SearchOutcome.NOT_CONVERGED)


class SearchCompleteness(StrEnum):
    """What a set of counterexample searches (one bound or floor) rests on, beside its value.

    ``NOT_SEARCHED_TO_COMPLETION`` is never reported as "none found": every search stopped at its time or
    iteration cap or failed inside the solver (or none ran), so the absence of a counterexample says
    nothing, not even locally.
    """

    #: A verified counterexample exists: the bound (or floor) is a value.
    FOUND = "counterexample-found"
    #: No verified counterexample, and at least one search ended on its own (a candidate rejected, locally
    #: infeasible, stalled): "none found" by a local solver, never a proof that none exists.
    NONE_FOUND = "none-found"
    #: No verified counterexample, and every search stopped at a limit or none ran.
    NOT_SEARCHED_TO_COMPLETION = "not-searched-to-completion"

    def describe(self) -> str:
        """The words a printout uses for a missing bound."""
        if self is SearchCompleteness.NOT_SEARCHED_TO_COMPLETION:
            return ("not searched to completion (every search stopped at its time or iteration limit or failed in "
                    "the solver, or none ran)")
        if self is SearchCompleteness.NONE_FOUND:
            return "none found (a local search: not a proof that none exists)"
        return "found"


def completeness(rows) -> SearchCompleteness:
    """:class:`SearchCompleteness` of the rows of one search (``SpeedRefutation`` or ``RecordingRefutation``)."""
    rows = list(rows)
    if any(r.verified for r in rows):
        return SearchCompleteness.FOUND
    if any(a.outcome in _ENDED for r in rows for a in r.attempts):
        return SearchCompleteness.NONE_FOUND
    return SearchCompleteness.NOT_SEARCHED_TO_COMPLETION


def row_outcome(verified: bool, attempts) -> SearchOutcome:
    """Outcome of a row of attempts: FOUND if verified, NOT_SEARCHED without attempts, else the deciding one's."""
    if verified:
        return SearchOutcome.FOUND
    dec = deciding_attempt(attempts)
    return SearchOutcome.NOT_SEARCHED if dec is None else dec.outcome


@dataclass(frozen=True, eq=False)
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
        Raw status of the deciding attempt (the verified one, else the last), for diagnostics.
    solve_time : float
        Total solver wall time over the attempts, s.
    attempts : tuple of BounceSearch
    outcome : SearchOutcome
        Derived: FOUND if ``verified``, NOT_SEARCHED without attempts, else the
        outcome of the deciding attempt (:func:`deciding_attempt`).
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
    outcome: SearchOutcome = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "outcome", row_outcome(self.verified, self.attempts))


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


@dataclass(frozen=True, eq=False)
class RecordingRefutation:
    """Search result for one recording of a family indexed by one parameter (with its unit).

    The general form of :class:`SpeedRefutation` (which is kept, indexed by
    speed, for the bounce searches over planned speeds): e.g. the bounce
    recordings of :func:`~planner.refute.crossing_floor`, indexed by the
    distance (m) before the locus at which they turn back.

    Attributes
    ----------
    parameter : float
        The value passed to ``make_recording``, in ``unit``.
    unit : str
        Unit of ``parameter`` (SI symbol, e.g. ``"m"`` or ``"m/s"``).
    kind : CounterexampleKind
        The kind of counterexample searched.
    n_samples : int
        Samples of the recording.
    found : bool
        Some start converged.
    verified : bool
        Some start gave a verified counterexample.
    geometry : ndarray (m,) or None
        Geometry of the verified counterexample (else of the last converged candidate, else ``None``).
    joint_ratio, accel_ratio, mode_margin : float
        The deciding candidate's :class:`Verification` figures (``nan`` if none converged).
    status : str
        Raw status of the deciding attempt, for diagnostics.
    solve_time : float
        Total solver wall time over the attempts, s.
    attempts : tuple of BounceSearch
    outcome : SearchOutcome
        Derived as in :class:`SpeedRefutation`.
    """

    parameter: float
    unit: str
    kind: CounterexampleKind
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
    outcome: SearchOutcome = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "outcome", row_outcome(self.verified, self.attempts))


@dataclass(frozen=True)
class CrossingFloor:
    """Crossing-counterexample search over bounce recordings indexed by turn-back distance.

    Attributes
    ----------
    rows : tuple of RecordingRefutation
        One per distance (``parameter`` in m, ``kind`` CROSSING), in the order given.
    floor : float or None
        Largest turn-back distance (m) with a verified crossing counterexample,
        ``None`` if none.  The bounce turning back that far before the locus
        is equally explained by a motion that changed mode, so no sound
        tracker can certify it ``mode-unchanged`` under the same bounds;
        certifying a bounce of this family needs it to turn back farther than
        ``floor`` (or the family is not monotone in the distance —
        :attr:`rows` shows which distances were refuted).
    """

    rows: tuple[RecordingRefutation, ...]
    floor: float | None
