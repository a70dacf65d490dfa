"""Tests of the time scaling along a crossing path (planner.timescale) on the DexTAR benchmark.

The path is the benchmark line (down the Y axis through the nominal singular
point), 35 mm before to 35 mm after the crossing point (cut to where the IK
stays valid), on a 0.1 mm grid.  Limits, chosen plausible for the DexTAR:

* ``qd_max = 30 rad/s`` (a direct-drive motor's speed, ~290 rpm),
* ``qdd_max = 3000 rad/s^2``,
* ``a_max = (80, 80) m/s^2``: the tracker's bound, Section III-A of the paper.

Under them only the end-effector bound is active, which gives a closed-form
check: rest to rest, ``|sddot| <= 80`` and the criterion's zero acceleration
on the two grid intervals next to ``s*`` allow ``v = sqrt(2 a_max (h - ds))``.
A second set (``qdd_max = 400 rad/s^2``) makes the joint acceleration at the
singular point (``qddot = q'' v^2``, since ``q' = 0`` there) the active bound.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import toppra.algorithm
from toppra.constraint import JointAccelerationConstraint, JointVelocityConstraint

from crosscert.planner.timescale import (  # noqa: E402
    FEAS_RTOL,
    LinearPathConstraint,
    PathSamples,
    ScalingLimits,
    TimeScaling,
    max_speed_at,
    resample,
    sample_path,
    time_optimal_scaling,
)
from crosscert.robots import DEXTAR, KinematicModel  # noqa: E402
from crosscert.robots.dextar import benchmark_crossing  # noqa: E402
from crosscert.robots.errors import InputError, SimulationError  # noqa: E402

V_SING = 1.458  # fastest crossing of Table II, m/s
HALF = 35e-3  # path extent on each side of the crossing point, m
DS = 1e-4  # grid step, m
LIMITS = ScalingLimits(qd_max=30.0, qdd_max=3000.0, a_max=(80.0, 80.0))
LIMITS_JOINT = ScalingLimits(qd_max=30.0, qdd_max=400.0, a_max=(80.0, 80.0))


@pytest.fixture(scope="module")
def kin():
    return KinematicModel(DEXTAR)


@pytest.fixture(scope="module")
def bench():
    return benchmark_crossing()


def _valid_extent(kin, bench, sign: float, limit: float, step: float = 1e-3) -> float:
    """Distance (m, multiple of DS) up to ``limit`` along ``sign * direction`` where the IK stays valid."""
    r, xi = kin.robot, DEXTAR.xi_nominal_array
    q = bench.q_point
    for k in range(1, int(round(limit / step)) + 1):
        x = bench.point + sign * k * step * bench.direction
        Q, ok = kin.ik_batch(x[None, :], xi, q[None, :])
        valid = ok[0] and np.all((x >= r.x_lo_array) & (x <= r.x_hi_array)) and np.all(
            (Q[0] >= r.q_lo_array) & (Q[0] <= r.q_hi_array))
        if not valid:
            return math.floor((k - 1) * step / DS) * DS
        q = Q[0]
    return limit


@pytest.fixture(scope="module")
def path(kin, bench):
    """``(samples, s_star)``: the benchmark path, the crossing point on a grid node."""
    before = _valid_extent(kin, bench, -1.0, HALF)
    after = _valid_extent(kin, bench, 1.0, HALF)
    n_before, n_after = round(before / DS), round(after / DS)
    s_star = n_before * DS
    samples = sample_path(kin, bench.point - s_star * bench.direction, bench.direction,
                          (n_before + n_after) * DS, n_before + n_after, bench.q_point)
    return samples, s_star


@pytest.fixture(scope="module")
def samples(path):
    return path[0]


@pytest.fixture(scope="module")
def s_star(path):
    return path[1]


@pytest.fixture(scope="module")
def k_star(samples, s_star):
    return int(round(s_star / samples.ds))


@pytest.fixture(scope="module")
def scaling(samples, s_star):
    return time_optimal_scaling(samples, LIMITS, V_SING, s_star)


@pytest.fixture(scope="module")
def v_top(samples, s_star):
    return max_speed_at(samples, LIMITS, s_star)


def _check_limits(sc: TimeScaling, samples: PathSamples, limits: ScalingLimits) -> None:
    """Every bound at every node, for both one-sided path accelerations, relative tol 1e-6."""
    tol = 1e-6
    b, a = sc.b, sc.a
    assert np.all(b >= 0.0)
    np.testing.assert_allclose(np.diff(b), 2.0 * samples.ds * a, rtol=0, atol=1e-12)
    qd = np.abs(samples.q_s) * np.sqrt(b)[:, None]
    assert np.all(qd <= np.asarray(limits.qd_max) * (1 + tol))
    for lo, hi in ((slice(0, -1), slice(0, -1)), (slice(1, None), slice(1, None))):
        qdd = samples.q_s[lo] * a[:, None] + samples.q_ss[hi] * b[hi, None]
        xdd = samples.x_s[lo] * a[:, None] + samples.x_ss[hi] * b[hi, None]
        assert np.all(np.abs(qdd) <= np.asarray(limits.qdd_max) * (1 + tol))
        assert np.all(np.abs(xdd) <= np.asarray(limits.a_max) * (1 + tol))


def _kernel_jx(kin, samples, k):
    jx = np.asarray(kin.jac_x(samples.x[k], samples.q[k], samples.xi), dtype=float)
    return np.linalg.svd(jx)[2][-1]


# ------------------------------------------------------------------ sampling
def test_path_spans_the_benchmark(samples, s_star, bench):
    assert s_star == pytest.approx(HALF) and samples.length == pytest.approx(2 * HALF)
    assert samples.n_intervals == 700 and samples.ds == pytest.approx(DS)
    k = int(round(s_star / samples.ds))
    np.testing.assert_allclose(samples.x[k], bench.point, atol=1e-15)
    np.testing.assert_allclose(samples.q[k], bench.q_point, atol=1e-10)
    assert all(not a.flags.writeable for a in (samples.s, samples.q, samples.q_s))


def test_path_derivatives_are_the_kinematic_ones(kin, samples):
    np.testing.assert_array_equal(samples.x_s, np.tile(samples.u, (samples.s.size, 1)))
    np.testing.assert_array_equal(samples.x_ss, 0.0)
    assert np.max(np.abs(kin.f_batch(samples.x, samples.q, samples.xi))) < 1e-12
    # Central differences of the exact q and q' agree to O(ds^2).
    h = samples.ds
    fd1 = (samples.q[2:] - samples.q[:-2]) / (2 * h)
    fd2 = (samples.q_s[2:] - samples.q_s[:-2]) / (2 * h)
    assert np.max(np.abs(fd1 - samples.q_s[1:-1])) < 1e-4 * np.max(np.abs(samples.q_s))
    assert np.max(np.abs(fd2 - samples.q_ss[1:-1])) < 1e-4 * np.max(np.abs(samples.q_ss))


def test_joints_are_stationary_at_the_singular_point(samples, k_star):
    # Distal links stretched along x: the joints do not move to first order.
    assert np.max(np.abs(samples.q_s[k_star])) < 1e-9
    assert np.min(np.abs(samples.q_ss[k_star])) > 100.0


def test_sample_path_errors(kin, bench):
    with pytest.raises(SimulationError, match="IK failed|outside x_bounds"):
        sample_path(kin, bench.point, bench.direction, 0.4, 400, bench.q_point)
    with pytest.raises(InputError):
        sample_path(kin, bench.point, bench.direction, 0.01, 1, bench.q_point)
    with pytest.raises(InputError):
        sample_path(kin, bench.point, (0.0, 0.0), 0.01, 10, bench.q_point)
    with pytest.raises(InputError):
        sample_path(kin, bench.point, bench.direction, -0.01, 10, bench.q_point)


# ------------------------------------------------------------------ cvxpy
def test_scaling_meets_limits_and_criterion(kin, samples, scaling, k_star):
    assert scaling.status in ("optimal", "optimal_inaccurate")
    _check_limits(scaling, samples, LIMITS)
    assert scaling.max_violation <= FEAS_RTOL
    assert scaling.b[0] == 0.0 and scaling.b[-1] == 0.0
    assert scaling.k_star == k_star
    assert abs(scaling.sd[k_star] - V_SING) <= 1e-12
    # Criterion: end-effector acceleration normal to the kernel of J_x (computed here).
    c = _kernel_jx(kin, samples, k_star)
    assert abs(abs(c @ samples.u) - 1.0) < 1e-12  # the path crosses along it
    for a in scaling.a[k_star - 1:k_star + 1]:
        xdd = samples.x_s[k_star] * a + samples.x_ss[k_star] * scaling.b[k_star]
        assert abs(c @ xdd) <= 1e-8
    assert scaling.criterion_residual <= 1e-8
    # Times follow the piecewise-constant-acceleration model.
    sd = np.sqrt(scaling.b)
    np.testing.assert_allclose(np.diff(scaling.t), 2 * samples.ds / (sd[:-1] + sd[1:]), rtol=1e-9)
    assert scaling.total_time == scaling.t[-1]


def test_seeded_random_speeds_meet_limits(samples, s_star, v_top):
    rng = np.random.default_rng(20261125)
    for v in rng.uniform(0.2, 0.95 * v_top, size=3):
        sc = time_optimal_scaling(samples, LIMITS, float(v), s_star)
        _check_limits(sc, samples, LIMITS)
        assert abs(sc.sd[sc.k_star] - v) <= 1e-12


def test_scaling_is_time_optimal(samples, s_star, k_star, scaling):
    # The criterion alone (speed free) is a relaxation; imposing its own speed changes nothing.
    free = time_optimal_scaling(samples, LIMITS, None, s_star)
    assert free.total_time <= scaling.total_time
    again = time_optimal_scaling(samples, LIMITS, free.sd[k_star], s_star)
    assert again.total_time == pytest.approx(free.total_time, rel=1e-6)


def test_unconstrained_crossing_matches_toppra_minimum_time(samples):
    # Joint limits only, no crossing: toppra's TOPP-RA (exact for this discretisation)
    # on its own cubic-spline path gives the same minimum time.
    lim = ScalingLimits(qd_max=4.0, qdd_max=400.0)
    sc = time_optimal_scaling(samples, lim)
    _check_limits(sc, samples, ScalingLimits(qd_max=4.0, qdd_max=400.0, a_max=np.inf))
    path = toppra.SplineInterpolator(samples.s, samples.q)
    algo = toppra.algorithm.TOPPRA([JointVelocityConstraint(np.full(2, 4.0)),
                                    JointAccelerationConstraint(np.full(2, 400.0))],
                                   path, gridpoints=np.array(samples.s), solver_wrapper="seidel")
    _sdd, sd, _v = algo.compute_parameterization(0.0, 0.0)
    t_top = float(np.sum(2 * samples.ds / (sd[:-1] + sd[1:])))
    assert sc.total_time == pytest.approx(t_top, rel=1e-5)


# ------------------------------------------------------------------ toppra
def test_toppra_max_speed_closed_form(samples, s_star, v_top):
    # Only the end-effector bound is active: decelerate from v to rest over h - ds at 80 m/s^2.
    h = min(s_star, samples.length - s_star)
    assert v_top == pytest.approx(math.sqrt(2 * 80.0 * (h - samples.ds)), rel=1e-9)


@pytest.mark.parametrize("limits", [LIMITS, LIMITS_JOINT], ids=["ee-bound", "joint-bound"])
def test_toppra_and_cvxpy_agree(samples, s_star, k_star, limits):
    v = max_speed_at(samples, limits, s_star)
    if limits is LIMITS_JOINT:  # joint acceleration at the singular point is active
        assert v < math.sqrt(400.0 / np.max(np.abs(samples.q_ss[k_star]))) * 1.001
    ok = time_optimal_scaling(samples, limits, 0.99 * v, s_star)
    _check_limits(ok, samples, limits)
    with pytest.raises(SimulationError, match="no feasible crossing at v_sing") as err:
        time_optimal_scaling(samples, limits, 1.01 * v, s_star)
    # The message's largest speed (cvxpy LP on the same grid) is toppra's.
    reported = float(str(err.value).split(" is ")[-1].split(" m/s")[0])
    assert reported == pytest.approx(v, rel=1e-5)


def test_extra_linear_constraint(samples, s_star):
    # |sddot| <= 40 m/s^2 written as an extra constraint A a + B b <= C.
    N1 = samples.s.size
    extra = LinearPathConstraint(A=np.tile([1.0, -1.0], (N1, 1)), B=np.zeros((N1, 2)),
                                 C=np.full((N1, 2), 40.0), name="half a_max")
    lim = dataclasses.replace(LIMITS, extra=(extra,))
    v = max_speed_at(samples, lim, s_star)
    h = min(s_star, samples.length - s_star)
    assert v == pytest.approx(math.sqrt(2 * 40.0 * (h - samples.ds)), rel=1e-9)
    sc = time_optimal_scaling(samples, lim, V_SING, s_star)
    assert np.max(np.abs(sc.a)) <= 40.0 * (1 + 1e-6)
    with pytest.raises(SimulationError, match="no feasible crossing"):
        time_optimal_scaling(samples, lim, 1.01 * v, s_star)


def test_general_criterion_direction_on_curved_path():
    # Synthetic 1-D path with x'' != 0: the criterion c.(x' a + x'' b) = 0 fixes
    # a = -x'' b / x' at s*, not 0; both solvers must see the same set.
    N, L, kappa = 200, 0.02, 30.0
    s = np.linspace(0.0, L, N + 1)
    one = np.ones((N + 1, 1))
    smp = PathSamples(s=s, x=s[:, None], x_s=one, x_ss=kappa * one, q=s[:, None], q_s=one,
                      q_ss=np.zeros((N + 1, 1)), p0=np.zeros(1), u=np.ones(1), length=L,
                      xi=np.zeros(1), kin=None)
    lim = ScalingLimits(a_max=50.0)
    s_star = s[N // 2]
    v = max_speed_at(smp, lim, s_star, criterion_direction=[1.0])
    sc = time_optimal_scaling(smp, lim, 0.99 * v, s_star, criterion_direction=[1.0])
    k = sc.k_star
    for a in sc.a[k - 1:k + 1]:
        assert a == pytest.approx(-kappa * sc.b[k], rel=1e-9)
    assert sc.criterion_residual <= 1e-8
    with pytest.raises(SimulationError, match="no feasible crossing"):
        time_optimal_scaling(smp, lim, 1.01 * v, s_star, criterion_direction=[1.0])


# ------------------------------------------------------------------ resampling
def test_resample(kin, samples, s_star, scaling, bench):
    t_s = DEXTAR.t_s
    tr = resample(scaling, samples, t_s, t_rest=0.05, t_rest_end=0.02)
    k = tr.k_star
    np.testing.assert_allclose(np.diff(tr.t), t_s, rtol=0, atol=1e-15)
    assert abs(tr.sd[k] - V_SING) <= 1e-6 and tr.s[k] == s_star
    np.testing.assert_array_equal(tr.x[k], samples.x[scaling.k_star])
    np.testing.assert_allclose(tr.x[k], bench.point, atol=1e-15)
    assert tr.t_start >= 0.05 and tr.t_start < 0.05 + t_s
    assert np.all(np.abs(tr.xdd) <= np.asarray(LIMITS.a_max) * (1 + 1e-6))
    assert np.max(np.abs(tr.xdd[k])) == 0.0  # criterion: s'' = 0 at the crossing
    # Rest before and after; exact IK at every sample; assembly mode changes at k.
    assert tr.sd[0] == 0.0 and tr.sd[-1] == 0.0 and tr.s[-1] == samples.length
    assert np.max(np.abs(kin.f_batch(tr.x, tr.q, samples.xi))) < 1e-12
    modes = kin.mode_batch(tr.x, tr.q, samples.xi)
    assert modes[k] == 0 and np.all(modes[:k] == 1) and np.all(modes[k + 1:] == -1)
    # Joint bounds hold between nodes up to the O(ds^2) curvature of q(s).
    assert np.max(np.abs(tr.qd)) <= 30.0 and np.max(np.abs(tr.qdd)) <= 3000.0 * 1.001
    # s(t) is consistent with sdot and sddot (exact piecewise quadratic).
    i = np.nonzero((tr.t > tr.t_start) & (tr.t < tr.t_start + scaling.total_time - t_s))[0]
    pred = tr.s[i] + tr.sd[i] * t_s + 0.5 * tr.sdd[i] * t_s**2
    assert np.max(np.abs(pred - tr.s[i + 1])) < 80.0 * t_s**2  # a jumps at most once per step


def test_resample_errors(samples, scaling):
    with pytest.raises(InputError):
        resample(scaling, samples, 0.0)
    with pytest.raises(InputError):
        resample(scaling, samples, 1e-3, t_rest=-1.0)


# ------------------------------------------------------------------ errors
def test_infeasible_and_bad_requests(samples, s_star, v_top):
    with pytest.raises(SimulationError, match=r"no feasible crossing at v_sing = 3 m/s .*max "
                                              r"feasible speed at s\* = 0.035 m is 2.36"):
        time_optimal_scaling(samples, LIMITS, 3.0, s_star)
    with pytest.raises(InputError, match="v_sing"):
        time_optimal_scaling(samples, LIMITS, 0.0, s_star)
    with pytest.raises(InputError, match="s_star"):
        time_optimal_scaling(samples, LIMITS, V_SING)
    with pytest.raises(InputError, match="not a grid node"):
        time_optimal_scaling(samples, LIMITS, V_SING, s_star + 0.3 * samples.ds)
    with pytest.raises(InputError, match="outside the path"):
        time_optimal_scaling(samples, LIMITS, V_SING, -0.01)
    with pytest.raises(InputError, match="interior"):
        time_optimal_scaling(samples, LIMITS, V_SING, 0.0)
    with pytest.raises(InputError, match="normal to the path"):
        time_optimal_scaling(samples, LIMITS, V_SING, s_star, criterion_direction=(1.0, 0.0))
    with pytest.raises(InputError):
        ScalingLimits(qd_max=-1.0)
    with pytest.raises(InputError, match="a_max"):  # shape checked against the path
        time_optimal_scaling(samples, ScalingLimits(a_max=(80.0, 80.0, 80.0)), V_SING, s_star)
    with pytest.raises(InputError, match="nodes"):
        bad = LinearPathConstraint(A=np.ones((3, 1)), B=np.ones((3, 1)), C=np.ones((3, 1)))
        time_optimal_scaling(samples, ScalingLimits(extra=(bad,)), V_SING, s_star)
    with pytest.raises(InputError):
        LinearPathConstraint(A=np.ones((3, 1)), B=np.ones((3, 2)), C=np.ones((3, 1)))
    with pytest.raises(InputError):
        time_optimal_scaling(samples, "limits", V_SING, s_star)
