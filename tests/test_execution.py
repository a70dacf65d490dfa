"""Execution classes of planning-time certificates (planner.execution)."""

import numpy as np
import pytest

from crosscert.planner import certify_plan, execution_class, plan_crossing
from crosscert.planner.execution import cartesian_class, effective_deviation, in_class, joint_class
from crosscert.planner.simulate import random_geometry
from crosscert.planner.task import PlanningBounds
from problems import check_contains
from crosscert.robots import DEXTAR
from crosscert.robots.errors import InputError
from crosscert.verifier.tracker import Verdict


@pytest.fixture(scope="module")
def plan(kin, task):
    return plan_crossing(kin, task, 1.45, PlanningBounds())


@pytest.fixture(scope="module")
def cls(kin, plan):
    return execution_class(kin, plan, PlanningBounds())


def test_cartesian_class_replaces_the_offset_box_only(cls):
    assert cls.kind == "cartesian"
    offs = [j for j in DEXTAR.joint_offsets if j is not None]
    others = [k for k in range(7) if k not in offs]
    np.testing.assert_array_equal(cls.xi_lo[others], DEXTAR.xi_lo_array[others])
    np.testing.assert_array_equal(cls.xi_hi[others], DEXTAR.xi_hi_array[others])
    # the length errors move the effective angles by up to a few mrad; the
    # drift along a 120 mm path is about 1 mrad
    assert np.all(cls.xi_hi[offs] - cls.xi_lo[offs] < 0.02)
    # never narrower than the robot's own offset intervals (the run-time tracker's)
    assert np.all(cls.xi_lo[offs] <= DEXTAR.xi_lo_array[offs]) and np.all(cls.xi_hi[offs] >= DEXTAR.xi_hi_array[offs])
    assert 1e-4 < cls.drift < 5e-3
    assert cls.reading_error == pytest.approx(DEXTAR.eps_q + cls.drift)
    # the drift changes slowly: a few hundredths of a mrad per sample
    # eps_q + tracking_error (0 here) rounded up: at most one outward step above eps_q
    assert DEXTAR.eps_q <= cls.fast_error <= np.nextafter(DEXTAR.eps_q, np.inf) and 1e-6 < cls.drift_per_sample < 1e-4


def test_executions_following_the_path_are_in_the_class(plan, cls, kin):
    """Fresh geometries (other seed, corners of the whole box included) all belong to the derived class."""
    rng = np.random.default_rng(2024)
    for r in range(60):
        xi = random_geometry(DEXTAR, rng, corners=(r % 3 == 0))
        q_true = kin.ik_path(plan.x, xi, plan.q[0])
        assert in_class(cls, DEXTAR, q_true, plan.q, xi, plan.xi_plan, DEXTAR.eps_q)
        # the effective deviation is the joint deviation plus the offset change
        D = effective_deviation(kin, plan.x, plan.q, plan.xi_plan, xi)
        np.testing.assert_allclose(D[:, 0], q_true[:, 0] - plan.q[:, 0] + xi[5] - plan.xi_plan[5], atol=1e-10)


def test_in_class_rejects_what_the_class_excludes(plan, cls, kin):
    xi = plan.xi_plan.copy()
    q = kin.ik_path(plan.x, xi, plan.q[0])
    assert in_class(cls, DEXTAR, q, plan.q, xi, plan.xi_plan, DEXTAR.eps_q)
    jump = q.copy()
    jump[len(q) // 2:, 0] += 3 * cls.reading_error  # drift larger than the class allows
    assert not in_class(cls, DEXTAR, jump, plan.q, xi, plan.xi_plan, DEXTAR.eps_q)
    long = xi.copy()
    long[0] = DEXTAR.xi_hi_array[0] + 1e-5  # a length outside [xi]
    assert not in_class(cls, DEXTAR, q, plan.q, long, plan.xi_plan, DEXTAR.eps_q)
    shifted = q + (cls.xi_hi[5] - cls.xi_lo[5] + 1e-3)  # constant beyond C
    assert not in_class(cls, DEXTAR, shifted, plan.q, xi, plan.xi_plan, DEXTAR.eps_q)


def test_in_class_checks_how_fast_the_drift_changes(plan, cls, kin):
    """A ramp of twice the per-sample bound, small enough for the amplitude, breaks the difference bound."""
    from dataclasses import replace

    q = kin.ik_path(plan.x, plan.xi_plan, plan.q[0]).copy()
    k0, n = len(q) // 2, 10
    q[k0:k0 + n, 0] += 2 * cls.drift_per_sample * np.arange(1, n + 1)
    q[k0 + n:, 0] += 2 * cls.drift_per_sample * n
    assert not in_class(cls, DEXTAR, q, plan.q, plan.xi_plan, plan.xi_plan, DEXTAR.eps_q)
    assert in_class(replace(cls, drift_per_sample=None), DEXTAR, q, plan.q, plan.xi_plan, plan.xi_plan, DEXTAR.eps_q)


def test_joint_class_is_the_literal_tube(plan, kin):
    jc = joint_class(DEXTAR, DEXTAR.eps_q, 1e-4)
    assert jc.reading_error == pytest.approx(DEXTAR.eps_q + 1e-4) and jc.drift == 0.0
    assert in_class(jc, DEXTAR, plan.q + 1e-4, plan.q, plan.xi_plan, plan.xi_plan, DEXTAR.eps_q, 1e-4)
    # a geometry with other offsets moves the joints by mrad: outside the tube
    xi = plan.xi_plan.copy()
    xi[5] = DEXTAR.xi_hi_array[5]
    q = kin.ik_path(plan.x, xi, plan.q[0])
    assert not in_class(jc, DEXTAR, q, plan.q, xi, plan.xi_plan, DEXTAR.eps_q, 1e-4)
    with pytest.raises(InputError, match="execution class"):
        PlanningBounds(execution="cartesain").resolve(DEXTAR)
    with pytest.raises(InputError, match="safety"):
        cartesian_class(kin, plan.x, plan.q, plan.xi_plan, DEXTAR.eps_q, safety=0.5)


def test_certifying_run_encloses_every_execution_of_the_class(plan, cls, imodel):
    """The class's run certifies at 1.45 m/s and its boxes contain the planned path.

    Every execution following the path has the planned pose and velocity as
    its truth, whatever its geometry; they must lie in every box.
    """
    res = certify_plan(imodel, plan, PlanningBounds(), 1, execution=cls)
    assert res.verdict is Verdict.MODE_CHANGED
    check_contains(res.x_lo, res.x_hi, plan.x, "planned pose")
    check_contains(res.xd_lo, res.xd_hi, plan.xd, "planned velocity", start=1)


def _rounding_pairs(rng, count=200):
    """Seeded ``(eps_q, tracking_error)`` pairs whose float sum rounds down for some, up for others."""
    return [(float(rng.uniform(1e-5, 1e-3)), float(rng.uniform(1e-7, 1e-3))) for _ in range(count)]


def test_the_joint_error_is_rounded_outward_on_each_side():
    """eps_q + tracking_error, summed in one place: rounded up for the classes a certificate covers, down for
    a counterexample's readings (exact sums checked with fractions)."""
    from fractions import Fraction

    from crosscert.planner.execution import joint_error
    from crosscert.planner.refute.orchestrate import refute_overrides

    pairs = _rounding_pairs(np.random.default_rng(20261207))
    below = [(e, t) for e, t in pairs if Fraction(e + t) < Fraction(e) + Fraction(t)]
    above = [(e, t) for e, t in pairs if Fraction(e + t) > Fraction(e) + Fraction(t)]
    assert below and above  # the plain sum would err on both sides
    for e, t in pairs:
        exact = Fraction(e) + Fraction(t)
        assert Fraction(joint_error(e, t)) >= exact
        assert Fraction(joint_error(e, t, down=True)) <= exact
        jc = joint_class(DEXTAR, e, t)
        assert Fraction(jc.reading_error) >= exact and Fraction(jc.fast_error) >= exact
        b = PlanningBounds(eps_q=e, tracking_error=t).resolve(DEXTAR)
        assert Fraction(refute_overrides(b)["eps_q"]) <= exact


def test_the_measured_cartesian_class_rounds_its_reading_error_up(kin, plan):
    """The measured class's fast and total reading errors cover the exact sums (eps_q + tracking_error, then
    + the drift bound)."""
    from fractions import Fraction

    for e, t in _rounding_pairs(np.random.default_rng(7), 6):
        c = cartesian_class(kin, [plan.x], [plan.q], plan.xi_plan, e, t, samples=2)
        assert Fraction(c.fast_error) >= Fraction(e) + Fraction(t)
        assert Fraction(c.reading_error) >= Fraction(c.fast_error) + Fraction(c.drift)
