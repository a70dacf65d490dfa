"""Counterexample searches on large NLPs: the 3-RPR's slow plans (tests/problems.py, ``RPR3_REFUTATION``).

A plan of the 3-RPR's benchmark task at 0.05 m/s has 2442 samples, 29580
unknowns in the bounce NLP, against at most 3845 for any plan the DexTAR's
certification searches (0.3 m/s and up).  Two things kept the 3-RPR's
refutation bound unknown: a CPU cap per attempt fit for the small NLPs
(IPOPT needs 3-5 CPU-s to converge on the large ones), and a starting guess
that jumped to the other assembly of the initial mode where the branch
vanished for the starting geometry.
"""

from __future__ import annotations

import numpy as np
import pytest

from crosscert.planner.certify import crossing as C
from crosscert.planner.refute import orchestrate as O
from crosscert.planner.refute import fk_branch_guess, verified_counterexample
from crosscert.planner.refute.nlp import nlp_variables, scaled_cpu_time
from crosscert.planner.simulate import random_geometry
from crosscert.planner.task import PlanningBounds, crossing_on_segment
from crosscert.planner.plan import plan_crossing
from crosscert.robots import KinematicModel, get_entry
from problems import PLANNING, RPR3_REFUTATION


def _setup(robot_name):
    entry = get_entry(robot_name)
    robot = entry.robot
    kin = KinematicModel(robot)
    task = PLANNING[f"{robot_name}_benchmark"].task()
    b = PlanningBounds().resolve(robot)
    m0 = crossing_on_segment(kin, task, robot.xi_center).m0
    # certify's starting geometries (planner.certify.crossing._start_refuter, seed 0)
    starts = [robot.xi_center, random_geometry(robot, np.random.default_rng(0), corners=True)]
    return robot, kin, task, b, m0, starts


def test_cap_is_scaled_only_above_cap_variables():
    assert scaled_cpu_time(2.0, 3000, 4000) == 2.0
    assert scaled_cpu_time(2.0, 4000, 4000) == 2.0
    assert scaled_cpu_time(2.0, 8000, 4000) == pytest.approx(4.0)
    assert scaled_cpu_time(2.0, 10 ** 6, None) == 2.0


def test_dextar_searches_keep_their_cap():
    # every speed certify's scan can ask on the DexTAR task (from SCAN_FROM up) keeps REFUTE_CPU_TIME as it is,
    # so its searches, and its refutation bound, are those of before the scaling
    robot, kin, task, b, _m0, _starts = _setup("dextar")
    plan = plan_crossing(kin, task, C.SCAN_FROM, b)
    assert nlp_variables(kin, len(plan.q)) <= O.REFUTE_CAP_VARIABLES


def test_branch_guess_does_not_jump_to_the_other_assembly():
    # on this plan the corner geometry's mode-m0 branch vanishes near the locus; the guess interpolates there
    # instead of taking the other mode-m0 assembly (phi = 0.46 rad against -0.3 rad: 3780 a_max in one sample)
    robot, kin, task, b, m0, starts = _setup(RPR3_REFUTATION["robot"])
    plan = plan_crossing(kin, task, RPR3_REFUTATION["guess"], b)
    a_max = b.for_plan(plan).assumptions.a_max
    X, solved = fk_branch_guess(kin, plan.q, starts[1], m0)
    assert not solved.all()
    ratio = np.max(np.abs(np.diff(X, 2, axis=0)) / b.t_s ** 2 / a_max)
    assert ratio < 100.0, ratio
    assert np.all(np.abs(X[:, 2] - plan.x[:, 2]) < 0.5)  # never near the other assembly's phi


@pytest.mark.slow
def test_slow_3rpr_plan_is_refuted_with_certifys_cap():
    # certify's own search (refute_speed: its plan, a_max, eps_q, starts and cap): verified at 0.05 m/s from
    # the box centre, and at 0.075 m/s started from that counterexample, as its bisection does
    robot, kin, task, b, m0, starts = _setup(RPR3_REFUTATION["robot"])
    row = O.refute_speed(robot, task, b, m0, starts, RPR3_REFUTATION["refuted"], kin=kin)
    assert row.verified, (row.status, [(a.status, a.verification) for a in row.attempts])
    warm = verified_counterexample(row)
    row2 = O.refute_speed(robot, task, b, m0, starts, RPR3_REFUTATION["refuted_warm"], kin=kin, warm=warm)
    assert row2.verified, (row2.status, [(a.status, a.verification) for a in row2.attempts])
    assert row2.attempts[0].verification.accel_ratio <= 1.0
