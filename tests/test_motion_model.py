"""The two-sample acceleration bound on tubes (verifier.motion_model): the exact truth stays inside.

The motions spend the whole budget: every coordinate accelerates at exactly
``+-a_max`` at every instant, switching sign between samples, so that the
bound is attained (``|x_l - x_k - (v_k + v_l) tau / 2|`` equals
``a tau^2 / 4 - (v_l - v_k)^2 / (4 a)`` on every interval between two
samples).  Positions and velocities are exact rationals (``Fraction``); the
tubes are the tightest float boxes around them (one ulp), or wider ones, and
the contracted boxes must still hold the exact values.

Removal checks (2026-12-02, each made a test here fail): the square term
dropped (``a tau^2 / 4`` alone: ``test_contracts_what_taylor_cannot``); the
square's upper bound instead of its lower one, or the remainder halved (the
containment tests; halved, also test_window's adversarial soundness tests);
``tau = j t_s`` rounded to nearest (``test_constants_and_remainder_...``).
Rounding the remainder, the quotient by ``4 a``, ``a tau^2 / 4`` or
``2 r / tau`` to nearest failed no test: each error is at most half an ulp,
absorbed by the next operation's outward step (docs/soundness.md, "Window
reasoning", step 8).

The compiled pair contraction (``contract_tubes(compiled=True)``,
verifier/compiled/motion_model.py) runs every containment test too and is compared
with the reference bit for bit.  Removal checks on the kernel (2026-12-02):
the remainder halved fails the containment tests; the remainder rounded to
nearest, the ``l`` ends written before the ``k`` ends, the old ``v_k`` used
for ``v_l``, or no flag on a negative remainder each fail
``test_compiled_contraction_is_the_reference_on_adversarial_tubes``.

Stamped times (``contract_tubes(times=...)``): motions sampled at jittered true times with a dropped
sample, stamps off by up to ``delta``.  Removal checks (2026-12-07, each made a test here fail): the
enclosures' ends not crossed (``t_l.lo - t_k.lo``, ``t_l.hi - t_k.hi``) or the stamps' midpoints (the
stamps' error dropped) fail ``test_stamped_times_keep_the_exact_truth``, as does the test's own
enclosures built with ``delta = 0`` (``test_the_stamps_error_term_is_needed`` keeps that as a test);
``a tau^2 / 4`` from ``tau``'s lower end, or each pair given its neighbour's constants, fail the
containment tests; ``tau`` rounded to nearest fails ``test_per_pair_constants_bound_the_exact_values``
only; contracting the pairs whose ``tau_lo`` is 0 or negative fails
``test_pairs_whose_time_enclosure_is_not_positive_are_skipped``; the kernel reading the first pair's
``2 / tau``, ``tau / 2`` or ``e4`` for every pair fails ``test_compiled_contraction_is_the_reference_with_times``
(and the compiled containment tests); read-only per-pair arrays (a second compilation) fail its check of
the argument types.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from crosscert.verifier import interval as I
from crosscert.verifier.motion_model import MOTION_OFFSETS, _constants, _constants_of_tau, _remainder, _taus, contract_tubes

T_S = 0.001  # s (A6: the float itself)
#: every containment test runs the numpy reference and the compiled kernel (verifier.compiled.motion_model)
BOTH = pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
A_MAX = np.array([80.0, 60.0])  # m/s^2


def _exact_motion(rng, K, a, x0, v0, dwell, at=None):
    """Exact positions and velocities at ``t_k = k T_S`` (or at the exact instants ``at``, increasing from 0)
    of a motion with ``x'' = +-a`` everywhere, its sign switching at rational instants drawn ``dwell`` (in
    periods ``T_S``) apart, never at a sample."""
    ts, a = Fraction(T_S), Fraction(a)
    at = [ts * k for k in range(K)] if at is None else at
    t_end, samples = at[-1], set(at)
    switches, t = [], Fraction(0)
    while t < t_end:
        t += ts * Fraction(int(rng.integers(int(1000 * dwell[0]), int(1000 * dwell[1]))), 1000)
        if t in samples:  # not at a sample
            t += ts / 7
        switches.append(t)
    sign = 1 if rng.random() < 0.5 else -1
    x, v, t, xs, vs = Fraction(x0), Fraction(v0), Fraction(0), [], []
    events = sorted([(tk, "sample") for tk in at] + [(s, "switch") for s in switches if s < t_end])
    for te, kind in events:
        h = te - t
        x, v, t = x + v * h + sign * a * h * h / 2, v + sign * a * h, te
        if kind == "sample":
            xs.append(x)
            vs.append(v)
        else:
            sign = -sign
    return xs, vs


def _box(values, widen=0.0, rng=None):
    """Tightest float boxes ``(K, 2)`` around exact values, widened by up to ``widen`` on each side."""
    lo = np.array([float(v) for v in values])
    hi = lo.copy()
    for i, v in enumerate(values):
        if Fraction(lo[i]) > v:
            lo[i] = np.nextafter(lo[i], -np.inf)
        if Fraction(hi[i]) < v:
            hi[i] = np.nextafter(hi[i], np.inf)
    if widen:
        lo -= widen * rng.random(len(lo))
        hi += widen * rng.random(len(hi))
    return np.stack([lo, hi], axis=1)


def _tubes(seed, rows=4, K=60, dwell=(1.1, 3.0), widen_x=0.0, widen_v=0.0, *, rng=None, at=None):
    """Rows of exact motions (both coordinates at their ``A_MAX``) and their tubes ``(R, K, 2, n)``, sampled
    every ``T_S`` or at the times ``at`` (s from the first); ``rng`` instead of a new generator of ``seed``."""
    rng = np.random.default_rng(seed) if rng is None else rng
    n = len(A_MAX)
    x, xd = np.empty((rows, K, 2, n)), np.empty((rows, K, 2, n))
    truth = []
    for r in range(rows):
        row = []
        for c in range(n):
            xs, vs = _exact_motion(rng, K, A_MAX[c], rng.uniform(-0.1, 0.1), rng.uniform(-1.5, 1.5), dwell, at)
            x[r, :, :, c] = _box(xs, widen_x, rng)
            xd[r, :, :, c] = _box(vs, widen_v, rng)
            row.append((xs, vs))
        truth.append(row)
    return x, xd, truth


def _check_inside(x, xd, truth):
    for r, row in enumerate(truth):
        for c, (xs, vs) in enumerate(row):
            for k in range(len(xs)):
                assert Fraction(x[r, k, 0, c]) <= xs[k] <= Fraction(x[r, k, 1, c]), ("pose", r, c, k)
                assert Fraction(xd[r, k, 0, c]) <= vs[k] <= Fraction(xd[r, k, 1, c]), ("velocity", r, c, k)


@BOTH
def test_one_ulp_tubes_keep_the_exact_truth(compiled):
    """The tightest tubes around motions that attain the bound on every interval: nothing may be lost."""
    for seed in range(3):
        x, xd, truth = _tubes(seed)
        empty = contract_tubes(x, xd, T_S, A_MAX, compiled=compiled)
        assert not empty.any()
        _check_inside(x, xd, truth)


@BOTH
@pytest.mark.parametrize("widen_x, widen_v", [(1e-6, 0.0), (0.0, 0.05), (2e-5, 0.3)])
def test_wide_tubes_keep_the_exact_truth_and_shrink(widen_x, widen_v, compiled):
    x, xd, truth = _tubes(10, widen_x=widen_x, widen_v=widen_v, dwell=(0.6, 4.0))
    w0 = (x[..., 1, :] - x[..., 0, :]).sum() + (xd[..., 1, :] - xd[..., 0, :]).sum()
    empty = contract_tubes(x, xd, T_S, A_MAX, compiled=compiled)
    assert not empty.any()
    _check_inside(x, xd, truth)
    assert (x[..., 1, :] - x[..., 0, :]).sum() + (xd[..., 1, :] - xd[..., 0, :]).sum() < w0


@BOTH
def test_contracts_what_taylor_cannot(compiled):
    """Velocities -0.039 and +0.039 m/s one sample apart at 80 m/s^2: the motion must accelerate almost the
    whole time, so the displacement lies within ``r = a tau^2 / 4 - (v_l - v_k)^2 / (4 a)`` (about 1 um) of
    ``(v_k + v_l) tau / 2 = 0``; both ends are reached (accelerate, then brake, or the reverse), so the
    contracted box must keep them.  Without the square term it is ``a tau^2 / 4 = 20 um`` wide."""
    a, v = 80.0, 0.039
    x = np.zeros((1, 2, 2, 1))
    xd = np.zeros((1, 2, 2, 1))
    x[0, 1, :, 0] = -1e-3, 1e-3
    xd[0, 0, :, 0], xd[0, 1, :, 0] = -v, v
    assert not contract_tubes(x, xd, T_S, [a], offsets=(1,), compiled=compiled).any()
    r = Fraction(a) * Fraction(T_S) ** 2 / 4 - (2 * Fraction(v)) ** 2 / (4 * Fraction(a))
    lo, hi = Fraction(x[0, 1, 0, 0]), Fraction(x[0, 1, 1, 0])
    assert lo <= -r and r <= hi
    assert hi - lo < Fraction(201, 100) * r, (float(lo), float(hi), float(r))


@BOTH
def test_no_motion_within_a_max_is_refuted(compiled):
    """Velocities 1 m/s apart one sample apart need 1000 m/s^2: the row is refuted, the other kept."""
    x = np.zeros((2, 5, 2, 2))
    xd = np.zeros((2, 5, 2, 2))
    xd[0, 3, :, 0] = 1.0
    xd[0, 3, 0, 1] = -1e-3
    x[0, 3:, :, 0] = 0.5e-3
    empty = contract_tubes(x, xd, T_S, A_MAX, compiled=compiled)
    assert empty.tolist() == [True, False]
    assert np.all(x[1] == 0.0) and np.all(xd[1] == 0.0)  # exact zeros stay exact


@BOTH
def test_offsets_beyond_the_recording_are_skipped(compiled):
    x, xd, truth = _tubes(3, rows=1, K=3)
    assert max(MOTION_OFFSETS) >= 3
    assert not contract_tubes(x, xd, T_S, A_MAX, compiled=compiled).any()
    _check_inside(x, xd, truth)


def test_constants_and_remainder_bound_the_exact_values():
    """Each rounded quantity against its exact rational value, on many random velocity pairs and sample
    distances (a rounding to nearest is below the exact value about half the time)."""
    rng = np.random.default_rng(5)
    for j in (1, 2, 3, 4, 7, 8, 13, 16):
        a = rng.uniform(1.0, 200.0, 64)
        tau, inv2, e4, four_a = _constants(j, T_S, a)
        t = j * Fraction(T_S)
        assert Fraction(float(tau[0])) <= t <= Fraction(float(tau[1]))
        assert Fraction(float(inv2[0])) <= 2 / t <= Fraction(float(inv2[1]))
        vk = rng.uniform(-2.0, 2.0, 64)
        vl = vk + rng.uniform(-1.0, 1.0, 64) * a * float(t)
        r = _remainder((vk, vk), (vl, vl), e4, four_a)
        for i in range(64):
            A = Fraction(float(a[i]))
            assert Fraction(float(four_a[0][i])) <= 4 * A <= Fraction(float(four_a[1][i]))
            assert Fraction(float(e4[i])) >= A * t * t / 4
            exact = A * t * t / 4 - (Fraction(float(vl[i])) - Fraction(float(vk[i]))) ** 2 / (4 * A)
            assert Fraction(float(r[i])) >= exact, (j, i)


def _same_floats(a, b):
    """Equal float for float, the sign of zeros included; NaN where the other has NaN."""
    num = ~np.isnan(a)
    return np.array_equal(a, b, equal_nan=True) and np.array_equal(np.signbit(a[num]), np.signbit(b[num]))


def _both_ways(x, xd, a, offsets=MOTION_OFFSETS, t_s=T_S, times=None):
    """Contract copies of the tubes with the numpy reference and with the compiled kernel; check both give the
    same floats and the same refuted rows.  Returns how many rows were refuted."""
    out = []
    for compiled in (False, True):
        xc, xdc = x.copy(), xd.copy()
        empty = contract_tubes(xc, xdc, t_s, a, offsets, compiled=compiled, times=times)
        out.append((xc, xdc, empty))
    (x0, xd0, e0), (x1, xd1, e1) = out
    assert np.array_equal(e0, e1)
    assert _same_floats(x0, x1) and _same_floats(xd0, xd1)
    return int(e0.sum())


def test_compiled_contraction_is_the_reference_on_a_window_run(monkeypatch):
    """The tubes the window contracts on the catalogue's slow crossing (``crossing_0500``, a few rounds), after
    every pass: the kernel gives numpy's floats bit for bit (the window's compiled backend uses the kernel,
    and its verdicts and reported tubes are those of the reference's contraction)."""
    import crosscert.verifier.window.hypotheses as H
    from problems import CATALOGUE, default_settings, interval_model, run_of
    from crosscert.verifier.window import track_window

    seen = []

    def spy(x, xd, t_s, a_max, *args, **kw):
        seen.append((x.copy(), xd.copy(), t_s, np.array(a_max)))
        return contract_tubes(x, xd, t_s, a_max, *args, **kw)

    monkeypatch.setattr(H, "contract_tubes", spy)
    run = run_of(CATALOGUE["crossing_0500"])
    track_window(interval_model(), run.q_meas, default_settings(), initial_mode=1, max_geometries=4)
    assert len(seen) >= 4
    pairs = 0
    for x, xd, t_s, a in seen:
        assert t_s == default_settings().t_s
        K = x.shape[1]
        pairs += sum(np.any(np.maximum(xd[:, j:, 0] - xd[:, :K - j, 1], xd[:, :K - j, 0] - xd[:, j:, 1]) > 0)
                     for j in MOTION_OFFSETS if j < K)
        _both_ways(x, xd, a, t_s=t_s)
    assert pairs > 0  # some pass had pairs to contract


def _adversarial_tubes(rng, special, steps=T_S):
    """The tubes of :func:`test_compiled_contraction_is_the_reference_on_adversarial_tubes` ``(6, 40, 2, 2)``,
    sampled ``steps`` apart (a float, or ``(40, 1, 1)``: the time from each sample's predecessor)."""
    R, K, n = 6, 40, 2
    # velocities 0.9 a_max t_s apart from sample to sample (the bound nearly binds), in boxes narrower than
    # that; poses their trapezoid sums, in boxes wider than the remainder
    v = np.cumsum(rng.choice([-0.9, 0.9], (R, K, 1, n)) * A_MAX * steps, axis=1)
    side = np.array([-1.0, 1.0])[:, None]
    xd = v + side * rng.uniform(0.0, 2e-3, (R, K, 2, n))
    sums = v[:, 1:] + v[:, :-1]
    trapezoids = np.cumsum(sums, axis=1) * (steps / 2) if np.ndim(steps) == 0 else np.cumsum(sums * (steps[1:] / 2), axis=1)
    x = np.concatenate([np.zeros((R, 1, 1, n)), trapezoids], axis=1)
    x = x + side * rng.uniform(1e-7, 5e-6, (R, K, 2, n))
    if special:
        values = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1e-310, -1e-310])
        for tube in (x, xd):
            hit = rng.random(tube.shape) < 0.03
            tube[hit] = rng.choice(values, hit.sum())
            flip = rng.random((R, K, n)) < 0.02  # empty boxes
            lo, hi = tube[:, :, 0].copy(), tube[:, :, 1].copy()
            tube[:, :, 0][flip], tube[:, :, 1][flip] = hi[flip], lo[flip]
            point = rng.random((R, K, n)) < 0.05
            tube[:, :, 1][point] = tube[:, :, 0][point]
        x[0], xd[0] = 0.0, 0.0  # a row of exact zeros
    xd[1, 10, :, 0] = 1.0  # a jump no motion within a_max makes
    # the same in a row whose pose boxes are so wide that no box becomes empty: only the negative remainder
    # refutes it (removal check: the kernel not flagging it passes every other test)
    x[2, :, 0], x[2, :, 1] = -1.0, 1.0
    xd[2, 20:, :, 1] += 0.5
    return x, xd


@pytest.mark.parametrize("seed, special", [(0, True), (1, True), (2, False), (3, False)])
def test_compiled_contraction_is_the_reference_on_adversarial_tubes(seed, special):
    """Random tubes with velocity jumps (some rows' remainders negative), and with ``special``, empty and NaN
    boxes, signed zeros, subnormal, infinite and point bounds: the kernel gives the reference's floats and
    refutes the same rows.  Without ``special`` most rows survive and are contracted."""
    x, xd = _adversarial_tubes(np.random.default_rng(seed), special)
    R = x.shape[0]
    refuted = _both_ways(x, xd, A_MAX)
    assert 2 <= refuted < R or special
    _both_ways(x, xd, A_MAX, offsets=(1, 3, 2, 1))
    if not special:  # the reference contracts the surviving rows
        xc, xdc = x.copy(), xd.copy()
        live = ~contract_tubes(xc, xdc, T_S, A_MAX)
        assert live.any() and (np.any(xc[live] != x[live]) or np.any(xdc[live] != xd[live]))


# Samples at stamped times (``contract_tubes(times=...)``): jittered true times, a dropped sample, stamps
# that are off by up to DELTA.

DELTA = 0.05 * T_S  # s: the bound on the true times' jitter about the grid and on the stamps' error
ORIGIN = 100  # s: the stamps' origin, so that a difference of two stamps is rounded


def _stamped_run(seed, delta=DELTA, rows=4, K=40, widen_x=1e-9, widen_v=1e-7):
    """Rows of exact motions (both coordinates at their ``A_MAX``, bang-bang) sampled at jittered true times
    ``ORIGIN + m T_S + e_m`` (``|e_m| <= delta``, one ``m`` dropped: a step of about ``2 T_S``), their tubes
    (the tightest boxes, widened by up to ``widen_*``), the stamps and the true times (exact).  The stamps
    spend their error budget: each is a true time plus or minus ``delta (1 - 1e-6)``, rounded to float
    (the margin covers the rounding), so that the true ``tau`` of a pair reaches either end of its
    enclosure where the stamps' errors have opposite signs."""
    rng = np.random.default_rng(seed)
    d = Fraction(delta)
    drop = int(rng.integers(K // 4, 3 * K // 4))
    grid = [m for m in range(K + 1) if m != drop]
    true = [ORIGIN + Fraction(T_S) * m + d * Fraction(int(rng.integers(-1000, 1001)), 1000) for m in grid]
    stamps = np.array([float(t + d * int(rng.choice([-1, 1])) * (1 - Fraction(1, 10**6))) for t in true])
    x, xd, truth = _tubes(None, rows, K, (1.1, 3.0), widen_x, widen_v, rng=rng, at=[t - true[0] for t in true])
    return x, xd, truth, stamps, true


def _enclosures(stamps, delta):
    """``[stamp - delta, stamp + delta]`` rounded outward ``(K, 2)``."""
    return np.stack([I.sub(stamps, stamps, delta, delta)[0], I.add(stamps, stamps, delta, delta)[1]], axis=1)


def _lost(x, xd, truth, empty):
    """Per row: refuted, or some exact value outside its box."""
    out = []
    for r, row in enumerate(truth):
        out.append(bool(empty[r]) or any(
            not (Fraction(x[r, k, 0, c]) <= xs[k] <= Fraction(x[r, k, 1, c]))
            or not (Fraction(xd[r, k, 0, c]) <= vs[k] <= Fraction(xd[r, k, 1, c]))
            for c, (xs, vs) in enumerate(row) for k in range(len(xs))))
    return np.array(out)


@BOTH
@pytest.mark.parametrize("delta", [DELTA, 1e-6 * T_S], ids=["5%", "1e-6"])
@pytest.mark.parametrize("widen_x, widen_v", [(1e-9, 1e-7), (2e-5, 0.3)], ids=["tight", "wide"])
def test_stamped_times_keep_the_exact_truth(delta, widen_x, widen_v, compiled):
    """Bang-bang motions sampled at jittered times with a dropped sample, stamps off by up to ``delta``: with
    ``times`` the stamps' enclosures, the truth stays in every box, no row is refuted, and the tubes shrink
    (the pairs were contracted, not skipped).  With ``delta = 1e-6 T_S`` each ``tau`` is known to about
    ``1e-9 s`` and the bound is nearly attained: the check is sharp."""
    for seed in range(3):
        x, xd, truth, stamps, true = _stamped_run(seed, delta, widen_x=widen_x, widen_v=widen_v)
        times = _enclosures(stamps, delta)
        assert all(Fraction(lo) <= t <= Fraction(hi) for (lo, hi), t in zip(times, true))
        assert max(b - a for a, b in zip(true, true[1:])) > Fraction(19, 10) * Fraction(T_S)  # the dropped sample
        w0 = (x[..., 1, :] - x[..., 0, :]).sum() + (xd[..., 1, :] - xd[..., 0, :]).sum()
        empty = contract_tubes(x, xd, T_S, A_MAX, compiled=compiled, times=times)
        assert not empty.any()
        _check_inside(x, xd, truth)
        assert (x[..., 1, :] - x[..., 0, :]).sum() + (xd[..., 1, :] - xd[..., 0, :]).sum() < w0


@BOTH
@pytest.mark.parametrize("wrong", ["stamps-as-exact", "constant-step"])
def test_the_stamps_error_term_is_needed(wrong, compiled):
    """Removal check as a test: the runs of ``test_stamped_times_keep_the_exact_truth`` (5%, tight tubes)
    contracted with the stamps taken as the true times (``delta = 0``), or as if sampled at ``k T_S``
    (``times=None``: the jitter and the dropped sample ignored), lose every row: refuted, or the truth out of
    a box.  With the stamps' enclosures, none."""
    for seed in range(3):
        x, xd, truth, stamps, _ = _stamped_run(seed)
        xc, xdc = x.copy(), xd.copy()
        assert not _lost(xc, xdc, truth, contract_tubes(xc, xdc, T_S, A_MAX, compiled=compiled,
                                                        times=_enclosures(stamps, DELTA))).any()
        times = _enclosures(stamps, 0.0) if wrong == "stamps-as-exact" else None
        empty = contract_tubes(x, xd, T_S, A_MAX, compiled=compiled, times=times)
        assert _lost(x, xd, truth, empty).all(), (seed, empty)


@BOTH
def test_pairs_whose_time_enclosure_is_not_positive_are_skipped(compiled):
    """``(*)`` needs ``tau > 0``: where the two enclosures touch or overlap, the pair is left as it is (the
    bound over ``[0, tau_hi]`` would still narrow the pose boxes here); the same tubes at stamps known exactly
    are contracted."""
    x = np.zeros((1, 3, 2, 1))
    xd = np.zeros((1, 3, 2, 1))
    x[0, 1:, 0], x[0, 1:, 1] = -1e-3, 1e-3
    xd[0, 1, :, 0] = 0.05, 0.06  # disjoint from its neighbours' [0, 0]: the pairs are chosen
    touching = np.array([[0.0, 1e-3], [1e-3, 2e-3], [1.5e-3, 3e-3]])  # tau_lo = 0, then < 0
    xc, xdc = x.copy(), xd.copy()
    assert not contract_tubes(xc, xdc, T_S, A_MAX[:1], offsets=(1,), compiled=compiled, times=touching).any()
    assert np.array_equal(xc, x) and np.array_equal(xdc, xd)
    exact = np.repeat([[0.0], [1e-3], [2e-3]], 2, axis=1)
    assert not contract_tubes(x, xd, T_S, A_MAX[:1], offsets=(1,), compiled=compiled, times=exact).any()
    assert np.all(x[0, 1:, 1] - x[0, 1:, 0] < 2e-3)


def test_per_pair_constants_bound_the_exact_values():
    """``tau``, ``2 / tau``, ``tau / 2`` and ``a tau^2 / 4`` from stamps' enclosures, against exact rational
    values over the whole enclosure of ``tau`` (stamps of mixed magnitudes: their differences round)."""
    rng = np.random.default_rng(7)
    K, j = 200, 3
    t = np.cumsum(rng.uniform(1e-5, 0.3, K)) * rng.choice([1e-3, 1.0, 37.0])
    w = rng.choice([0.0, 1e-9, 1e-6, 1e-4], (K, 2))
    times = np.stack([t - w[:, 0], t + w[:, 1]], axis=1)
    lo, hi = _taus(times, j)
    a = rng.uniform(1.0, 200.0, 3)
    keep = lo > 0.0
    tau, inv2, e4, four_a = _constants_of_tau((lo[keep, None], hi[keep, None]), a)
    half = I.scale(0.5, *tau)
    assert keep.sum() > K // 2 and e4.shape == (keep.sum(), a.size)
    for i, k in enumerate(np.nonzero(keep)[0]):
        t_lo = Fraction(float(times[k + j, 0])) - Fraction(float(times[k, 1]))
        t_hi = Fraction(float(times[k + j, 1])) - Fraction(float(times[k, 0]))
        assert Fraction(float(lo[k])) <= t_lo and t_hi <= Fraction(float(hi[k]))
        for exact in (t_lo, t_hi):
            assert Fraction(float(inv2[0][i, 0])) <= 2 / exact <= Fraction(float(inv2[1][i, 0]))
            assert Fraction(float(half[0][i, 0])) <= exact / 2 <= Fraction(float(half[1][i, 0]))
        for c in range(a.size):
            assert Fraction(float(e4[i, c])) >= Fraction(float(a[c])) * t_hi * t_hi / 4


def test_times_are_checked():
    x, xd = np.zeros((1, 3, 2, 1)), np.zeros((1, 3, 2, 1))
    good = np.repeat([[0.0], [1e-3], [2e-3]], 2, axis=1)
    for bad in (good[:2], good.T, np.where(good == 1e-3, np.nan, good), good[:, ::-1] + [[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]]):
        with pytest.raises(ValueError, match="times"):
            contract_tubes(x, xd, T_S, [1.0], times=bad)


def _adversarial_times(rng, K):
    """Steps ``(K, 1, 1)`` between samples jittered by 5% of ``T_S``, one of them a dropped sample's ``2 T_S``,
    and enclosures ``(K, 2)`` about the times they add up to, of widths from 0 to ``2 T_S``: some neighbouring
    enclosures overlap (``tau_lo <= 0``: those pairs are skipped)."""
    steps = T_S * (1.0 + rng.uniform(-0.05, 0.05, K))
    steps[K // 2] += T_S
    t = 7.0 + np.cumsum(steps)
    w = rng.choice([0.0, 1e-9, 5e-5, 2e-3], (K, 2), p=[0.2, 0.4, 0.3, 0.1])
    return steps[:, None, None], np.stack([t - w[:, 0], t + w[:, 1]], axis=1)


@pytest.mark.parametrize("seed, special", [(0, True), (1, True), (2, False), (3, False)])
def test_compiled_contraction_is_the_reference_with_times(seed, special, monkeypatch):
    """The adversarial tubes with stamped times (per-pair constants, some pairs skipped), and the stamped runs
    (with the right enclosures and with the stamps taken as exact, which refutes rows): the kernel gives the
    reference's floats bit for bit and refutes the same rows.  Its argument types are those of the constant
    step's calls (one compilation serves both)."""
    import numba

    import crosscert.verifier.compiled.motion_model as motion

    kinds, real = set(), motion.pair_kernel

    def spy(*args):
        kinds.add(tuple(numba.typeof(a) for a in args))
        return real(*args)

    monkeypatch.setattr(motion, "pair_kernel", spy)
    steps, times = _adversarial_times(np.random.default_rng(100 + seed), 40)
    x, xd = _adversarial_tubes(np.random.default_rng(seed), special, steps)
    lo, _ = _taus(times, 1)
    assert (lo <= 0.0).any() and (lo > 0.0).any()
    refuted = _both_ways(x, xd, A_MAX, times=times)
    assert 1 <= refuted < x.shape[0] or special
    _both_ways(x, xd, A_MAX, offsets=(1, 3, 2, 1), times=times)
    _both_ways(x, xd, A_MAX)
    x, xd, _, stamps, _ = _stamped_run(seed, rows=2)
    assert _both_ways(x, xd, A_MAX, times=_enclosures(stamps, DELTA)) == 0
    assert _both_ways(x, xd, A_MAX, times=_enclosures(stamps, 0.0)) > 0
    x, xd = np.zeros((1, 2, 2, 2)), np.zeros((1, 2, 2, 2))
    xd[0, 1] = 1.0
    _both_ways(x, xd, A_MAX, offsets=(1,))  # one pair, as verifier.compiled.driver._load_pair_kernel warms it
    assert len(kinds) == 1, kinds
    if not special:  # the reference contracts the surviving rows
        x, xd = _adversarial_tubes(np.random.default_rng(seed), special, steps)
        xc, xdc = x.copy(), xd.copy()
        live = ~contract_tubes(xc, xdc, T_S, A_MAX, times=times)
        assert live.any() and (np.any(xc[live] != x[live]) or np.any(xdc[live] != xd[live]))
