"""The second certification at the robot's a_max (planner.assumption_cost): what it reuses of the first."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import crosscert.planner.assumption_cost as ac
import crosscert.planner.certify.plan as certify_mod
from crosscert.planner.acceleration import robot_a_max_assumption
from crosscert.planner.certify.certificate import CrossingCertificate
from crosscert.planner.certify.crossing import certify_crossing
from crosscert.planner.task import PlanningBounds
from crosscert.robots import DEXTAR
from crosscert.verifier.tracker import Verdict
from problems import MARGIN, MARGIN_CERTIFICATION

#: v_min at the DexTAR's a_max (80, 80) m/s^2 on the benchmark task: 1.062375 m/s as the search without a guess
#: finds it (from the first certificate's v_min, 8 questions; crosscert certify 2026-12-02, one-motion step off);
#: 1.025712 m/s with the step on by default (2026-12-04: the search without a guess from v_min 0.929155 m/s
#: asks 8 speeds and finds the same; from 0.6 m/s it finds 1.024716 m/s, within tol of it).
V_MIN_AT_ROBOT_A_MAX = 1.025712


def test_the_guess_scales_v_min_with_the_square_root_of_the_largest_a_max_ratio():
    ref = robot_a_max_assumption(DEXTAR)
    assert ac.speed_guess(0.9, ref, ref) == pytest.approx(0.9)
    tighter = [80.0, 65.91]  # the benchmark's: robot a_max on x, plan peak + 10 % on y
    used = type(ref)(tuple(replace(a, value=v) for a, v in zip(ref.axes, tighter)))
    assert ac.speed_guess(0.961008, used, ref) == pytest.approx(0.961008 * math.sqrt(80.0 / 65.91))


def test_at_the_robot_a_max_two_questions_give_the_full_searchs_v_min(task, kin, imodel, monkeypatch):
    """A certificate under a 10 % tracking margin: at the robot's a_max the guess lies in the answer's last
    bisection bracket: its two ends are the only questions (8 without the guess), and v_min is the one the
    search without a guess finds."""
    cert = certify_crossing(DEXTAR, task, PlanningBounds(a_margin=MARGIN), kin=kin, imodel=imodel, refute=False,
                            monte_carlo_runs=0, bounce=False)
    assert cert.v_min == pytest.approx(MARGIN_CERTIFICATION["v_min"], abs=1e-4)
    asked = []
    real = certify_mod.certify_speed

    def counting(kin, imodel, task, b, v, **kw):
        asked.append(v)
        return real(kin, imodel, task, b, v, **kw)

    monkeypatch.setattr(certify_mod, "certify_speed", counting)
    at = ac.certify_at_robot_a_max(DEXTAR, task, cert, refute=False, kin=kin, imodel=imodel).at_robot_a_max
    assert at.outcome is ac.ComparisonOutcome.COMPUTED and at.verdict is Verdict.MODE_CHANGED
    assert at.v_min == V_MIN_AT_ROBOT_A_MAX and len(asked) == 2, asked
    assert min(asked) < at.v_min and at.v_min - min(asked) <= 0.01


class _Attempt:
    def __init__(self, ce):
        self.verified, self.counterexample = True, ce


class _Row:
    def __init__(self, v, ce=None):
        self.speed, self.verified = v, ce is not None
        self.attempts = (_Attempt(ce),) if ce is not None else ()


def test_the_scan_at_the_robot_a_max_starts_from_the_first_bound_and_its_counterexample(monkeypatch):
    """The robot's bound covers the default's: the scan starts at the default's refutation bound, every scan
    search starts from the counterexample verified there (a start only), and the speed search from v_min."""
    ref = robot_a_max_assumption(DEXTAR)
    used = type(ref)(tuple(replace(a, value=v) for a, v in zip(ref.axes, (80.0, 65.91))))
    trials = tuple(certify_mod.SpeedTrial(v, Verdict.MODE_CHANGED if v >= 0.96 else Verdict.UNKNOWN, 0.0, 0.0,
                                          None, Verdict.UNKNOWN) for v in (0.95, 0.961, 1.959))
    cert = CrossingCertificate(Verdict.MODE_CHANGED, 0.961, 0.84375, trials, None, None,
                               PlanningBounds().resolve(DEXTAR), used, None, {}, 0.0,
                               refutation=(_Row(0.8), _Row(0.84375, "ce@0.84375"), _Row(0.85)))
    seen = {}

    def spy(robot, task, bounds, **kw):
        seen.update(kw, bounds=bounds)
        return replace(cert, v_min=1.06, refutation_bound=0.9375)

    monkeypatch.setattr(ac, "certify_crossing", spy)
    at = ac.certify_at_robot_a_max(DEXTAR, None, cert).at_robot_a_max
    assert seen["refute_warm"] == "ce@0.84375"
    assert np.allclose(seen["refute_speeds"], [0.84375, 0.94375, 1.04375, 1.14375, 1.24375, 1.34375, 1.44375,
                                               1.54375, 1.64375, 1.74375, 1.84375, 1.94375])
    assert seen["v_low"] == 0.961 and seen["v_guess"] == pytest.approx(0.961 * math.sqrt(80.0 / 65.91))
    assert tuple(seen["bounds"].a_max) == (80.0, 80.0)
    assert at.v_min == 1.06 and at.refutation_bound == 0.9375
    # no bound under the default's bounds: nothing to reuse
    seen.clear()
    ac.certify_at_robot_a_max(DEXTAR, None, replace(cert, refutation_bound=None, refutation=()))
    assert seen["refute_warm"] is None and seen["refute_speeds"] is None
