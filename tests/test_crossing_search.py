"""Tests of the crossing search (planner.refute.search_crossing, verify_crossing, crossing_floor).

The refutation search run the other way: for a *bounce* recording of the
DexTAR benchmark crossing, a motion that changed mode yet explains the
readings.  Measured (seed 0, floor quantisation, box-centre start,
2026-12-01): verified crossings for bounces turning back up to 9.84 mm before
the locus at 1.2 and 1.0 m/s, IPOPT reports infeasibility from 10 mm on; the
tests assert only robust ends of that (0, 1 and 7.5 mm found; 15 and 30 mm
not found).
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np
import pytest

from crosscert.planner.refute import (
    MODE_MARGIN,
    BounceSearch,
    CounterexampleKind,
    CrossingFloor,
    RecordingBounds,
    RecordingRefutation,
    SearchOutcome,
    crossing_floor,
    fk_crossing_guess,
    search_bounce,
    search_counterexample,
    search_crossing,
    verify_bounce,
    verify_counterexample,
    verify_crossing,
)
from crosscert.planner.refute.nlp import SAMPLE_BUCKET
from crosscert.planner.simulate import max_v_sing, simulate_bounce
from crosscert.planner.sweep import cruise_for
from problems import default_settings, interval_model, kinematics
from crosscert.robots import DEXTAR
from crosscert.robots.dextar import benchmark_crossing
from crosscert.robots.errors import InputError, SimulationError
from crosscert.verifier.tracker import Verdict, track

SPEED = 1.2  # m/s, approach speed of the bounces
FAR = 0.03  # m: a bounce turning back this far before the locus admits no crossing


@lru_cache(maxsize=None)
def _bounce(short: float, v: float = SPEED):
    """The benchmark bounce at ``v`` turning back ``short`` (m) before the locus; its start stays
    70 mm before the locus while the 5 mm cruise allows (seeded: floor quantisation, seed 0)."""
    bench = benchmark_crossing()
    return simulate_bounce(kinematics(), bench.point, bench.direction, v, t_rest=0.05,
                           working_guess=bench.q_point, seed=0, cruise=max(5e-3, cruise_for(v) - short / 2),
                           short=short)


def _recording(short: float):
    run = _bounce(short)
    return run.q_meas, run.t_s


def _bounds(short: float) -> RecordingBounds:
    return RecordingBounds.for_model(kinematics(), _bounce(short).q_meas, m0=1)


@pytest.fixture(scope="module")
def on_locus():
    """A verified crossing for the bounce that touches the locus."""
    kin = kinematics()
    rb = _bounds(0.0)
    res = search_crossing(kin, rb, max_cpu_time=30.0)
    assert res.verified, (res.status, res.verification)
    return kin, rb, res


def test_bounce_touching_the_locus_admits_a_verified_crossing(on_locus):
    kin, rb, res = on_locus
    assert res.outcome is SearchOutcome.FOUND and res.kind is CounterexampleKind.CROSSING
    ce, v = res.counterexample, res.verification
    assert ce.kind is CounterexampleKind.CROSSING and ce.m0 == 1
    assert v.ok and not v.failures and v.mode_margin > 0
    assert v.joint_ratio <= 1.0 and v.accel_ratio <= 1.0 and v.xi_excess == 0.0 and v.dense_ik_failures == 0
    assert DEXTAR.xi_in_box(ce.xi)
    # it starts in mode +1, ends in -1 with the NLP's margin, and meets the locus in between
    n = kin.normalised_mode_batch(ce.x, ce.q, ce.xi)
    assert n[0] >= MODE_MARGIN and n[-1] <= -MODE_MARGIN
    assert np.all(kin.mode_batch(ce.x, ce.q, ce.xi)[[0, -1]] == [1, -1])
    # a crossing is no bounce: the bounce check refuses it
    assert not verify_bounce(kin, ce, rb).ok
    assert not verify_bounce(kin, dataclasses.replace(ce, kind=CounterexampleKind.BOUNCE), rb).ok


def test_bounce_one_millimetre_short_admits_a_verified_crossing():
    res = search_crossing(kinematics(), _bounds(1e-3), max_cpu_time=30.0)
    assert res.verified and res.outcome is SearchOutcome.FOUND, (res.status, res.verification)


def test_bounce_far_short_of_the_locus_admits_none():
    res = search_crossing(kinematics(), _bounds(FAR), max_cpu_time=30.0)
    assert not res.verified and res.outcome is not SearchOutcome.FOUND
    assert res.kind is CounterexampleKind.CROSSING


def test_nlp_size(on_locus):
    """Sized for the recording extended to a multiple of SAMPLE_BUCKET samples (its last reading repeated)."""
    kin, rb, res = on_locus
    K = -(-rb.n_samples // SAMPLE_BUCKET) * SAMPLE_BUCKET
    assert res.counterexample.x.shape == (rb.n_samples, kin.n)
    assert res.n_variables == kin.m + kin.n * (4 * K - 1)
    assert res.n_constraints == 2 * kin.n * (K - 1) + kin.n * K + 2  # mode at the first and last sample only


def test_verification_rejects_acceleration_above_bound(on_locus):
    kin, rb, res = on_locus
    ce = res.counterexample
    # a_max just below what the candidate uses: only the acceleration check can refuse it
    tight = dataclasses.replace(rb, a_max=rb.a_max * 0.99 * res.verification.accel_ratio)
    v = verify_crossing(kin, ce, tight)
    assert not v.ok and v.accel_ratio > 1.0
    assert v.failures and all("a_max" in f for f in v.failures)


def test_verification_rejects_a_final_mode_not_flipped(on_locus):
    kin, rb, _res = on_locus
    # the bounce through the same readings, claimed as a crossing: its last sample is in mode +1
    bounce = search_bounce(kin, rb, max_cpu_time=30.0)
    assert bounce.verified, (bounce.status, bounce.verification)
    claimed = dataclasses.replace(bounce.counterexample, kind=CounterexampleKind.CROSSING)
    v = verify_crossing(kin, claimed, rb)
    assert not v.ok and v.mode_margin < 0
    assert v.failures and all("last sample" in f for f in v.failures)


def test_verification_rejects_geometry_outside_the_box(on_locus):
    kin, rb, res = on_locus
    ce = res.counterexample
    # move one bound just past the candidate's geometry: only the geometry check can refuse it
    j = int(np.argmax(rb.xi_hi - ce.xi))
    lo = rb.xi_lo.copy()
    lo[j] = ce.xi[j] + 1e-9
    v = verify_crossing(kin, ce, dataclasses.replace(rb, xi_lo=lo))
    assert not v.ok and v.xi_excess > 0
    assert v.failures and all("calibration box" in f for f in v.failures)


def test_verification_rejects_a_crossing_starting_in_the_other_mode(on_locus):
    kin, rb, res = on_locus
    ce = dataclasses.replace(res.counterexample, m0=-1)
    v = verify_crossing(kin, ce, dataclasses.replace(rb, m0=-1))
    assert not v.ok and v.mode_margin < 0
    assert any("first sample" in f for f in v.failures) and any("last sample" in f for f in v.failures)


def test_untampered_crossing_passes_again(on_locus):
    kin, rb, res = on_locus
    assert verify_crossing(kin, res.counterexample, rb, dense=16).ok
    assert verify_counterexample(kin, res.counterexample, rb, "crossing").ok
    with pytest.raises(InputError):
        verify_counterexample(kin, res.counterexample, rb, "sideways")


def test_the_tracker_agrees_with_the_crossing_search(on_locus):
    """Same bounds on both sides: where a crossing is verified the tracker may not certify
    ``mode-unchanged``; far short of the locus it does (measured: from 10.13 mm on, floor 9.92 mm)."""
    kin, _rb, _res = on_locus
    settings = default_settings()
    assert settings.a_max.tolist() == list(DEXTAR.a_max) and np.all(settings.eps_q == DEXTAR.eps_q)
    near = search_crossing(kin, _bounds(0.0075), max_cpu_time=30.0)
    assert near.verified, (near.status, near.verification)
    for d in (0.0, 0.0075):
        res = track(interval_model(), _bounce(d).q_meas, settings, initial_mode=1)
        assert res.verdict is not Verdict.MODE_UNCHANGED, (d, res.summary())
    far = track(interval_model(), _bounce(FAR).q_meas, settings, initial_mode=1)
    assert far.verdict is Verdict.MODE_UNCHANGED, far.summary()


def test_crossing_guess_switches_branch_at_the_turn():
    kin = kinematics()
    run = _bounce(0.0)
    X, k = fk_crossing_guess(kin, run.q_meas, run.xi_true, 1)
    assert abs(k - run.k_sing) <= 5
    np.testing.assert_allclose(X[:k - 25], run.x_true[:k - 25], atol=1e-4)  # FK of the readings: exact far from the locus
    # after the turn: the other FK solution, on the far side of the locus from the true way back
    assert np.all(kin.mode_batch(X[k + 10:], run.q_meas[k + 10:], run.xi_true) == -1)


def test_crossing_guess_switch_ignores_the_last_bits_of_equal_gaps(monkeypatch):
    """Over a run of equal readings the two branches' gaps agree up to Newton's last bits, which differ between
    machines: the switch is the middle of the whole run whatever those bits are (on one machine the exact minimum
    fell on sample 140 of the run 133-159, and the switch 6 samples early)."""
    import crosscert.planner.refute.guess as guess

    K, run = 60, slice(20, 41)
    rng = np.random.default_rng(7)
    gap = np.linspace(1.0, 2.0, K)[:, None] * np.ones((K, 2))
    gap[run] = 1.4074804786538692e-3 * (1.0 + 4 * np.finfo(float).eps * rng.standard_normal((21, 1)))
    branches = {1: (np.zeros((K, 2)), np.ones(K, bool)), -1: (gap, np.ones(K, bool))}
    monkeypatch.setattr(guess, "fk_branch_guess", lambda kin, q, xi, m: branches[m])
    _, k = guess.fk_crossing_guess(None, np.zeros((K, 2)), np.zeros(3), 1)
    assert k == 30


def test_crossing_floor_bisects_between_found_and_not_found():
    rows = []
    res = crossing_floor(kinematics(), _recording, [FAR, 0.0], tol=0.01, max_cpu_time=30.0, progress=rows.append)
    assert isinstance(res, CrossingFloor)
    ds = [r.parameter for r in res.rows]
    assert ds == sorted(ds) == [0.0, 0.0075, 0.015, FAR]  # two bisection steps, then 7.5 mm apart
    assert len(rows) == 4 and all(isinstance(r, RecordingRefutation) for r in rows)
    assert [r.verified for r in res.rows] == [True, True, False, False]
    assert res.floor == 0.0075
    for r in res.rows:
        assert r.unit == "m" and r.kind is CounterexampleKind.CROSSING
        assert r.outcome is (SearchOutcome.FOUND if r.verified else r.attempts[-1].outcome)
        assert all(isinstance(a, BounceSearch) and a.kind is CounterexampleKind.CROSSING for a in r.attempts)
    assert np.isnan(res.rows[-1].accel_ratio) or not res.rows[-1].verified


def test_short_bounce_turns_back_before_the_locus():
    d = 4e-3
    run, touch = _bounce(d), _bounce(0.0)
    assert run.bounce and run.short == d and touch.short == 0.0
    k = run.k_sing
    np.testing.assert_allclose(run.x_true[k], run.x_sing - d * run.direction, atol=1e-12)
    np.testing.assert_allclose(run.x_sing, touch.x_sing, atol=1e-12)  # the same locus point
    assert np.all(run.xd_true[k] == 0)
    assert np.all(run.mode_true == 1)  # never on the locus, never across it
    assert touch.mode_true[touch.k_sing] == 0
    # it comes back to its start, at rest
    np.testing.assert_allclose(run.x_true[-1], run.x_true[0], atol=1e-9)
    # the default is the touching bounce, unchanged
    bench = benchmark_crossing()
    kw = dict(t_rest=0.05, working_guess=bench.q_point, seed=0, cruise=5e-3)
    a = simulate_bounce(kinematics(), bench.point, bench.direction, SPEED, **kw)
    b = simulate_bounce(kinematics(), bench.point, bench.direction, SPEED, short=0.0, **kw)
    np.testing.assert_array_equal(a.q_meas, b.q_meas)


def test_fastest_short_bounce():
    """A bounce turning back farther from the locus starts farther back: a lower top speed."""
    bench = benchmark_crossing()
    kw = dict(working_guess=bench.q_point, bounce=True, cruise=5e-3)
    v0 = max_v_sing(kinematics(), bench.point, bench.direction, **kw)
    v1 = max_v_sing(kinematics(), bench.point, bench.direction, short=FAR, **kw)
    assert 0.0 < v1 < v0
    _bounce(FAR, v1 * 0.999)  # simulable just below it
    with pytest.raises(SimulationError):
        _bounce(FAR, v1 * 1.01)


def test_input_errors(on_locus):
    kin, rb, res = on_locus
    bench = benchmark_crossing()
    with pytest.raises(InputError):
        simulate_bounce(kin, bench.point, bench.direction, SPEED, working_guess=bench.q_point, short=-1e-3)
    with pytest.raises(InputError):
        crossing_floor(kin, _recording, [-1e-3])
    with pytest.raises(InputError):
        crossing_floor(kin, _recording, [0.0], tol=0.0)
    with pytest.raises(InputError):
        crossing_floor(kin, "not callable", [0.0])
    with pytest.raises(InputError):
        search_crossing(kin, rb, xi_start=DEXTAR.xi_hi_array + 1.0)
    with pytest.raises(InputError):
        search_counterexample(kin, rb, "sideways")
    with pytest.raises(InputError):
        dataclasses.replace(res.counterexample, kind="sideways")
