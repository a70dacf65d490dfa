"""The Gough–Stewart's planned crossing (docs/examples/gough_stewart_crossing.py and .csv) through ``certify --plan``.

The shipped CSV is what the script writes; the plan crosses the locus at ``yaw = pi/2`` once, within the
robot's ranges and ``a_max``.  Through the command line, the robot file with a ten times narrower
calibration box (docs/examples/gough_stewart_calibrated.py) certifies it ``mode-changed``: about 130
CPU-s with two Monte Carlo executions (290 s wall on 2 cores shared with other jobs), under the
``slow`` marker.  The shipped robot's box leaves it ``unknown`` (docs/robots.md); that run (about two
CPU-minutes) is not repeated here.
"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

from crosscert.planner.certify.trajectory import plan_from_trajectory, read_plan
from crosscert.planner.cli import main
from crosscert.robots import KinematicModel, get_robot
from crosscert.robots.gough_stewart import mode_by_plucker

EXAMPLES = Path(__file__).resolve().parents[1] / "docs" / "examples"
CSV = EXAMPLES / "gough_stewart_crossing.csv"
CALIBRATED = EXAMPLES / "gough_stewart_calibrated.py"


def _script():
    spec = importlib.util.spec_from_file_location("gough_stewart_crossing", EXAMPLES / "gough_stewart_crossing.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_shipped_plan_is_what_the_script_writes(tmp_path):
    out = tmp_path / "plan.csv"
    assert _script().main(["-o", str(out)]) == 0
    written, shipped = (np.loadtxt(f, delimiter=",", skiprows=1) for f in (out, CSV))
    assert written.shape == shipped.shape == (367, 13)
    assert np.allclose(written, shipped, rtol=0.0, atol=1e-12)  # the same plan (up to the platform's libm)
    assert CSV.stat().st_size < 200_000


def test_the_shipped_plan_crosses_the_locus_once_at_a_quarter_turn():
    robot = get_robot("gough-stewart")
    traj, _digest = read_plan(CSV, robot)
    plan, source = plan_from_trajectory(KinematicModel(robot), traj, name=str(CSV))
    assert source.poses == "given" and len(plan.t) == 367
    k = plan.k_sing
    assert abs(plan.x[k, 3] - math.pi / 2) < 1e-3
    assert np.ptp(plan.x, axis=0).min() > 0.03  # a 6-DOF motion: every pose coordinate moves
    modes = mode_by_plucker(plan.x)
    assert modes[0] == -1 and modes[-1] == 1 and np.count_nonzero(np.diff(modes)) == 1
    assert np.all(np.abs(plan.xdd[1:-1]) <= np.array(robot.a_max))
    assert abs(plan.v_sing - 0.5) < 1e-6  # the translational speed at the singularity, m/s
    assert 6.9 < plan.xd[k, 3] < 7.0  # the yaw rate there, rad/s
    # the last joints also reach a mode -1 pose inside x_bounds: the final readings alone do not decide the mode
    kin = KinematicModel(robot)
    other = kin.fk(plan.q[-1], robot.xi_center, np.array([0.04, 0.03, 0.98, 1.0, 0.03, -0.02]))
    assert kin.mode(other, plan.q[-1], robot.xi_center) == -1
    assert np.all(other >= robot.x_lo_array) and np.all(other <= robot.x_hi_array)


@pytest.mark.slow
def test_slow_the_calibrated_robot_certifies_the_plan_through_the_cli(tmp_path, capsys):
    out = tmp_path / "c"
    argv = ["certify", "--robot", str(CALIBRATED), "--plan", str(CSV), "--monte-carlo", "2", "--no-progress",
            "--out", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert text.startswith("your plan (0.500 m/s at the singularity): certified mode-changed"), text
    report = json.loads((out / "certificate.json").read_text())
    assert report["verdict"] == "mode-changed" and report["execution"]["kind"] == "cartesian"
    assert report["plan"]["samples"] == 367 and report["plan"]["poses"] == "given"
    mc = report["monte_carlo"]
    assert mc["runs"] == 2 and mc["containment_failures"] == [] and mc["wrong_verdicts"] == []
