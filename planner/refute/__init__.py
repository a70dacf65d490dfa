"""Refutation bound: search for "bounce" motions that explain a crossing's encoder data.

A sound tracker may certify that a recording changed the assembly mode only if
*no* motion compatible with its assumptions explains the same data without a
mode change.  This package searches for such a motion, a counterexample, with
CasADi's NLP interface and IPOPT, and checks every candidate independently.

* :mod:`.problem` — the bounds of a recording, a candidate, the outcome words;
* :mod:`.results` — what a search returns;
* :mod:`.nlp` — the NLP and its solution (:func:`search_bounce`);
* :mod:`.verify` — the trusted check of a candidate (:func:`verify_bounce`),
  which builds no optimisation problem;
* :mod:`.search` — the sweep over speeds (:func:`refutation_bound`).

Non-convergence of IPOPT is never a counterexample; an unverified candidate is
never reported as one.  Only :attr:`BounceSearch.verified` results
(:attr:`SearchOutcome.FOUND`) count, and no other outcome means that no
counterexample exists.  SI units throughout (m, rad, s).

Explicit re-exports (no star imports).
"""

from .nlp import fk_branch_guess, search_bounce
from .problem import (
    ACCEL_MARGIN,
    JOINT_MARGIN,
    MODE_MARGIN,
    XI_MARGIN,
    Counterexample,
    RecordingBounds,
    SearchOutcome,
    ipopt_outcome,
)
from .results import BounceSearch, RefutationBound, SpeedRefutation, Verification
from .search import refutation_bound
from .verify import BRANCH_TOL, STATE_TOL, verify_bounce

__all__ = [
    "ACCEL_MARGIN",
    "BRANCH_TOL",
    "JOINT_MARGIN",
    "MODE_MARGIN",
    "STATE_TOL",
    "XI_MARGIN",
    "BounceSearch",
    "Counterexample",
    "RecordingBounds",
    "RefutationBound",
    "SearchOutcome",
    "SpeedRefutation",
    "Verification",
    "fk_branch_guess",
    "ipopt_outcome",
    "refutation_bound",
    "search_bounce",
    "verify_bounce",
]
