"""Lumped-mass dynamics (robots.dynamics) and crossing generation with the dynamic criterion (planner.generate).

Benchmark task: the DexTAR crossing of Section IV (down the Y axis through
the Type 2 locus), from 60 mm above the crossing point to 60 mm below it, at
v_sing = 1.3 m/s.  Limits: qd_max = 30 rad/s, qdd_max = 3000 rad/s^2 (those
of tests/test_timescale.py) and the assumed torque limits of
DEXTAR_DYNAMICS (3 N m).  Every check below recomputes what it checks from
the returned samples (joint rates from the kinematics, torques from the
dynamics), so it does not trust the generator's own report.
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from crosscert.planner.certify.plan import certify_plan
from crosscert.planner.task import CrossingTask, PlannedTrajectory, PlanningBounds, crossing_on_segment
from crosscert.planner.generate import (
    CheckFailed,
    GeneratedTrajectory,
    GenerationLimits,
    NotConverged,
    generate_crossing,
)
from problems import interval_model, kinematics
from crosscert.robots import DEXTAR
from crosscert.robots.dextar import benchmark_crossing
from crosscert.robots.dextar import DEXTAR_DYNAMICS, dextar_mass_points
from crosscert.robots.dynamics import LumpedDynamics, criterion_residual, uncontrolled_direction
from crosscert.robots.errors import InputError, ModelError, SimulationError
from crosscert.verifier.tracker import Verdict

V_SING = 1.3  # m/s
LIMITS = GenerationLimits(qd_max=30.0, qdd_max=3000.0)
RTOL = 1e-6  # relative tolerance of every limit
M_E = DEXTAR_DYNAMICS.masses[DEXTAR_DYNAMICS.point_names.index("E")]  # kg, every mass moving with x


@pytest.fixture(scope="module")
def dyn():
    return LumpedDynamics(kinematics(), DEXTAR_DYNAMICS)


@pytest.fixture(scope="module")
def bench():
    return benchmark_crossing()


@pytest.fixture(scope="module")
def task(bench):
    return CrossingTask(bench.point - 0.06 * bench.direction, bench.point + 0.06 * bench.direction, bench.q_point)


@pytest.fixture(scope="module")
def generated(task):
    """Both objectives at 1.3 m/s (each ~1-2 s)."""
    kin = kinematics()
    return {obj: generate_crossing(kin, DEXTAR_DYNAMICS, task, V_SING, LIMITS, objective=obj)
            for obj in ("time", "jerk")}


# ------------------------------------------------------------------ dynamics
def test_model_is_validated_data():
    with pytest.raises(ModelError, match="masses"):
        dataclasses.replace(DEXTAR_DYNAMICS, masses=(1.0, -1.0, 1.0, 1.0, 1.0))
    with pytest.raises(ModelError, match="tau_max"):
        dataclasses.replace(DEXTAR_DYNAMICS, tau_max=(3.0,))
    with pytest.raises(ModelError, match="robot"):
        LumpedDynamics(kinematics(), dataclasses.replace(DEXTAR_DYNAMICS, robot_name="other"))
    with pytest.raises(ModelError, match="shape"):
        LumpedDynamics(kinematics(), dataclasses.replace(DEXTAR_DYNAMICS, positions=lambda x, q, xi: x))
    # a casadi.Function of (x, q, xi) is an acceptable position function
    k = kinematics()
    fun = ca.Function("pts", [k.sx_x, k.sx_q, k.sx_xi], [dextar_mass_points(k.sx_x, k.sx_q, k.sx_xi)])
    LumpedDynamics(k, dataclasses.replace(DEXTAR_DYNAMICS, positions=fun))


def test_lumped_criterion_is_acceleration_normal_to_the_uncontrolled_direction(dyn, bench):
    """With every distal mass at B_i or E, t_s^T w_x = m_E t_s . (xdd - g), whatever the velocity."""
    kin = kinematics()
    rng = np.random.default_rng(7)
    xi = DEXTAR.xi_nominal_array
    t_s = uncontrolled_direction(kin, bench.point, bench.q_point, xi)
    # nominal (symmetric) geometry: distal links aligned with X, uncontrolled motion along Y
    assert np.allclose(t_s, [0.0, 1.0], atol=1e-12)
    XD = rng.normal(0.0, 1.5, (20, 2))
    XDD = rng.normal(0.0, 60.0, (20, 2))
    X, Q = np.tile(bench.point, (20, 1)), np.tile(bench.q_point, (20, 1))
    res = dyn.criterion_residual(X, Q, XD, XDD, xi)
    assert np.allclose(res, M_E * XDD @ t_s, rtol=1e-12, atol=1e-12)
    assert np.allclose(criterion_residual(dyn, X, Q, XD, XDD, xi), res, rtol=0, atol=0)
    # in a vertical plane: the acceleration minus gravity
    g = np.array([0.0, -9.81])
    dyn_g = LumpedDynamics(kin, dataclasses.replace(DEXTAR_DYNAMICS, gravity=tuple(g)))
    assert np.allclose(dyn_g.criterion_residual(X, Q, XD, XDD, xi), M_E * (XDD - g) @ t_s, rtol=1e-12, atol=1e-12)

    # the reduction is specific to the lumping: a mass at mid-distal-link adds velocity terms
    def with_mid_distal(x, q, xi_):
        p = dextar_mass_points(x, q, xi_)
        return ca.horzcat(p, 0.5 * (p[:, 1] + p[:, 4]), 0.5 * (p[:, 3] + p[:, 4]))

    mid = dataclasses.replace(DEXTAR_DYNAMICS, point_names=DEXTAR_DYNAMICS.point_names + ("D1", "D2"),
                              masses=DEXTAR_DYNAMICS.masses + (0.02, 0.02), positions=with_mid_distal)
    res_mid = LumpedDynamics(kin, mid).criterion_residual(X, Q, XD, XDD, xi)
    assert np.max(np.abs(res_mid - M_E * XDD @ t_s)) > 1e-3


def test_inverse_dynamics_balance_the_energy(dyn, bench):
    """tau . qd = dE/dt, E from finite differences of the mass positions (no Jacobians)."""
    kin = kinematics()
    xi = DEXTAR.xi_nominal_array
    h = 1e-5
    t = np.arange(0.0, 0.02, h)
    y0 = bench.point[1] + 0.02  # stays in mode +1, away from the locus

    def path(tt):
        x = np.stack([0.01 * np.sin(30 * tt), y0 - 0.3 * tt + 0.005 * np.cos(20 * tt)], 1)
        xd = np.stack([0.3 * np.cos(30 * tt), -0.3 - 0.1 * np.sin(20 * tt)], 1)
        xdd = np.stack([-9.0 * np.sin(30 * tt), -2.0 * np.cos(20 * tt)], 1)
        return x, xd, xdd

    X, XD, XDD = path(t)
    Q = kin.ik_path(X, xi, bench.q_point)
    QD = kin.joint_velocity(X, Q, xi, XD)
    tau = dyn.torques(X, Q, XD, XDD, xi)
    pos = ca.Function("p", [kin.sx_x, kin.sx_q, kin.sx_xi], [dextar_mass_points(kin.sx_x, kin.sx_q, kin.sx_xi)])
    P = np.stack([np.asarray(pos(X[k], Q[k], xi)) for k in range(t.size)])  # (K, 2, 5)
    Pd = np.gradient(P, h, axis=0, edge_order=2)
    Qd_fd = np.gradient(Q, h, axis=0, edge_order=2)
    E = 0.5 * np.einsum("j,kdj->k", np.array(DEXTAR_DYNAMICS.masses), Pd**2) \
        + 0.5 * Qd_fd**2 @ np.array(DEXTAR_DYNAMICS.motor_inertia)
    dE = np.gradient(E, h, edge_order=2)
    power = np.einsum("ki,ki->k", tau, QD)
    inner = slice(5, -5)
    assert np.max(np.abs(dE[inner] - power[inner])) <= 1e-5 * np.max(np.abs(power))


def test_singular_torques_are_the_limit_of_the_regular_ones(dyn, bench):
    """A crossing meeting the criterion: eq. (1) tends to eq. (3) at the singular instant."""
    kin = kinematics()
    xi = DEXTAR.xi_nominal_array
    jerk = np.array([300.0, 2400.0])

    def motion(tt):  # through the singular point at t = 0 with yddot(0) = 0 (criterion), jerk `jerk`
        tt = np.atleast_1d(tt)[:, None]
        a0 = np.array([0.6, 0.0])
        v0 = np.array([0.0, -V_SING])
        return bench.point + v0 * tt + a0 * tt**2 / 2 + jerk * tt**3 / 6, v0 + a0 * tt + jerk * tt**2 / 2, \
            a0 + jerk * tt

    x0, xd0, xdd0 = (a[0] for a in motion(0.0))
    assert abs(dyn.criterion_residual(x0, bench.q_point, xd0, xdd0, xi)[0]) <= 1e-14
    assert dyn.is_singular(x0, bench.q_point, xi)[0]
    assert np.all(np.isnan(dyn.torques(x0, bench.q_point, xd0, xdd0, xi)))
    tau_s = dyn.singular_torques(x0, bench.q_point, xd0, xdd0, jerk, xi)
    for side in (1.0, -1.0):
        err = []
        for dt in (1e-4, 1e-5, 1e-6):  # regular torques at dt from the singular instant: error O(dt)
            ts = np.linspace(-3e-3 * side, side * dt, 50)
            X, XD, XDD = motion(ts)
            Q = kin.ik_path(X, xi, bench.q_point)
            err.append(np.max(np.abs(dyn.torques(X[-1], Q[-1], XD[-1], XDD[-1], xi)[0] - tau_s)))
        assert err[2] <= 3e-4 * np.max(np.abs(tau_s))
        assert 5.0 < err[0] / err[1] < 20.0 and 5.0 < err[1] / err[2] < 20.0


# ------------------------------------------------------------------ generation
def _check_trajectory(g: GeneratedTrajectory, task, dyn, limits=LIMITS):
    kin = kinematics()
    xi, k = g.xi_plan, g.k_sing
    t_s = DEXTAR.t_s
    assert np.allclose(np.diff(g.t), t_s, rtol=0, atol=1e-12)
    assert np.abs(kin.f_batch(g.x, g.q, xi)).max() <= 1e-10
    # rest to rest, start -> goal, modes +1 -> -1
    assert np.array_equal(g.x[0], task.start) and np.allclose(g.x[-1], task.goal, rtol=0, atol=1e-12)
    assert np.all(g.xd[[0, -1]] == 0.0) and np.all(g.xdd[[0, -1]] == 0.0)
    modes = kin.mode_batch(g.x, g.q, xi)
    assert modes[0] == 1 and modes[-1] == -1 and g.modes == (1, -1)
    assert np.all(modes[:k] == 1) and np.all(modes[k + 1:] == -1)
    # the crossing sample: on the crossing point, at v_sing
    assert np.array_equal(g.x[k], g.crossing_point)
    assert abs(kin.mode_batch(g.x[k:k + 1], g.q[k:k + 1], xi, rtol=1e-9)[0]) == 0
    assert abs(np.linalg.norm(g.xd[k]) - V_SING) <= 1e-6
    # the criterion, recomputed, and in its simple form (masses lumped at the ends)
    res = dyn.criterion_residual(g.x[k], g.q[k], g.xd[k], g.xdd[k], xi)[0]
    t_dir = uncontrolled_direction(kin, g.x[k], g.q[k], xi)
    assert abs(res) <= 1e-8 and abs(g.criterion_residual) <= 1e-8
    assert abs(M_E * g.xdd[k] @ t_dir) <= 1e-8
    # limits, recomputed from the samples
    qd = kin.joint_velocity(g.x, g.q, xi, g.xd)
    qdd = kin.joint_acceleration(g.x, g.q, xi, g.xd, qd, g.xdd)
    reg = np.arange(g.t.size) != k
    tau = np.empty_like(qd)
    tau[reg] = dyn.torques(g.x[reg], g.q[reg], g.xd[reg], g.xdd[reg], xi)
    tau[k] = dyn.singular_torques(g.x[k], g.q[k], g.xd[k], g.xdd[k], g.xddd[k], xi)
    assert np.allclose(qd, g.qd, rtol=0, atol=1e-9) and np.allclose(tau, g.tau, rtol=0, atol=1e-9)
    assert np.all(np.abs(qd) <= float(limits.qd_max) * (1 + RTOL))
    assert np.all(np.abs(qdd) <= float(limits.qdd_max) * (1 + RTOL))
    assert np.all(np.abs(tau) <= DEXTAR_DYNAMICS.tau_max_array * (1 + RTOL))
    if limits.a_max is not None:
        assert np.all(np.abs(g.xdd) <= float(limits.a_max) * (1 + RTOL))
    # the joints stay in the working range
    assert np.all(g.q >= DEXTAR.q_lo_array) and np.all(g.q <= DEXTAR.q_hi_array)


@pytest.mark.parametrize("objective", ["time", "jerk"])
def test_generated_crossing_meets_criterion_and_limits(generated, task, dyn, objective):
    g = generated[objective]
    assert g.objective == objective and g.solver_stats["status"] == "Solve_Succeeded"
    _check_trajectory(g, task, dyn)
    p = g.to_planned_trajectory()
    assert isinstance(p, PlannedTrajectory)
    assert p.k_sing == g.k_sing and p.v_sing == V_SING and np.array_equal(p.q, g.q)


def test_objectives_are_consistent(generated):
    gt, gj = generated["time"], generated["jerk"]
    # the torque limit is active in the minimal-time motion
    assert gt.peak_ratio["tau"] >= 0.97
    assert gt.objective_value == gt.duration and 0.09 < gt.duration < 0.12  # s (measured 0.1065)
    # "jerk" runs at 1.25 x the minimal time (same discretisation) with less jerk
    assert abs(gj.duration - 1.25 * gt.duration) <= 1e-6 * gt.duration
    h_t = np.diff(gt.node_t)
    assert gj.objective_value < float(np.sum(h_t * np.sum(gt.node_jerk**2, axis=1)))


def test_free_path_through_another_point_of_the_locus(task, dyn):
    """A crossing point 10 mm off the segment: the path bends, the criterion tilts with t_s."""
    kin = kinematics()
    shift = np.array([0.01, 0.0])
    aside = CrossingTask(task.start + shift, task.goal + shift, task.working_guess)
    c = crossing_on_segment(kin, aside, DEXTAR.xi_center)
    s_star, u = c.s_star, c.u
    point = aside.start + s_star * u
    g = generate_crossing(kin, DEXTAR_DYNAMICS, task, V_SING, LIMITS, crossing_point=point)
    _check_trajectory(g, task, dyn)
    assert np.allclose(g.crossing_point, point, rtol=0, atol=0)
    assert abs(g.criterion_direction[0]) > 0.01  # the uncontrolled direction is no longer Y
    assert abs(g.xdd[g.k_sing, 1]) > 0.1  # ... so yddot = 0 is not what the criterion asks


def test_limits_between_nodes_are_enforced_by_backing_off(task, dyn):
    """No back-off at the nodes: the torque overshoots between them, the generator re-solves tighter."""
    lim = GenerationLimits(qd_max=30.0, qdd_max=3000.0, margin=0.0)
    g = generate_crossing(kinematics(), DEXTAR_DYNAMICS, task, V_SING, lim, intervals=(20, 20))
    assert g.solver_stats["attempts"] >= 2 and g.solver_stats["margin"] > 0.0
    _check_trajectory(g, task, dyn, lim)


def test_generated_plan_with_a_max_is_certified(task, dyn):
    """With the tracker's acceleration bound as a limit the plan certifies at 1.3 m/s."""
    lim = GenerationLimits(qd_max=30.0, qdd_max=3000.0, a_max=60.0)
    g = generate_crossing(kinematics(), DEXTAR_DYNAMICS, task, V_SING, lim)
    _check_trajectory(g, task, dyn, lim)
    res = certify_plan(interval_model(), g.to_planned_trajectory(), PlanningBounds(), 1)
    assert res.verdict is Verdict.MODE_CHANGED


def test_infeasible_and_bad_requests(task, bench):
    kin = kinematics()
    with pytest.raises(NotConverged, match="trajectory generation did not converge") as failed:
        generate_crossing(kin, DEXTAR_DYNAMICS, task, 10.0, LIMITS)
    assert isinstance(failed.value, SimulationError) and failed.value.status == "Infeasible_Problem_Detected"
    same = CrossingTask(task.start, task.start + np.array([0.0, 0.01]), task.working_guess)
    with pytest.raises(InputError, match="same assembly mode"):
        generate_crossing(kin, DEXTAR_DYNAMICS, same, V_SING, LIMITS)
    # the nominal singular point is off the locus of the planning geometry (centre of [xi])
    with pytest.raises(InputError, match="not on the Type 2 locus"):
        generate_crossing(kin, DEXTAR_DYNAMICS, task, V_SING, LIMITS, crossing_point=bench.point)
    for kwargs in ({"objective": "energy"}, {"intervals": (1, 40)}, {"duration": -1.0}):
        with pytest.raises(InputError):
            generate_crossing(kin, DEXTAR_DYNAMICS, task, V_SING, LIMITS, **kwargs)
    with pytest.raises(InputError):
        generate_crossing(kin, DEXTAR_DYNAMICS, task, -1.0, LIMITS)
    with pytest.raises(InputError, match="qd_max"):
        generate_crossing(kin, DEXTAR_DYNAMICS, task, V_SING, GenerationLimits(qd_max=-1.0, qdd_max=1.0))
    with pytest.raises(InputError, match="robot"):
        generate_crossing(kin, dataclasses.replace(DEXTAR_DYNAMICS, robot_name="other"), task, V_SING, LIMITS)


def test_speeds_share_one_nlp_and_every_warm_solution_is_checked(task, dyn, monkeypatch):
    """Plans at several speeds solve one NLP (the speed is a parameter), each from the nearest speed's
    solution, and each is checked independently: with a check that fails, a warm-started plan fails."""
    import crosscert.planner.generate.crossing as crossing_mod
    import crosscert.planner.generate.nlp as nlp_mod

    kin = kinematics()
    nlp_mod._SOLVERS.clear()
    generate_crossing(kin, DEXTAR_DYNAMICS, task, 1.2, LIMITS)
    warm = generate_crossing(kin, DEXTAR_DYNAMICS, task, V_SING, LIMITS)
    assert len(nlp_mod._SOLVERS) == 1  # one solver for both speeds
    _check_trajectory(warm, task, dyn)  # at V_SING, within every limit

    def failing_check(*args, **kwargs):
        raise CheckFailed("test", "the check of this test fails every plan")

    monkeypatch.setattr(crossing_mod, "check_plan", failing_check)
    with pytest.raises(CheckFailed, match="fails every plan"):
        generate_crossing(kin, DEXTAR_DYNAMICS, task, 1.25, LIMITS)
