"""Uneven recordings: dropped samples and jittered stamps enter the tracker as step intervals (verifier.clock).

* A clock whose steps are one period each gives the boxes of the constant period bit for bit, and
  :func:`verifier.constants.for_step` of a one-period step gives :func:`pack_constants`' floats.
* Adversarial runs (the acceleration budget spent, readings at the edges of ``eps_q``, corner
  geometries; :mod:`adversarial`) sampled at jittered true times, with dropped samples and stamps off
  the truth by ``delta`` in the worst alternating pattern: the truth stays inside every box.  The same
  run with the stamp error ignored lets it out (the removal check of ``delta``).
* ``joint-fd`` on a model whose pose is its joints, in exact arithmetic: the truth at (or within
  the truncation's share of) the ends of the prediction's ``[step] [xd]`` and of the rate box's
  ``2 eps_q / [step]``, so that either term taken at one end of the step lets it out.
* The window over such a run (its passes on the clock and the reversed clock, its pairs' time
  enclosures) decides a crossing the forward pass leaves open, the truth inside its tubes.
* The numpy reference and the compiled kernels agree on such a run, and the clock refuses what it
  cannot enclose (a step that is not a whole number of periods without ``--stamp-error``, stamps closer
  than ``2 delta``).
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from adversarial import near_scenarios
from problems import interval_model
from crosscert.robots.errors import InputError, TrajectoryFileError
from crosscert.verifier.clock import SampleClock
from crosscert.verifier.constants import for_step, pack_constants
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.tracker import Tracker, TrackerSettings, initial_box_from_mode, track_batch
from crosscert.verifier.settings import Verdict
from crosscert.verifier.window import track_window
from test_containment import BACKENDS, _Joints, _violations

#: Jitter of the true sample times and stamp error bound, s: stamps alternate at +-delta around the truth,
#: so that ignoring delta misreads every step by 2 delta (0.1 t_s).
JITTER, DELTA = 100e-6, 50e-6
#: Samples the controller dropped (one alone, two in a row).
DROPPED = (40, 90, 91)
K = 201


def _run(scenarios, settings, clock=None, backend="compiled"):
    m = interval_model()
    boxes = [initial_box_from_mode(m, sc.q_meas[0], int(sc.mode[0]), settings, backend=backend) for sc in scenarios]
    x0 = (np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes]))
    return track_batch(m, np.stack([sc.q_meas for sc in scenarios]), settings, x0, record=True, backend=backend,
                       clock=clock)


def _jittered(settings, seed=5):
    """True times (jittered, with dropped samples) and stamps at +-DELTA around them, alternating."""
    rng = np.random.default_rng(seed)
    t_true = np.arange(K) * settings.t_s + rng.uniform(-JITTER, JITTER, K)
    t_true[0] = 0.0
    keep = np.setdiff1d(np.arange(K), DROPPED)
    t_true = t_true[keep]
    stamps = t_true + DELTA * (1.0 - 1e-9) * np.where(np.arange(len(t_true)) % 2 == 0, 1.0, -1.0)
    return t_true, stamps


@pytest.fixture(scope="module")
def jittered(settings):
    t_true, stamps = _jittered(settings)
    return near_scenarios(4, 11, t_end=0.2, times=t_true), stamps


def test_one_period_steps_give_the_constant_period_bit_for_bit(settings):
    sc = near_scenarios(2, 11, t_end=0.08)
    plain = _run(sc, settings)[1]
    clocked = _run(sc, settings, SampleClock.from_stamps(sc[0].t, settings.t_s))[1]
    for key in plain:
        np.testing.assert_array_equal(clocked[key], plain[key], err_msg=key)


def test_for_step_of_one_period_is_pack_constants(imodel, settings):
    s = settings.validated(imodel.n)
    c = pack_constants(s, imodel.n)
    spans = np.array([[c.baseline["h_lo"][i], c.baseline["h_hi"][i]] for i in range(len(c.baseline))])
    d = for_step(c, s, (s.t_s, s.t_s), spans)
    for name in c.axis.dtype.names:
        np.testing.assert_array_equal(d.axis[name], c.axis[name], err_msg=name)
    np.testing.assert_array_equal(d.baseline, c.baseline)
    np.testing.assert_array_equal(d.diff_err, c.diff_err)
    assert (d.step_lo, d.step_hi) == (c.step_lo, c.step_hi) == (s.t_s, s.t_s)


def test_dropped_samples_keep_the_truth_inside(settings):
    """A fixed-period controller that dropped samples: steps of 2 and 3 periods, stamp error 0."""
    keep = np.setdiff1d(np.arange(161), DROPPED)
    times = keep * settings.t_s
    sc = near_scenarios(4, 11, times=times)
    clock = SampleClock.from_stamps(times, settings.t_s)
    assert not clock.even
    res, rec = _run(sc, settings, clock)
    assert _violations(sc, res, rec) == []


def test_jittered_stamps_keep_the_truth_inside(jittered, settings):
    sc, stamps = jittered
    res, rec = _run(sc, settings, SampleClock.from_stamps(stamps, settings.t_s, DELTA))
    assert _violations(sc, res, rec) == []


def test_the_stamp_error_is_needed(jittered, settings):
    """Removal check of ``delta``: the same stamps read as exact let the truth out (or empty a box)."""
    sc, stamps = jittered
    res, rec = _run(sc, settings, SampleClock.from_stamps(stamps, settings.t_s, 1e-15))
    assert _violations(sc, res, rec)


@pytest.mark.parametrize("backend", BACKENDS)
def test_joint_fd_on_jittered_stamps_spends_the_step_interval(backend):
    """``joint-fd``, pose = joints, stamps ``delta`` off the jittered true times: the step's interval spent in full.

    The stamps alternate at ``+-delta`` around the truth, so that each true step lies at an end of its
    enclosure ``[lo, hi]``: ``lo`` at even samples, ``hi`` at odd ones.  The readings err by ``eps_q`` (less
    1e-12 of it) with alternating signs; joint 0 accelerates at ``+g`` forward, joint 1 brakes at ``-g``
    (``g = a_max = qdd_bound``).  Checked in exact rational arithmetic: the truth inside every box, and

    * joint 0's rate box: its upper end at even samples is the truth's but for the truncation's
      ``g (hi - lo) / 2`` (``(t / 2) [qdd]`` at ``t = hi``): its quantisation ``2 eps_q / t`` is spent at
      ``t = lo``, the readings' errors pushing the finite difference up;
    * the prediction ``x + [lo, hi] [xd]``: joint 0's upper end at odd samples (``t = hi``, a forward
      joint) and joint 1's lower end at even samples (``t = lo``, a braking joint) are closer to the
      truth than ``(hi - lo) |xd|``, which scaling ``[xd]`` by ``lo`` alone, or ``hi`` alone, takes off.
    """
    ts, eps, g = 1e-3, 1e-4, 100.0  # s, rad, rad/s^2 (g < 4 eps / t^2: the quantisation's share of [lo, hi] wins)
    n_samples = 40
    settings = TrackerSettings(t_s=ts, eps_q=eps, a_max=(g, g), xd0=(1.0, 6.0), xi_splits=None,
                               velocity_model="joint-fd", qdd_bound=g)
    rng = np.random.default_rng(4302)
    t_true = np.arange(n_samples) * ts + rng.uniform(-JITTER, JITTER, n_samples)
    t_true[0] = 0.0
    T, G, E = [Fraction(float(v)) for v in t_true], Fraction(g), Fraction(eps) * (1 - Fraction(1, 10**12))
    sign = [(-1) ** k for k in range(n_samples)]
    stamps = np.array([float(T[k] + sign[k] * Fraction(DELTA) * (1 - Fraction(1, 10**9))) for k in range(n_samples)])
    c0 = [Fraction(float(v)) for v in rng.uniform(-0.3, 0.3, 2)]  # rad
    v0 = [Fraction(float(rng.uniform(0.5, 0.9))), Fraction(float(rng.uniform(5.0, 5.5)))]  # rad/s, inside xd0
    acc = (G, -G)
    q_true = [[c0[i] + v0[i] * T[k] + acc[i] * T[k] ** 2 / 2 for i in range(2)] for k in range(n_samples)]
    rate = [[v0[i] + acc[i] * T[k] for i in range(2)] for k in range(n_samples)]
    q = np.array([[float(q_true[k][i] - sign[k] * E) for i in range(2)] for k in range(n_samples)])
    x0 = (q[0] - 0.01, q[0] + 0.01)  # holds the truth x(0) = q(0)
    clock = SampleClock.from_stamps(stamps, ts, DELTA)
    res, rec = track_batch(IntervalModel(_Joints()), q[None], settings, (x0[0][None], x0[1][None]), record=True,
                           backend=backend, clock=clock)
    assert res.inconsistent_at_step[0] < 0
    for key, truth in (("x", q_true), ("xd", rate)):
        for k in range(1, n_samples):
            for i in range(2):
                lo, hi = Fraction(rec[f"{key}_lo"][0, k, i]), Fraction(rec[f"{key}_hi"][0, k, i])
                assert lo <= truth[k][i] <= hi, (backend, key, k, i, float(lo), float(truth[k][i]), float(hi))
    # not vacuous: the ends named above are as close to the truth as claimed
    for k in range(2, n_samples):
        step = [Fraction(v) for v in clock.span(k, k - 1)]
        assert abs(T[k] - T[k - 1] - step[k % 2]) < Fraction(1, 10**12)  # the true step at the end named
        shift = [(step[1] - step[0]) * abs(rate[k - 1][i]) for i in range(2)]
        if k % 2 == 0:
            assert Fraction(rec["xd_hi"][0, k, 0]) - rate[k][0] <= G * (step[1] - step[0]) / 2 + Fraction(1, 10**9)
            assert q_true[k][1] - Fraction(rec["x_lo"][0, k, 1]) < shift[1]
        else:
            assert Fraction(rec["x_hi"][0, k, 0]) - q_true[k][0] < shift[0]


def test_numpy_and_compiled_agree_on_a_jittered_run(settings):
    t_true, stamps = _jittered(settings, seed=7)
    sc = near_scenarios(2, 13, t_end=0.05, times=t_true[:45])
    clock = SampleClock.from_stamps(stamps[:45], settings.t_s, DELTA)
    a = _run(sc, settings, clock, "compiled")[1]
    b = _run(sc, settings, clock, "numpy")[1]
    for key in a:
        np.testing.assert_allclose(a[key], b[key], rtol=0, atol=1e-12, err_msg=key)  # sin/cos' last bits only


def test_online_tracker_with_stamps_matches_the_batch(jittered, settings):
    sc, stamps = jittered
    one = sc[0]
    m = interval_model()
    x0 = initial_box_from_mode(m, one.q_meas[0], int(one.mode[0]), settings)
    batch = track_batch(m, one.q_meas[None], settings, (x0[0][None], x0[1][None]), record=True,
                        clock=SampleClock.from_stamps(stamps, settings.t_s, DELTA))[1]
    tr = Tracker(m, settings, x0, clock=SampleClock(settings.t_s, DELTA))
    for k, (q, t) in enumerate(zip(one.q_meas, stamps)):
        r = tr.update(q, t)
        np.testing.assert_array_equal(r.x[0], batch["x_lo"][0, k])
        np.testing.assert_array_equal(r.xd[1], batch["xd_hi"][0, k])
    with pytest.raises(InputError, match="stamp"):
        tr.update(one.q_meas[-1])


def test_a_step_between_periods_needs_a_stamp_error():
    clock = SampleClock(1e-3)
    clock.append(0.0)
    clock.append(1e-3)
    clock.append(3e-3)  # one dropped sample: fine
    with pytest.raises(TrajectoryFileError, match="--stamp-error"):
        clock.append(3.5e-3)


def test_stamps_closer_than_twice_the_error_are_refused():
    clock = SampleClock(1e-3, 1e-4)
    clock.append(0.0)
    with pytest.raises(TrajectoryFileError, match="closer than twice --stamp-error"):
        clock.append(1.5e-4)


def test_spans_enclose_the_true_steps():
    rng = np.random.default_rng(3)
    t_true = np.cumsum(rng.uniform(0.8e-3, 1.2e-3, 50))
    stamps = t_true + rng.uniform(-1e-5, 1e-5, 50)
    clock = SampleClock.from_stamps(stamps, 1e-3, 1e-5)
    for k in range(1, 50):
        for j in (1, 2, 7):
            if j <= k:
                lo, hi = clock.span(k, k - j)
                assert lo <= t_true[k] - t_true[k - j] <= hi and lo > 0
    rev = clock.window(10, 30, reverse=True)
    for k in range(1, 20):
        lo, hi = rev.span(k, k - 1)
        assert lo <= t_true[29 - k + 1] - t_true[29 - k] <= hi


@pytest.mark.parametrize("seed", [1, 2, 4])
def test_the_window_runs_on_the_stamps(settings, seed):
    """A crossing at 1.0-1.15 m/s sampled at jittered true times, stamps ``DELTA`` off them, cut 6 ms past the
    locus (the last reading does not decide: the hypotheses' passes run) with a sample dropped just after
    the locus: the window's forward passes on the clock, its backward passes on the reversed clock and its
    pairs on their time enclosures keep the truth inside the tubes (a window whose passes ignore the clock,
    or whose backward passes read the stamps as exact, lets it out on these seeds) and never decide
    wrongly."""
    rng = np.random.default_rng(seed)
    t_true = np.arange(K) * settings.t_s + rng.uniform(-JITTER, JITTER, K)
    t_true[0] = 0.0
    sc = near_scenarios(2, seed, t_end=0.2, v_cross=(1.0, 1.15), times=t_true)[0]
    cut = int(np.flatnonzero(sc.mode != sc.mode[0])[0]) + 6
    keep = np.setdiff1d(np.arange(cut), [cut - 4])
    stamps = t_true + (DELTA - 1e-9) * np.where(np.arange(K) % 2 == 0, 1.0, -1.0)
    res = track_window(interval_model(), sc.q_meas[keep], settings, initial_mode=int(sc.mode[0]),
                       clock=SampleClock.from_stamps(stamps[keep], settings.t_s, DELTA))
    assert res.forward_verdict is Verdict.UNKNOWN and sum(h.passes for h in res.hypotheses) > 2
    assert res.verdict in (Verdict.MODE_CHANGED, Verdict.UNKNOWN)
    for lo, hi, truth in ((res.x_lo, res.x_hi, sc.x[keep]), (res.xd_lo, res.xd_hi, sc.xd[keep])):
        assert np.all((lo <= truth) & (truth <= hi))
