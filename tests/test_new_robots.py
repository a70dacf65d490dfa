"""The 3-RPR and the Gough–Stewart platform: models, validation, commands and containment.

Containment runs are adversarial where they can be: geometries at corners of
``[xi]``, every reading off by ``eps_q`` (random signs), ramps at 0.98 of the
robot's acceleration bound along the motion.
"""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

import casadi as ca
import numpy as np
import pytest

from crosscert.planner.cli import main
from crosscert.planner.simulate import random_geometry, simulate_bounce, simulate_crossing, simulate_motion
from crosscert.robots import KinematicModel, get_entry, get_robot
from crosscert.robots.gough_stewart import HOME, gs_ik, mode_by_plucker
from crosscert.robots.rpr3 import RPR3, mode_by_leg_lines, rpr3_ik
from crosscert.robots.errors import ModelError
from crosscert.robots.validation import CheckOutcome
from crosscert.robots.validation import check_definition
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.tracker import TrackerSettings, Verdict, initial_box_from_mode, track_batch
from crosscert.verifier.validation import validate

N_RPR3 = 20  # seeded geometries, each tracked through a crossing and a bounce
N_GS = 8  # seeded simulated motions of the Gough-Stewart platform


def _edge_readings(q_true, eps, rng):
    """Readings off by eps_q (1 - 1e-9) with random signs: the edge of the error bound."""
    return q_true + eps * (1 - 1e-9) * rng.choice([-1.0, 1.0], size=q_true.shape)


# ------------------------------------------------------------------- models
def test_rpr3_loop_closure_matches_an_independent_transcription():
    km = KinematicModel(RPR3)
    rng = np.random.default_rng(3)
    for _ in range(20):
        xi = random_geometry(RPR3, rng)
        x = np.array([rng.uniform(0.05, 0.3), rng.uniform(0.05, 0.25), rng.uniform(-0.8, 0.2)])
        q = rng.uniform(0.05, 0.3, 3)
        A, b, d = xi[:6].reshape(3, 2), xi[6:12].reshape(3, 2), xi[12:]
        c, s = math.cos(x[2]), math.sin(x[2])
        B = x[:2] + b @ np.array([[c, s], [-s, c]])
        ref = ((B - A) ** 2).sum(1) - (q + d) ** 2
        np.testing.assert_allclose(km.f_batch(x, q, xi)[0], ref, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(km.f_batch(x, rpr3_ik(x, xi), xi)[0], 0.0, atol=1e-14)


def test_mode_conventions_match_sign_det():
    """The geometric mode functions equal mode_sign * sign(det J_x) on random poses and geometries."""
    rng = np.random.default_rng(5)
    for robot, ik, geo, draw in (
        (RPR3, rpr3_ik, lambda X, xi: mode_by_leg_lines(X, xi),
         lambda n: np.column_stack([rng.uniform(0.05, 0.3, n), rng.uniform(0.05, 0.25, n), rng.uniform(-0.8, 0.2, n)])),
        (get_robot("gough-stewart"), gs_ik, lambda X, xi: mode_by_plucker(X, xi),
         lambda n: HOME + rng.uniform(-1, 1, (n, 6)) * np.array([0.1, 0.1, 0.1, 0.3, 0.3, 0.3])),
    ):
        km = KinematicModel(robot)
        xi = random_geometry(robot, rng, corners=True)
        X = draw(200)
        Q = ik(X, xi)
        m = km.mode_batch(X, Q, xi)
        keep = m != 0
        assert keep.mean() > 0.9
        np.testing.assert_array_equal(geo(X, xi)[keep], m[keep])


def test_rpr3_benchmark_crosses_the_locus_once():
    entry = get_entry("3rpr")
    b = entry.benchmark_crossing()
    km = KinematicModel(RPR3)
    assert abs(km.normalised_mode_batch(b.point, b.q_point, b.xi)[0]) < 1e-9
    s = np.linspace(-0.06, 0.06, 121)
    X = b.point + s[:, None] * b.direction
    modes = km.mode_batch(X, rpr3_ik(X, b.xi), b.xi)
    nz = modes[modes != 0]
    assert np.count_nonzero(nz[1:] != nz[:-1]) == 1
    assert modes[0] == -1 and modes[-1] == 1


def test_rpr3_joint_offsets_are_additive():
    """joint_offsets: the loop closure reads q_i only through q_i + delta_i."""
    km = KinematicModel(RPR3)
    xi = RPR3.xi_center.copy()
    x = np.array([0.18, 0.14, -0.3])
    q = rpr3_ik(x, xi)
    for i, j in enumerate(RPR3.joint_offsets):
        xi2, q2 = xi.copy(), q.copy()
        xi2[j] += 1e-4
        q2[i] -= 1e-4
        np.testing.assert_allclose(km.f_batch(x, q2, xi2), km.f_batch(x, q, xi), atol=1e-15)


@pytest.mark.parametrize("name", ["dextar", "3rpr", "gough-stewart"])
def test_robots_pickle_for_worker_processes(name):
    """certify runs its searches in worker processes: a robot (with its mode_reference) must pickle."""
    import pickle

    robot = get_robot(name)
    again = pickle.loads(pickle.dumps(robot))
    assert again == robot and again.mode_reference is robot.mode_reference  # by reference: a module-level function


# --------------------------------------------------------------- validation
@pytest.mark.parametrize("name", ["dextar", "3rpr", "gough-stewart"])
def test_validate_passes_for_every_shipped_robot(name):
    report = validate(get_robot(name))
    assert report.ok, [(c.name, c.message) for c in report.failures]
    assert {c.name for c in report.checks} >= {"units", "jacobians", "ik-fk-round-trip", "mode-convention",
                                                "interval-evaluation", "interval-containment"}


def _failed(report, name):
    c = next(c for c in report.checks if c.name == name)
    assert c.outcome is CheckOutcome.FAILED, (c, report)
    return c.message


def test_validate_finds_a_flipped_mode_sign():
    broken = dataclasses.replace(RPR3, mode_sign=-RPR3.mode_sign)
    msg = _failed(validate(broken), "mode-convention")
    assert "mode_sign has the wrong sign" in msg


def test_validate_finds_inconsistent_units_in_the_bounds():
    # the angular acceleration bound written in deg/s^2 instead of rad/s^2
    broken = dataclasses.replace(RPR3, a_max=(80.0, 80.0, 200.0 * 180 / math.pi))  # deg/s^2
    assert "a_max[2]" in _failed(validate(broken), "units")
    # the initial velocity bound of the position in mm/s
    gs = get_robot("gough-stewart")
    broken = dataclasses.replace(gs, xd0=(50.0, 50.0, 50.0, 0.15, 0.15, 0.15))
    assert "xd0" in _failed(validate(broken), "units")
    with pytest.raises(ModelError, match="units"):
        validate(broken).raise_if_failed()
    # x_bounds of the 3-RPR's position in mm (the robot is built; validate names the field)
    lo, hi = RPR3.x_bounds
    broken = dataclasses.replace(RPR3, x_bounds=((1e3 * lo[0], 1e3 * lo[1], lo[2]), (1e3 * hi[0], 1e3 * hi[1], hi[2])))
    assert "x_bounds" in _failed(validate(broken), "units")


def test_validate_finds_a_wrong_jacobian(monkeypatch):
    original = KinematicModel.jac_x_batch
    monkeypatch.setattr(KinematicModel, "jac_x_batch", lambda self, X, Q, xi: 1.01 * original(self, X, Q, xi))
    report = validate(RPR3)
    assert "J_x differs from the finite differences" in _failed(report, "jacobians")
    assert "J_x misses" in _failed(report, "interval-evaluation").replace("evaluation of J_x misses", "J_x misses")


def test_validate_finds_a_loop_closure_the_interval_evaluator_cannot_read():
    """CasADi builds the model, but exp has no interval implementation: the interval checks fail, naming it."""
    def with_exp(x, q, xi):
        return RPR3.loop_closure(x, q, xi) * ca.exp(1e-12 * x[0])

    report = validate(dataclasses.replace(RPR3, loop_closure=with_exp))
    assert "interval implementation" in _failed(report, "interval-evaluation")


def test_validate_reports_interval_checks_not_run_without_them():
    """The robots layer's check_definition never runs (or passes) the interval checks, whatever was imported before
    (the verifier is imported here); the message says which call runs them."""
    report = check_definition(RPR3)
    by_name = {c.name: c for c in report.checks}
    assert by_name["interval-evaluation"].outcome is CheckOutcome.NOT_RUN
    assert "crosscert.verifier.validate" in by_name["interval-containment"].message
    assert not report.ok


def test_validate_does_not_depend_on_what_was_imported():
    """A fresh interpreter that imports only crosscert.robots gets the same report as this process, which has
    imported the verifier (it registered its checks on import before: NOT_RUN in one, passed in the other)."""
    code = ("from crosscert.robots import RPR3, check_definition\n"
            "print([(c.name, c.outcome.value) for c in check_definition(RPR3, samples=4).checks])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    here = [(c.name, c.outcome.value) for c in check_definition(RPR3, samples=4).checks]
    assert out.stdout.strip() == str(here)


# ------------------------------------------------------------------ commands
def test_robots_command(capsys):
    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    assert "3rpr: n = 3, m = 15" in out and "gough-stewart: n = 6, m = 36" in out and "dextar: n = 2, m = 7" in out
    assert main(["robots", "--validate", "3rpr"]) == 0
    assert "every check passed" in capsys.readouterr().out
    assert main(["robots", "--validate", "delta"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "known robots" in err


def test_gough_stewart_refuses_crossing_commands_in_one_line(capsys, tmp_path):
    for argv in (["certify", "--robot", "gough-stewart", "--out", str(tmp_path / "c")],
                 ["plan", "--robot", "gough-stewart", "--v-sing", "1", "-o", str(tmp_path / "p.csv")],
                 ["simulate", "--robot", "gough-stewart", "--v-sing", "0.3", "--bounce", "-o", str(tmp_path / "s.csv")],
                 ["plan", "--robot", "3rpr", "--v-sing", "1", "--method", "dynamic", "-o", str(tmp_path / "d.csv")]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and ("gough-stewart" in err or "no dynamic model" in err), err


def test_gough_stewart_simulate_then_check(capsys, tmp_path):
    path = tmp_path / "gs.csv"
    assert main(["simulate", "--robot", "gough-stewart", "--v-sing", "0.3", "-o", str(path)]) == 0
    capsys.readouterr()
    assert main(["check", str(path), "--robot", "gough-stewart", "--initial-mode", "-1", "--json"]) == 0
    assert '"verdict": "mode-unchanged"' in capsys.readouterr().out


def test_rpr3_simulate_then_monitor(capsys, tmp_path):
    path = tmp_path / "r.csv"
    assert main(["simulate", "--robot", "3rpr", "--v-sing", "1.5", "-o", str(path)]) == 0
    capsys.readouterr()
    assert main(["monitor", str(path), "--robot", "3rpr", "--initial-mode", "-1", "--json"]) == 0
    last = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert last["verdict"] == "mode-changed" and last["initial_mode"] == -1 and last["final_mode"] == 1


def test_rpr3_simulate_then_check(capsys, tmp_path):
    """A bounce touches the locus and comes back: the sound answer is ``unknown`` with both final modes still
    consistent (measured, seed 0); a false ``mode-changed``, a collapse to ``inconsistent`` or a refuted
    hypothesis all fail here."""
    path = tmp_path / "r.csv"
    assert main(["simulate", "--robot", "3rpr", "--v-sing", "1.0", "--bounce", "-o", str(path)]) == 0
    capsys.readouterr()
    assert main(["check", str(path), "--robot", "3rpr", "--initial-mode", "-1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["verdict"] == "unknown" and out["initial_mode"] == -1 and out["inconsistent_at_step"] is None, out
    hyp = {h["final_mode"]: h["status"] for h in out["window"]["hypotheses"]}
    assert hyp == {-1: "consistent", 1: "consistent"}, out["window"]


# --------------------------------------------------------------- containment
def _violations(runs, res, rec):
    out = []
    for b, run in enumerate(runs):
        if res.inconsistent_at_step[b] >= 0:
            out.append(f"run {b}: inconsistent at {res.inconsistent_at_step[b]}")
            continue
        for what, lo, hi, truth, k0 in (("x", rec["x_lo"][b], rec["x_hi"][b], run.x, 0),
                                        ("xd", rec["xd_lo"][b], rec["xd_hi"][b], run.xd, 1)):
            bad = np.nonzero(~((lo[k0:] <= truth[k0:]) & (truth[k0:] <= hi[k0:])).all(1))[0]
            if bad.size:
                out.append(f"run {b}: {what} outside its box at sample {bad[0] + k0}")
        mode = rec["mode"][b]
        wrong = np.nonzero((mode != 0) & (mode != run.mode_true) & (run.mode_true != 0))[0]
        if wrong.size:
            out.append(f"run {b}: wrong certified mode at sample {wrong[0]}")
    return out


def _track(robot, runs, rng):
    im = IntervalModel(robot)
    s = TrackerSettings.for_robot(robot)
    K = max(len(r.t) for r in runs)
    q = np.stack([np.concatenate([_edge_readings(r.q, robot.eps_q, rng),
                                  np.repeat(r.q_meas[-1:], K - len(r.t), axis=0)]) for r in runs])
    boxes = [initial_box_from_mode(im, q[b, 0], int(r.mode_true[0]), s) for b, r in enumerate(runs)]
    x0 = (np.array([bx[0] for bx in boxes]), np.array([bx[1] for bx in boxes]))
    res, rec = track_batch(im, q, s, x0, record=True)
    # truth only up to each run's end (padding repeats its last reading: the robot at rest)
    return res, {k: v[:, :] for k, v in rec.items()}, K


def _pad(run, K):
    """Truth arrays of ``run`` padded at rest to K samples."""
    extra = K - len(run.t)

    class P:
        x = np.concatenate([run.x, np.repeat(run.x[-1:], extra, axis=0)])
        xd = np.concatenate([run.xd, np.zeros((extra, run.xd.shape[1]))])
        mode_true = np.concatenate([run.mode_true, np.repeat(run.mode_true[-1:], extra)])
    return P


def test_rpr3_monte_carlo_containment():
    """20 seeded corner geometries, each through a crossing and a bounce at 1 m/s, ramps at 0.98 a_max."""
    robot = RPR3
    km = KinematicModel(robot)
    entry = get_entry("3rpr")
    bench = entry.benchmark_crossing()
    rng = np.random.default_rng(2024)
    runs = []
    for i in range(N_RPR3):
        xi = random_geometry(robot, np.random.default_rng(100 + i), corners=True)
        for fn in (simulate_crossing, simulate_bounce):
            runs.append(fn(km, bench.point, bench.direction, 1.0, xi_true=xi, t_rest=0.03,
                           a_peak=0.98 * robot.a_max[0], working_guess=bench.q_point, seed=i, cruise=0.02))
    res, rec, K = _track(robot, runs, rng)
    padded = [_pad(r, K) for r in runs]
    bad = _violations(padded, res, rec)
    assert not bad, "\n".join(bad)
    bounces = [b for b, r in enumerate(runs) if r.bounce]
    assert len(bounces) == N_RPR3
    assert all(res.verdict[b] is not Verdict.MODE_CHANGED for b in bounces)
    assert np.all(rec["mode"][:, 0] == np.array([r.mode_true[0] for r in runs]))  # not vacuous: starts certified


def test_gough_stewart_monte_carlo_containment():
    """Seeded regular motions around HOME, corner geometries, readings at +-eps_q."""
    robot = get_robot("gough-stewart")
    km = KinematicModel(robot)
    rng = np.random.default_rng(7)
    scale = np.array([0.06, 0.06, 0.06, 0.15, 0.15, 0.15])
    runs = []
    for i in range(N_GS):
        xi = random_geometry(robot, np.random.default_rng(200 + i), corners=True)
        d = rng.uniform(-1, 1, 6) * scale
        u = d / np.linalg.norm(d)
        a_peak = 0.98 * float(np.min(robot.a_max_array / np.maximum(np.abs(u), 1e-12)))
        start, goal = HOME - d, HOME + d
        runs.append(simulate_motion(km, start, goal, 0.25, xi_true=xi, a_peak=a_peak, working_guess=gs_ik(start, xi),
                                    seed=i, t_rest=0.02, t_rest_end=0.02))
    res, rec, K = _track(robot, runs, rng)
    padded = [_pad(r, K) for r in runs]
    bad = _violations(padded, res, rec)
    assert not bad, "\n".join(bad)
    assert np.mean(rec["mode"] != 0) > 0.9  # not vacuous


def test_gough_stewart_near_singular_motion_is_contained():
    """A yaw turn from 0.2 to 1.25 rad (|det| falls 6-fold towards the singularity near pi/2): sound throughout.

    The mode may be lost near the end (undecided), never wrong; the truth stays in every box.
    """
    robot = get_robot("gough-stewart")
    km = KinematicModel(robot)
    rng = np.random.default_rng(11)
    start, goal = HOME.copy(), HOME.copy()
    start[3], goal[3], goal[0] = 0.2, 1.25, 0.03
    runs = []
    for i in range(2):
        xi = random_geometry(robot, np.random.default_rng(300 + i), corners=True)
        runs.append(simulate_motion(km, start, goal, 0.5, xi_true=xi, a_peak=100.0, working_guess=gs_ik(start, xi),
                                    seed=i, t_rest=0.02, t_rest_end=0.02))
    nm = [abs(km.normalised_mode_batch(r.x[[0, -1]], r.q[[0, -1]], r.xi_true)) for r in runs]
    assert all(v[1] < v[0] / 5 for v in nm), nm
    res, rec, K = _track(robot, runs, rng)
    bad = _violations([_pad(r, K) for r in runs], res, rec)
    assert not bad, "\n".join(bad)
    assert np.all(rec["mode"][:, 0] == -1)
    assert all(v is not Verdict.MODE_CHANGED for v in res.verdict)


# --------------------------------------------------------------- certification
def test_rpr3_certify_on_a_coarse_tolerance(capsys, tmp_path):
    """The 3-RPR through the whole certification path, coarsely (no refutation, 2 Monte Carlo runs).

    ``--v-low 0.1`` lies below its v_min (0.3125 m/s at the default tolerance, docs/robots.md), so the
    search brackets v_min inside its range instead of returning the floor: the slowest trial fails to
    certify, v_min certifies within the tolerance above the measured one (0.3324 m/s, seed 0)."""
    argv = ["certify", "--robot", "3rpr", "--v-low", "0.1", "--tol", "0.25", "--monte-carlo", "2", "--no-refute",
            "--no-progress", "--out", str(tmp_path / "c"), "--json"]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    v_min = report["v_min_mps"]
    assert report["v_min_at_lower_end"] is False and 0.1 < v_min <= 0.3125 + 0.25, report["trials"]
    verdicts = {t["v_sing_mps"]: t["verdict"] for t in report["trials"]}
    assert verdicts[0.1] != "mode-changed" and verdicts[v_min] == "mode-changed", verdicts
    assert all(v == "mode-changed" for s, v in verdicts.items() if s >= v_min), verdicts
    assert report["refutation_bound_mps"] is None and report["refutation"] == []
    mc = report["monte_carlo"]
    assert mc["runs"] == mc["detected"] == mc["detected_in_class"] == 2
    assert mc["containment_failures"] == mc["wrong_verdicts"] == []
    assert report["execution"]["proved"] is True, report["execution"]


@pytest.mark.slow
def test_rpr3_default_certification(capsys, tmp_path):
    """``crosscert certify --robot 3rpr`` with every default (~1 min): v_min and the refutation line.

    docs/robots.md (2026-12-01): the slowest speed tried, 0.6 m/s, certifies (0.3125 m/s with
    ``--v-low 0.1``); the counterexample search finds none, so there is no refutation bound.
    """
    assert main(["certify", "--robot", "3rpr", "--no-progress", "--out", str(tmp_path / "c"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["v_min_mps"] == pytest.approx(0.6, abs=0.01)
    assert report["v_min_at_lower_end"] is True
    assert report["refutation_bound_mps"] is None


def test_rpr3_sweep_starts_in_the_benchmark_mode(capsys, tmp_path):
    """The sweep gives the tracker the mode the benchmark starts in (-1 for the 3-RPR, +1 for the DexTAR)."""
    assert main(["sweep", "--robot", "3rpr", "--speeds", "1.5", "--out", str(tmp_path / "s"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if line.strip().startswith("1.500")]
    assert [r[1] for r in rows] == ["paper", "sound"]
    sound = rows[1]
    assert sound[5] == "mode-changed" and sound[6] == "True", out
