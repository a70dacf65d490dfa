"""Adversarial containment: true motions and readings that spend every bound of the tracker.

The tracker is sound when ``|xdd_i| <= a_max_i``, ``|q_meas - q_true| <=
eps_q``, the true geometry is a constant point of ``[xi]``, ``|xd(0)| <= xd0``
and the initial box holds ``x(0)``.  Gentle simulations (smooth ramps,
rounding-level reading errors, central geometries) leave so much room that a
tracker missing one of its soundness terms still contains the truth.  Here
(see :mod:`adversarial`):

* every pose coordinate accelerates at ``+-0.999 a_max`` at every instant
  (bang-bang, exact piecewise-quadratic truth), starting at ``0.999 xd0``;
* every reading errs by ``eps_q (1 - 1e-9)``, in sign patterns worst for
  short baselines (alternating), long ones (blocks) or mixed (random);
* the true geometry is the centre or a corner of ``[xi]``;
* the motions wander far from the Type 2 locus, cross it at 1.3-1.6 m/s
  (drift) or run up to it and back.

Every box must hold the truth at every sample, no run may be reported
inconsistent, and every certified mode must be the true one.  Each of the
tracker's soundness terms (the prediction remainders ``(t_s^2/2)[a]`` and
``t_s [a]``, the truncation slack ``(h/2)[a_max]``, the ``2 eps_q`` error of
reading differences) was removed in turn, in each backend, and made these
tests fail.  The strict sign test of the mode (``det > 0``, not ``>= 0``)
is guarded on a toy robot whose determinant enclosure touches 0 exactly:
directly (:func:`test_mode_of_needs_a_strict_sign`) and through the tracker
(:func:`test_tracker_certifies_no_mode_on_the_singular_locus`).  The ``joint-fd`` model's truncation
term ``(t_s/2)|qdd|`` is spent in full by exact joint motions at the ``|qdd|`` bound on a toy robot whose
pose is its joints (:func:`test_joint_fd_truncation_is_spent_in_full`; fails with the term halved).
"""

from __future__ import annotations

from fractions import Fraction

import casadi as ca
import numpy as np
import pytest

from adversarial import A_FRACTION, EDGE, V0_FRACTION, far_scenarios, near_scenarios
from problems import interval_model
from crosscert.robots import DEXTAR
from crosscert.verifier.contractors import mode_of
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.tracker import TrackerSettings, initial_box_from_mode, track_batch

FAR_SEED = 1  # seeds of the scenario families (each scenario derives its own)
NEAR_SEED = 2
N_FAR = 24  # runs of 201 samples (0.2 s)
N_NEAR = 24  # runs of 161 samples (0.16 s), half crossings, half bounces


BACKENDS = ("compiled", "numpy")


def _run(q, x0, settings, backend, model=None):
    """Track a batch: ``q`` (B, K, n) readings (rad), ``x0`` = (lo, hi) initial boxes (B, n), m.

    The one place the tracker is called; ``model`` defaults to the DexTAR's.
    Returns ``(BatchResult, record)``.
    """
    return track_batch(interval_model() if model is None else model, q, settings, x0, record=True, backend=backend)


def _track(scenarios, backend, m, s):
    """Run the tracker (interval model ``m``, settings ``s``) on scenarios, from their true initial mode."""
    boxes = [initial_box_from_mode(m, sc.q_meas[0], int(sc.mode[0]), s, backend=backend) for sc in scenarios]
    x0 = (np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes]))
    q = np.stack([sc.q_meas for sc in scenarios])
    return _run(q, x0, s, backend, m)


@pytest.fixture(scope="module", params=BACKENDS)
def far(request, imodel, settings):
    sc = far_scenarios(N_FAR, FAR_SEED)
    return (sc, *_track(sc, request.param, imodel, settings))


@pytest.fixture(scope="module", params=BACKENDS)
def near(request, imodel, settings):
    sc = near_scenarios(N_NEAR, NEAR_SEED)
    return (sc, *_track(sc, request.param, imodel, settings))


def _violations(scenarios, res, rec):
    """Every breach of soundness, as readable strings (empty when sound).

    Checked at every sample ``k >= 0`` (at ``k = 0``, ``[xd]`` is the assumed
    ``[-xd0, xd0]``, which holds ``xd(0) = +-0.999 xd0``).
    """
    out = []
    for b, sc in enumerate(scenarios):
        tag = f"{sc.name} (seed {sc.seed}, readings {'/'.join(sc.pattern)})"
        if res.inconsistent_at_step[b] >= 0:
            out.append(f"{tag}: reported inconsistent at step {res.inconsistent_at_step[b]}")
            continue
        for what, lo, hi, truth, unit, scale in (("x", rec["x_lo"][b], rec["x_hi"][b], sc.x, "um", 1e6),
                                                 ("xd", rec["xd_lo"][b], rec["xd_hi"][b], sc.xd, "mm/s", 1e3)):
            margin = np.minimum(truth - lo, hi - truth)  # < 0 (or NaN): the truth is outside
            bad = np.nonzero(~(margin >= 0).all(1))[0]
            if bad.size:
                k = bad[0]
                out.append(f"{tag}: {what} outside [{what}] at {bad.size} steps, first {k}: "
                           f"truth {truth[k]}, box {lo[k]} .. {hi[k]}, margin {scale * margin[k]} {unit}")
        mode = rec["mode"][b]
        wrong = np.nonzero((mode != 0) & (mode != sc.mode))[0]
        if wrong.size:
            k = wrong[0]
            out.append(f"{tag}: wrong certified mode at {wrong.size} steps, first {k}: "
                       f"certified {mode[k]:+d}, true {sc.mode[k]:+d}")
    return out


def test_scenarios_spend_every_bound(kin):
    """The generator is as hard as claimed (guards it against becoming gentle).

    Acceleration exactly ``+-A_FRACTION a_max`` between switches and never
    more (checked on velocity increments, m/s); ``|xd(0)| = V0_FRACTION xd0``;
    reading errors within ``eps_q`` and at its edge; joints solve ``f = 0``
    with the true geometry and move continuously; geometries at the centre
    or a corner of ``[xi]``; some runs cross the locus, some bounce on it.
    """
    km = kin
    lo, hi = DEXTAR.xi_lo_array, DEXTAR.xi_hi_array
    ts, eps = DEXTAR.t_s, DEXTAR.eps_q
    a = A_FRACTION * np.asarray(DEXTAR.a_max)
    scenarios = far_scenarios(N_FAR, FAR_SEED) + near_scenarios(N_NEAR, NEAR_SEED)
    for sc in scenarios:
        dv = np.abs(np.diff(sc.xd, axis=0))
        assert np.all(dv <= a * ts * (1 + 1e-9)), sc.name
        full = np.isclose(dv, a * ts, rtol=1e-9, atol=0)  # no switch inside the interval
        assert full.mean() > 0.5, (sc.name, full.mean())
        assert np.allclose(np.abs(sc.xd[0]), V0_FRACTION * np.asarray(DEXTAR.xd0), rtol=1e-12)
        err = np.abs(sc.q_meas - sc.q_true)
        assert np.all(err <= eps) and np.all(err >= EDGE * eps * (1 - 1e-9)), sc.name
        assert np.abs(km.f_batch(sc.x, sc.q_true, sc.xi)).max() < 1e-15, sc.name
        assert np.abs(np.diff(sc.q_true, axis=0)).max() < 0.1, sc.name  # rad per sample
        assert np.all((sc.xi >= lo) & (sc.xi <= hi)), sc.name
        at_edge = np.isclose(sc.xi, lo, rtol=0, atol=1e-15) | np.isclose(sc.xi, hi, rtol=0, atol=1e-15)
        assert at_edge.all() or np.allclose(sc.xi, DEXTAR.xi_center), sc.name
        assert np.all(sc.mode != 0), sc.name
    crossings = [sc for sc in scenarios if sc.mode[0] != sc.mode[-1]]
    assert len(crossings) >= N_NEAR // 2 - 1
    assert any(np.count_nonzero(np.diff(sc.mode)) == 2 for sc in scenarios)  # a bounce past the locus
    for sc in crossings:
        k = np.nonzero(np.diff(sc.mode))[0][0]
        assert 1.2 < -sc.xd[k, 1] < 2.2, (sc.name, sc.xd[k])  # crossing speed, m/s


def test_far_motions_are_contained(far):
    """Bang-bang wandering far from the locus: truth in every box, right modes, no inconsistency."""
    scenarios, res, rec = far
    bad = _violations(scenarios, res, rec)
    assert not bad, "\n".join(bad)
    # not vacuous: the modes are certified nearly everywhere
    certified = np.mean(rec["mode"] != 0)
    assert certified > 0.9, certified


def test_crossings_and_bounces_are_contained(near):
    """Bang-bang runs through the locus and up to it and back: truth in every box, right modes."""
    scenarios, res, rec = near
    bad = _violations(scenarios, res, rec)
    assert not bad, "\n".join(bad)
    # not vacuous: every run starts certified, and some crossings end certified in the new mode
    assert np.all(rec["mode"][:, 0] != 0)
    changed = [sc.name for b, sc in enumerate(scenarios)
               if sc.mode[0] != sc.mode[-1] and rec["mode"][b, -1] == sc.mode[-1]]
    assert changed, "no crossing certified"


class _Toy:
    """A robot-like object for :class:`IntervalModel`: ``f = (x0 x1 - q0, xi x1 - q1)``, ``xi = 1``.

    ``J_x = [[x1, x0], [0, xi]]``, so ``det J_x = x1 xi``; a box with ``x1``
    in ``[0, c]`` has a determinant enclosure whose lower bound is exactly 0
    (a product with 0 is exact; other bounds may be rounded outward).
    """

    n = 2
    xi_nominal = (1.0,)
    xi_lo = (1.0,)
    xi_hi = (1.0,)
    name = "toy"

    def __init__(self, mode_sign):
        self.mode_sign = mode_sign

    @staticmethod
    def loop_closure(x, q, xi):
        return ca.vertcat(x[0] * x[1] - q[0], xi[0] * x[1] - q[1])


@pytest.mark.parametrize("mode_sign", [1.0, -1.0])
def test_mode_of_needs_a_strict_sign(mode_sign):
    """A determinant enclosure touching 0 certifies no mode; one strictly off 0 does.

    On the singular locus (``x1 = 0``, a point box) and on boxes with one
    bound exactly on it, ``mode_of`` must return 0: ``det >= 0`` does not
    exclude the singularity.
    """
    model = IntervalModel(_Toy(mode_sign))
    x1 = [(0.0, 0.0), (0.0, 1e-3), (-1e-3, 0.0), (1e-300, 1e-3), (-1e-3, -1e-300), (-1e-3, 1e-3)]
    X = (np.array([[0.5, a] for a, _ in x1]), np.array([[0.5, b] for _, b in x1]))
    B = len(x1)
    Q = (np.full((B, 2), -1.0), np.full((B, 2), 1.0))
    XI = (np.ones((B, 1)), np.ones((B, 1)))
    D = model.tape_det.evaluate([X, Q, XI])[0]
    # the first three enclosures have a bound exactly 0 (products with 0 are exact)
    assert np.all((D[0][:3, 0] == 0.0) | (D[1][:3, 0] == 0.0)), D
    expected = np.array([0, 0, 0, 1, -1, 0]) * int(mode_sign)
    np.testing.assert_array_equal(mode_of(model, X, Q, XI), expected)


@pytest.mark.parametrize("backend", BACKENDS)
def test_tracker_certifies_no_mode_on_the_singular_locus(backend):
    """The toy robot at rest exactly on its singular locus ``x1 = 0`` (``det J_x = 0``).

    Readings ``q1 = eps_q`` (true ``q1 = 0``) give ``[x1] = [0, 2 eps_q]``
    exactly, so the determinant enclosure is ``[0, d]`` at every sample: the
    true configuration has no assembly mode, and none may be certified.
    """
    eps = 1e-4  # rad
    settings = TrackerSettings(t_s=1e-3, eps_q=eps, a_max=(1.0, 1.0), xd0=(0.1, 0.1), xi_splits=None)
    q = np.zeros((1, 30, 2))
    q[..., 1] = eps
    x0 = (np.array([[-0.01, 0.0]]), np.array([[0.01, 2 * eps]]))  # holds the truth x = (0, 0), m
    res, rec = _run(q, x0, settings, backend, model=IntervalModel(_Toy(1.0)))
    assert res.inconsistent_at_step[0] < 0
    assert np.all(rec["x_lo"][0] <= 0.0) and np.all(rec["x_hi"][0] >= 0.0)
    assert np.all(rec["xd_lo"][0] <= 0.0) and np.all(rec["xd_hi"][0] >= 0.0)
    assert np.all(rec["x_lo"][0, :, 1] == 0.0)  # the enclosure touches the locus, exactly
    np.testing.assert_array_equal(rec["mode"][0], 0)


class _Joints:
    """A robot-like object whose pose is its joints: ``f = (xi x0 - q0, x1 - q1)``, ``xi = 1``.

    ``J_x = diag(xi, 1)``, ``J_q = -I``: the velocity is the joint rate and ``xdd = qdd``, so the
    velocity box the tracker reports is its joint-rate box intersected with the prediction."""

    n = 2
    xi_nominal = (1.0,)
    xi_lo = (1.0,)
    xi_hi = (1.0,)
    name = "joints"
    mode_sign = 1.0

    @staticmethod
    def loop_closure(x, q, xi):
        return ca.vertcat(xi[0] * x[0] - q[0], x[1] - q[1])


@pytest.mark.parametrize("backend", BACKENDS)
def test_joint_fd_truncation_is_spent_in_full(backend):
    """``joint-fd`` with a given ``|qdd|`` bound ``g``: its rate box is the finite difference of the last two
    readings, ``+- 2 eps_q / t_s``, ``+ (t_s / 2) [-g, g]`` (A8).

    The true joints accelerate at exactly ``+g`` and ``-g`` at every instant, and the readings err by
    ``eps_q`` (less 1e-12 of it) with signs alternating from sample to sample, so that at every even
    sample the reading errors and the truncation ``q_{k-1} = q_k - t_s qd_k + (t_s^2 / 2) qdd`` push
    the finite difference the same way: the true rate is within rounding of an end of the rate box.
    Checked in exact rational arithmetic: the true rate (= velocity) inside every velocity box.  With
    ``(t_s / 2)|qdd|`` halved, the truth leaves the box by ``t_s g / 4`` = 0.25 rad/s.
    """
    ts, eps, g = 1e-3, 1e-4, 1000.0  # s, rad, rad/s^2
    K = 30
    settings = TrackerSettings(t_s=ts, eps_q=eps, a_max=(2 * g, 2 * g), xd0=(1.0, 1.0), xi_splits=None,
                               velocity_model="joint-fd", qdd_bound=g)
    T, G, E = Fraction(ts), Fraction(g), Fraction(eps) * (1 - Fraction(1, 10**12))
    rng = np.random.default_rng(4301)
    c0 = [Fraction(float(v)) for v in rng.uniform(-0.3, 0.3, 2)]  # rad
    v0 = [Fraction(float(v)) for v in rng.uniform(-0.9, 0.9, 2)]  # rad/s, inside xd0
    acc, push = (G, -G), (1, -1)  # joint 1 mirrors joint 0: both ends of the rate box are spent
    q_true = [[c0[i] + v0[i] * k * T + acc[i] * (k * T) ** 2 / 2 for i in range(2)] for k in range(K)]
    rate = [[v0[i] + acc[i] * k * T for i in range(2)] for k in range(K)]
    q = np.array([[float(q_true[k][i] + push[i] * (-1) ** (k + 1) * E) for i in range(2)] for k in range(K)])
    assert all(abs(Fraction(q[k, i]) - q_true[k][i]) <= Fraction(eps) for k in range(K) for i in range(2))  # A3
    x0 = (q[0] - 0.01, q[0] + 0.01)  # holds the truth x(0) = q(0)
    res, rec = _run(q[None], (x0[0][None], x0[1][None]), settings, backend, model=IntervalModel(_Joints()))
    assert res.inconsistent_at_step[0] < 0
    worst = []
    for k in range(1, K):
        for i in range(2):
            lo, hi = Fraction(rec["xd_lo"][0, k, i]), Fraction(rec["xd_hi"][0, k, i])
            assert lo <= rate[k][i] <= hi, (backend, k, i, float(lo), float(rate[k][i]), float(hi))
            if k % 2 == 0:
                worst.append(float(min(rate[k][i] - lo, hi - rate[k][i])))
    # not vacuous: at the even samples the truth is at an end of the box (rounding and the 1e-12 apart)
    assert max(worst) < 1e-9, max(worst)
