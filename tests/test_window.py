"""Window reasoning (verifier.window): sound on adversarial runs, stronger than the forward tracker.

The tubes of the surviving final-mode hypotheses must hold the true pose and
velocity at every sample, the true hypothesis must never be refuted, a bounce
is never ``mode-changed`` and a crossing never ``mode-unchanged``.  The runs
are those of test_containment (bang-bang at 0.999 a_max, reading errors at the
edges of +-eps_q, geometries at corners of [xi]) plus crossings slow enough
that the forward tracker cannot certify them.

Removal checks (each made a test here fail, 2026-12-01): the velocity sign
flip of the time reversal (``_reverse``), undecided boxes kept in the final
box of a hypothesis (``m in (mode, 0)``), the velocity prior of the passes.
2026-12-02 (issue 20), the geometry sub-boxes kept from pass to pass
(``Hypothesis.take``): shrunk by one ulp per side, the true geometry test
fails; shrunk by 10 % of their width per side, the adversarial soundness test
(pose tube without the truth at sample 0), the true geometry test and the
test of runs ending at the locus fail.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from adversarial import near_scenarios
from problems import MARGIN, check_contains, interval_model
from crosscert.planner.certify.plan import tracker_settings
from crosscert.planner.execution_proof import execution_class
from crosscert.planner.plan import plan_crossing
from crosscert.planner.task import PlanningBounds
from crosscert.robots import DEXTAR, get_entry
from crosscert.robots.errors import InputError
from crosscert.verifier.tracker import Verdict, initial_box_from_mode, track
from crosscert.verifier.window import HypothesisStatus, Refutation, track_window

N_RUNS = 16  # per family, half crossings and half bounces


def _window(sc, settings, backend="compiled", **kw):
    x0 = initial_box_from_mode(interval_model(), sc.q_meas[0], int(sc.mode[0]), settings)
    return track_window(interval_model(), sc.q_meas, settings, x0=x0, backend=backend, **kw)


def _check_sound(sc, res):
    """No wrong verdict, the true hypothesis alive, the truth in the tubes."""
    crossed = sc.mode[0] != sc.mode[-1]
    assert res.verdict is not Verdict.INCONSISTENT, sc.name
    if crossed:
        assert res.verdict is not Verdict.MODE_UNCHANGED, (sc.name, res.summary())
    else:
        assert res.verdict is not Verdict.MODE_CHANGED, (sc.name, res.summary())
    for h in res.hypotheses:
        if h.final_mode == sc.mode[-1]:
            assert h.status is HypothesisStatus.CONSISTENT, (sc.name, res.summary())
    check_contains(res.x_lo, res.x_hi, sc.x, f"{sc.name}: pose tube")
    check_contains(res.xd_lo, res.xd_hi, sc.xd, f"{sc.name}: velocity tube")


@pytest.fixture(scope="module")
def runs():
    """Fast (1.3-1.6 m/s) and slow (0.9-1.25 m/s) crossings, and bounces, adversarial in every bound."""
    return near_scenarios(N_RUNS, 2) + near_scenarios(N_RUNS, 7, v_cross=(0.9, 1.25), v_bounce=(0.9, 1.3))


@pytest.fixture(scope="module")
def results(runs, settings):
    return [(sc, _window(sc, settings, max_geometries=8)) for sc in runs]


def test_window_is_sound_on_adversarial_runs(results):
    for sc, res in results:
        _check_sound(sc, res)


def _true_geometry_kept(sc, res):
    """Under the true final mode, one surviving geometry sub-box holds the true geometry ``sc.xi``; returns
    whether that hypothesis ran window passes (its sub-boxes were contracted by them)."""
    true = {h.final_mode: h for h in res.hypotheses}.get(int(sc.mode[-1]))
    if true is None:  # no initial mode certified: the window tested no hypothesis
        return False
    inside = np.all((true.xi_lo <= sc.xi) & (sc.xi <= true.xi_hi), axis=1)
    assert inside.any(), (sc.name, res.summary(), sc.xi, true.xi_lo, true.xi_hi)
    return true.passes > 0


def test_window_keeps_the_true_geometry(results):
    """The rows' calibration sub-boxes are contracted by every sample of every pass (``keep_xi``) and kept
    from pass to pass: the true geometry (at a corner of ``[xi]`` in most runs) must stay in one of the
    true hypothesis' surviving sub-boxes.  Removal check: shrinking the sub-boxes a pass returns by one ulp
    on each side (``Hypothesis.take``) loses the corner geometries, and this test fails."""
    passed = sum(_true_geometry_kept(sc, res) for sc, res in results)
    assert passed >= 3, passed  # not vacuous: the window passes ran under the true hypothesis


def _cut(sc, k):
    """The run ``sc`` ending at sample ``k``."""
    return replace(sc, name=f"{sc.name}[:{k + 1}]", t=sc.t[:k + 1], x=sc.x[:k + 1], xd=sc.xd[:k + 1],
                   q_true=sc.q_true[:k + 1], q_meas=sc.q_meas[:k + 1], mode=sc.mode[:k + 1])


def test_window_is_sound_on_runs_ending_at_the_locus(runs, settings):
    """Recordings that end just past a mode change, where the last reading's poses have no certified mode:
    the hypotheses must keep those undecided poses."""
    checked = 0
    for sc in runs[N_RUNS:N_RUNS + 8]:
        for k in np.nonzero(np.diff(sc.mode))[0][:1]:
            for extra in (0, 1, 2):
                cut = _cut(sc, k + extra)
                _check_sound(cut, _window(cut, settings, max_geometries=4))
                checked += 1
    assert checked >= 6


@pytest.mark.parametrize("before", [0, 1, 3, 6])
def test_recordings_ending_at_the_locus(settings, before):
    """A bounce cut where it touches the true locus, or a few samples before: the last reading's poses near
    the truth have no certified mode, and a hypothesis must keep them.  On the locus (mode 0) neither
    hypothesis is true, so the run is neither inconsistent nor certified; before it, the true mode survives.

    End to end, the guard of the undecided forward-kinematics solutions in the final boxes
    (``hull_of_mode``): with them dropped, the tubes of both hypotheses lose the truth at the last sample
    of the cut on the locus (``before`` = 0), and this test fails."""
    from problems import simulate

    run = simulate(1.0, True, 0)
    k = run.k_sing - before
    assert run.mode_true[run.k_sing] == 0
    res = track_window(interval_model(), run.q_meas[:k + 1], settings, initial_mode=int(run.mode_true[0]),
                       max_geometries=4)
    assert res.verdict in (Verdict.UNKNOWN, Verdict.MODE_UNCHANGED), res.summary()
    if before:
        true = {h.final_mode: h for h in res.hypotheses}[int(run.mode_true[k])]
        assert true.status is HypothesisStatus.CONSISTENT, res.summary()
    else:
        assert res.verdict is Verdict.UNKNOWN, res.summary()
    check_contains(res.x_lo, res.x_hi, run.x_true[:k + 1], "pose tube")
    # each hypothesis the truth satisfies (last pose of its mode or on the locus) keeps the truth in its own
    # tubes; the hull over both would hide a final box that lost the locus (both sides surround it)
    held = [h for h in res.hypotheses if run.mode_true[k] in (0, h.final_mode)]
    assert len(held) == (2 if before == 0 else 1)
    for h in held:
        assert h.status is HypothesisStatus.CONSISTENT, res.summary()
        check_contains(h.x_lo, h.x_hi, run.x_true[:k + 1], f"pose tube of final mode {h.final_mode:+d}")
        check_contains(h.xd_lo, h.xd_hi, run.xd_true[:k + 1], f"velocity tube of final mode {h.final_mode:+d}")


def test_early_stop_is_reported(settings, monkeypatch):
    """The rounds stop at the first refutation: the other hypothesis, whose later passes might have
    refuted it too (then the recording is ``inconsistent``), is reported consistent but incomplete.  The
    violation is simulated: every window pass after the forward one reports its rows empty, so the first
    hypothesis is refuted at its first pass and the second never runs one (fails when the survivor is
    reported complete)."""
    import crosscert.verifier.window.passes as P
    from problems import simulate

    real = P.run_pass

    def emptied(config, q, x0, xi_rows, prior, clock=None):
        x, xd, md, bad, xi = real(config, q, x0, xi_rows, prior, clock)
        return (x, xd, md, np.zeros_like(bad) if prior is not None else bad, xi)

    run = simulate(1.0, False, 0)
    honest = track_window(interval_model(), run.q_meas, settings, initial_mode=1, max_geometries=4)
    assert honest.forward_verdict is Verdict.UNKNOWN
    assert all(h.complete for h in honest.hypotheses), honest.summary()  # neither refuted: every round ran
    monkeypatch.setattr(P, "run_pass", emptied)
    res = track_window(interval_model(), run.q_meas, settings, initial_mode=1, max_geometries=4)
    first, second = res.hypotheses
    assert first.status is HypothesisStatus.REFUTED and first.passes == 1 and first.complete, res.summary()
    assert second.status is HypothesisStatus.CONSISTENT and second.passes == 0, res.summary()
    assert not second.complete and res.summary()["hypotheses"][1]["complete"] is False, res.summary()


def test_final_boxes_keep_poses_of_undecided_mode(settings):
    """On the locus the true pose is the limit of both modes: the final box of either hypothesis holds it."""
    from problems import simulate
    from crosscert.verifier.window.passes import _final_box

    run = simulate(1.0, True, 0)
    k = run.k_sing
    s = settings.validated(2)
    for mode in (1, -1):
        box = _final_box(interval_model(), run.q_meas[k], mode, s, interval_model().xi_box(), "compiled")
        check_contains(box[0][None], box[1][None], run.x_true[k][None], f"final box of mode {mode:+d}")


def test_window_certifies_what_the_forward_tracker_cannot(results, settings):
    """Not vacuous: some crossings are certified only by the window, and every forward certificate is kept."""
    gained = 0
    for sc, res in results:
        if res.forward_verdict is not Verdict.UNKNOWN:
            assert res.verdict is res.forward_verdict, (sc.name, res.summary())
        elif res.verdict is not Verdict.UNKNOWN:
            gained += 1
    assert gained >= 3, gained
    changed = [sc.name for sc, res in results if res.verdict is Verdict.MODE_CHANGED]
    assert len(changed) >= N_RUNS // 2, changed


def test_forward_pass_is_the_tracker(results, settings):
    """The window's first pass is the tracker: same verdict as ``track``."""
    for sc, res in results[:4]:
        fwd = track(interval_model(), sc.q_meas, settings, initial_mode=int(sc.mode[0]))
        assert res.forward_verdict is fwd.verdict, sc.name


@pytest.mark.parametrize("speed, certified", [(1.0, True), (0.8, False)])
def test_planning_run_at_one_metre_per_second(speed, certified):
    """The benchmark plan at 1.0 m/s: the forward tracker says unknown, the window certifies the change
    (below the refutation floor, 0.84 m/s, it must not)."""
    entry = get_entry("dextar")
    from crosscert.planner.task import benchmark_task
    from crosscert.robots import KinematicModel

    kin = KinematicModel(DEXTAR)
    b = PlanningBounds(a_margin=MARGIN).resolve(DEXTAR)
    plan = plan_crossing(kin, benchmark_task(entry), speed, b)
    cls = execution_class(kin, plan, b)
    s = tracker_settings(b.for_plan(plan), cls)
    res = track_window(interval_model(), plan.q, s, initial_mode=1, xi_box=cls.xi_box, max_geometries=4)
    assert res.forward_verdict is Verdict.UNKNOWN
    assert res.verdict is (Verdict.MODE_CHANGED if certified else Verdict.UNKNOWN), res.summary()
    if certified:
        wrong = {h.final_mode: h for h in res.hypotheses}[1]
        assert wrong.refutation is Refutation.EMPTY_TUBE


def test_backends_agree(runs, settings):
    """The numpy reference and the compiled kernels give the same window verdict and the same tubes."""
    sc = runs[N_RUNS + 2]  # a slow crossing
    a = _window(sc, settings, "compiled", max_passes=2, max_geometries=4)
    b = _window(sc, settings, "numpy", max_passes=2, max_geometries=4)
    assert a.verdict is b.verdict and a.hypotheses == b.hypotheses
    for name in ("x_lo", "x_hi", "xd_lo", "xd_hi"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=1e-12, err_msg=name)
    for ha, hb in zip(a.hypotheses, b.hypotheses):  # the contracted geometry sub-boxes too
        for name in ("xi_lo", "xi_hi"):
            np.testing.assert_array_equal(getattr(ha, name), getattr(hb, name), err_msg=name)


def test_a_goal_gives_the_same_verdict_with_one_hypothesis(results, settings):
    """``goal``: asked about the true verdict, the window refutes the same false hypothesis as with both (the
    true one is never refuted, and each hypothesis' rounds ignore the other's), while the other runs no
    round; asked about the wrong one, it can only say ``unknown`` (or what the forward pass or the last
    reading alone decided).  Removal check: picking the other hypothesis in ``_targets`` fails the first
    assertion on every run the window passes decide."""
    decided = 0
    for sc, res in results[N_RUNS:]:  # the slow crossings and bounces: most undecided by the forward pass
        truth = Verdict.MODE_CHANGED if sc.mode[0] != sc.mode[-1] else Verdict.MODE_UNCHANGED
        wrong = Verdict.MODE_UNCHANGED if truth is Verdict.MODE_CHANGED else Verdict.MODE_CHANGED
        asked = _window(sc, settings, max_geometries=8, goal=truth)
        assert asked.verdict is res.verdict, (sc.name, res.summary(), asked.summary())
        _check_sound(sc, asked)
        if res.forward_verdict is not Verdict.UNKNOWN or asked.verdict is Verdict.UNKNOWN:
            continue
        decided += 1
        other = {h.final_mode: h for h in asked.hypotheses}[int(sc.mode[-1])]
        assert other.passes == 0 and not other.complete, asked.summary()
        misled = _window(sc, settings, max_geometries=8, goal=wrong.value)
        assert misled.verdict in (Verdict.UNKNOWN, truth), (sc.name, misled.summary())
        _check_sound(sc, misled)
    assert decided >= 2, decided  # not vacuous: some verdicts come from the window passes


def test_rounds_go_to_the_hypothesis_with_fewest_rows(settings, monkeypatch):
    """The next round goes to the hypothesis that has run the fewest rows (ties: the initial mode's), among
    those with budget left.  On a simulated run where nothing is refuted, a hypothesis has budget left
    exactly while it has a round to come.  Removal check: giving every round to the first open hypothesis
    (no balancing) fails here."""
    import crosscert.verifier.window.hypotheses as H
    from problems import simulate

    order, real = [], H._round

    def logged(h, passes, max_passes, rel_tol):
        order.append((h.m, passes.rows))
        real(h, passes, max_passes, rel_tol)

    monkeypatch.setattr(H, "_round", logged)
    run = simulate(1.0, False, 0)
    # one_motion=0: the one-motion refutation decides this run (2026-12-02), and a refutation ends the rounds
    res = track_window(interval_model(), run.q_meas, settings, initial_mode=1, max_geometries=4, one_motion=0)
    assert res.verdict is Verdict.UNKNOWN and order[0][0] == 1, (order, res.summary())
    spent = {1: 0, -1: 0}
    for i, ((m, total), nxt) in enumerate(zip(order, order[1:] + [(None, None)])):
        still_open = {h for h, _ in order[i:]}
        assert spent[m] == min(spent[h] for h in still_open), (order, spent)
        if nxt[1] is not None:
            spent[m] += nxt[1] - total
    assert {m for m, _ in order} == {1, -1}, order


def test_bad_arguments_are_refused(runs, settings):
    sc = runs[0]
    with pytest.raises(InputError, match="exactly one"):
        track_window(interval_model(), sc.q_meas, settings)
    with pytest.raises(InputError, match="max_passes"):
        _window(sc, settings, max_passes=-1)
    with pytest.raises(InputError, match="max_geometries"):
        _window(sc, settings, max_geometries=0)
    with pytest.raises(InputError, match="shape"):
        track_window(interval_model(), sc.q_meas[:, :1], settings, initial_mode=1)
    for goal in (Verdict.UNKNOWN, "crossed", Verdict.INCONSISTENT):
        with pytest.raises(InputError, match="goal"):
            _window(sc, settings, goal=goal)


def test_halving_follows_the_pose_spread_and_covers_the_parent():
    """Sub-boxes are halved along the parameter that spreads the pose most (the joint offsets of the
    DexTAR's partition first: about 0.7 mm against 0.2-0.5 mm for the lengths at the benchmark's start),
    through a shared float split point, and along the widest relative width where the spread is not finite."""
    from problems import simulate
    from crosscert.verifier.step import partition_xi
    from crosscert.verifier.window.hypotheses import _bisect, _pose_spread

    im = interval_model()
    XI = im.xi_box()
    lo, hi = (v[0] for v in partition_xi((XI[0][None], XI[1][None]), DEXTAR.xi_splits))
    run = simulate(1.0, False, 0)
    x = np.repeat(np.stack([run.x_true[0] - 1e-4, run.x_true[0] + 1e-4])[None], len(lo), axis=0)
    spread = _pose_spread(im, x, run.q_meas[0], lo, hi)
    assert np.all(np.isfinite(spread)) and np.all(spread > 0)
    assert set(np.argmax(spread, axis=1)) <= {5, 6}, spread  # the offsets delta1, delta2
    full_w = XI[1] - XI[0]
    for sp, axes in ((spread, np.argmax(spread, axis=1)), (np.full_like(spread, np.nan), np.zeros(len(lo), int))):
        nlo, nhi = _bisect(lo, hi, full_w, sp)
        R = len(lo)
        for r in range(R):
            a = axes[r]
            left, right = (nlo[r], nhi[r]), (nlo[R + r], nhi[R + r])
            assert left[1][a] == right[0][a] and lo[r][a] < left[1][a] < hi[r][a]  # one shared split point
            assert np.array_equal(left[0], lo[r]) and np.array_equal(right[1], hi[r])
            others = np.arange(len(XI[0])) != a
            assert np.array_equal(left[1][others], hi[r][others]) and np.array_equal(right[0][others], lo[r][others])


def test_the_pose_spread_of_rows_evaluated_together_is_that_of_each_alone():
    """``Hypothesis.split`` evaluates both ends of every row in one call (per-row readings): each row's
    spread must be bit for bit what a call of its own gives, or the halving (and so the verdicts) would
    depend on how rows are batched."""
    from problems import simulate
    from crosscert.verifier.step import partition_xi
    from crosscert.verifier.window.hypotheses import _pose_spread

    im = interval_model()
    XI = im.xi_box()
    lo, hi = (v[0] for v in partition_xi((XI[0][None], XI[1][None]), DEXTAR.xi_splits))
    run = simulate(1.0, False, 0)
    ends = []
    for k in (0, len(run.q_meas) - 1):
        x = np.repeat(np.stack([run.x_true[k] - 1e-4, run.x_true[k] + 2e-4])[None], len(lo), axis=0)
        ends.append((x, run.q_meas[k]))
    R = len(lo)
    together = _pose_spread(im, np.concatenate([ends[0][0], ends[1][0]]),
                            np.concatenate([np.tile(ends[0][1], (R, 1)), np.tile(ends[1][1], (R, 1))]),
                            np.concatenate([lo, lo]), np.concatenate([hi, hi]))
    for e, (x, q) in enumerate(ends):
        assert np.array_equal(together[e * R:(e + 1) * R], _pose_spread(im, x, q, lo, hi))
        for r in range(R):
            assert np.array_equal(together[e * R + r], _pose_spread(im, x[r:r + 1], q, lo[r:r + 1], hi[r:r + 1])[0])


def test_acceleration_bound_between_samples_certifies_the_plan_at_0961(monkeypatch):
    """``crosscert certify``'s plan at 0.961 m/s (derived a_max 80 / 66 m/s^2): undecided by the passes
    alone (the bounce hypothesis survives with 9-10 sub-boxes), certified once every pass's tubes are
    contracted with the two-sample acceleration bound (verifier.motion_model, docs/soundness.md, "Window
    reasoning", step 8).  Removal check (2026-12-02): without the call in ``Hypothesis.take`` this test
    fails (``unknown``).  The one-motion step (step 9) is off here: it certifies this plan on its own."""
    import crosscert.verifier.window.hypotheses as H
    from crosscert.planner.certify.plan import certify_speed

    monkeypatch.setattr(H, "one_motion_rows",
                        lambda model, s, q, XI, *a, **kw: (np.zeros(len(XI[0]), dtype=bool), XI[0].copy(), XI[1].copy()))
    from crosscert.planner.task import benchmark_task
    from crosscert.robots import KinematicModel

    run = certify_speed(KinematicModel(DEXTAR), interval_model(), benchmark_task(get_entry("dextar")),
                        PlanningBounds(a_margin=MARGIN), 0.961)
    assert run.forward.verdict is Verdict.UNKNOWN
    assert run.window.verdict is Verdict.MODE_CHANGED, run.window.summary()


def test_the_compiled_contraction_changes_no_reported_box(monkeypatch):
    """The window's compiled backend contracts its tubes with the compiled pair kernel
    (``contract_tubes(compiled=True)``); with numpy's contraction instead, the same run reports the same
    verdicts, passes and sub-boxes and the same tubes, bit for bit (catalogue problem ``crossing_0500``)."""
    import crosscert.verifier.window.hypotheses as H
    from problems import CATALOGUE, default_settings, run_of

    real, calls = H.contract_tubes, []

    def reference(*args, compiled=False, **kw):
        calls.append(compiled)
        return real(*args, **kw)

    run, s = run_of(CATALOGUE["crossing_0500"]), default_settings()
    kernel = track_window(interval_model(), run.q_meas, s, initial_mode=1, max_geometries=8)
    monkeypatch.setattr(H, "contract_tubes", reference)
    numpy = track_window(interval_model(), run.q_meas, s, initial_mode=1, max_geometries=8)
    assert calls and all(calls)  # the compiled backend asked for the kernel, and got numpy's here
    assert sum(h.passes for h in kernel.hypotheses) >= 4, kernel.summary()
    assert kernel.verdict is numpy.verdict and kernel.hypotheses == numpy.hypotheses
    pairs = [(kernel, numpy)] + list(zip(kernel.hypotheses, numpy.hypotheses))
    for a, b in pairs:
        for name in ("x_lo", "x_hi", "xd_lo", "xd_hi", "xi_lo", "xi_hi"):
            u, v = getattr(a, name, None), getattr(b, name, None)
            assert (u is None) == (v is None), name
            if u is not None:
                assert np.array_equal(u, v, equal_nan=True), name


def test_a_sub_box_the_one_motion_step_left_as_it_was_is_not_asked_again(monkeypatch):
    """``crosscert certify``'s plan at 0.8548 m/s (undecided, the step runs seven times): a sub-box that a step
    returned unchanged (not dropped, not narrowed) is not passed to the step again while it stays the same,
    and the verdict is the same as when every row is asked.  Fails without the rows kept in
    ``Hypothesis.one_motion``."""
    import crosscert.verifier.window.hypotheses as H
    from crosscert.planner.certify.plan import certify_speed
    from crosscert.planner.task import benchmark_task
    from crosscert.robots import KinematicModel

    real, kept, again = H.one_motion_rows, set(), []

    def watching(model, s, q, XI, X, XD, samples, **kw):
        out, lo, hi = real(model, s, q, XI, X, XD, samples, **kw)
        for r in range(len(XI[0])):
            key = XI[0][r].tobytes() + XI[1][r].tobytes()
            again.append(key in kept)
            if not out[r] and np.array_equal(lo[r], XI[0][r]) and np.array_equal(hi[r], XI[1][r]):
                kept.add(key)
        return out, lo, hi

    monkeypatch.setattr(H, "one_motion_rows", watching)
    run = certify_speed(KinematicModel(DEXTAR), interval_model(), benchmark_task(get_entry("dextar")),
                        PlanningBounds(one_motion=40, a_margin=MARGIN), 0.8548)
    assert run.window.verdict is Verdict.UNKNOWN
    assert len(kept) > 0 and len(again) >= 20 and not any(again), (len(kept), len(again), sum(again))
