"""What a refutation bound or crossing floor rests on: "none found" only when some search ended on its own."""

import json

import numpy as np
import pytest

from crosscert.planner.bounce import BounceGap
from crosscert.planner.certify.certificate import CrossingCertificate
from crosscert.planner.certify.plan import SpeedTrial
from crosscert.planner.cli.planning import _bound_text
from crosscert.planner.refute import BounceSearch, SearchCompleteness, SpeedRefutation, completeness
from crosscert.planner.task import PlanningBounds
from crosscert.robots import DEXTAR
from crosscert.verifier.settings import Verdict


def _attempt(status: str, verified: bool = False) -> BounceSearch:
    return BounceSearch(found=verified, verified=verified, status=status, iterations=10, solve_time=2.0,
                        n_variables=100, n_constraints=100, xi_start=np.zeros(7))


def _row(v: float, *statuses: str, verified: bool = False) -> SpeedRefutation:
    attempts = tuple(_attempt(s) for s in statuses)
    nan = float("nan")
    return SpeedRefutation(v, 300, verified, verified, None, nan, nan, nan, statuses[-1] if statuses else "",
                           2.0 * len(statuses), attempts)


CAPPED = ("Maximum_CpuTime_Exceeded", "Maximum_Iterations_Exceeded")


def test_searches_that_all_stopped_at_a_limit_are_not_searched_to_completion():
    rows = [_row(0.5, *CAPPED), _row(0.6, "Maximum_WallTime_Exceeded"), _row(0.7, "Internal_Error")]
    assert completeness(rows) is SearchCompleteness.NOT_SEARCHED_TO_COMPLETION
    assert completeness([]) is SearchCompleteness.NOT_SEARCHED_TO_COMPLETION
    assert completeness([_row(0.5)]) is SearchCompleteness.NOT_SEARCHED_TO_COMPLETION  # no attempt at all
    # one search that ended on its own is enough for "none found", which still claims no proof
    assert completeness([*rows, _row(0.8, "Infeasible_Problem_Detected")]) is SearchCompleteness.NONE_FOUND
    assert completeness([_row(0.8, *CAPPED), _row(0.9, "Maximum_CpuTime_Exceeded", verified=True)]) \
        is SearchCompleteness.FOUND


def test_the_printout_never_says_none_found_for_capped_searches():
    capped = completeness([_row(0.5, *CAPPED)])
    text = _bound_text(None, capped, "m/s", 1.0, ".4f")
    assert text.startswith("not searched to completion") and "none found" not in text
    assert _bound_text(None, SearchCompleteness.NONE_FOUND, "m/s", 1.0, ".4f").startswith("none found")
    assert _bound_text(0.84843, SearchCompleteness.FOUND, "m/s", 1.0, ".4f") == "0.8484 m/s"
    assert _bound_text(None, None, "m/s", 1.0, ".4f") == "not computed"


def test_certificate_and_bounce_json_state_what_the_bound_rests_on():
    trials = (SpeedTrial(1.0, Verdict.MODE_CHANGED, 0.1, 1.0, 5, Verdict.MODE_CHANGED),)
    b = PlanningBounds().resolve(DEXTAR)
    cert = CrossingCertificate(Verdict.MODE_CHANGED, 1.0, None, trials, None, None, b, None, None, {}, 1.0,
                               refutation=(_row(0.5, *CAPPED),), refutation_ran=True)
    assert cert.summary()["refutation_search"] == "not-searched-to-completion"
    assert cert.summary()["refutation_bound_mps"] is None
    off = CrossingCertificate(Verdict.MODE_CHANGED, 1.0, None, trials, None, None, b, None, None, {}, 1.0)
    assert off.summary()["refutation_search"] is None  # not run: not computed, not "none found"
    gap = BounceGap(1.0, (0.01,), (Verdict.MODE_UNCHANGED,), 0.01, None, ())
    assert gap.summary()["crossing_floor_search"] == "not-searched-to-completion"
    json.dumps(cert.summary())


@pytest.mark.parametrize("member", list(SearchCompleteness))
def test_every_completeness_has_words(member):
    assert member.describe()
