"""The two speed searches of a certification and the bracket they share (planner.certify.plan, planner.certify.crossing).

The searches' logic is checked on stand-in answers (a speed certifies above
a threshold, a counterexample exists below one), so every case runs in
milliseconds; the real certifications are in test_certify.py.
"""

from __future__ import annotations

import math
import threading
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

import pytest

import crosscert.planner.certify.plan as certify_mod
import crosscert.planner.certify.crossing as crossing_mod
import crosscert.planner.refute.orchestrate as orchestrate_mod
from crosscert.planner.certify.plan import search_v_min
from crosscert.planner.refute.orchestrate import Refuter, refutation_search
from crosscert.planner.task import PlanningBounds
from crosscert.robots import DEXTAR
from crosscert.robots.errors import InputError
from crosscert.verifier.tracker import Verdict


class _Run:
    """What search_v_min reads of a CertifiedRun: the verdict and the table row."""

    def __init__(self, v, ok):
        self.verdict = Verdict.MODE_CHANGED if ok else Verdict.UNKNOWN
        self.v = v

    def trial(self):
        return certify_mod.SpeedTrial(self.v, self.verdict, 0.0, 0.0, -1, Verdict.UNKNOWN)


def _answers(monkeypatch, certifies):
    asked = []

    def fake(kin, imodel, task, b, v, progress=None, parallel=True):
        asked.append(v)
        return _Run(v, certifies(v))

    monkeypatch.setattr(certify_mod, "certify_speed", fake)
    return asked


KIN = SimpleNamespace(robot=DEXTAR)


@pytest.mark.parametrize("threshold", [0.61, 0.8438, 0.9987, 1.5, 1.95])
def test_bisection_brackets_a_monotone_threshold_within_tol(monkeypatch, threshold):
    asked = _answers(monkeypatch, lambda v: v >= threshold)
    r = search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, tol=0.01)
    assert r.v_min is not None and threshold <= r.v_min <= threshold + 0.01
    below = [t.v_sing for t in r.trials if t.v_sing < r.v_min]
    assert below and r.v_min - max(below) <= 0.01
    # about log2((v_high - v_low) / tol) questions, each asked once, v_high first
    assert asked[0] == 1.96 and len(asked) == len(set(asked)) <= math.ceil(math.log2(1.36 / 0.01)) + 1
    assert [t.v_sing for t in r.trials] == sorted(asked)


def test_v_low_is_tried_when_everything_certifies(monkeypatch):
    asked = _answers(monkeypatch, lambda v: True)
    r = search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, tol=0.01)
    assert r.v_min == 0.6 and 0.6 in asked


def test_no_v_min_when_the_fastest_speed_fails(monkeypatch):
    asked = _answers(monkeypatch, lambda v: False)
    r = search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, tol=0.01)
    assert r.v_min is None and asked == [1.96]


def test_non_monotone_answers_still_give_a_certified_speed_with_every_faster_trial_certified(monkeypatch):
    """Certified above 1.2 and in (0.9, 1.0) only: whatever bisection finds is certified, and so is every
    tried speed above it (the guarantee that does not need monotonicity)."""
    _answers(monkeypatch, lambda v: v >= 1.2 or 0.9 < v < 1.0)
    r = search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, tol=0.01)
    by_v = {t.v_sing: t.verdict for t in r.trials}
    assert by_v[r.v_min] is Verdict.MODE_CHANGED
    assert all(v is Verdict.MODE_CHANGED for s, v in by_v.items() if s >= r.v_min)


def test_observer_sees_every_trial_in_order(monkeypatch):
    asked = _answers(monkeypatch, lambda v: v >= 1.0)
    seen = []
    search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, tol=0.05, observe=lambda t: seen.append(t.v_sing))
    assert seen == asked


def test_bad_bracket_is_refused(monkeypatch):
    _answers(monkeypatch, lambda v: True)
    with pytest.raises(InputError):
        search_v_min(KIN, None, None, PlanningBounds(), 1.5, 1.0)


class _Row:
    def __init__(self, v, refuted):
        self.speed, self.verified = v, refuted
        self.attempts = ()  # no counterexample to warm-start the bisection from


def test_refuter_never_starts_a_search_at_or_above_the_certified_ceiling(monkeypatch):
    """Once the speed search certifies a speed (drop_from), no search at or above it starts, and the
    bisection stays below it too; the bound is the largest refuted speed within tol."""
    started, gate = [], threading.Event()

    def fake(robot, task, b, m0, starts, v, kin=None, warm=None):
        started.append(v)
        if len(started) == 1:
            gate.wait(10)  # hold the first search until the ceiling is set
        return _Row(v, v <= 0.84)

    monkeypatch.setattr(orchestrate_mod, "refute_speed", fake)
    scan = [round(0.3 + 0.1 * i, 6) for i in range(17)]
    with ThreadPoolExecutor(max_workers=1) as pool:
        ref = Refuter(DEXTAR, None, None, 1, [], None, pool)
        ref.submit(scan)
        ref.failed_at(1.5)  # (stand-in answers) the speed search failed at 1.5: searches start ahead
        ref.drop_from(0.99)  # the speed search certified 0.99 while the first search was running
        gate.set()
        bound, rows = refutation_search(ref, 0.99, 0.01)
        ref.close()
    assert all(v < 0.99 for v in started[1:]), started
    assert 0.83 <= bound <= 0.84 and all(r.speed < 0.99 for r in rows)
    assert len(started) == len(set(started))


def _refuting(monkeypatch, refuted, log=None):
    """refute_speed answering ``refuted(v)``, each row with a counterexample named after its speed."""

    class _Attempt:
        def __init__(self, v):
            self.verified, self.counterexample = True, f"ce@{v}"

    def fake(robot, task, b, m0, starts, v, kin=None, warm=None):
        if log is not None:
            log.append((v, warm))
        row = _Row(v, refuted(v))
        row.attempts = (_Attempt(v),) if row.verified else ()
        return row

    monkeypatch.setattr(orchestrate_mod, "refute_speed", fake)


def test_bisection_steps_start_from_the_fastest_refuted_speeds_counterexample(monkeypatch):
    """The scan's searches start cold; each bisection step gets the counterexample of the fastest
    refuted speed so far (deterministic: it comes from the rows, not from what the worker did last)."""
    calls = []
    _refuting(monkeypatch, lambda v: v <= 0.84, calls)
    ref = Refuter(DEXTAR, None, None, 1, [], None, None)
    ref.submit([0.5, 0.6, 0.7, 0.8, 0.9])
    bound, _rows = refutation_search(ref, 0.99, 0.01)
    assert 0.83 <= bound <= 0.84
    # the scan's bisection: the middle speed, then up while refuted
    assert calls[:3] == [(0.7, None), (0.8, None), (0.9, None)]
    assert len(calls) > 3
    for i in range(3, len(calls)):
        v, warm = calls[i]
        fastest = max(u for u, _w in calls[:i] if u <= 0.84)  # the fastest refuted speed searched before
        assert warm == f"ce@{fastest}", (v, warm)


@pytest.mark.parametrize("threshold", [0.25, 0.31, 0.55, 0.84, 0.97, 1.5])
def test_the_scan_is_bisected_to_the_bracket_searching_every_speed_finds(monkeypatch, threshold):
    """Refuted up to a threshold: the scan's bisection finds the bracket (fastest refuted scan speed, the
    next one) that searching every scan speed finds, in about log2 of the scan's length searches, and so
    the same bound; below the slowest scan speed nothing is refuted and no bound is given."""
    calls = []
    _refuting(monkeypatch, lambda v: v <= threshold, calls)
    scan = [round(0.3 + 0.1 * i, 6) for i in range(12)]  # 0.3 .. 1.4
    top = 1.35
    every = [v for v in scan if v < top]
    refuted = [v for v in every if v <= threshold]
    ref = Refuter(DEXTAR, None, None, 1, [], None, None)
    ref.submit(scan)
    ref.drop_from(top)
    bound, rows = refutation_search(ref, top, 0.01)
    scanned = [v for v, _w in calls if v in scan]
    assert len(scanned) <= math.ceil(math.log2(len(every) + 1)) and len(scanned) < len(every)
    if not refuted:
        assert bound is None and scanned[-1] == every[0]
        return
    assert max(refuted) <= bound <= min(threshold, top) and bound > min(threshold, top) - 0.01
    assert [r.speed for r in rows] == sorted(v for v, _w in calls)


def test_searches_started_ahead_change_neither_rows_nor_bound(monkeypatch):
    """The searches started while the speed search runs are a guess of what the final search asks: with
    the ceiling moving down at any moment, the final rows and bound are those of a search run here."""
    _refuting(monkeypatch, lambda v: v <= 0.84 or 1.05 <= v <= 1.1)  # not monotone either
    scan = [round(0.3 + 0.1 * i, 6) for i in range(17)]
    alone = Refuter(DEXTAR, None, None, 1, [], None, None)
    alone.submit(scan)
    alone.drop_from(0.99)
    want = refutation_search(alone, 0.99, 0.01)
    for pause in (0.0, 0.001, 0.01):
        with ThreadPoolExecutor(max_workers=1) as pool:
            ref = Refuter(DEXTAR, None, None, 1, [], None, pool)
            ref.submit(scan)
            for top, failed in ((1.6, 0.7), (1.3, 1.0), (1.2, 0.98), (0.99, 0.985)):  # the speed search, at its pace
                threading.Event().wait(pause)
                ref.drop_from(top)
                ref.failed_at(failed)
            got = refutation_search(ref, 0.99, 0.01)
            ref.close()
        assert got[0] == want[0] and [(r.speed, r.verified) for r in got[1]] == [(r.speed, r.verified)
                                                                              for r in want[1]]


def test_searches_ahead_are_those_of_the_final_search(monkeypatch):
    """Started once the speed search failed a speed, the searches ahead are those the final search asks
    when no scan speed lies between that failure and v_min (the scan's bisection, then the steps of a
    bracket below the failure): it then starts none of its own, and no speed above the failure is
    searched ahead."""
    calls = []
    _refuting(monkeypatch, lambda v: v <= 0.84, calls)
    scan = [round(0.3 + 0.1 * i, 6) for i in range(17)]
    with ThreadPoolExecutor(max_workers=1) as pool:
        ref = Refuter(DEXTAR, None, None, 1, [], None, pool)
        ref.submit(scan)
        ref.drop_from(1.96)
        ref.drop_from(1.28)
        ref.failed_at(0.94)  # the benchmark's third question
        for _ in range(1000):  # let the searches ahead finish
            if not ref._ahead:
                break
            threading.Event().wait(0.01)
        ahead = [v for v, _w in calls]
        ref.drop_from(0.961)
        bound, rows = refutation_search(ref, 0.961, 0.01)
        ref.close()
    # the scan's bisection of 0.3 .. 0.9 (no speed above the failure), then the steps between 0.8 and 0.9
    assert ahead[:3] == [0.6, 0.8, 0.9] and all(0.8 < v < 0.9 for v in ahead[3:]) and len(ahead) > 3
    assert [v for v, _w in calls] == ahead and 0.83 <= bound <= 0.84  # the final search started none
    assert [r.speed for r in rows] == sorted(ahead)


def _plain(monkeypatch, certifies):
    """v_min and the speeds asked by the search without a guess."""
    asked = _answers(monkeypatch, certifies)
    return search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, tol=0.01).v_min, list(asked)


@pytest.mark.parametrize("threshold", [0.61, 0.8438, 0.9987, 1.5, 1.95])
@pytest.mark.parametrize("guess", [0.3, 0.6, 0.95, 0.9987, 1.0, 1.3, 1.96, 2.5])
def test_search_from_a_guess_finds_the_bisections_answer(monkeypatch, threshold, guess):
    """From any guess (inside, outside or at the ends of the bracket) the search finds the speed the search
    without a guess finds (monotone answers), with every failed speed below v_min and one within tol of it."""
    want, _ = _plain(monkeypatch, lambda v: v >= threshold)
    asked = _answers(monkeypatch, lambda v: v >= threshold)
    r = search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, tol=0.01, v_guess=guess)
    assert r.v_min == want
    by_v = {t.v_sing: t.verdict for t in r.trials}
    assert all((v is Verdict.MODE_CHANGED) == (s >= r.v_min) for s, v in by_v.items())
    below = [s for s in by_v if s < r.v_min]
    assert below and r.v_min - max(below) <= 0.01
    assert len(asked) == len(set(asked))
    # steps doubling away from the guess, then bisection: about 2 log2(distance / tol) questions
    far = max(abs(threshold - min(max(guess, 0.6), 1.96)), 0.01)
    assert len(asked) <= 2 * math.ceil(math.log2(far / 0.01)) + 5


@pytest.mark.parametrize("threshold", [0.6105, 0.8438, 0.9680, 1.0624, 1.5, 1.9555])
def test_a_guess_in_the_answers_cell_asks_its_two_ends(monkeypatch, threshold):
    """The repeated-task case (a guess near the answer): a guess inside the bisection's last bracket asks
    only that bracket's two ends; one a cell away, at most two speeds more."""
    want, plain = _plain(monkeypatch, lambda v: v >= threshold)
    v_fail = max(v for v in plain if v < want)
    assert want - v_fail <= 0.01 and len(plain) >= 8
    cell = want - v_fail
    for guess, most in ((0.5 * (v_fail + want), 2), (want, 2), (want + 0.5 * cell, 4), (v_fail - 0.5 * cell, 4)):
        asked = _answers(monkeypatch, lambda v: v >= threshold)
        r = search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, tol=0.01, v_guess=guess)
        assert r.v_min == want and len(asked) <= most, (guess, asked)
        if most == 2:
            assert asked == [want, v_fail]


def test_search_from_a_guess_at_the_ends(monkeypatch):
    """Everything certifies: v_low itself; nothing certifies: no v_min, v_high asked and failed."""
    asked = _answers(monkeypatch, lambda v: True)
    r = search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, tol=0.01, v_guess=1.0)
    assert r.v_min == 0.6 and asked[-1] == 0.6
    asked = _answers(monkeypatch, lambda v: False)
    r = search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, tol=0.01, v_guess=1.0)
    assert r.v_min is None and asked[-1] == 1.96 and all(v < 1.96 for v in asked[:-1])


def test_non_monotone_answers_from_a_guess_keep_the_guarantee(monkeypatch):
    _answers(monkeypatch, lambda v: v >= 1.2 or 0.9 < v < 1.0)
    for guess in (0.7, 0.95, 1.1, 1.5):
        r = search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, tol=0.01, v_guess=guess)
        by_v = {t.v_sing: t.verdict for t in r.trials}
        assert by_v[r.v_min] is Verdict.MODE_CHANGED
        assert all(v is Verdict.MODE_CHANGED for s, v in by_v.items() if s >= r.v_min)


def test_bad_guess_is_refused(monkeypatch):
    _answers(monkeypatch, lambda v: True)
    with pytest.raises(InputError, match="v_guess"):
        search_v_min(KIN, None, None, PlanningBounds(), 0.6, 1.96, v_guess=-1.0)


def test_the_speed_search_tells_the_refuter_each_answer(monkeypatch):
    """A certified speed caps the counterexample searches, a failed one lets them start ahead of time."""
    told = []

    class _Refuter:
        def drop_from(self, v):
            told.append(("certified", v))

        def failed_at(self, v):
            told.append(("failed", v))

    def fake_search(kin, imodel, task, b, v_low, v_high, *, observe, **kw):
        for v, ok in ((1.9, True), (0.9, False), (1.2, True)):
            observe(certify_mod.SpeedTrial(v, Verdict.MODE_CHANGED if ok else Verdict.UNKNOWN, 0.0, 0.0, None,
                                           Verdict.UNKNOWN))

    monkeypatch.setattr(crossing_mod, "search_v_min", fake_search)
    job = SimpleNamespace(bracket=crossing_mod.SpeedBracket(0.6, 1.96, 0.01), kin=None, imodel=None, task=None,
                          b=None, threads=False)
    crossing_mod._search(job, _Refuter(), None)
    assert told == [("certified", 1.9), ("failed", 0.9), ("certified", 1.2)]


def _certify_without_v_min(monkeypatch, **kw):
    """certify_crossing on the benchmark task with every speed failing (stand-in answers) and counterexamples
    up to 0.849 m/s: only the refutation search runs, here."""
    from crosscert.planner.certify.crossing import certify_crossing
    from crosscert.planner.task import benchmark_task
    from crosscert.robots import KinematicModel, get_entry

    _answers(monkeypatch, lambda v: False)
    _refuting(monkeypatch, lambda v: v <= 0.849)
    return certify_crossing(DEXTAR, benchmark_task(get_entry("dextar")), kin=KinematicModel(DEXTAR), imodel=object(),
                            monte_carlo_runs=0, bounce=False, refute_in_background=False, **kw)


def test_the_refutation_bound_is_bisected_to_a_tenth_of_tol_by_default(monkeypatch):
    """The ratio v_min / bound is only as good as the coarser of the two: the bound is bisected to
    tol / REFUTE_TOL_DIVISOR (0.001 m/s) unless refute_tol says otherwise (at 0.01 m/s it stops 5 mm/s
    short of the last refuted speed here)."""
    assert crossing_mod.REFUTE_TOL_DIVISOR == 10
    fine = _certify_without_v_min(monkeypatch).refutation_bound
    assert 0.849 - 0.001 <= fine <= 0.849
    coarse = _certify_without_v_min(monkeypatch, refute_tol=0.01).refutation_bound
    assert coarse == 0.84375 and 0.849 - coarse > 0.001


@pytest.mark.parametrize("bad", [0.0, -0.001, float("nan"), float("inf"), True])
def test_a_bad_refutation_resolution_is_refused_before_any_model_is_built(monkeypatch, bad):
    from crosscert.planner.certify.crossing import certify_crossing

    def no_model(*a, **k):
        raise AssertionError("a model was built before refute_tol was checked")

    monkeypatch.setattr(crossing_mod, "KinematicModel", no_model)
    with pytest.raises(InputError, match="refute_tol"):
        certify_crossing(DEXTAR, None, refute_tol=bad)
