"""Refutation searches: motions that explain a recording's encoder data yet contradict a verdict.

A sound tracker may certify that a recording changed the assembly mode only if
*no* motion compatible with its assumptions explains the same data without a
mode change (a *bounce*), and that it did not change only if no such motion
ends in the other mode (a *crossing*).  This package searches for such a
motion, a counterexample, with CasADi's NLP interface and IPOPT, and checks
every candidate independently.

* :mod:`.problem` — the bounds of a recording, a candidate, the outcome words;
* :mod:`.results` — what a search returns;
* :mod:`.nlp` — the NLP and its solution (:func:`search_bounce`,
  :func:`search_crossing`);
* :mod:`.verify` — the trusted check of a candidate (:func:`verify_bounce`,
  :func:`verify_crossing`), which builds no optimisation problem;
* :mod:`.explain` — the window's explainer (:class:`RefutingExplainer`): a
  verified search per final-mode hypothesis, to stop a window no sound method
  can decide;
* :mod:`.search` — the sweeps over a family of recordings: crossings by speed
  (:func:`refutation_bound`), bounces by turn-back distance (:func:`crossing_floor`);
* :mod:`.orchestrate` — a certification's searches by speed, run ahead on an
  executor while the speed search runs (:class:`~.orchestrate.Refuter`), and
  the bisection to the refutation bound (:func:`~.orchestrate.refutation_search`);
  imported from there (it plans, so it is not re-exported here).

Non-convergence of IPOPT is never a counterexample; an unverified candidate is
never reported as one.  Only :attr:`BounceSearch.verified` results
(:attr:`SearchOutcome.FOUND`) count, and no other outcome means that no
counterexample exists.  SI units throughout (m, rad, s).

Explicit re-exports (no star imports).
"""

from .explain import ExplainAttempt, RefutingExplainer
from .guess import fk_branch_guess, fk_crossing_guess
from .nlp import search_bounce, search_counterexample, search_crossing
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
from .results import (
    BounceSearch,
    CrossingFloor,
    RecordingRefutation,
    RefutationBound,
    SearchCompleteness,
    SpeedRefutation,
    Verification,
    completeness,
)
from .search import crossing_floor, refutation_bound, verified_counterexample
from .verify import BRANCH_TOL, STATE_TOL, verify_bounce, verify_counterexample, verify_crossing

__all__ = [
    "ACCEL_MARGIN",
    "BRANCH_TOL",
    "JOINT_MARGIN",
    "MODE_MARGIN",
    "STATE_TOL",
    "XI_MARGIN",
    "BounceSearch",
    "Counterexample",
    "CounterexampleKind",
    "CrossingFloor",
    "ExplainAttempt",
    "RecordingBounds",
    "RecordingRefutation",
    "RefutationBound",
    "RefutingExplainer",
    "SearchCompleteness",
    "SearchOutcome",
    "SpeedRefutation",
    "Verification",
    "completeness",
    "crossing_floor",
    "verified_counterexample",
    "fk_branch_guess",
    "fk_crossing_guess",
    "ipopt_outcome",
    "refutation_bound",
    "search_bounce",
    "search_counterexample",
    "search_crossing",
    "verify_bounce",
    "verify_counterexample",
    "verify_crossing",
]
