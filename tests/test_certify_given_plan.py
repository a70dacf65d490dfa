"""``certify --plan FILE`` / ``certify_trajectory``: a user's own planned trajectory certified before it runs."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

import problems
from crosscert.planner import PlanningBounds
from crosscert.planner.certify.plan import certify_speed
from crosscert.planner.certify.trajectory import certify_trajectory, plan_from_trajectory, read_plan
from crosscert.planner.cli import main
from crosscert.planner.plan import plan_crossing
from crosscert.robots import DEXTAR
from crosscert.robots.errors import InputError
from crosscert.verifier.settings import Verdict
from crosscert.verifier.trajectory import Trajectory
from crosscert.verifier.trajfile import write_trajectory

#: A certified speed under the robot's a_max on the DexTAR benchmark task (v_min 1.026 m/s there).
V_CERTIFIED = 1.1


@pytest.fixture(scope="module")
def planned(kin, task):
    """The benchmark task planned at :data:`V_CERTIFIED` (what ``crosscert plan --v-sing 1.1`` computes)."""
    return plan_crossing(kin, task, V_CERTIFIED, PlanningBounds())


@pytest.fixture(scope="module")
def plan_file(tmp_path_factory, planned):
    path = tmp_path_factory.mktemp("plan") / "plan.csv"
    write_trajectory(path, planned.t, planned.q, x=planned.x)
    return path


def _write(path, t, q, x=None):
    write_trajectory(path, t, q, x=x)
    return path


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def test_the_given_plan_gets_the_tasks_certificate_bit_for_bit(kin, imodel, task, planned, plan_file):
    """The file of a plan certify makes itself: the same verdict and the same forward boxes as certify's own run."""
    own = certify_speed(kin, imodel, task, PlanningBounds(), V_CERTIFIED)
    cert = certify_trajectory(DEXTAR, plan_file, monte_carlo_runs=0, kin=kin, imodel=imodel)
    assert own.verdict is Verdict.MODE_CHANGED and cert.verdict is own.verdict
    assert cert.v_min == pytest.approx(V_CERTIFIED, rel=1e-9)
    assert cert.execution.kind.value == "cartesian"
    for name in ("x_lo", "x_hi", "xd_lo", "xd_hi"):
        assert np.array_equal(getattr(cert.enclosures, name), getattr(own.forward, name)), name
    assert cert.a_max_used.values == tuple(DEXTAR.a_max)
    assert cert.plan_source.sha256 == hashlib.sha256(plan_file.read_bytes()).hexdigest()
    assert cert.trajectory.k_sing in (planned.k_sing - 1, planned.k_sing, planned.k_sing + 1)


def test_joints_only_need_the_initial_mode_and_are_certified_for_joint_executions(kin, planned, tmp_path):
    path = _write(tmp_path / "q.csv", planned.t, planned.q)
    traj, _digest = read_plan(path, DEXTAR)
    with pytest.raises(InputError, match="joints only: state its initial assembly mode"):
        plan_from_trajectory(kin, traj)
    m0 = int(kin.mode(planned.x[0], planned.q[0], planned.xi_plan))
    plan, source = plan_from_trajectory(kin, traj, initial_mode=m0)
    # the forward-kinematics continuation follows the planned path through the locus
    assert np.max(np.abs(plan.x - planned.x)) < 1e-6 and source.poses == "forward kinematics"
    with pytest.raises(InputError, match="contradicts the given poses"):
        plan_from_trajectory(kin, Trajectory(t=planned.t, q=planned.q, t_s=planned.t_s, x=planned.x),
                             initial_mode=-m0)
    with pytest.raises(InputError, match="no path for 'cartesian' executions"):
        certify_trajectory(DEXTAR, path, initial_mode=m0, execution="cartesian", monte_carlo_runs=0, kin=kin)


def test_cli_certifies_a_plan_file_and_reports_its_source(plan_file, tmp_path, capsys):
    out = tmp_path / "c"
    assert main(["certify", "--plan", str(plan_file), "--monte-carlo", "2", "--no-progress", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"your plan ({V_CERTIFIED:.3f} m/s at the singularity): certified mode-changed")
    assert "a_max used: axis 1: 80 m/s^2 (robot a_max); axis 2: 80 m/s^2 (robot a_max)" in text
    report = json.loads((out / "certificate.json").read_text())
    assert report["schema"] == "crosscert-certificate/4" and report["verdict"] == "mode-changed"
    assert report["plan"]["sha256"] == hashlib.sha256(plan_file.read_bytes()).hexdigest()
    assert report["plan"]["poses"] == "given" and report["task"] is None
    assert report["execution"]["kind"] == "cartesian" and report["monte_carlo"]["runs"] == 2
    assert report["refutation_search"] is None  # certified: nothing to refute
    assert (out / "certificate_dextar_plan.png").is_file()


def _bad_plans(planned, tmp_path):
    t, q, x = planned.t, planned.q.copy(), planned.x
    k = planned.k_sing
    out_of_range = q.copy()
    out_of_range[50, 0] = DEXTAR.q_hi[0] + 0.1
    moved = x.copy()
    moved[:, 1] += 0.01
    uneven = t.copy()
    uneven[40:] += 0.0004
    return {
        "never crosses": (_write(tmp_path / "short.csv", t[:k - 20], q[:k - 20], x[:k - 20]),
                          "never crosses a Type 2 singularity"),
        "out of range": (_write(tmp_path / "range.csv", t, out_of_range), "sample 50 leaves the robot's joint range"),
        "not at rest": (_write(tmp_path / "moving.csv", t[: len(t) - 40], q[40:], x[40:]),
                        "does not start at rest.*state the initial speed"),
        "uneven": (_write(tmp_path / "uneven.csv", uneven, q, x), "step|uneven|sampling"),
        "other poses": (_write(tmp_path / "poses.csv", t, q, moved), "do not close the loop"),
    }


@pytest.mark.parametrize("case", ["never crosses", "out of range", "not at rest", "uneven", "other poses"])
def test_bad_plans_get_one_line_and_exit_2_with_nothing_written(case, planned, tmp_path, capsys):
    path, message = _bad_plans(planned, tmp_path)[case]
    out = tmp_path / "c"
    argv = ["certify", "--plan", str(path), "--monte-carlo", "0", "--no-progress", "--out", str(out)]
    if case == "out of range":
        argv += ["--initial-mode", "1"]
    assert main(argv) == 2
    err = _one_line(capsys)
    assert __import__("re").search(message, err), err
    assert not out.exists()


def test_a_stated_initial_speed_admits_a_plan_that_starts_moving(kin, planned, tmp_path):
    t, q, x = planned.t, planned.q, planned.x
    traj = Trajectory(t=t[: len(t) - 40], q=q[40:], t_s=planned.t_s, x=x[40:])
    with pytest.raises(InputError, match="does not start at rest"):
        plan_from_trajectory(kin, traj)
    plan, _ = plan_from_trajectory(kin, traj, xd0=(1.5, 1.5))
    assert plan.k_sing < planned.k_sing


def test_plan_options_are_checked_before_any_work(plan_file, tmp_path, capsys):
    out = tmp_path / "c"
    assert main(["certify", "--plan", str(plan_file), "--start", "0,0.1", "--out", str(out)]) == 2
    assert "--plan certifies the given trajectory: --start" in _one_line(capsys)
    assert main(["certify", "--plan", str(tmp_path / "missing.csv"), "--out", str(out)]) == 2
    assert "is not a readable file" in _one_line(capsys)
    assert main(["certify", "--initial-mode", "1", "--out", str(out)]) == 2
    assert "use them with --plan" in _one_line(capsys)
    assert main(["certify", "--retime", "--out", str(out)]) == 2
    assert "--retime are about a given plan" in _one_line(capsys)
    assert not out.exists()


def test_a_plan_the_robot_cannot_execute_is_refused(kin, planned):
    """Poses accelerating beyond the robot's a_max: no execution of the plan exists under the robot's bound."""
    t = planned.t * 0.5  # the same path twice as fast: four times the acceleration
    traj = Trajectory(t=t, q=planned.q, t_s=planned.t_s * 0.5, x=planned.x)
    plan, _ = plan_from_trajectory(kin, traj)
    with pytest.raises(InputError, match="the robot's a_max = 80 m/s\\^2 is below the planned peak"):
        certify_trajectory(DEXTAR, plan, monte_carlo_runs=0, kin=kin, imodel=problems.interval_model())


def test_monte_carlo_of_a_plan_that_starts_moving_assumes_the_stated_initial_speed(kin, imodel, planned):
    """The Monte Carlo executions of a given plan that starts at 0.73 m/s are tracked from the stated ``xd0``:
    under the robot's own 0.1 m/s their true speed lay outside the initial box (every execution a containment
    failure, and ``inconsistent``) while the certificate, under the stated bound, was ``mode-changed``."""
    cut = 40
    t, q, x = planned.t, planned.q, planned.x
    traj = Trajectory(t=t[: len(t) - cut], q=q[cut:], t_s=planned.t_s, x=x[cut:])
    bounds = PlanningBounds(xd0=(1.0, 1.0))
    cert = certify_trajectory(DEXTAR, traj, bounds, monte_carlo_runs=5, refute_plan=False, kin=kin, imodel=imodel)
    assert cert.verdict is Verdict.MODE_CHANGED
    plan = cert.trajectory
    v0 = np.abs(plan.xd[0])
    assert np.any(v0 > np.asarray(DEXTAR.xd0)) and np.all(v0 <= 1.0)  # the truth starts outside the robot's box
    assert np.array_equal(cert.bounds.tracker_settings().xd0, [1.0, 1.0])
    mc = cert.monte_carlo
    # the truth (the plan's poses and velocities, from the first sample on) lies in every box of every execution
    assert mc.containment_failures == () and mc.wrong_verdicts == ()
    assert mc.detected_in_class == mc.in_class == 5
