"""The IRI five-bar: its data, its loop closure read three ways, its benchmark crossing and the commands."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from crosscert.planner.cli import main
from crosscert.robots import KinematicModel, get_entry, get_robot
from crosscert.robots.dextar import distal_joints, elbows_out_ik, mode_by_cross_product
from crosscert.robots.iri_five_bar import IRI_FIVE_BAR, iri_benchmark_crossing, iri_singular_y
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.validation import validate

NAME = "iri-five-bar"
#: ``crosscert certify --robot iri-five-bar`` with every default (docs/robots.md), m/s.
V_MIN = 1.2745


def _independent_closure(x, q, xi):
    """The five-bar's loop closure written again from its geometry in numpy, m^2 (independent of CasADi)."""
    b1, b2 = distal_joints(q, xi)
    E = np.atleast_2d(x)
    return np.stack([((E - b1) ** 2).sum(1) - xi[2] ** 2, ((E - b2) ** 2).sum(1) - xi[3] ** 2], axis=1)


def _random_configurations(rng, count):
    """Elbows-out configurations ``(x, q, xi)`` with ``xi`` uniform in the box and ``x`` near the benchmark."""
    robot = IRI_FIVE_BAR
    out = []
    while len(out) < count:
        xi = robot.xi_lo_array + (robot.xi_hi_array - robot.xi_lo_array) * rng.random(7)
        x = np.array([rng.uniform(-0.12, 0.12), rng.uniform(0.08, 0.30)])
        q = elbows_out_ik(x, xi)
        if np.all(np.isfinite(q)):
            out.append((x, q, xi))
    return out


def test_registered_with_its_published_geometry():
    entry = get_entry(NAME)
    assert entry.robot is IRI_FIVE_BAR and get_robot(" IRI-Five-Bar ") is IRI_FIVE_BAR
    assert entry.dynamics is None and entry.benchmark is iri_benchmark_crossing
    # Scherbot2.m: proximal 0.2 m, distal 0.15 m, base 0.12 m
    assert IRI_FIVE_BAR.xi_nominal == (0.2, 0.2, 0.15, 0.15, 0.12, 0.0, 0.0)
    assert IRI_FIVE_BAR.xi_in_box(IRI_FIVE_BAR.xi_nominal_array)
    assert all(u.value == "m" for u in IRI_FIVE_BAR.pose_units)
    assert "Bordalba" in IRI_FIVE_BAR.description


def test_validates():
    report = validate(IRI_FIVE_BAR)
    assert report.ok, [(c.name, c.message) for c in report.failures]
    assert {c.name for c in report.checks} >= {"units", "jacobians", "ik-fk-round-trip", "mode-convention",
                                                "interval-evaluation", "interval-containment"}


def test_pickles_for_worker_processes():
    again = pickle.loads(pickle.dumps(IRI_FIVE_BAR))
    assert again == IRI_FIVE_BAR and again.mode_reference is IRI_FIVE_BAR.mode_reference


def test_casadi_numeric_and_interval_evaluations_agree():
    """f at 64 seeded configurations: CasADi's function, the numpy batch, an independent transcription and
    the interval tape on point boxes (which must enclose the float values) agree; all vanish on the IK."""
    km = KinematicModel(IRI_FIVE_BAR)
    im = IntervalModel(IRI_FIVE_BAR)
    rng = np.random.default_rng(41)
    confs = _random_configurations(rng, 64)
    # off the manifold too: perturb each pose by up to 1 mm
    x = np.array([c[0] for c in confs]) + rng.uniform(-1e-3, 1e-3, (64, 2))
    q = np.array([c[1] for c in confs])
    xi = np.array([c[2] for c in confs])
    f_batch = np.stack([km.f_batch(x[k:k + 1], q[k:k + 1], xi[k])[0] for k in range(64)])
    f_casadi = np.stack([np.array(im.numeric["f"](x[k], q[k], xi[k])).ravel() for k in range(64)])
    f_numpy = np.concatenate([_independent_closure(x[k], q[k], xi[k]) for k in range(64)])
    np.testing.assert_allclose(f_casadi, f_numpy, rtol=0, atol=1e-15)
    np.testing.assert_allclose(f_batch, f_numpy, rtol=0, atol=1e-15)
    lo, hi = im.tape_f.evaluate([(x, x), (q, q), (xi, xi)])[0]
    assert np.all(lo <= f_casadi) and np.all(f_casadi <= hi)
    assert np.max(hi - lo) < 1e-14
    on = np.concatenate([_independent_closure(c[0], c[1], c[2]) for c in confs])
    assert np.max(np.abs(on)) < 1e-14


def test_det_and_mode_agree_with_the_geometry():
    """The interval ``det J_x`` on point boxes encloses CasADi's, whose sign is the cross-product mode."""
    im = IntervalModel(IRI_FIVE_BAR)
    confs = _random_configurations(np.random.default_rng(7), 32)
    for x, q, xi in confs:
        det = float(im.numeric["det"](x, q, xi))
        lo, hi = im.tape_det.evaluate([(x, x), (q, q), (xi, xi)])[0]
        assert lo.item() <= det <= hi.item()
        if abs(det) > 1e-9:
            assert np.sign(det) == mode_by_cross_product(x, q, xi)[0]


def test_benchmark_crosses_the_locus():
    """Along the benchmark, 60 mm either side of its point, det J_x changes sign once, on the locus, with
    the joints well inside their range; the same for corner geometries of the box."""
    robot = IRI_FIVE_BAR
    km = KinematicModel(robot)
    corners = [robot.xi_nominal_array, robot.xi_lo_array, robot.xi_hi_array]
    for xi in corners:
        bench = iri_benchmark_crossing(xi)
        assert bench.point[0] == 0.0 and 0.17 < bench.point[1] < 0.19  # ~0.1786 m at the nominal
        np.testing.assert_array_equal(bench.direction, [0.0, -1.0])
        s = np.linspace(-0.06, 0.06, 241)
        E = bench.point + s[:, None] * bench.direction
        q = elbows_out_ik(E, xi)
        assert np.all(np.isfinite(q))
        assert np.all(q > robot.q_lo_array + 0.5) and np.all(q < robot.q_hi_array - 0.5)
        det = km.det_batch(E, q, xi)
        flips = np.nonzero(np.sign(det[:-1]) != np.sign(det[1:]))[0]
        assert flips.size == 1 and abs(s[flips[0]]) < 1e-3
        assert det[0] > 0 > det[-1]  # from mode +1 to mode -1
        assert abs(float(km.det_batch(bench.point[None], bench.q_point[None], xi)[0])) < 1e-12
        # on the locus the distal links are aligned: B1, E and B2 collinear
        b1, b2 = distal_joints(bench.q_point, xi)
        u, v = b2[0] - b1[0], bench.point - b1[0]
        assert abs(u[0] * v[1] - u[1] * v[0]) < 1e-12
    assert iri_singular_y() == pytest.approx(0.17860571, abs=1e-7)


def test_plan_then_check(capsys, tmp_path):
    """``plan`` the benchmark at 1.5 m/s, ``check`` the plan: mode-changed from the benchmark's mode +1."""
    plan = tmp_path / "p.csv"
    assert main(["plan", "--robot", NAME, "--v-sing", "1.5", "-o", str(plan)]) == 0
    capsys.readouterr()
    assert main(["check", str(plan), "--robot", NAME, "--initial-mode", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["initial_mode"] == 1 and out["verdict"] == "mode-changed", out


def test_certify_on_a_coarse_tolerance(capsys, tmp_path):
    """The whole certification path, coarsely (no refutation, 2 Monte Carlo runs): the bisection of
    [1.1, 1.5] m/s (measured: 1.2 and 1.25 unknown, 1.3 and 1.5 mode-changed) certifies v_min within the
    tolerance above the default run's."""
    argv = ["certify", "--robot", NAME, "--v-low", "1.1", "--v-high", "1.5", "--tol", "0.1", "--monte-carlo", "2",
            "--no-refute", "--no-progress", "--out", str(tmp_path / "c"), "--json"]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    verdicts = {t["v_sing_mps"]: t["verdict"] for t in report["trials"]}
    v_min = report["v_min_mps"]
    assert report["v_min_at_lower_end"] is False and verdicts[min(verdicts)] != "mode-changed", verdicts
    assert verdicts[v_min] == "mode-changed" and V_MIN - 0.01 <= v_min <= V_MIN + 0.1, verdicts
    assert all(v == "mode-changed" for s, v in verdicts.items() if s >= v_min), verdicts
    mc = report["monte_carlo"]
    assert mc["runs"] == 2 and mc["containment_failures"] == mc["wrong_verdicts"] == []
    assert report["execution"]["proved"] is True, report["execution"]


@pytest.mark.slow
def test_default_certification(capsys, tmp_path):
    """``crosscert certify --robot iri-five-bar`` with every default (docs/robots.md)."""
    assert main(["certify", "--robot", NAME, "--no-progress", "--out", str(tmp_path / "c"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["v_min_mps"] == pytest.approx(V_MIN, abs=0.02)
    assert report["refutation_bound_mps"] is not None and report["refutation_bound_mps"] < report["v_min_mps"]
    mc = report["monte_carlo"]
    assert mc["containment_failures"] == mc["wrong_verdicts"] == []
