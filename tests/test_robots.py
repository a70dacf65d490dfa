"""Tests of the robot descriptions, the registry and the kinematic model (DexTAR)."""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest

from crosscert.robots import DEXTAR, IRI_FIVE_BAR, ROBOTS, KinematicModel, Robot, available_robots, get_robot
from crosscert.robots.dextar import benchmark_crossing, distal_joints, elbows_out_ik, mode_by_cross_product, singular_y
from crosscert.robots.errors import InputError, ModelError, SimulationError, UnknownRobotError


def eq7_numpy(x, q, xi):
    """Independent numpy transcription of eq. (7) of the paper (the +- form)."""
    l11, l21, l12, l22, d, d1, d2 = xi
    f1 = (x[0] + d / 2 - l11 * math.cos(q[0] + d1)) ** 2 + (x[1] - l11 * math.sin(q[0] + d1)) ** 2 - l12**2
    f2 = (x[0] - d / 2 - l21 * math.cos(q[1] + d2)) ** 2 + (x[1] - l21 * math.sin(q[1] + d2)) ** 2 - l22**2
    return np.array([f1, f2])


def random_xi(rng) -> np.ndarray:
    return DEXTAR.xi_lo_array + (DEXTAR.xi_hi_array - DEXTAR.xi_lo_array) * rng.random(7)


def random_elbows_out_pose(rng, xi):
    """A pose around the benchmark region, reachable elbows out, with its joints."""
    while True:
        x = np.array([rng.uniform(-0.06, 0.06), rng.uniform(0.0, 0.15)])
        q = elbows_out_ik(x, xi)
        if np.all(np.isfinite(q)):
            return x, q


# ------------------------------------------------------------------ registry
def test_registry():
    assert available_robots() == ["3rpr", "dextar", "gough-stewart", "iri-five-bar"]
    assert ROBOTS["dextar"].robot is DEXTAR
    assert get_robot("dextar") is DEXTAR
    assert get_robot("  DexTAR ") is DEXTAR
    with pytest.raises(UnknownRobotError, match="dextar") as err:
        get_robot("delta")
    assert isinstance(err.value, InputError) and isinstance(err.value, KeyError)
    assert "delta" in str(err.value)


def test_dextar_data_in_si():
    r = DEXTAR
    assert r.n == 2 and r.m == 7
    assert r.param_names == ("l11", "l21", "l12", "l22", "d", "delta1", "delta2")
    np.testing.assert_allclose(r.xi_nominal, (0.09, 0.09, 0.09, 0.09, 0.118, 0.0, 0.0), rtol=0, atol=1e-15)
    np.testing.assert_allclose(r.xi_lo, (0.089832, 0.089929, 0.089899, 0.089877, 0.117843, -0.004, -0.004), atol=1e-15)
    np.testing.assert_allclose(r.xi_hi, (0.089995, 0.090115, 0.090050, 0.090084, 0.118107, 0.004, 0.004), atol=1e-15)
    assert r.a_max == (80.0, 80.0)
    assert r.eps_q == pytest.approx(math.pi / 34000, rel=1e-15)
    assert r.t_s == 1e-3 and r.mode_sign == 1.0
    assert r.xd0 == (0.1, 0.1)
    assert r.xi_in_box(r.xi_center)
    # Table I's design value of l11 lies just above its calibrated interval.
    assert not r.xi_in_box(r.xi_nominal)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.n = 3  # type: ignore[misc]


def _robot_kwargs(**over):
    kw = {f.name: getattr(DEXTAR, f.name) for f in dataclasses.fields(Robot)}
    kw.update(over)
    return kw


@pytest.mark.parametrize(
    "over",
    [
        {"xi_lo": DEXTAR.xi_lo[:6]},
        {"xi_lo": DEXTAR.xi_hi, "xi_hi": DEXTAR.xi_lo},
        {"xi_nominal": (90.0, 0.09, 0.09, 0.09, 0.118, 0.0, 0.0)},  # mm, not m
        {"q_lo": (0.0, 0.0), "q_hi": (0.0, 1.0)},
        {"x_bounds": ((0.1, -0.1), (-0.1, 0.1))},
        {"a_max": (80.0,)},
        {"a_max": (80.0, -1.0)},
        {"xd0": (0.1,)},
        {"xd0": (0.1, -0.1)},  # 0 is admissible: a run known to start at rest
        {"eps_q": 0.0},
        {"t_s": float("nan")},
        {"mode_sign": 0.5},
        {"n": 0},
        {"param_names": ("a", "a", "b", "c", "d", "e", "f")},
        {"loop_closure": None},
        {"joint_offsets": (5,)},
        {"joint_offsets": (5, 5)},
        {"joint_offsets": (7, None)},
    ],
)
def test_robot_validation(over):
    with pytest.raises(ModelError):
        Robot(**_robot_kwargs(**over))


def test_model_rejects_bad_loop_closures():
    def boom(x, q, xi):
        raise RuntimeError("nope")

    def wrong_shape(x, q, xi):
        return ca.vertcat(x[0] - q[0], x[1] - q[1], xi[0])

    def foreign(x, q, xi):
        return ca.vertcat(x[0] - ca.SX.sym("z"), x[1] - q[1] + q[0])

    def numeric(x, q, xi):
        return np.zeros(2)

    def singular(x, q, xi):
        return ca.vertcat(x[0] - q[0], x[0] + q[1])

    for fn in (boom, wrong_shape, foreign, numeric, singular):
        with pytest.raises(ModelError):
            KinematicModel(Robot(**_robot_kwargs(loop_closure=fn)))
    with pytest.raises(ModelError):
        KinematicModel("dextar")  # type: ignore[arg-type]


def test_model_is_immutable(kin):
    with pytest.raises(AttributeError):
        kin.f = None
    with pytest.raises(AttributeError):
        kin.new_attribute = 1
    assert kin.n == 2 and kin.m == 7
    assert kin.sx_jx.shape == (2, 2) and kin.sx_det.shape == (1, 1)
    assert kin.sx_x.shape == (2, 1) and kin.sx_xi.shape == (7, 1)


@pytest.mark.parametrize("robot", [DEXTAR, IRI_FIVE_BAR], ids=lambda r: r.name)
def test_declared_joint_offsets_enter_as_q_plus_xi(robot):
    """f(x, q + t e_i, xi - t e_j) == f(x, q, xi) for every declared offset (i, j)."""
    kin = KinematicModel(robot)
    rng = np.random.default_rng(21)
    lo, hi = robot.xi_lo_array, robot.xi_hi_array
    pairs = [(i, j) for i, j in enumerate(robot.joint_offsets or ()) if j is not None]
    assert pairs
    for _ in range(20):
        x = rng.uniform(robot.x_lo_array, robot.x_hi_array)
        q = rng.uniform(robot.q_lo_array, robot.q_hi_array)
        xi = lo + (hi - lo) * rng.random(lo.size)
        base = kin.f_batch(x, q, xi)
        for i, j in pairs:
            t = rng.uniform(-0.3, 0.3)
            q2, xi2 = q.copy(), xi.copy()
            q2[i] += t
            xi2[j] -= t
            np.testing.assert_allclose(kin.f_batch(x, q2, xi2), base, rtol=1e-9, atol=1e-15)


# --------------------------------------------------------------- kinematics
def test_f_matches_numpy_eq7(kin):
    rng = np.random.default_rng(11)
    for _ in range(50):
        x = rng.uniform(-0.15, 0.15, 2)
        q = rng.uniform(-4, 4, 2)
        xi = random_xi(rng)
        got = np.asarray(kin.f(x, q, xi)).ravel()
        np.testing.assert_allclose(got, eq7_numpy(x, q, xi), rtol=1e-13, atol=1e-17)


def test_batch_equals_pointwise(kin):
    rng = np.random.default_rng(12)
    X = rng.uniform(-0.1, 0.1, (7, 2))
    Q = rng.uniform(-3, 3, (7, 2))
    xi = random_xi(rng)
    F, JX, JQ, DET = (kin.f_batch(X, Q, xi), kin.jac_x_batch(X, Q, xi),
                      kin.jac_q_batch(X, Q, xi), kin.det_batch(X, Q, xi))
    for k in range(7):
        np.testing.assert_array_equal(F[k], np.asarray(kin.f(X[k], Q[k], xi)).ravel())
        np.testing.assert_array_equal(JX[k], np.asarray(kin.jac_x(X[k], Q[k], xi)))
        np.testing.assert_array_equal(JQ[k], np.asarray(kin.jac_q(X[k], Q[k], xi)))
        assert DET[k] == float(kin.det_jx(X[k], Q[k], xi))


def test_jacobians_match_central_differences(kin):
    rng = np.random.default_rng(13)
    h = 1e-6
    for _ in range(20):
        x = rng.uniform(-0.1, 0.1, 2)
        q = rng.uniform(-3, 3, 2)
        xi = random_xi(rng)
        jx = np.asarray(kin.jac_x(x, q, xi))
        jq = np.asarray(kin.jac_q(x, q, xi))
        for j in range(2):
            e = np.zeros(2)
            e[j] = h
            fdx = (eq7_numpy(x + e, q, xi) - eq7_numpy(x - e, q, xi)) / (2 * h)
            fdq = (eq7_numpy(x, q + e, xi) - eq7_numpy(x, q - e, xi)) / (2 * h)
            np.testing.assert_allclose(jx[:, j], fdx, atol=1e-9)
            np.testing.assert_allclose(jq[:, j], fdq, atol=1e-9)
        assert float(kin.det_jx(x, q, xi)) == pytest.approx(np.linalg.det(jx), rel=1e-12, abs=1e-20)
        assert float(kin.mode_value(x, q, xi)) == float(kin.det_jx(x, q, xi))  # mode_sign = +1


def test_jdot_term_is_time_derivative(kin):
    rng = np.random.default_rng(14)
    h = 1e-5
    for _ in range(10):
        x, q = rng.uniform(-0.1, 0.1, 2), rng.uniform(-3, 3, 2)
        xd, qd = rng.normal(size=2), rng.normal(size=2)
        xi = random_xi(rng)

        def g(t):
            xx, qq = x + t * xd, q + t * qd
            return np.asarray(kin.jac_x(xx, qq, xi)) @ xd + np.asarray(kin.jac_q(xx, qq, xi)) @ qd

        fd = (g(h) - g(-h)) / (2 * h)
        got = np.asarray(kin.jdot_term(x, q, xi, xd, qd)).ravel()
        np.testing.assert_allclose(got, fd, rtol=1e-6, atol=1e-9)


def test_ik_fk_round_trip(kin):
    rng = np.random.default_rng(15)
    worst_q = worst_x = 0.0
    for _ in range(40):
        xi = random_xi(rng)
        x, q_closed = random_elbows_out_pose(rng, xi)
        q = kin.ik(x, xi, q_closed + rng.uniform(-0.2, 0.2, 2))
        assert np.max(np.abs(kin.f_batch(x, q, xi))) < 1e-13
        worst_q = max(worst_q, np.max(np.abs(q - q_closed)))
        # The guess must be nearer to x than to the other assembly mode.
        x_back = kin.fk(q, xi, x + rng.uniform(-2e-4, 2e-4, 2))
        worst_x = max(worst_x, np.max(np.abs(x_back - x)))
    assert worst_q < 1e-11
    assert worst_x < 1e-11


def test_ik_and_fk_failures(kin):
    xi = DEXTAR.xi_nominal_array
    with pytest.raises(SimulationError, match="IK failed"):
        kin.ik([0.0, 0.5], xi, [1.9, 1.2])  # beyond the legs' reach
    with pytest.raises(SimulationError, match="FK failed"):
        kin.fk([math.pi, 0.0], xi, [0.0, 0.05])  # B1, B2 farther apart than l12 + l22
    with pytest.raises(ModelError):
        kin.ik([0.0, 0.1, 0.0], xi, [1.9, 1.2])


def test_ik_path_follows_the_branch(kin):
    xi = DEXTAR.xi_center
    X = np.stack([np.linspace(-0.03, 0.03, 61), np.linspace(0.13, 0.05, 61)], axis=1)
    Q = kin.ik_path(X, xi, elbows_out_ik(X[0], xi) + 0.1)
    np.testing.assert_allclose(Q, elbows_out_ik(X, xi), atol=1e-11)
    with pytest.raises(SimulationError, match="path point 2"):
        kin.ik_path(np.array([[0.0, 0.1], [0.0, 0.12], [0.0, 0.4]]), xi, elbows_out_ik(X[0], xi))


def test_fk_all_two_solutions_of_opposite_modes(kin):
    rng = np.random.default_rng(16)
    for E in ([0.0, 0.1], [0.01, 0.09], [-0.02, 0.06], [0.0, 0.0845]):
        xi = random_xi(rng)
        E = np.array(E)
        q = elbows_out_ik(E, xi)
        sols = kin.fk_all(q, xi)
        assert sols.shape == (2, 2)
        assert np.min(np.max(np.abs(sols - E), axis=1)) < 1e-11
        modes = [kin.mode(s, q, xi) for s in sols]
        assert sorted(modes) == [-1, 1]
        np.testing.assert_array_equal(modes, mode_by_cross_product(sols, np.tile(q, (2, 1)), xi))
        assert np.max(np.abs(kin.f_batch(sols, np.tile(q, (2, 1)), xi))) < 1e-13


def test_mode_convention_is_the_cross_product(kin):
    """mode = mode_sign * sign(det J_x) agrees with sign(cross(B2 - B1, E - B1))."""
    rng = np.random.default_rng(17)
    xs, qs = [], []
    xi = random_xi(rng)
    while len(xs) < 200:
        E = rng.uniform(DEXTAR.x_lo_array, DEXTAR.x_hi_array)
        q = elbows_out_ik(E, xi)
        if not np.all(np.isfinite(q)):
            continue
        # Flip a random subset of legs to their other branch: q_i1 -> 2 phi_i - q_i1.
        ax = np.array([-xi[4] / 2, xi[4] / 2])
        phi = np.arctan2(E[1], E[0] - ax)
        delta = xi[5:7]
        flip = rng.integers(0, 2, 2) == 1
        q = np.where(flip, 2 * phi - (q + delta) - delta, q)
        for sol in kin.fk_all(q, xi, grid=4):
            xs.append(sol)
            qs.append(q)
    X, Q = np.array(xs), np.array(qs)
    modes = kin.mode_batch(X, Q, xi)
    assert set(modes.tolist()) == {-1, 1}
    np.testing.assert_array_equal(modes, mode_by_cross_product(X, Q, xi))
    # Elbows out with E above the distal links (benchmark start) is mode +1.
    E = np.array([0.0, 0.11])
    assert kin.mode(E, elbows_out_ik(E), DEXTAR.xi_nominal) == 1


def test_det_changes_sign_across_the_benchmark_singularity(kin):
    xi = DEXTAR.xi_nominal_array
    y_s = singular_y()
    modes = []
    for y in (y_s + 1e-4, y_s, y_s - 1e-4):
        E = np.array([0.0, y])
        modes.append(kin.mode(E, elbows_out_ik(E, xi), xi))
    assert modes == [1, 0, -1]


def test_nominal_singular_point(kin):
    b = benchmark_crossing()
    # Distal links aligned along X: |B1 A1| = 90 mm with B1 = (-90 mm, y_s).
    assert b.point[1] == pytest.approx(math.sqrt(0.09**2 - 0.031**2), abs=1e-13)
    assert b.point[1] == pytest.approx(0.0845, abs=1e-4)
    np.testing.assert_array_equal(b.direction, [0.0, -1.0])
    b1, b2 = distal_joints(b.q_point, b.xi)
    np.testing.assert_allclose(b1[0], [-0.09, b.point[1]], atol=1e-12)
    np.testing.assert_allclose(b2[0], [0.09, b.point[1]], atol=1e-12)
    assert b1[0, 0] < -DEXTAR.xi_nominal[4] / 2 and b2[0, 0] > DEXTAR.xi_nominal[4] / 2  # elbows out
    assert kin.mode(b.point, kin.ik(b.point, b.xi, b.q_point), b.xi) == 0


def test_singular_y_for_true_geometries(kin):
    rng = np.random.default_rng(18)
    y_nom = singular_y()
    for _ in range(5):
        xi = random_xi(rng)
        y = singular_y(xi)
        assert abs(y - y_nom) < 1e-3
        for dy, want in ((1e-7, 1), (-1e-7, -1)):
            E = np.array([0.0, y + dy])
            assert kin.mode(E, elbows_out_ik(E, xi), xi) == want
    with pytest.raises(ModelError):
        singular_y(y_range=(0.12, 0.16))


def test_x_bounds_contain_every_reachable_pose(kin):
    rng = np.random.default_rng(19)
    lo, hi = DEXTAR.x_lo_array, DEXTAR.x_hi_array
    # Extreme reach: fully stretched legs, longest links, narrowest base.
    xi = DEXTAR.xi_hi_array.copy()
    xi[4] = DEXTAR.xi_lo[4]
    for _ in range(40):
        q = rng.uniform(-0.5 * np.pi, 1.5 * np.pi, 2)
        for E in kin.fk_all(q, xi, grid=5):
            assert np.all(E >= lo) and np.all(E <= hi)
    r_max = max(xi[0] + xi[2], xi[1] + xi[3])
    assert hi[0] >= r_max - xi[4] / 2 and -lo[0] >= r_max - xi[4] / 2
    assert hi[1] >= math.sqrt(r_max**2 - (xi[4] / 2) ** 2)
