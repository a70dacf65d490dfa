"""A certificate's promise at run time (``planner.certify.envelope``, ``check``/``monitor --certificate``)."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

from crosscert.planner import PlanningBounds
from crosscert.planner.certify.envelope import CertifiedEnvelope, EnvelopeMonitor, EnvelopeState
from crosscert.planner.certify.plan import certify_planned
from crosscert.planner.cli import main
from crosscert.planner.montecarlo import monte_carlo_confirmation
from crosscert.planner.plan import plan_crossing
from crosscert.planner.simulate import quantise, random_geometry
from crosscert.robots import DEXTAR, RPR3
from crosscert.robots.errors import InputError
from crosscert.verifier.settings import Verdict
from crosscert.verifier.trajfile import write_trajectory

V_CERTIFIED = 1.1  # m/s: certified on the DexTAR benchmark task under the robot's a_max


@pytest.fixture(scope="module")
def certified(tmp_path_factory, kin, task):
    """``certify --plan`` of the benchmark plan at :data:`V_CERTIFIED`: (folder, plan, certificate path)."""
    folder = tmp_path_factory.mktemp("certified")
    plan = plan_crossing(kin, task, V_CERTIFIED, PlanningBounds())
    path = folder / "plan.csv"
    write_trajectory(path, plan.t, plan.q, x=plan.x)
    out = folder / "out"
    assert main(["certify", "--plan", str(path), "--monte-carlo", "0", "--no-progress", "--out", str(out)]) == 0
    return folder, plan, out / "certificate.json"


@pytest.fixture(scope="module")
def envelope(certified):
    return CertifiedEnvelope.load(certified[2], DEXTAR, DEXTAR.eps_q, certified[0] / "plan.csv")


def _run(env, q):
    m = EnvelopeMonitor(env)
    for row in q:
        s = m.update(row)
    return s


def test_the_certified_run_is_recorded_with_the_class_it_rests_on(certified, envelope):
    report = json.loads(certified[2].read_text())
    run = report["certified_run"]
    assert report["verdict"] == "mode-changed" and run["final_mode"] == -run["initial_mode"]
    assert run["decided_by"] == "window" and run["decided_at_sample"] == len(certified[1].q) - 1
    e = report["execution"]["reading_error"]
    assert np.all(envelope.radius < e - DEXTAR.eps_q) and np.all(envelope.radius > 0.99 * (e - DEXTAR.eps_q))


def test_readings_inside_the_envelope_carry_the_certified_verdict_from_its_decision(envelope):
    q = np.array(envelope.q_plan)
    wobble = 0.5 * envelope.radius * np.sin(np.linspace(0.0, 3.0, len(q)))[:, None]  # slow: within the drift
    m = EnvelopeMonitor(envelope)
    states = [m.update(row).state for row in q + wobble]
    assert states[-1] is EnvelopeState.CERTIFIED and m.status.verdict is Verdict.MODE_CHANGED
    assert all(s is EnvelopeState.INSIDE for s in states[:envelope.decided_at])
    # samples after the plan: the certificate says nothing of them
    assert m.update(q[-1]).state is EnvelopeState.BEYOND_PLAN


def test_a_reading_just_outside_falls_back_and_never_keeps_the_verdict(envelope):
    """A reading one radius away at one sample, then a lasting offset just beyond it: the run falls back to the
    tracker at that sample and never reports the certified verdict."""
    q = np.array(envelope.q_plan)
    k, j = 40, 1
    pushed = q.copy()
    # the float exactly one radius away: its computed deviation is the radius itself
    pushed[k, j] = q[k, j] + envelope.radius[j]
    assert abs(pushed[k, j] - q[k, j]) == envelope.radius[j] or abs(pushed[k, j] - q[k, j]) > envelope.radius[j]
    s = _run(envelope, pushed)
    assert s.state is EnvelopeState.LEFT and s.verdict is Verdict.UNKNOWN
    assert (s.left_at, s.joint, s.what) == (k, j, "reading")
    farther = q.copy()
    farther[k:, j] += 1.01 * envelope.radius[j]
    s = _run(envelope, farther)
    assert s.state is EnvelopeState.LEFT and s.left_at == k and s.excess > 0


def test_a_deviation_rounded_down_onto_the_radius_still_counts_as_outside():
    """Removal check of the rounding up of ``|D|`` in ``EnvelopeMonitor.update``: the computed difference of
    these two floats is rounded down onto the radius (exactly ``0.0035 - 0.0010000000000000002`` is above
    ``0.0024999999999999996``), so without it the reading would count as inside."""
    from fractions import Fraction

    plan, reading = 0.0010000000000000002, 0.0035
    radius = reading - plan
    assert Fraction(reading) - Fraction(plan) > Fraction(radius)
    env = CertifiedEnvelope("dextar", np.array([[plan, plan]]), 0.001, np.array([radius, radius]), None,
                            Verdict.MODE_CHANGED, 0, 1, -1, "")
    s = EnvelopeMonitor(env).update(np.array([reading, plan]))
    assert s.state is EnvelopeState.LEFT and s.joint == 0
    # half the radius away: inside, and certified at once (the decision sample is 0 here)
    inside = EnvelopeMonitor(env).update(np.array([plan + radius / 2, plan]))
    assert inside.state is EnvelopeState.CERTIFIED


def test_a_drift_faster_than_certified_falls_back(envelope):
    """A jump of the deviation by more than ``d`` between two samples, each reading within the radius."""
    assert envelope.step is not None  # a cartesian class: the drift model A9 applies
    q = np.array(envelope.q_plan)
    jumped = q.copy()
    jumped[60:, 0] += min(1.5 * envelope.step[0], 0.9 * envelope.radius[0])
    s = _run(envelope, jumped)
    assert s.state is EnvelopeState.LEFT and (s.left_at, s.joint, s.what) == (60, 0, "drift")


def test_executions_of_another_geometry_following_the_path_leave_the_joint_envelope(kin, envelope, certified):
    """The cartesian class covers them through the offset box, which readings cannot confirm: the run-time
    check says so and the tracker answers (what limits the Monte Carlo row at run time)."""
    plan = certified[1]
    rng = np.random.default_rng(4)
    xi = random_geometry(DEXTAR, rng, corners=True)
    q_true, ok = kin.ik_batch(plan.x, xi, plan.q)
    assert ok.all()
    s = _run(envelope, quantise(q_true, DEXTAR.eps_q, "floor", rng))
    assert s.state is EnvelopeState.LEFT


def test_the_envelope_of_a_certified_run_is_the_one_its_certificate_file_gives(kin, imodel, certified, envelope):
    """``CertifiedRun.envelope`` (what the Monte Carlo checks) and ``CertifiedEnvelope.load`` (what ``monitor
    --certificate`` reads) are one envelope."""
    b = PlanningBounds().resolve(DEXTAR)
    run = certify_planned(kin, imodel, certified[1], b)
    env = run.envelope(DEXTAR, DEXTAR.eps_q)
    assert (env.verdict, env.decided_at, env.initial_mode, env.final_mode) == (
        envelope.verdict, envelope.decided_at, envelope.initial_mode, envelope.final_mode)
    np.testing.assert_array_equal(env.radius, envelope.radius)
    np.testing.assert_array_equal(env.step, envelope.step)
    np.testing.assert_allclose(env.q_plan, envelope.q_plan, rtol=0, atol=1e-12)  # the file's decimal digits


def test_monte_carlo_counts_the_executions_the_envelope_confirms(kin, imodel, certified, envelope):
    """Each execution's readings go through the run-time envelope check: those of random geometries leave
    the certificate's envelope (where, recorded), and an envelope wide enough confirms them all."""
    plan = certified[1]
    b = PlanningBounds().resolve(DEXTAR)
    run = certify_planned(kin, imodel, plan, b)
    mc = monte_carlo_confirmation(kin, imodel, plan, b, runs=3, seed=1, execution=run.execution, envelope=envelope)
    assert mc.envelope_checked and mc.covered_at_run_time == 0 and len(mc.left_envelope) == 3
    assert all(w["sample"] is not None and w["sample"] <= envelope.decided_at and w["excess"] > 0
               for w in mc.left_envelope)
    summary = mc.summary()
    assert summary["covered_at_run_time"] == 0 and summary["left_envelope"][0]["run"] == 0
    wide = dataclasses.replace(envelope, radius=np.full(2, 0.05), step=None)
    mc = monte_carlo_confirmation(kin, imodel, plan, b, runs=3, seed=1, execution=run.execution, envelope=wide)
    assert mc.covered_at_run_time == 3 and mc.left_envelope == ()
    mc = monte_carlo_confirmation(kin, imodel, plan, b, runs=1, seed=1, execution=run.execution)
    assert not mc.envelope_checked and mc.summary()["covered_at_run_time"] is None
    short = wide.check(np.array(envelope.q_plan)[: envelope.decided_at])  # ends before the decision
    assert short.state is EnvelopeState.INSIDE and not short.holds


def test_check_with_the_certificate_reports_its_verdict(certified, tmp_path, capsys):
    folder, plan, cert = certified
    rec = tmp_path / "run.csv"
    write_trajectory(rec, plan.t, plan.q)  # the plan executed at the nominal geometry, read exactly
    assert main(["check", str(rec), "--initial-mode", "1", "--certificate", str(cert), "--certified-plan",
                 str(folder / "plan.csv"), "--json", "--no-progress"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["verdict"] == "mode-changed" and out["certificate"]["state"] == "certified"
    assert out["certified_at_step"] == len(plan.q) - 1 and out["final_mode"] == -1


def test_check_with_the_certificate_refuses_a_dropped_sample(certified, tmp_path, capsys):
    """The envelope pairs the readings with the plan's samples by index: a recording that lost one is refused
    (one line, exit 2), not checked against the wrong samples."""
    folder, plan, cert = certified
    keep = np.setdiff1d(np.arange(len(plan.q)), [20])
    rec = tmp_path / "gap.csv"
    write_trajectory(rec, np.asarray(plan.t)[keep], np.asarray(plan.q)[keep])
    assert main(["check", str(rec), "--initial-mode", "1", "--certificate", str(cert), "--certified-plan",
                 str(folder / "plan.csv"), "--json", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "line 22: a sample was dropped before this one" in err and "\n" not in err, err


def test_monitor_with_the_certificate_falls_back_when_a_reading_leaves(certified, tmp_path, capsys):
    folder, plan, cert = certified
    q = np.array(plan.q)
    q[30:, 0] += 0.01  # 10 mrad off the plan from sample 30
    rec = tmp_path / "off.csv"
    write_trajectory(rec, plan.t, q)
    shutil.copy(folder / "plan.csv", cert.parent / "plan.csv")  # found beside the certificate
    main(["monitor", str(rec), "--initial-mode", "1", "--certificate", str(cert), "--json"])
    lines = [json.loads(s) for s in capsys.readouterr().out.splitlines()]
    left = [e for e in lines if e.get("event") == "certificate-left"]
    assert left and left[0]["k"] == 30 and left[0]["joint"] == 1
    summary = lines[-1]
    assert summary["certificate"]["state"] == "left" and summary["certificate"]["left_at_sample"] == 30
    # samples 0-29 were held while the certificate answered, tracked when sample 30 left the envelope
    assert summary["certificate"]["tracked_later"] == 30 and summary["steps"] == len(plan.q)


def test_monitor_inside_the_envelope_answers_from_the_certificate_and_tracks_later(certified, tmp_path, capsys):
    """Inside the envelope each sample costs the envelope check only; the tracker runs over them at the end (for
    the summary), and its boxes agree with the certificate's verdict (they would contradict it otherwise)."""
    folder, plan, cert = certified
    rec = tmp_path / "run.csv"
    write_trajectory(rec, plan.t, plan.q)
    shutil.copy(folder / "plan.csv", cert.parent / "plan.csv")
    assert main(["monitor", str(rec), "--initial-mode", "1", "--certificate", str(cert), "--json"]) == 0
    lines = [json.loads(s) for s in capsys.readouterr().out.splitlines()]
    events = [e["event"] for e in lines[:-1]]
    assert events[0] == "certificate-certified" and lines[0]["k"] == len(plan.q) - 1
    summary = lines[-1]
    assert summary["verdict"] == "mode-changed" and summary["certificate"]["state"] == "certified"
    assert summary["latency_us_mean"] is None  # no sample waited for the tracker
    assert summary["certificate"]["tracked_later"] == len(plan.q) == summary["steps"]


@pytest.mark.parametrize("case", ["robot", "plan", "json"])
def test_a_certificate_of_another_robot_or_plan_is_refused(case, certified, tmp_path, capsys):
    folder, plan, cert = certified
    rec = tmp_path / "run.csv"
    write_trajectory(rec, plan.t, plan.q)
    argv = ["check", str(rec), "--initial-mode", "1", "--certificate", str(cert), "--no-progress"]
    if case == "robot":
        with pytest.raises(InputError, match="a certificate of robot 'dextar', not '3rpr'"):
            CertifiedEnvelope.load(cert, RPR3, RPR3.eps_q, folder / "plan.csv")
        return
    if case == "plan":
        other = tmp_path / "other.csv"
        q = np.array(plan.q)
        q[5, 0] += 1e-6
        write_trajectory(other, plan.t, q, x=plan.x)
        argv += ["--certified-plan", str(other)]
        message = "is not the certified one"
    else:
        bad = tmp_path / "bad.json"
        bad.write_text('{"schema": "something-else"}')
        argv[argv.index(str(cert))] = str(bad)
        message = "not a crosscert certificate"
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
