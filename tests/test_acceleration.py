"""The acceleration assumption: one bound per pose axis, in its own unit, with a stated source (issue 23)."""

import dataclasses
import json
import re
import types

import numpy as np
import pytest

from crosscert.planner import PlanningBounds
from crosscert.planner.acceleration import AccelerationAssumption, AccelerationSource, AxisAcceleration, acceleration_assumption
from crosscert.planner.cli import main
from crosscert.robots import DEXTAR, GOUGH_STEWART, RPR3, PoseUnit
from crosscert.robots.errors import CrosscertError, InputError, ModelError

SRC = AccelerationSource


def _plan(*peaks):
    """A stand-in plan whose axes peak at ``peaks`` (only ``xdd`` is read), each in its axis' unit per s^2."""
    xdd = np.zeros((5, len(peaks)))
    xdd[2] = peaks
    xdd[3] = -0.5 * np.asarray(peaks)
    return types.SimpleNamespace(xdd=xdd)


def _resolved(robot, **kw):
    return PlanningBounds(**kw).resolve(robot)


def test_robots_declare_the_unit_of_each_pose_axis():
    assert DEXTAR.pose_units == (PoseUnit.METRE, PoseUnit.METRE) and not DEXTAR.mixed_units
    assert RPR3.acceleration_units == ("m/s^2", "m/s^2", "rad/s^2") and RPR3.mixed_units
    assert RPR3.velocity_units == ("m/s", "m/s", "rad/s")
    assert GOUGH_STEWART.acceleration_units == ("m/s^2",) * 3 + ("rad/s^2",) * 3
    # no shipped robot declares a tracking margin (none has a stated reason for one)
    assert all(r.tracking_a_margin is None for r in (DEXTAR, RPR3, GOUGH_STEWART))


def test_by_default_every_axis_takes_the_robots_physical_a_max():
    """No margin asked for, none declared: the robot's a_max on every axis, whatever the plan's peaks."""
    for robot, peaks in ((RPR3, (66.0, 0.0, 150.0)), (DEXTAR, (6.0, 66.0))):
        a = acceleration_assumption(_plan(*peaks), _resolved(robot), robot)
        assert a.sources == (SRC.ROBOT_A_MAX,) * robot.n
        assert a.values == tuple(robot.a_max)
        assert [x.unit for x in a.axes] == list(robot.acceleration_units)


def test_a_plan_above_the_robots_a_max_is_refused():
    """No execution of such a plan exists under the robot's bound: certifying it would assume the impossible."""
    with pytest.raises(InputError, match=r"axis 2: the robot's a_max = 80 m/s\^2 is below the planned peak 81 m/s\^2"):
        acceleration_assumption(_plan(6.0, 81.0), _resolved(DEXTAR), DEXTAR)
    with pytest.raises(InputError, match="the robot's a_max"):
        acceleration_assumption(_plan(6.0, 81.0), _resolved(DEXTAR, a_margin=0.1), DEXTAR)


def test_no_axis_bound_comes_from_another_axis_of_another_unit():
    """The 3-RPR's pure translation, a margin asked for: the rotation axis' bound is the robot's, whatever the
    translation peak (10 % of a m/s^2 peak is no rad/s^2 bound)."""
    b = _resolved(RPR3, a_margin=0.1)
    for peak in (6.6, 66.0):
        a = acceleration_assumption(_plan(peak, 0.0, 0.0), b, RPR3)
        assert a.sources == (SRC.PLAN_PEAK, SRC.ROBOT_A_MAX, SRC.ROBOT_A_MAX)
        assert a.values == pytest.approx((1.1 * peak, 80.0, 200.0))
        assert [x.unit for x in a.axes] == ["m/s^2", "m/s^2", "rad/s^2"]
    # the same on a rotation-only plan: the translation axes do not get 10 % of a rad/s^2 peak
    a = acceleration_assumption(_plan(0.0, 0.0, 150.0), b, RPR3)
    assert a.values == pytest.approx((80.0, 80.0, 165.0))
    assert a.sources == (SRC.ROBOT_A_MAX, SRC.ROBOT_A_MAX, SRC.PLAN_PEAK)
    # the margin never lifts a bound above the robot's physical one
    a = acceleration_assumption(_plan(75.0, 0.0, 0.0), b, RPR3)
    assert a.values == (80.0, 80.0, 200.0) and a.sources[0] is SRC.PLAN_PEAK


def test_a_declared_tracking_margin_bounds_each_axis_by_the_planned_peak_plus_the_margin():
    """``|x''_executed - x''_planned| <= margin`` gives ``|x''_executed| <= peak + margin``, never above a_max."""
    robot = dataclasses.replace(RPR3, tracking_a_margin=(5.0, 4.0, 30.0))
    a = acceleration_assumption(_plan(66.0, 2.0, 0.0), _resolved(robot), robot)
    assert a.sources == (SRC.TRACKING_MARGIN,) * 3
    assert a.values == pytest.approx((71.0, 6.0, 30.0))
    assert a.describe() == ("axis 1: 71 m/s^2 (plan peak + robot tracking margin); axis 2: 6 m/s^2 (plan peak + "
                            "robot tracking margin); axis 3: 30 rad/s^2 (plan peak + robot tracking margin)")
    a = acceleration_assumption(_plan(78.0, 2.0, 0.0), _resolved(robot), robot)
    assert a.values[0] == 80.0  # 78 + 5 capped by the physical bound
    # an asked-for relative margin takes precedence on the axes the plan accelerates
    a = acceleration_assumption(_plan(66.0, 2.0, 0.0), _resolved(robot, a_margin=0.1), robot)
    assert a.sources == (SRC.PLAN_PEAK, SRC.PLAN_PEAK, SRC.TRACKING_MARGIN)
    assert a.values == pytest.approx((72.6, 2.2, 30.0))


def test_a_margin_and_a_max_together_are_refused():
    with pytest.raises(InputError, match="a_margin and a_max both"):
        PlanningBounds(a_max=80.0, a_margin=0.1)


def test_given_bounds_are_named_given_and_checked_against_the_plan():
    a = acceleration_assumption(_plan(66.0, 0.0, 0.0), _resolved(RPR3, a_max=(70.0, 70.0, 100.0)), RPR3)
    assert a.sources == (SRC.GIVEN,) * 3 and a.values == (70.0, 70.0, 100.0)
    with pytest.raises(InputError, match=r"axis 1: a_max = 60 m/s\^2 is below the planned peak 66 m/s\^2"):
        acceleration_assumption(_plan(66.0, 0.0, 0.0), _resolved(RPR3, a_max=(60.0, 70.0, 100.0)), RPR3)


def test_one_number_cannot_bound_axes_of_different_units():
    with pytest.raises(InputError, match=r"one number.*\(m/s\^2, m/s\^2, rad/s\^2\).*a_max = \(80, 80, 200\)"):
        _resolved(RPR3, a_max=80.0)
    with pytest.raises(InputError, match="3 entries.*one bound per pose axis of robot 3rpr"):
        _resolved(RPR3, a_max=(80.0, 200.0))
    assert _resolved(DEXTAR, a_max=80.0).a_max_given == (80.0, 80.0)  # one unit: one number is fine


def test_widest_of_a_batch_compares_each_axis_with_itself_only():
    m, r = "m/s^2", "rad/s^2"
    one = AccelerationAssumption((AxisAcceleration(66.0, m, SRC.PLAN_PEAK), AxisAcceleration(200.0, r, SRC.ROBOT_A_MAX)))
    two = AccelerationAssumption((AxisAcceleration(70.0, m, SRC.PLAN_PEAK), AxisAcceleration(200.0, r, SRC.ROBOT_A_MAX)))
    assert AccelerationAssumption.widest([one, two]).values == (70.0, 200.0)
    bad = AccelerationAssumption((AxisAcceleration(66.0, m, SRC.PLAN_PEAK), AxisAcceleration(1.0, m, SRC.GIVEN)))
    with pytest.raises(InputError, match="different units"):
        AccelerationAssumption.widest([one, bad])


@pytest.mark.parametrize("over, message", [
    ({"pose_units": ("m",)}, "one unit per pose axis"),
    ({"pose_units": ("m", "deg")}, r"pose_units\[1\] = 'deg' is not a pose unit"),
    ({"pose_units": "mm"}, "must be a tuple of units"),
    ({"tracking_a_margin": (5.0, 90.0)}, r"tracking_a_margin\[1\] = 90 m/s\^2 must be positive and at most a_max"),
    ({"tracking_a_margin": (5.0, 0.0)}, "must be positive"),
    ({"tracking_a_margin": (5.0,)}, "tracking_a_margin must have 2 entries"),
])
def test_robot_unit_and_margin_errors_are_model_errors(over, message):
    with pytest.raises(ModelError, match=message) as err:
        dataclasses.replace(DEXTAR, **over)
    assert isinstance(err.value, CrosscertError)


def _one_line_error(capsys):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    return err


@pytest.mark.parametrize("argv, message", [
    (["--robot", "3rpr", "--a-max", "80"], "give one per axis, e.g. --a-max 80,80,200"),
    (["--robot", "3rpr", "--a-max", "80,200"], "--a-max takes 1 or 3 comma-separated bounds"),
    (["--robot", "3rpr", "--a-max", "80,80,0"], r"--a-max \(axis 3\) = 0 rad/s\^2 is out of range"),
])
def test_cli_a_max_per_axis_errors(argv, message, tmp_path, capsys):
    assert main(["certify", *argv, "--out", str(tmp_path / "c"), "--no-progress"]) == 2
    err = _one_line_error(capsys)
    assert re.search(message, err), err


def test_certificate_json_of_the_3rpr_names_units_sources_and_the_robot_a_max_run(tmp_path, capsys):
    """``certify --robot 3rpr --a-margin 0.1``, coarse: every axis' bound with its unit and source, and v_min at
    the robot's a_max beside it."""
    out = tmp_path / "c"
    argv = ["certify", "--robot", "3rpr", "--a-margin", "0.1", "--tol", "0.25", "--monte-carlo", "0", "--no-refute",
            "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert ("a_max used: axis 1: 66 m/s^2 (plan peak + margin); axis 2: 80 m/s^2 (robot a_max); "
            "axis 3: 200 rad/s^2 (robot a_max)") in text
    assert "at the robot's a_max (80 m/s^2, 80 m/s^2, 200 rad/s^2): minimal certified v_sing" in text
    report = json.loads((out / "certificate.json").read_text())
    assert report["schema"] == "crosscert-certificate/4"
    assert report["acceleration_units"] == ["m/s^2", "m/s^2", "rad/s^2"]
    # prismatic legs: the joint quantities (eps_q, the execution class) are in metres, and say so
    assert report["joint_units"] == ["m", "m", "m"] and report["pose_units"] == ["m", "m", "rad"]
    assert report["bounds"]["eps_q"] == 5e-6 and "eps_q_rad" not in report["bounds"]
    assert report["bounds"]["a_margin"] == 0.1
    assert report["a_max_used"] == [
        {"value": pytest.approx(66.0), "unit": "m/s^2", "source": "plan peak + margin"},
        {"value": 80.0, "unit": "m/s^2", "source": "robot a_max"},
        {"value": 200.0, "unit": "rad/s^2", "source": "robot a_max"},
    ]
    at = report["at_robot_a_max"]
    assert at["outcome"] == "computed" and [x["value"] for x in at["a_max"]] == [80.0, 80.0, 200.0]
    assert report["v_min_at_robot_a_max_mps"] == at["v_min_mps"] is not None
    assert report["v_min_at_robot_a_max_mps"] >= report["v_min_mps"]  # the run starts at the default's v_min


def test_the_default_certificate_is_the_robots_a_max_and_runs_once(tmp_path, capsys):
    """No --a-max, no --a-margin: the robot's a_max on every axis, so no second certification."""
    out = tmp_path / "c"
    argv = ["certify", "--robot", "3rpr", "--tol", "0.25", "--monte-carlo", "0", "--no-refute", "--no-progress",
            "--out", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert ("a_max used: axis 1: 80 m/s^2 (robot a_max); axis 2: 80 m/s^2 (robot a_max); "
            "axis 3: 200 rad/s^2 (robot a_max)") in text
    report = json.loads((out / "certificate.json").read_text())
    assert report["bounds"]["a_margin"] is None
    assert report["at_robot_a_max"]["outcome"] == "coincides"


def test_cli_refuses_a_margin_with_a_max(tmp_path, capsys):
    assert main(["certify", "--a-max", "80", "--a-margin", "0.1", "--out", str(tmp_path / "c"), "--no-progress"]) == 2
    assert "--a-margin and --a-max both" in _one_line_error(capsys)
    assert not (tmp_path / "c").exists()


def test_given_a_max_is_stated_as_given_and_the_robot_run_skipped_when_they_coincide(tmp_path, capsys):
    out = tmp_path / "c"
    argv = ["certify", "--robot", "3rpr", "--a-max", "80,80,200", "--tol", "0.25", "--monte-carlo", "0",
            "--no-refute", "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "the same bounds, the same certificate" in text
    report = json.loads((out / "certificate.json").read_text())
    assert [x["source"] for x in report["a_max_used"]] == ["given"] * 3
    assert report["bounds"]["a_max"] == [{"value": 80.0, "unit": "m/s^2"}, {"value": 80.0, "unit": "m/s^2"},
                                         {"value": 200.0, "unit": "rad/s^2"}]
    assert report["at_robot_a_max"]["outcome"] == "coincides"
    assert report["v_min_at_robot_a_max_mps"] is None


def test_check_refuses_one_a_max_for_axes_of_different_units(tmp_path, capsys):
    csv = tmp_path / "t.csv"
    csv.write_text("t,q1,q2,q3\n0,0.1,0.1,0.1\n0.001,0.1,0.1,0.1\n")
    assert main(["check", str(csv), "--robot", "3rpr", "--initial-mode", "1", "--a-max", "80"]) == 2
    err = _one_line_error(capsys)
    assert "axes are in m, m, rad: omit --a-max to use the robot's per-axis a_max (80, 80, 200)" in err, err


def test_bounds_resolve_once_per_robot_and_refuse_another():
    """Resolving takes the robot's defaults (a variant of the same name: the variant's); bounds resolved for
    one robot are read as they are, never bound again, and refused for another robot."""
    from dataclasses import replace

    from crosscert.planner.task import PlanningBounds, resolved
    from crosscert.robots import DEXTAR

    variant = replace(DEXTAR, eps_q=2 * DEXTAR.eps_q, t_s=2 * DEXTAR.t_s)
    b = PlanningBounds().resolve(DEXTAR)
    assert (b.eps_q, b.t_s) == (DEXTAR.eps_q, DEXTAR.t_s) and resolved(b, DEXTAR) is b
    v = PlanningBounds().resolve(variant)
    assert (v.eps_q, v.t_s) == (variant.eps_q, variant.t_s) and v.robot.name == DEXTAR.name
    given = PlanningBounds(eps_q=1e-4).resolve(variant)
    assert given.eps_q == 1e-4 and given.t_s == variant.t_s
    with pytest.raises(InputError, match="resolved for robot dextar, not for another definition of dextar"):
        resolved(b, variant)


def test_the_plan_dependent_part_is_an_explicit_step():
    """for_plan: new bounds whose a_max is the plan's (the source per axis in ``acceleration``), the robot-level
    bounds unchanged; the same plan again changes nothing."""
    b = _resolved(DEXTAR, a_margin=0.1)
    plan = _plan(6.0, 66.0)
    p = b.for_plan(plan)
    assert b.acceleration is None and b.assumptions.a_max.tolist() == list(DEXTAR.a_max)
    assert p.acceleration.sources == (SRC.PLAN_PEAK, SRC.PLAN_PEAK) and p.plan is plan
    assert p.assumptions.a_max.tolist() == list(p.acceleration.values) == [6.0 * 1.1, 66.0 * 1.1]
    assert p.for_plan(plan) is p and p.a_max_given is None and p.eps_q == b.eps_q
