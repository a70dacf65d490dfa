"""One motion, one geometry (verifier.one_motion): every inequality holds for the truth, only proved rows go.

* the Farkas check accepts a true certificate and refuses a feasible system, including a certificate that
  holds only in round-to-nearest arithmetic (tests/problems.py, ``FARKAS``), and refuses systems tight at a
  corner of their box with exact zeros, where only the strict ``>`` of the check stands between a feasible
  system and a proof;
* the loop-closure rows hold, in exact rational arithmetic, for true solutions at the corners of their boxes
  (the second-order remainder is what keeps them);
* the acceleration rows hold exactly for motions at exactly ``±a`` (constant, and switching between samples)
  and the drift rows for reading errors at the edges of the drift model;
* end to end, a row whose tubes and sub-box hold an adversarial true motion (every bound spent: bang-bang at
  0.999 ``a_max``, readings at the edges of ``±eps_q``, the geometry at a corner of ``[ξ]``) is never
  refuted, and ``crosscert certify``'s plan at 0.9557 m/s is certified by it while the plan at the
  refutation bound is not.

Removal checks (2026-12-02): see docs/soundness.md, "Window reasoning", step 9.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from adversarial import near_scenarios
from problems import FARKAS, MARGIN, ONE_MOTION_PLAN, interval_model
from crosscert.robots import DEXTAR
from crosscert.verifier import certified_lp as LP
from crosscert.verifier import one_motion as OM
from crosscert.verifier.settings import TrackerSettings


def _system(name):
    A, b, lo, hi, y = FARKAS[name]
    rows, cols = np.nonzero(np.ones_like(A, dtype=bool))
    return OM.LinearSystem(rows, cols, A[rows, cols], b, lo, hi), y


def _exact_rows(system):
    """``A`` as rows of (column, Fraction) and ``b`` as Fractions."""
    rows = [[] for _ in range(system.shape[0])]
    for r, c, v in zip(system.rows, system.cols, system.vals):
        rows[r].append((int(c), Fraction(float(v))))
    return rows, [Fraction(float(v)) for v in system.b]


def _violations(system, z):
    """Rows of ``A z <= b`` that the exact (rational) point ``z`` violates."""
    rows, b = _exact_rows(system)
    return [i for i, row in enumerate(rows) if sum(v * z[c] for c, v in row) > b[i]]


@pytest.mark.parametrize("compiled", [False, True])
def test_a_true_certificate_is_proved(compiled):
    """``z <= 0.4`` and ``z >= 0.6``: the hand-made multipliers and those of the solver both prove it."""
    system, y = _system("infeasible")
    assert OM.prove_infeasible(system, y, compiled=compiled)
    found = LP._phase_one(system)
    assert found is not None and OM.prove_infeasible(system, found, compiled=compiled)


@pytest.mark.parametrize("compiled", [False, True])
def test_a_feasible_system_is_never_proved(compiled):
    """A feasible system: no multipliers prove it (none exist), whatever is given, and the solver finds none."""
    system, _ = _system("infeasible")
    feasible = OM.LinearSystem(system.rows, system.cols, system.vals, np.array([0.6, -0.4]), system.lo, system.hi)
    rng = np.random.default_rng(0)
    for y in [np.ones(2), np.array([1.0, 0.0]), np.array([np.inf, 1.0]), np.array([-1.0, 2.0])] + \
            [rng.uniform(0, 10, 2) for _ in range(50)]:
        assert not OM.prove_infeasible(feasible, y, compiled=compiled)
    assert LP._phase_one(feasible) is None


@pytest.mark.parametrize("compiled", [False, True])
def test_a_certificate_that_holds_only_in_floats_is_refused(compiled):
    """``FARKAS["float_only"]``: feasible, yet ``yᵀ(A z - b)`` is positive in round to nearest; the outward-rounded
    check must refuse it (fails when the check's products and sums are rounded to nearest)."""
    A, b, lo, hi, y = FARKAS["float_only"]
    c = float(y[0]) * float(A[0, 0]) + float(y[1]) * float(A[1, 0])  # Python floats: round to nearest, no FMA
    naive = c * float(lo[0]) - (float(y[0]) * float(b[0]) + float(y[1]) * float(b[1]))
    assert naive > 0  # the trap is real
    exact = sum(Fraction(y[i]) * (Fraction(A[i, 0]) * Fraction(lo[0]) - Fraction(b[i])) for i in range(2))
    assert exact <= 0  # z = lo satisfies every row exactly
    system, _ = _system("float_only")
    assert not OM.prove_infeasible(system, y, compiled=compiled)


def _tight_at_a_corner(rng):
    """A feasible ``A z <= 0`` over a box with a corner at ``z = 0``, tight there for every ``y >= 0``.

    Column ``j``'s box is ``[0, h_j]`` with ``A_ij >= 0`` or ``[-h_j, 0]`` with ``A_ij <= 0`` (some entries
    and some ``h_j`` exactly 0; magnitudes from 1e-150 to 1e150), ``b = 0``: ``z = 0`` satisfies every row
    with equality, and for ``y >= 0`` each ``(yᵀA)_j z_j`` is smallest, exactly 0, at ``z_j = 0``, so the
    Farkas bound ``min over the box of yᵀA z − yᵀb`` is exactly 0: a proof needs it strictly positive."""
    M, N = int(rng.integers(1, 8)), int(rng.integers(1, 7))
    side = rng.choice([-1.0, 1.0], N)
    h = 10.0 ** rng.uniform(-150, 150, N) * (rng.random(N) > 0.1)
    A = side * 10.0 ** rng.uniform(-150, 150, (M, N)) * (rng.random((M, N)) > 0.2)
    rows, cols = np.nonzero(np.ones((M, N), dtype=bool))
    lo, hi = np.where(side > 0, 0.0, -h), np.where(side > 0, h, 0.0)
    return OM.LinearSystem(rows, cols, A[rows, cols], np.zeros(M), lo, hi)


@pytest.mark.parametrize("compiled", [False, True])
def test_a_system_tight_at_a_corner_with_exact_zeros_is_never_proved(compiled):
    """Seeded systems feasible only with equality at a corner of their box, where the products and sums
    of the check are exact zeros (:func:`_tight_at_a_corner`): no multipliers may prove them infeasible,
    neither random ones (every scale, some 0, some negative or non-finite) nor the solver's.  The dual
    bound is exactly ``left = yb = 0`` for most of them (checked: the test is not vacuous), so it fails
    when the strict ``left > yb`` of :func:`prove_infeasible` is made ``>=``."""
    rng = np.random.default_rng(4303)
    tight = tried = 0
    for _ in range(60):
        system = _tight_at_a_corner(rng)
        M = system.shape[0]
        assert not _violations(system, [Fraction(0)] * system.shape[1])  # z = 0 is a solution
        ys = [np.ones(M), 10.0 ** rng.uniform(-300, 300, M), rng.uniform(0, 1, M) * (rng.random(M) > 0.5),
              np.where(rng.random(M) > 0.7, -1.0, rng.uniform(0, 5, M)),
              np.where(rng.random(M) > 0.7, np.inf, rng.uniform(0, 5, M))]
        found = LP._phase_one(system)
        if found is not None:
            ys.append(found)
        for y in ys:
            assert not OM.prove_infeasible(system, y, compiled=compiled), (system, y)
            if np.any(np.isfinite(y) & (y > 0)):
                left, yb = LP._dual_bound(system, y, compiled=compiled)
                tight += bool(left == 0.0 and yb == 0.0)
                tried += 1
    assert tight > 0.5 * tried, (tight, tried)


def _corner_boxes(rng, x, q, xi_lo, xi_hi, eps):
    """Boxes of ``x`` ``(S, n)`` (0.2-0.8 mm wide) and of ``q`` (``2 eps`` wide) with the truth at a corner."""
    w = rng.uniform(2e-4, 8e-4, x.shape)
    up = rng.random(x.shape) < 0.5
    X = (np.where(up, x, x - w), np.where(up, x + w, x))
    upq = rng.random(q.shape) < 0.5
    Q = (np.where(upq, q, q - 2 * eps), np.where(upq, q + 2 * eps, q))
    return X, Q, (xi_lo, xi_hi)


@pytest.fixture(scope="module")
def scenarios():
    return near_scenarios(4, 11, v_cross=(0.9, 1.1), v_bounce=(0.9, 1.1))


@pytest.mark.parametrize("compiled", [False, True])
def test_loop_closure_rows_hold_true_solutions_at_box_corners(scenarios, compiled):
    """For true ``(x_k, q_k, ξ)`` (``ξ`` a corner of ``[ξ]``, ``x_k``, ``q_k`` at corners of their boxes):
    ``blo <= Jc z <= bhi`` in exact arithmetic.  Fails without the second-order remainder."""
    im = interval_model()
    rng = np.random.default_rng(5)
    lo_xi, hi_xi = im.xi_box()
    for sc in scenarios:
        ks = np.arange(0, len(sc.t), 7)
        X, Q, XI = _corner_boxes(rng, sc.x[ks], sc.q_true[ks], lo_xi, hi_xi, DEXTAR.eps_q)
        Jc, blo, bhi = OM.loop_closure_rows(im, X, Q, XI, compiled=compiled)
        for s, k in enumerate(ks):
            z = [Fraction(float(v)) for v in np.concatenate([sc.x[k], sc.q_true[k], sc.xi])]
            for i in range(im.n):
                val = sum(Fraction(float(c)) * zj for c, zj in zip(Jc[s, i], z))
                assert Fraction(float(blo[s, i])) <= val <= Fraction(float(bhi[s, i])), (sc.name, k, i)


@pytest.mark.parametrize("compiled", [False, True])
def test_loop_closure_rows_hold_with_one_wide_parameter(scenarios, compiled):
    """The true pose and joints as points and one geometry parameter wide (the truth at either end of it, the
    others at their true values): the remainder is then that parameter's diagonal term alone, and the truth
    at a corner attains it.  Fails when either side of the diagonal term is dropped (``max(−H_jj, 0) r_j²``
    for the parameters of negative curvature, ``max(H̄_jj, 0) r_j²`` for the others)."""
    im = interval_model()
    lo_xi, hi_xi = im.xi_box()
    m = len(lo_xi)
    for sc in scenarios[:2]:
        ks = np.arange(0, len(sc.t), 23)
        X, Q = (sc.x[ks], sc.x[ks]), (sc.q_true[ks], sc.q_true[ks])
        for j in range(m):
            w = 0.5 * (hi_xi[j] - lo_xi[j])
            for side in (-1.0, 1.0):
                xlo, xhi = sc.xi.copy(), sc.xi.copy()
                if side > 0:
                    xhi[j] = sc.xi[j] + w
                else:
                    xlo[j] = sc.xi[j] - w
                Jc, blo, bhi = OM.loop_closure_rows(im, X, Q, (xlo, xhi), compiled=compiled)
                for s_, k in enumerate(ks):
                    z = [Fraction(float(v)) for v in np.concatenate([sc.x[k], sc.q_true[k], sc.xi])]
                    for i in range(im.n):
                        val = sum(Fraction(float(c)) * zj for c, zj in zip(Jc[s_, i], z))
                        assert Fraction(float(blo[s_, i])) <= val <= Fraction(float(bhi[s_, i])), (sc.name, j, side, i)


def _exact_motion(a, t_s, K, switches):
    """Exact (rational) positions and velocities at ``k t_s`` of a motion at ``+a`` then ``-a`` alternately,
    switching at the times ``switches`` (rationals, s), from rest at 0."""
    a, ts = Fraction(a), Fraction(t_s)
    x, v, t, acc, out_x, out_v = Fraction(0), Fraction(0), Fraction(0), a, [], []
    events = sorted(switches)
    for k in range(K):
        tk = k * ts
        while events and events[0] <= tk:
            dt = events[0] - t
            x, v, t = x + v * dt + acc * dt * dt / 2, v + acc * dt, events.pop(0)
            acc = -acc
        dt = tk - t
        x, v, t = x + v * dt + acc * dt * dt / 2, v + acc * dt, tk
        out_x.append(x)
        out_v.append(v)
    return out_x, out_v


@pytest.mark.parametrize("a, t_s", [(60.0, 1e-3), (65.97936997, 1e-3), (80.0, 1e-3), (75.0, 5e-4)])
def test_acceleration_rows_hold_for_motions_at_the_bound(a, t_s):
    """Motions at exactly ``±a`` (constant over many samples: the second difference is ``a t_s²`` exactly; and
    switching inside sample intervals, where the two-sample bound is attained): every row holds exactly.  For
    ``a`` = 60, 65.97936997 and 75 m/s², ``a t_s²`` rounded to nearest is below the exact value: fails when
    the bounds are not rounded up, or are tightened by a factor."""
    S, n = 12, 1
    ts = Fraction(t_s)
    for switches in ([], [ts * Fraction(7, 2), ts * Fraction(13, 3), ts * Fraction(29, 4)], [ts * 5 + ts / 7]):
        xs, vs = _exact_motion(a, t_s, S, switches)
        blocks = OM.motion_rows(t_s, np.array([a]), S, n, velocity=True)
        system = OM._stack(blocks, 2 * S * n, np.full(2 * S, -1.0), np.full(2 * S, 1.0))
        assert not _violations(system, xs + vs), switches


def test_drift_rows_hold_for_errors_at_the_edges_of_the_drift_model():
    """Reading errors ``e_k = s_k + f_k``, the fast part ``f_k`` alternating at its bound, the slow part ``s_k``
    drifting at its rate (both times 0.999): the true joints ``q̃_k - e_k`` and the true slow part satisfy every
    drift row exactly (in rational arithmetic), and ``|s_k|`` is within the returned bound.  Fails when the
    fast bound or the drift step is tightened (times 0.99) or not rounded outward."""
    fast, rate, eps, t_s, S = 9.23997839e-05, 0.02856415, 0.00130629, 1e-3, 80
    s = TrackerSettings.for_robot(DEXTAR, eps_q=eps, eps_q_fast=fast, drift_rate=rate, t_s=t_s)
    rng = np.random.default_rng(3)
    q_true = np.cumsum(rng.uniform(-1e-3, 1e-3, (S, 2)), axis=0)
    signs = np.where(np.arange(S) % 2 == 0, 1.0, -1.0)[:, None] * np.array([1.0, -1.0])
    slow = 0.999 * (rate * (np.arange(S)[:, None] * t_s) - 0.5 * rate * S * t_s) * np.ones((1, 2))
    q_meas = q_true + 0.999 * fast * signs + slow
    blocks, bound = OM.drift_rows(s, q_meas, S, 2)
    assert blocks and np.all(np.abs(slow) <= bound)
    system = OM._stack(blocks, 2 * 2 * S, np.full(4 * S, -9.0), np.full(4 * S, 9.0))
    # the stored reading errs from q_true + e by a rounding: the true slow part is exact, the fast part absorbs it
    z = [Fraction(float(v)) for v in q_true.ravel()] + [Fraction(float(v)) for v in slow.ravel()]
    assert not _violations(system, z)
    # the drift step at its bound: consecutive slow parts exactly drift_rate t_s apart (rationally)
    step = Fraction(rate) * Fraction(t_s)
    slow_edge = [[Fraction(k) * step * sgn for sgn in (1, -1)] for k in range(S)]
    q_edge = [Fraction(float(v)) for v in q_meas.ravel()]
    z = [q - sl for q, sl in zip(q_edge, [v for row in slow_edge for v in row])] + \
        [v for row in slow_edge for v in row]
    assert not _violations(system, z)


def _tubes(rng, x, xd, width=3e-4, vwidth=0.05):
    """Tubes ``(K, 2, n)`` around the truth, off-centre (the truth at a random place inside)."""
    u = rng.random((2,) + x.shape)
    X = np.stack([x - width * u[0], x + width * u[1]], axis=1)
    XD = np.stack([xd - vwidth * u[1], xd + vwidth * u[0]], axis=1)
    return X, XD


@pytest.mark.parametrize("velocity, compiled", [(False, False), (True, False), (False, True)])
def test_a_row_holding_an_adversarial_truth_is_never_refuted(scenarios, settings, velocity, compiled):
    """Tubes holding an adversarial true motion (bang-bang at 0.999 a_max, readings at the edges of ±eps_q),
    the whole ``[ξ]`` (the true geometry at a corner) or a sub-box with the truth at its corner: never refuted,
    over 40 samples around the widest box and over the whole run."""
    im = interval_model()
    rng = np.random.default_rng(9)
    lo, hi = im.xi_box()
    for sc in scenarios:
        X, XD = _tubes(rng, sc.x, sc.xd)
        corner = (np.minimum(sc.xi, 0.5 * (lo + hi)), np.maximum(sc.xi, 0.5 * (lo + hi)))
        for XI in ((lo, hi), corner):
            for size in (40, len(sc.t)):
                assert not OM.refute_row(im, settings, sc.q_meas, XI, X, XD, size=size, velocity=velocity,
                                         compiled=compiled), sc.name


def test_tight_tubes_around_a_motion_at_the_bound_are_not_refuted(settings):
    """The pose tube a single float wide per side around a motion at exactly ``a_max`` along a line, with
    readings at the edges of ``±eps_q``: nothing to spare in the acceleration rows, and still feasible."""
    im = interval_model()
    sc = near_scenarios(2, 4, v_cross=(1.0, 1.0))[0]
    X = np.stack([np.nextafter(sc.x, -1), np.nextafter(sc.x, 1)], axis=1)
    XD = np.stack([np.nextafter(sc.xd, -9), np.nextafter(sc.xd, 9)], axis=1)
    assert not OM.refute_row(im, settings, sc.q_meas, (sc.xi, sc.xi), X, XD, size=len(sc.t))


def test_the_one_motion_refutation_certifies_the_plan_at_09557_and_not_at_the_floor():
    """``crosscert certify``'s plan at 0.9557 m/s: undecided by the passes alone (the bounce hypothesis
    survives with 10 sub-boxes), certified once the rows of a spent budget are refuted one motion at a time;
    at the refutation bound (0.8438 m/s, a verified bounce explains the readings) the bounce hypothesis
    survives.  Fails without the call in ``verifier.window.hypotheses.decide``."""
    from crosscert.planner.certify.plan import certify_speed
    from crosscert.planner.task import PlanningBounds, benchmark_task
    from crosscert.robots import KinematicModel, get_entry
    from crosscert.verifier.settings import Verdict
    from crosscert.verifier.window import Refutation

    kin, task = KinematicModel(DEXTAR), benchmark_task(get_entry("dextar"))
    with_step = PlanningBounds(one_motion=OM.ONE_MOTION_SAMPLES, a_margin=MARGIN)
    run = certify_speed(kin, interval_model(), task, with_step, ONE_MOTION_PLAN["certified"])
    assert run.forward.verdict is Verdict.UNKNOWN
    assert run.window.verdict is Verdict.MODE_CHANGED, run.window.summary()
    wrong = {h.final_mode: h for h in run.window.hypotheses}[1]
    assert wrong.refutation is Refutation.ONE_MOTION
    floor = certify_speed(kin, interval_model(), task, with_step, ONE_MOTION_PLAN["floor"])
    assert floor.window.verdict is Verdict.UNKNOWN, floor.window.summary()


def test_certify_runs_the_step_by_default_and_not_when_the_bounds_say_0():
    """On in certify's windows by default (``PlanningBounds.one_motion`` = ``ONE_MOTION_SAMPLES``, as in
    ``track_window``; issue 20's ratio); ``one_motion=0`` turns it off, and the plan at 0.9557 m/s then stays
    undecided (with the step it is certified: the test above)."""
    from crosscert.planner.certify.plan import certify_speed
    from crosscert.planner.task import PlanningBounds, benchmark_task
    from crosscert.robots import KinematicModel, get_entry
    from crosscert.verifier.settings import Verdict

    assert PlanningBounds().one_motion == OM.ONE_MOTION_SAMPLES == 40
    kin, task = KinematicModel(DEXTAR), benchmark_task(get_entry("dextar"))
    run = certify_speed(kin, interval_model(), task, PlanningBounds(one_motion=0, a_margin=MARGIN),
                        ONE_MOTION_PLAN["certified"])
    assert run.window.verdict is Verdict.UNKNOWN, run.window.summary()


@pytest.mark.parametrize("bad", [-1, 1.5, True, "40", None])
def test_bad_bounds_sample_counts_are_refused(bad):
    from crosscert.planner.task import PlanningBounds
    from crosscert.robots.errors import InputError

    with pytest.raises(InputError, match="one_motion"):
        PlanningBounds(one_motion=bad)


def test_bad_sample_counts_are_refused(settings):
    from crosscert.robots.errors import InputError
    from crosscert.verifier.window import track_window

    q = np.zeros((3, 2))
    for bad in (-1, 1.5, True):
        with pytest.raises(InputError, match="one_motion"):
            track_window(interval_model(), q, settings, initial_mode=1, one_motion=bad)


def test_the_interval_sum_is_outward():
    """The pairwise sum of the check encloses the exact sum of many terms (odd counts padded with exact 0)."""
    rng = np.random.default_rng(1)
    v = rng.uniform(-1, 1, (3, 37)) * 10.0 ** rng.integers(-8, 3, (3, 37))
    lo, hi = LP.tree_sum(v, v)
    for r in range(3):
        exact = sum(Fraction(float(t)) for t in v[r])
        assert Fraction(float(lo[r])) <= exact <= Fraction(float(hi[r]))


@pytest.mark.parametrize("compiled", [False, True])
def test_a_certified_minimum_is_below_the_true_minimum(compiled):
    """Weak duality with outward rounding: ``FARKAS["float_only"]`` (``z = 5.2`` feasible, a certificate that
    holds only in round to nearest) gives no bound above ``0`` for the cost 0 nor above ``5.2`` for ``z``
    itself; on ``z_0 + z_1 >= 0.7`` over ``[0, 1]²`` the solver's multipliers prove ``min z_0 + z_1`` from below
    to within ``1e-12`` and never above the exact minimum."""
    A, b, lo, hi, y = FARKAS["float_only"]
    system, _ = _system("float_only")
    for cost, exact in (([0.0], Fraction(0)), ([1.0], Fraction(float(lo[0])))):
        low = float(OM.certified_minimum(system, y, np.array(cost), compiled=compiled))
        assert Fraction(low) <= exact, (cost, low)
    tie = OM.LinearSystem(np.array([0, 0]), np.array([0, 1]), np.array([-1.0, -1.0]), np.array([-0.7]),
                          np.zeros(2), np.ones(2))
    solver = LP.HighsSolver(compiled)
    assert solver.phase_one(tie) is None and solver.feasible
    lo2, hi2 = solver.bounds(tie, [0, 1])  # each in [0, 1]: z_0 >= 0.7 - 1 < 0, no narrowing
    assert np.all(lo2 <= 0.0) and np.all(hi2 >= 1.0)
    y2 = np.array([1.0])
    low = float(OM.certified_minimum(tie, y2, np.array([1.0, 1.0]), compiled=compiled))
    assert Fraction(low) <= Fraction(0.7) and low > 0.7 - 1e-12


@pytest.mark.parametrize("compiled", [False, True])
def test_the_contractor_keeps_the_true_geometry(scenarios, settings, compiled):
    """Tubes holding an adversarial true motion, the true geometry at a corner of ``[ξ]`` and the sub-box with
    the truth at its corner: the contracted sub-box keeps the true geometry (over 40 samples and the whole
    run), and the contractor narrows something (not vacuous).  Fails when a proved bound is moved inward by
    a thousandth of the width (the truth sits on a side of the box that no bound narrows)."""
    im = interval_model()
    rng = np.random.default_rng(13)
    lo, hi = im.xi_box()
    narrowed = 0
    for sc in scenarios:
        X, XD = _tubes(rng, sc.x, sc.xd)
        corner = (np.minimum(sc.xi, 0.5 * (lo + hi)), np.maximum(sc.xi, 0.5 * (lo + hi)))
        for XI in ((lo, hi), corner):
            for size in (40, len(sc.t)):
                out, clo, chi = OM.one_motion_rows(im, settings, sc.q_meas, (XI[0][None], XI[1][None]), X[None],
                                                   XD[None], size, compiled=compiled)
                assert not out[0], sc.name
                assert np.all((clo[0] <= sc.xi) & (sc.xi <= chi[0])), (sc.name, size, clo[0] - sc.xi, chi[0] - sc.xi)
                assert np.all((XI[0] <= clo[0]) & (chi[0] <= XI[1]))
                narrowed += bool(np.any(chi[0] - clo[0] < 0.99 * (XI[1] - XI[0])))
    assert narrowed >= 4, narrowed


def test_the_contractor_certifies_the_certify_plan_at_0930():
    """``crosscert certify``'s plan at 0.9300 m/s: undecided with the refutation alone, certified once the
    rows' sub-boxes are narrowed to the geometries one motion explains (and another round runs with them).
    (At the refutation bound the bounce hypothesis survives the same step:
    ``test_the_one_motion_refutation_certifies_the_plan_at_09557_and_not_at_the_floor``.)  Fails without the
    narrowing kept in ``verifier.window.hypotheses.Hypothesis.one_motion``."""
    from crosscert.planner.certify.plan import certify_speed
    from crosscert.planner.task import PlanningBounds, benchmark_task
    from crosscert.robots import KinematicModel, get_entry
    from crosscert.verifier.settings import Verdict

    kin, task = KinematicModel(DEXTAR), benchmark_task(get_entry("dextar"))
    with_step = PlanningBounds(one_motion=OM.ONE_MOTION_SAMPLES, a_margin=MARGIN)
    run = certify_speed(kin, interval_model(), task, with_step, ONE_MOTION_PLAN["contracted"])
    assert run.window.verdict is Verdict.MODE_CHANGED, run.window.summary()


def test_the_contractor_skips_only_the_sides_a_point_attains():
    """``z_0 + z_1 >= 1.5`` over ``[0, 1]²``: ``min z_j`` is 0.5 (proved from below to within ``1e-12``),
    ``max z_j`` the box's 1, which phase one's vertex or a later program's point attains: those programs are
    not run (fewer than the four), the same bounds come out.  Fails when the skip takes the other side."""
    system = OM.LinearSystem(np.array([0, 0]), np.array([0, 1]), np.array([-1.0, -1.0]), np.array([-1.5]),
                             np.zeros(2), np.ones(2))
    solver = LP.HighsSolver()
    runs = []
    real = solver.highs

    class Counting:
        def __getattr__(self, name):
            return getattr(real, name)

        def run(self):
            runs.append(1)
            return real.run()

    assert solver.phase_one(system) is None and solver.feasible
    solver.highs = Counting()
    lo, hi = solver.bounds(system, [0, 1])
    assert np.all(hi == 1.0)
    assert np.all(lo <= 0.5) and np.all(lo > 0.5 - 1e-12), lo
    assert len(runs) < 4, len(runs)
