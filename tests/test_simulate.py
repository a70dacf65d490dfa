"""Tests of the simulated crossings and bounces (planner.simulate) on the DexTAR benchmark."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest

import crosscert.planner.simulate as sim
from crosscert.planner.simulate import (
    RAMP_PEAK,
    bounce_time_law,
    crossing_time_law,
    max_v_sing,
    ramp_length,
    random_geometry,
    simulate_bounce,
    simulate_crossing,
)
from crosscert.robots import DEXTAR
from crosscert.robots.dextar import singular_y
from crosscert.robots.dextar import mode_by_cross_product
from crosscert.robots.errors import InputError, SimulationError

V_SING = 1.458  # fastest crossing of Table II, m/s


@pytest.fixture(scope="module")
def xi_true():
    return random_geometry(DEXTAR, np.random.default_rng(2024))


@pytest.fixture(scope="module")
def crossing(kin, bench, xi_true):
    return simulate_crossing(kin, bench.point, bench.direction, V_SING, xi_true=xi_true,
                             working_guess=bench.q_point, seed=1)


@pytest.fixture(scope="module")
def bounce(kin, bench, xi_true):
    return simulate_bounce(kin, bench.point, bench.direction, V_SING, xi_true=xi_true,
                           working_guess=bench.q_point, seed=1)


@pytest.fixture(scope="module")
def fine_runs(kin, bench, xi_true):
    """Crossing and bounce sampled at 10 kHz, for finite-difference checks."""
    kw = dict(xi_true=xi_true, working_guess=bench.q_point, t_s=1e-4, t_rest=0.01, t_rest_end=0.01)
    return (simulate_crossing(kin, bench.point, bench.direction, V_SING, **kw),
            simulate_bounce(kin, bench.point, bench.direction, V_SING, **kw))


def central(a, t):
    return (a[2:] - a[:-2]) / (t[2:] - t[:-2])[:, None]


# ------------------------------------------------------------------ time law
def test_ramp_length():
    T, D = ramp_length(1.5, 60.0)
    assert T == pytest.approx(1.875 * 1.5 / 60.0)
    assert D == pytest.approx(1.875 * 1.5**2 / (2 * 60.0))


@pytest.mark.parametrize("law", [
    crossing_time_law(1.2, 60.0, 5e-3, 0.05, 0.02),
    bounce_time_law(1.2, 60.0, 5e-3, 0.05, 0.02, 1e-3),
])
def test_time_law_is_smooth_and_bounded(law):
    t = np.linspace(-0.01, law.duration + 0.01, 200001)
    s, v, a = law.evaluate(t)
    dt = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(s, dt)[1:-1], v[1:-1], atol=1e-6)
    np.testing.assert_allclose(np.gradient(v, dt)[1:-1], a[1:-1], atol=2e-2)
    assert np.max(np.abs(a)) <= 60.0 * (1 + 1e-12)
    assert np.max(np.abs(a)) == pytest.approx(60.0, rel=1e-6)
    assert v[0] == v[-1] == a[0] == a[-1] == 0.0
    assert np.max(np.abs(np.diff(a))) < 1e-2  # continuous acceleration
    assert RAMP_PEAK == 1.875


def test_crossing_law_has_constant_speed_around_the_point():
    law = crossing_time_law(1.2, 60.0, 5e-3, 0.05, 0.02)
    T, D = ramp_length(1.2, 60.0)
    assert law.s_start == pytest.approx(-(D + 5e-3)) and law.s_end == pytest.approx(D + 5e-3)
    t = 0.05 + T + np.linspace(0, 2 * 5e-3 / 1.2, 11)[1:-1]
    s, v, a = law.evaluate(t)
    np.testing.assert_allclose(s, np.linspace(-5e-3, 5e-3, 11)[1:-1], atol=1e-15)
    assert np.all(v == 1.2) and np.all(a == 0.0)


# ---------------------------------------------------------------- crossings
def test_encoder_error_bounds(kin, bench, xi_true, crossing):
    err = crossing.q_meas - crossing.q_true
    eps = DEXTAR.eps_q
    assert np.all(np.abs(err) <= eps)
    assert np.all(err <= 1e-15) and np.all(err > -eps)  # floor
    kw = dict(xi_true=xi_true, working_guess=bench.q_point, t_rest=0.05, t_rest_end=0.01)
    rnd = simulate_crossing(kin, bench.point, bench.direction, V_SING, quantisation="round", **kw)
    assert np.all(np.abs(rnd.q_meas - rnd.q_true) <= eps / 2 * (1 + 1e-9))
    u1 = simulate_crossing(kin, bench.point, bench.direction, V_SING, quantisation="uniform", seed=5, **kw)
    u2 = simulate_crossing(kin, bench.point, bench.direction, V_SING, quantisation="uniform", seed=5, **kw)
    u3 = simulate_crossing(kin, bench.point, bench.direction, V_SING, quantisation="uniform", seed=6, **kw)
    e1 = u1.q_meas - u1.q_true
    assert np.all(np.abs(e1) <= eps)
    assert np.max(np.abs(e1)) > 0.9 * eps and np.min(e1) < 0 < np.max(e1)
    np.testing.assert_array_equal(u1.q_meas, u2.q_meas)
    assert not np.array_equal(u1.q_meas, u3.q_meas)


def test_ground_truth_satisfies_the_model(kin, crossing, xi_true):
    f = kin.f_batch(crossing.x_true, crossing.q_true, xi_true)
    assert np.max(np.abs(f)) < 1e-13
    np.testing.assert_array_equal(crossing.xi_true, xi_true)
    # Eq. (2) holds exactly (up to rounding) with the simulated velocities.
    jx = kin.jac_x_batch(crossing.x_true, crossing.q_true, xi_true)
    jq = kin.jac_q_batch(crossing.x_true, crossing.q_true, xi_true)
    res = np.einsum("kij,kj->ki", jx, crossing.xd_true) + np.einsum("kij,kj->ki", jq, crossing.qd_true)
    assert np.max(np.abs(res)) < 1e-14


def test_derivatives_match_finite_differences(fine_runs):
    for run in fine_runs:
        t = run.t
        k = slice(1, -1)
        np.testing.assert_allclose(central(run.x_true, t), run.xd_true[k], atol=1e-5 * V_SING)
        np.testing.assert_allclose(central(run.xd_true, t), run.xdd_true[k], atol=2e-3)
        qd_scale = np.max(np.abs(run.qd_true))
        qdd_scale = np.max(np.abs(run.qdd_true))
        np.testing.assert_allclose(central(run.q_true, t), run.qd_true[k], atol=3e-5 * qd_scale)
        np.testing.assert_allclose(central(run.qd_true, t), run.qdd_true[k], atol=1e-4 * qdd_scale)


def test_joint_derivatives_are_exact(crossing, xi_true):
    """qd, qdd against 5-point stencils of the closed-form IK on the time law (no simulator IK)."""
    from crosscert.robots.dextar import elbows_out_ik

    law, p, u = crossing.time_law, crossing.crossing_point, crossing.direction
    h = 2e-5
    ks = [int(np.argmax(np.linalg.norm(crossing.xdd_true, axis=1))), crossing.k_sing,
          crossing.k_sing - 3, crossing.k_sing + 20]
    for k in ks:
        tt = crossing.t[k] + h * np.arange(-2, 3)
        s, _v, _a = law.evaluate(tt)
        q = elbows_out_ik(p + s[:, None] * u, xi_true)
        qd = (q[0] - 8 * q[1] + 8 * q[3] - q[4]) / (12 * h)
        qdd = (-q[0] + 16 * q[1] - 30 * q[2] + 16 * q[3] - q[4]) / (12 * h**2)
        np.testing.assert_allclose(crossing.qd_true[k], qd, rtol=1e-8, atol=1e-9)
        np.testing.assert_allclose(crossing.qdd_true[k], qdd, rtol=1e-5, atol=1e-3)


def test_acceleration_and_speed(crossing):
    acc = np.linalg.norm(crossing.xdd_true, axis=1)
    assert np.max(acc) <= crossing.a_peak * (1 + 1e-9)
    assert np.max(acc) > 0.99 * crossing.a_peak
    k = crossing.k_sing
    assert np.linalg.norm(crossing.xd_true[k]) == pytest.approx(V_SING, rel=1e-12)
    assert np.all(crossing.xdd_true[k] == 0.0)  # crossing criterion: no acceleration
    assert np.all(crossing.xd_true[[0, -1]] == 0.0)
    assert crossing.t_sing == crossing.t[k] and crossing.t[k] == pytest.approx(k * crossing.t_s)
    np.testing.assert_allclose(np.diff(crossing.t), crossing.t_s, rtol=1e-9)
    assert crossing.t[k] >= 0.5  # the default rest precedes the motion


def test_mode_flips_exactly_once(crossing, kin, xi_true):
    m = crossing.mode_true
    nz = m[m != 0]
    assert np.count_nonzero(nz[1:] != nz[:-1]) == 1
    assert m[0] == 1 and m[-1] == -1
    k = crossing.k_sing
    assert m[k] == 0 and np.all(m[:k] == 1) and np.all(m[k + 1:] == -1)
    np.testing.assert_array_equal(nz, mode_by_cross_product(crossing.x_true, crossing.q_true, xi_true)[m != 0])
    assert not crossing.bounce


def test_true_singular_point(crossing, bench, xi_true, kin):
    # The generic line search agrees with the DexTAR-specific solver.
    assert crossing.x_sing[0] == 0.0
    assert crossing.x_sing[1] == pytest.approx(singular_y(xi_true), abs=1e-13)
    assert crossing.s_sing == pytest.approx(bench.point[1] - crossing.x_sing[1], abs=1e-15)
    assert abs(crossing.s_sing) < 1e-3
    np.testing.assert_allclose(crossing.x_true[crossing.k_sing], crossing.x_sing, atol=1e-16)


def test_run_is_read_only(crossing):
    with pytest.raises(ValueError):
        crossing.q_meas[0, 0] = 0.0
    with pytest.raises(AttributeError):
        crossing.v_sing = 2.0


# ------------------------------------------------------------------ bounces
def test_bounce_never_changes_mode(bounce, kin, xi_true):
    m = bounce.mode_true
    assert bounce.bounce
    assert np.all(m[m != 0] == 1)
    k = bounce.k_sing
    assert m[k] == 0  # touching the locus
    assert np.all(bounce.xd_true[k] == 0.0)
    assert np.linalg.norm(bounce.xdd_true, axis=1).max() <= bounce.a_peak * (1 + 1e-9)
    np.testing.assert_allclose(bounce.x_true[k], bounce.x_sing, atol=1e-16)
    np.testing.assert_allclose(bounce.x_true[-1], bounce.x_true[0], atol=1e-15)
    np.testing.assert_allclose(bounce.q_true[-1], bounce.q_true[0], atol=1e-12)
    # Goes down the path, then back up: the velocity along the path changes sign once.
    vs = bounce.xd_true @ bounce.direction
    vs = vs[vs != 0]
    assert np.count_nonzero(np.sign(vs[1:]) != np.sign(vs[:-1])) == 1
    assert np.max(vs) == pytest.approx(V_SING)
    # It never passes the true locus.
    assert np.all((bounce.x_true - bounce.x_sing) @ bounce.direction <= 1e-15)
    assert np.max(np.abs(kin.f_batch(bounce.x_true, bounce.q_true, xi_true))) < 1e-13
    assert np.all(np.abs(bounce.q_meas - bounce.q_true) <= bounce.eps_q)


# --------------------------------------------------------- limits, errors
def test_max_v_sing_of_the_default_benchmark(kin, bench):
    v = max_v_sing(kin, bench.point, bench.direction, working_guess=bench.q_point)
    assert 2.2 < v < 2.35
    run = simulate_crossing(kin, bench.point, bench.direction, 0.999 * v, working_guess=bench.q_point,
                            t_rest=0.01, t_rest_end=0.01)
    assert run.mode_true[0] == 1 and run.mode_true[-1] == -1
    with pytest.raises(SimulationError, match=r"v_sing <= 2\.2"):
        simulate_crossing(kin, bench.point, bench.direction, 1.01 * v, working_guess=bench.q_point)
    vb = max_v_sing(kin, bench.point, bench.direction, working_guess=bench.q_point, bounce=True)
    assert 1.2 < vb < v


@pytest.mark.parametrize("over, err", [
    ({"a_peak": 80.0}, InputError),
    ({"a_peak": -1.0}, InputError),
    ({"v_sing": 0.0}, InputError),
    ({"v_sing": float("inf")}, InputError),
    ({"direction": [0.0, 0.0]}, InputError),
    ({"crossing_point": [0.0, 0.08, 0.0]}, InputError),
    ({"quantisation": "ceil"}, InputError),
    ({"xi_true": DEXTAR.xi_nominal}, InputError),  # l11 = 90 mm is outside [xi]
    ({"xi_true": DEXTAR.xi_hi[:6]}, InputError),
    ({"working_guess": None}, InputError),
    ({"cruise": 0.0}, InputError),
    ({"t_rest": -1.0}, InputError),
    ({"eps_q": 0.0}, InputError),
    ({"crossing_point": [0.0, 0.12]}, SimulationError),   # 35 mm from the locus
    ({"crossing_point": [0.0, 0.3]}, SimulationError),    # unreachable
    ({"working_guess": [-1.4, 4.5]}, SimulationError),    # joints outside their limits
])
def test_bad_inputs(kin, bench, over, err):
    kw = dict(crossing_point=bench.point, direction=bench.direction, v_sing=1.0,
              working_guess=bench.q_point, t_rest=0.01, t_rest_end=0.01)
    kw.update(over)
    for fn in (simulate_crossing, simulate_bounce):
        with pytest.raises(err):
            fn(kin, **kw)


def test_nominal_geometry_needs_opt_in(kin, bench):
    run = simulate_crossing(kin, bench.point, bench.direction, 1.0, xi_true=DEXTAR.xi_nominal,
                            strict_xi=False, working_guess=bench.q_point, t_rest=0.01)
    assert abs(run.s_sing) < 1e-15  # the nominal point is the nominal singularity


def test_random_geometry():
    a = random_geometry(DEXTAR, 3)
    np.testing.assert_array_equal(a, random_geometry(DEXTAR, np.random.default_rng(3)))
    assert DEXTAR.xi_in_box(a)
    rng = np.random.default_rng(4)
    for _ in range(10):
        c = random_geometry(DEXTAR, rng, corners=True)
        assert np.all((c == DEXTAR.xi_lo_array) | (c == DEXTAR.xi_hi_array))


def test_simulator_is_robot_agnostic():
    src = inspect.getsource(sim).lower()
    for word in ("dextar", "five-bar", "five bar", "fivebar"):
        assert word not in src
    assert math.isclose(sim.RAMP_PEAK, 30 / 16)


def test_line_scans_reused_across_bounces_are_the_fresh_ones(kin, bench, xi_true, monkeypatch):
    """Bounces of one line at several turn-back distances share its IK continuation (planner.locus keeps
    the grid points): each one is, to the last bit, the bounce simulated with nothing kept."""
    import crosscert.planner.locus as locus

    kw = dict(xi_true=xi_true, working_guess=bench.q_point, seed=3, quantisation="uniform")
    shorts = (0.004, 0.0, 0.012, 0.0075)  # a short scan first, then longer and shorter ones
    locus._SIDES.clear()
    reused = [simulate_bounce(kin, bench.point, bench.direction, 1.2, short=d, **kw) for d in shorts]
    assert locus._SIDES  # the continuations were kept ...
    fresh = []
    for d in shorts:
        locus._SIDES.clear()  # ... and each is compared with one computed afresh
        fresh.append(simulate_bounce(kin, bench.point, bench.direction, 1.2, short=d, **kw))
    for a, b in zip(reused, fresh):
        assert np.array_equal(a.q_true, b.q_true) and np.array_equal(a.q_meas, b.q_meas)
    # the scans themselves, to extents off the grid, ending at an invalid pose or not
    p, u, qg, h = bench.point, bench.direction, bench.q_point, 1.01e-3
    ends = [(-0.0123, 0.0031), (-0.2, 0.2), (-0.05, 0.0), (-0.0123, 0.0031), (-0.3, 0.009)]
    locus._SIDES.clear()
    kept = [locus.scan_line(kin, p, u, xi_true, qg, lo, hi, h) for lo, hi in ends]
    for (lo, hi), a in zip(ends, kept):
        locus._SIDES.clear()
        b = locus.scan_line(kin, p, u, xi_true, qg, lo, hi, h)
        assert np.array_equal(a.s, b.s) and np.array_equal(a.q, b.q) and np.array_equal(a.det, b.det)
        assert (a.lo_done, a.hi_done) == (b.lo_done, b.hi_done)
        assert np.array_equal([a.lo_fail, a.hi_fail], [b.lo_fail, b.hi_fail], equal_nan=True)
    assert not kept[1].lo_done and kept[0].lo_done  # a long scan ends at an invalid pose, a short one not
