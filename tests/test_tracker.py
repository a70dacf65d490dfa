"""The tracker on simulated crossings: containment, verdicts, no false positive."""

import numpy as np
import pytest

from problems import CATALOGUE, default_settings, interval_model, run_of, simulate
from robots.errors import InputError
from verifier.tracker import VelocityModel, Verdict, initial_box_from_mode, track, track_batch


def _inside(lo, hi, truth):
    return np.all(lo <= truth) and np.all(truth <= hi)


@pytest.mark.parametrize("name", sorted(CATALOGUE))
def test_reference_problem(name):
    p = CATALOGUE[name]
    run = run_of(p)
    res = track(interval_model(), run.q_meas, default_settings(), initial_mode=int(run.mode_true[0]))
    assert res.verdict in p.expected, (name, res.summary())
    assert _inside(res.x_lo, res.x_hi, run.x_true)
    assert _inside(res.xd_lo[1:], res.xd_hi[1:], run.xd_true[1:])
    if res.verdict is Verdict.MODE_CHANGED:
        assert res.final_mode == run.mode_true[-1] != run.mode_true[0]
        assert res.certified_at_step > run.k_sing


def test_monte_carlo_containment_and_no_false_positive():
    """>= 20 seeded random geometries and speeds, crossings and bounces, one batch.

    The true pose and velocity must lie in every box at every step; no bounce
    may be reported mode-changed; every certified mode must be the true one.
    """
    rng = np.random.default_rng(2026)
    runs = []
    for i in range(24):
        bounce = i % 3 == 2
        v = float(rng.uniform(0.6, 1.5 if bounce else 1.8))  # a bounce needs twice the run-up
        quant = ("floor", "round", "uniform")[i % 3]
        runs.append(simulate(round(v, 3), bounce, 100 + i, quant))
    K = max(r.n_samples for r in runs)
    pad = lambda a: np.vstack([a, np.repeat(a[-1:], K - len(a), axis=0)])  # noqa: E731  (rest at the end)
    q = np.stack([pad(r.q_meas) for r in runs])
    model = interval_model()
    s = default_settings()
    lo = []
    hi = []
    for r in runs:
        b = initial_box_from_mode(model, r.q_meas[0], int(r.mode_true[0]), s)
        lo.append(b[0])
        hi.append(b[1])
    res, rec = track_batch(model, q, s, (np.array(lo), np.array(hi)), record=True)
    assert np.all(res.inconsistent_at_step < 0)
    for b, r in enumerate(runs):
        N = r.n_samples
        assert _inside(rec["x_lo"][b, :N], rec["x_hi"][b, :N], r.x_true), b
        assert _inside(rec["xd_lo"][b, 1:N], rec["xd_hi"][b, 1:N], r.xd_true[1:]), b
        certified = rec["mode"][b, :N] != 0
        assert np.all(rec["mode"][b, :N][certified] == r.mode_true[certified]), b
        if r.bounce:
            assert res.verdict[b] is not Verdict.MODE_CHANGED


def test_paper_model_is_labelled_and_selectable():
    run = run_of(CATALOGUE["crossing_1458"])
    res = track(interval_model(), run.q_meas, default_settings(velocity_model="paper"), initial_mode=1)
    assert res.settings.velocity_model is VelocityModel.PAPER
    assert res.verdict in set(Verdict)


def test_violated_acceleration_bound_is_inconsistent_not_a_verdict():
    run = run_of(CATALOGUE["crossing_1458"])
    s = default_settings(a_max=2.0)
    res = track(interval_model(), run.q_meas, s, initial_mode=1)
    assert res.verdict is Verdict.INCONSISTENT
    assert 0 < res.inconsistent_at_step < run.n_samples


def test_initial_mode_must_match_the_data():
    run = run_of(CATALOGUE["crossing_1458"])
    # the FK of the first sample has both modes; the box of each is disjoint
    m = interval_model()
    s = default_settings()
    up = initial_box_from_mode(m, run.q_meas[0], 1, s)
    down = initial_box_from_mode(m, run.q_meas[0], -1, s)
    assert _inside(up[0], up[1], run.x_true[0])
    assert not _inside(down[0], down[1], run.x_true[0])
    # starting in the wrong branch contradicts the motion sooner or later or stays unknown,
    # but never yields a certified change into the true final mode from the wrong start
    res = track(m, run.q_meas, s, initial_mode=-1)
    assert res.verdict is not Verdict.MODE_CHANGED or res.final_mode != run.mode_true[-1]


def test_bad_arguments_raise_input_errors():
    m = interval_model()
    s = default_settings()
    q = np.zeros((10, 2))
    with pytest.raises(InputError, match="exactly one"):
        track(m, q, s)
    with pytest.raises(InputError, match="finite"):
        track(m, np.full((10, 2), np.nan), s, initial_mode=1)
    with pytest.raises(InputError, match="shape"):
        track(m, np.zeros((10, 3)), s, initial_mode=1)
    with pytest.raises(InputError, match="t_s"):
        track(m, q, default_settings().__class__(t_s=-1.0, eps_q=1e-4, a_max=[80, 80]), initial_mode=1)


@pytest.mark.parametrize("qdd_bound", [None, 1000.0])
def test_joint_fd_model_contains_the_truth(qdd_bound):
    """The finite-difference model, with a derived or a given joint-acceleration bound."""
    run = run_of(CATALOGUE["crossing_1458"])
    s = default_settings(velocity_model="joint-fd", qdd_bound=qdd_bound)
    res = track(interval_model(), run.q_meas, s, initial_mode=1)
    assert res.verdict is not Verdict.INCONSISTENT
    assert _inside(res.x_lo, res.x_hi, run.x_true)
    assert _inside(res.xd_lo[1:], res.xd_hi[1:], run.xd_true[1:])
    finite = np.isfinite(res.qdd_bound).all(1)
    assert finite[1:50].all()  # a bound is proved away from the singularity
    assert np.all(res.qdd_bound[finite] >= np.abs(run.qdd_true[finite]) - 1e-9)


def test_drifting_reading_error_is_contained_and_tightens_the_velocity():
    """Readings = truth + a slow drift (amplitude 1 mrad, <= 0.02 mrad/sample) + a fast error (<= eps_q).

    With ``eps_q`` = amplitude + fast part alone the differences of readings
    err by up to 2.2 mrad; the drift model bounds them by 2 eps_fast + j d.
    Both runs must contain the truth; the drift model's velocity boxes are
    narrower.
    """
    run = simulate(1.458, False, 0)
    rng = np.random.default_rng(77)
    K = run.n_samples
    t = np.arange(K)
    amp, per_sample, fast = 1e-3, 2e-5, default_settings().eps_q
    phase = rng.uniform(0, 2 * np.pi, 2)
    # |d/dk amp sin(w k + p)| = amp w <= per_sample
    drift = amp * np.sin((per_sample / amp) * t[:, None] + phase[None, :])
    q = run.q_true + drift + rng.uniform(-fast, fast, run.q_true.shape)
    m0 = int(run.mode_true[0])
    plain = track(interval_model(), q, default_settings(eps_q=amp + fast), initial_mode=m0)
    rate = np.nextafter(per_sample / default_settings().t_s, np.inf)
    drifting = track(interval_model(), q, default_settings(eps_q=amp + fast, eps_q_fast=fast, drift_rate=rate),
                     initial_mode=m0)
    for res in (plain, drifting):
        assert _inside(res.x_lo, res.x_hi, run.x_true)
        assert _inside(res.xd_lo[1:], res.xd_hi[1:], run.xd_true[1:])
        assert res.verdict in (Verdict.MODE_CHANGED, Verdict.UNKNOWN)
    far = slice(5, run.k_sing - 40)  # before the crossing zone
    w_plain = (plain.xd_hi - plain.xd_lo)[far].max()
    w_drift = (drifting.xd_hi - drifting.xd_lo)[far].max()
    assert w_drift < 0.5 * w_plain, (w_drift, w_plain)
    with pytest.raises(InputError, match="together"):
        track(interval_model(), q, default_settings(eps_q_fast=fast), initial_mode=m0)
