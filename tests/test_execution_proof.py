"""The cartesian execution class proved over the whole calibration box (planner.execution_proof)."""

from dataclasses import replace
from fractions import Fraction

import casadi as ca
import numpy as np
import pytest

from crosscert.planner import execution_class, plan_crossing
from crosscert.planner.execution import cartesian_class, effective_deviation, in_class
from crosscert.planner import execution_proof, execution_search
from crosscert.planner.execution_proof import describe, offset_split, prove_cartesian_class, proved_class
from crosscert.planner.task import PlanningBounds
from crosscert.robots import DEXTAR, KinematicModel, get_entry
from crosscert.verifier.implicit import ImplicitTapes, inflate_roots, strictly_inside

import problems


@pytest.fixture(scope="module")
def plan(kin, task):
    return plan_crossing(kin, task, 1.45, PlanningBounds())


@pytest.fixture(scope="module")
def proof(plan):
    return prove_cartesian_class(DEXTAR, plan.x, plan.q, plan.xi_plan)


def _free(robot):
    offs = {j for j in robot.joint_offsets or () if j is not None}
    return [j for j in range(robot.m) if j not in offs and robot.xi_hi[j] > robot.xi_lo[j]]


def _geometries(robot, corners: int | None, interior: int, seed: int) -> np.ndarray:
    """Corners of the non-offset parameters (all, or ``corners`` random ones) and uniform interior points (seeded)."""
    rng = np.random.default_rng(seed)
    lo, hi = robot.xi_lo_array, robot.xi_hi_array
    free = _free(robot)
    if corners is None:
        bits = (np.arange(2 ** len(free))[:, None] >> np.arange(len(free))) & 1
    else:
        bits = rng.integers(0, 2, (corners, len(free)))
    rows = []
    for b in bits:
        xi = lo + (hi - lo) * rng.random(lo.size)  # offsets anywhere: they drop out
        xi[free] = np.where(b == 1, hi[free], lo[free])
        rows.append(xi)
    rows.extend(lo + (hi - lo) * rng.random((interior, lo.size)))
    return np.array(rows)


def _violation(proof, D, off) -> float:
    """How far (rad) the true effective deviation ``D`` (K, n) is from the class ``C, e, d`` (<= 0: inside)."""
    worst = float(np.abs(np.diff(D, axis=0)).max()) - proof.step
    for i in range(D.shape[1]):
        if off[i]:
            # a constant c in C within e of every D_k
            c_lo = max(D[:, i].max() - proof.drift, proof.c_lo[i])
            c_hi = min(D[:, i].min() + proof.drift, proof.c_hi[i])
            worst = max(worst, c_lo - c_hi)
        else:
            worst = max(worst, float(np.abs(D[:, i]).max()) - proof.drift)
    return worst


def _offset_mask(robot):
    return [j is not None for j in (robot.joint_offsets or (None,) * robot.n)]


def test_every_sampled_geometry_is_in_the_proved_class(proof, plan, kin):
    """All 32 corners of the lengths' box and 256 seeded interior geometries: the true deviations lie
    inside the proved C, e, d (the proof is never tighter than a sample), and the class admits them."""
    assert proof.proved and proof.boxes > 0 and proof.time_s > 0
    cls = proved_class(DEXTAR, proof, plan.xi_plan, DEXTAR.eps_q)
    off = _offset_mask(DEXTAR)
    for xi in _geometries(DEXTAR, None, 256, seed=11):
        D = effective_deviation(kin, plan.x, plan.q, plan.xi_plan, xi)
        assert _violation(proof, D, off) <= 0.0, xi
    for xi in _geometries(DEXTAR, None, 8, seed=12):
        q_true = kin.ik_path(plan.x, xi, plan.q[0])
        assert in_class(cls, DEXTAR, q_true, plan.q, xi, plan.xi_plan, DEXTAR.eps_q)


def test_proved_bounds_are_no_looser_than_the_measured_ones(proof, plan, kin):
    """Tighter than the sampled bounds times 1.25 on the default task, and at least what was met."""
    measured = cartesian_class(kin, plan.x, plan.q, plan.xi_plan, DEXTAR.eps_q)
    assert proof.drift <= measured.drift and proof.step <= measured.drift_per_sample
    assert proof.drift >= measured.derivation["largest_drift"]
    assert proof.step >= measured.derivation["largest_step"]
    # the robot's own offset interval still holds the proved constants' box for the DexTAR
    cls = proved_class(DEXTAR, proof, plan.xi_plan, DEXTAR.eps_q)
    np.testing.assert_array_equal(cls.xi_lo[[5, 6]], DEXTAR.xi_lo_array[[5, 6]])
    assert cls.proved and cls.summary()["proved"] is True and cls.summary()["proof"]["boxes_explored"] == proof.boxes


def test_a_bound_cut_by_ten_percent_leaves_out_a_geometry(proof, plan, kin):
    """The worst geometries the branch and bound met break e and d cut by 10 %: the bounds are within 10 %."""
    off = _offset_mask(DEXTAR)
    for key, cut in (("drift_xi", dict(drift=0.9 * proof.drift)), ("step_xi", dict(step=0.9 * proof.step))):
        xi = proof.found[key]
        D = effective_deviation(kin, plan.x, plan.q, plan.xi_plan, xi)
        assert _violation(proof, D, off) <= 0.0
        assert _violation(replace(proof, **cut), D, off) > 0.0, key


def test_without_the_mean_value_remainder_a_corner_falls_outside(plan, kin):
    """Removal check of the remainder term: the bounds at box centres alone miss the box's corners."""
    bare = prove_cartesian_class(DEXTAR, plan.x, plan.q, plan.xi_plan, remainder=False)
    off = _offset_mask(DEXTAR)
    worst = max(_violation(bare, effective_deviation(kin, plan.x, plan.q, plan.xi_plan, xi), off)
                for xi in _geometries(DEXTAR, None, 0, seed=11))
    assert worst > 0.0


def test_offset_split_rounds_outward():
    """For every exact D_k - D_r in [lo, hi] and D_r in [r_lo, r_hi]: |D_k - (D_r + m)| <= e and
    D_r + m in [c_lo, c_hi], in exact rational arithmetic (fails without the outward rounding)."""
    rng = np.random.default_rng(5)
    lo = -rng.random(400) * 10.0 ** rng.integers(-9, -2, 400)
    hi = rng.random(400) * 10.0 ** rng.integers(-9, -2, 400)
    r_lo = rng.normal(size=400) * 1e-3
    r_hi = r_lo + rng.random(400) * 1e-7
    m, e, c_lo, c_hi = offset_split(lo, hi, r_lo, r_hi)
    for k in range(400):
        M, E = Fraction(m[k]), Fraction(e[k])
        assert Fraction(hi[k]) - M <= E and M - Fraction(lo[k]) <= E
        assert Fraction(c_lo[k]) <= Fraction(r_lo[k]) + M and Fraction(r_hi[k]) + M <= Fraction(c_hi[k])


@pytest.mark.parametrize("name", ["dextar", "3rpr"])
def test_the_proof_is_the_same_with_the_tapes_compiled_or_in_numpy(name, monkeypatch):
    """The proof's tapes evaluated by the compiled kernel (the default) or by numpy: the same class, bit for
    bit (the kernel computes numpy's floats; tests/test_one_motion_compiled.py checks it tape by tape)."""
    entry = get_entry(name)
    robot = entry.robot
    plan = plan_crossing(KinematicModel(robot), problems.PLANNING[f"{name}_benchmark"].task(), 1.2,
                         PlanningBounds())
    tapes = execution_search.loop_closure_tapes(robot)[0][0]
    assert tapes.compiled
    proofs = []
    for compiled in (True, False):
        monkeypatch.setattr(tapes, "compiled", compiled)
        proofs.append(prove_cartesian_class(robot, plan.x, plan.q, plan.xi_plan))
    a, b = proofs
    assert a.proved and b.proved, (a.reason, b.reason)
    assert (a.drift, a.step, a.boxes) == (b.drift, b.step, b.boxes)
    assert np.array_equal(a.c_lo, b.c_lo) and np.array_equal(a.c_hi, b.c_hi)


def test_root_boxes_are_only_used_once_proved(plan, kin):
    """Removal check of the inflation's proof condition: a radius too small for the roots' motion over
    [xi] is not proved in one attempt; grown until proved, the box holds the corners' roots."""
    x, u, p = ca.SX.sym("x", 2), ca.SX.sym("u", 2), ca.SX.sym("xi", 7)
    tapes = ImplicitTapes(x, u, p, DEXTAR.loop_closure(x, u, p))
    K = len(plan.x)
    P = (np.repeat(DEXTAR.xi_lo_array[None], K, 0), np.repeat(DEXTAR.xi_hi_array[None], K, 0))
    X = (plan.x, plan.x)
    _, ok = inflate_roots(tapes, X, plan.q, np.full(plan.q.shape, 1e-5), P, attempts=1)
    assert not ok.any()
    U, ok = inflate_roots(tapes, X, plan.q, np.full(plan.q.shape, 1e-5), P)
    assert ok.all()
    for xi in _geometries(DEXTAR, 8, 0, seed=3):
        q = kin.ik_path(plan.x, xi, plan.q[0])
        assert np.all((U[0] <= q) & (q <= U[1]))


def test_the_3rpr_class_is_proved_too():
    """Joints in metres, six free parameters: proved, and sampled geometries lie inside."""
    entry = get_entry("3rpr")
    robot = entry.robot
    kin = KinematicModel(robot)
    plan = plan_crossing(kin, problems.PLANNING["3rpr_benchmark"].task(), 1.0, PlanningBounds())
    pr = prove_cartesian_class(robot, plan.x, plan.q, plan.xi_plan)
    assert pr.proved, pr.reason
    off = _offset_mask(robot)
    for xi in _geometries(robot, 16, 16, seed=4):
        assert _violation(pr, effective_deviation(kin, plan.x, plan.q, plan.xi_plan, xi), off) <= 0.0


def test_a_model_whose_offsets_do_not_drop_out_falls_back_to_the_measured_class(plan):
    """joint_offsets that the loop closure does not honour: not proved, the measured class with the reason."""
    wrong = replace(DEXTAR, joint_offsets=(6, 5))
    pr = prove_cartesian_class(wrong, plan.x, plan.q, plan.xi_plan)
    assert not pr.proved and "offsets" in pr.reason
    cls = execution_class(KinematicModel(wrong), plan, PlanningBounds())
    assert cls.kind == "cartesian" and not cls.proved
    assert cls.summary()["proof"] == {"proved": False, "reason": pr.reason, "time_s": cls.proof["time_s"]}
    assert "NOT proved" in describe(cls) and "offsets" in describe(cls)


def test_certifying_path_uses_the_proved_class(plan, kin, proof):
    cls = execution_class(kin, plan, PlanningBounds())
    assert cls.proved and cls.drift == proof.drift and cls.drift_per_sample == proof.step
    # eps_q + e rounded up, in exact arithmetic
    assert Fraction(cls.reading_error) >= Fraction(DEXTAR.eps_q) + Fraction(proof.drift)
    line = describe(cls)
    assert "proved for every geometry of [xi]" in line and f"{proof.boxes} boxes" in line
    joint = execution_class(kin, plan, PlanningBounds(execution="joint"))
    assert joint.proved and "stated" in describe(joint)


def test_a_joint_without_offset_has_an_exact_zero_constant(plan, kin):
    """Only joint 1 declares an offset: joint 2's deviation is all drift (its offset parameter is branched
    on like a length), its constant is exactly 0, and sampled geometries lie inside."""
    robot = replace(DEXTAR, joint_offsets=(5, None))
    pr = prove_cartesian_class(robot, plan.x, plan.q, plan.xi_plan)
    assert pr.proved, pr.reason
    assert pr.c_lo[1] == 0.0 and pr.c_hi[1] == 0.0
    off = _offset_mask(robot)
    kin2 = KinematicModel(robot)
    for xi in _geometries(robot, 16, 8, seed=9):
        assert _violation(pr, effective_deviation(kin2, plan.x, plan.q, plan.xi_plan, xi), off) <= 0.0
    # the offset of joint 2 moves it by up to 4 mrad: e covers it
    assert pr.drift > 4e-3


def test_a_krawczyk_image_touching_the_box_is_not_a_proof():
    """Existence and uniqueness need the image in the box's interior: one shared edge refuses the proof."""
    outer = (np.zeros((1, 2)), np.ones((1, 2)))
    assert strictly_inside((np.full((1, 2), 0.1), np.full((1, 2), 0.9)), outer).all()
    assert not strictly_inside((np.array([[0.0, 0.1]]), np.full((1, 2), 0.9)), outer).any()
    assert not strictly_inside((np.full((1, 2), 0.1), np.array([[0.9, 1.0]])), outer).any()
    assert not strictly_inside((np.full((1, 2), np.nan), np.full((1, 2), 0.9)), outer).any()


def test_a_bound_that_is_not_finite_is_not_a_proof(plan, monkeypatch):
    """A NaN leaf bound would vanish in the maximum over the leaves: the proof is refused instead."""
    real = execution_search._Path.evaluate

    def nan_drift(self, *args, **kwargs):
        ev = real(self, *args, **kwargs)
        ev["e"] = np.full_like(ev["e"], np.nan)
        return ev

    monkeypatch.setattr(execution_search._Path, "evaluate", nan_drift)
    pr = prove_cartesian_class(DEXTAR, plan.x, plan.q, plan.xi_plan)
    assert not pr.proved and "not finite" in pr.reason


def test_the_planned_joints_enter_as_an_outward_enclosure(plan, monkeypatch):
    """The deviation is taken from an enclosure of planned joints + planning offsets that brackets the exact sum."""
    seen = []
    real = execution_proof.setup_path

    def spy(tapes, numeric, robot, free, x, u_plan, remainder):
        seen.append(u_plan)
        return real(tapes, numeric, robot, free, x, u_plan, remainder)

    monkeypatch.setattr(execution_proof, "setup_path", spy)
    offs = execution_search.offset_joints(DEXTAR)
    xi = plan.xi_plan.copy()
    xi[list(offs.values())] = 1e-3  # planning offsets whose sums with the joints are not floats
    assert prove_cartesian_class(DEXTAR, plan.x, plan.q, xi).proved
    lo, hi = seen[0]
    off = [xi[offs[i]] if i in offs else 0.0 for i in range(DEXTAR.n)]
    inexact = 0
    for k in range(plan.q.shape[0]):
        for i in range(DEXTAR.n):
            exact = Fraction(float(plan.q[k, i])) + Fraction(float(off[i]))
            assert Fraction(float(lo[k, i])) <= exact <= Fraction(float(hi[k, i]))
            inexact += Fraction(float(plan.q[k, i]) + float(off[i])) != exact
    assert inexact > 0  # the case the enclosure is for occurs on this plan


def _same_result(a, b) -> bool:
    """Two results of a joint's branch and bound, bit for bit (bounds, counts, what was met and where)."""
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    fa, fb = a["found"], b["found"]
    return (all(np.float64(a[k]).tobytes() == np.float64(b[k]).tobytes() for k in ("e", "d", "c_lo", "c_hi"))
            and a["boxes"] == b["boxes"] and a["converged"] == b["converged"]
            and all(np.float64(fa[k]).tobytes() == np.float64(fb[k]).tobytes()
                    for k in ("drift", "step", "c_lo", "c_hi"))
            and np.array_equal(fa["drift_xi"], fb["drift_xi"]) and np.array_equal(fa["step_xi"], fb["step_xi"]))


@pytest.mark.parametrize("name", ["dextar", "3rpr"])
def test_joints_searched_in_lockstep_give_the_bounds_of_one_search_at_a_time(name, kin, plan):
    """The branch and bounds of all joints share their evaluations (one call per round, each distinct
    sub-box once): the bounds are those of the joints searched one after the other, bit for bit."""
    if name == "dextar":
        robot, p = DEXTAR, plan
    else:
        robot = get_entry(name).robot
        p = plan_crossing(KinematicModel(robot), problems.PLANNING["3rpr_benchmark"].task(), 1.0, PlanningBounds())
    (tapes, free, numeric), _ = execution_search.loop_closure_tapes(robot)
    offs = execution_search.offset_joints(robot)
    off = np.array([p.xi_plan[offs[i]] if i in offs else 0.0 for i in range(robot.n)])
    from crosscert.verifier import interval as I

    with I.quiet_fp():
        path = execution_search.setup_path(tapes, numeric, robot, free, p.x, I.add(p.q, p.q, off, off), True)
        together = execution_search.branch_and_bound_joints(path, 0.05, 16, range(robot.n))
        alone = [execution_search._branch_and_bound(path, 0.05, 16, i) for i in range(robot.n)]
    assert all(_same_result(a, b) for a, b in zip(together, alone))
    # a budget that stops the searches after different rounds: still the same
    with I.quiet_fp():
        together = execution_search.branch_and_bound_joints(path, 0.0, 9, range(robot.n))
        alone = [execution_search._branch_and_bound(path, 0.0, 9, i) for i in range(robot.n)]
    assert all(_same_result(a, b) for a, b in zip(together, alone))
