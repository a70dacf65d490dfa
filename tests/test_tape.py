"""The interval tapes agree with CasADi's float evaluation of the same model."""

import casadi as ca
import numpy as np
import pytest

from crosscert.robots import DEXTAR
from crosscert.verifier import interval as I
from crosscert.verifier.contractors import hc4_pose, newton
from crosscert.robots.errors import ModelError
from crosscert.verifier.linalg import linear_enclosure
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.tape import Tape


@pytest.fixture(scope="module")
def model():
    return IntervalModel(DEXTAR)


def _random_points(rng, count):
    x = np.column_stack([rng.uniform(-0.05, 0.05, count), rng.uniform(0.03, 0.15, count)])
    q = np.column_stack([rng.uniform(1.5, 2.5, count), rng.uniform(0.6, 1.6, count)])
    lo, hi = DEXTAR.xi_lo_array, DEXTAR.xi_hi_array
    xi = lo + (hi - lo) * rng.random((count, len(lo)))
    return x, q, xi


@pytest.mark.parametrize("name", ["f", "jx", "jq", "det"])
def test_point_boxes_enclose_casadi_values(model, name):
    rng = np.random.default_rng(1)
    x, q, xi = _random_points(rng, 200)
    tape = {"f": model.tape_f, "jx": model.tape_jx, "jq": model.tape_jq, "det": model.tape_det}[name]
    lo, hi = tape.evaluate([(x, x), (q, q), (xi, xi)])[0]
    fun = model.numeric[name]
    for b in range(len(x)):
        val = np.array(fun(x[b], q[b], xi[b])).reshape(lo[b].shape)
        assert np.all(lo[b] <= val) and np.all(val <= hi[b])
        # point boxes stay tight: a few ulp of the largest intermediate
        assert np.all(hi[b] - lo[b] <= 1e-12)


def test_wide_boxes_enclose_random_points(model):
    rng = np.random.default_rng(2)
    x, q, xi = _random_points(rng, 50)
    r = 1e-3
    X = (x - r, x + r)
    Q = (q - r, q + r)
    XI = (DEXTAR.xi_lo_array, DEXTAR.xi_hi_array)
    for tape, name in ((model.tape_f, "f"), (model.tape_jx, "jx"), (model.tape_det, "det")):
        lo, hi = tape.evaluate([X, Q, XI])[0]
        for _ in range(20):
            xs = x + rng.uniform(-r, r, x.shape)
            qs = q + rng.uniform(-r, r, q.shape)
            xis = XI[0] + (XI[1] - XI[0]) * rng.random(xi.shape)
            for b in range(len(x)):
                val = np.array(model.numeric[name](xs[b], qs[b], xis[b])).reshape(lo[b].shape)
                assert np.all(lo[b] <= val) and np.all(val <= hi[b])


def test_second_order_term_matches_casadi(model):
    rng = np.random.default_rng(3)
    x, q, xi = _random_points(rng, 30)
    xd = rng.normal(size=x.shape)
    qd = rng.normal(size=q.shape)
    xdd = rng.normal(size=x.shape)
    lo, hi = model.tape_accel_rhs.evaluate([(x, x), (q, q), (xi, xi), (xd, xd), (qd, qd), (xdd, xdd)])[0]
    for b in range(len(x)):
        h = np.array(model.numeric["h"](x[b], q[b], xi[b], xd[b], qd[b])).ravel()
        jx = np.array(model.numeric["jx"](x[b], q[b], xi[b]))
        val = jx @ xdd[b] + h
        assert np.all(lo[b] <= val + 1e-12) and np.all(val - 1e-12 <= hi[b])


def test_contractors_never_lose_the_solution(model):
    from crosscert.robots import KinematicModel

    kin = KinematicModel(DEXTAR)
    rng = np.random.default_rng(4)
    for _ in range(40):
        xi = DEXTAR.xi_lo_array + (DEXTAR.xi_hi_array - DEXTAR.xi_lo_array) * rng.random(7)
        x = np.array([rng.uniform(-0.04, 0.04), rng.uniform(0.1, 0.14)])
        q = kin.ik(x, xi, np.array([2.0, 1.1]))
        r = rng.uniform(1e-5, 5e-3)
        X = ((x - r * rng.random(2))[None], (x + r * rng.random(2))[None])
        Q = ((q - 1e-4)[None], (q + 1e-4)[None])
        XI = (DEXTAR.xi_lo_array[None], DEXTAR.xi_hi_array[None])
        X1, Q1, XI1 = hc4_pose(model, X, Q, XI)
        assert np.all(X1[0] <= x) and np.all(x <= X1[1])
        assert np.all(Q1[0] <= q) and np.all(q <= Q1[1])
        assert np.all(XI1[0] <= xi) and np.all(xi <= XI1[1])
        X2 = newton(model, X1, Q1, XI, "x")
        assert np.all(X2[0] <= x) and np.all(x <= X2[1])


def test_linear_enclosure_contains_solutions():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(100, 3, 3)) + 3 * np.eye(3)
    b = rng.normal(size=(100, 3))
    lo, hi = linear_enclosure(A - 1e-3, A + 1e-3, b - 1e-3, b + 1e-3)
    for _ in range(20):
        Ap = A + rng.uniform(-1e-3, 1e-3, A.shape)
        bp = b + rng.uniform(-1e-3, 1e-3, b.shape)
        y = np.linalg.solve(Ap, bp[..., None])[..., 0]
        assert np.all(lo <= y) and np.all(y <= hi)


def test_unsupported_operation_is_a_model_error():
    x = ca.SX.sym("x")
    with pytest.raises(ModelError, match="no interval implementation"):
        Tape(ca.Function("g", [x], [ca.exp(x)]))


def test_hc4_on_a_square_keeps_both_signs():
    x = ca.SX.sym("x")
    tape = Tape(ca.Function("g", [x], [x * x - 4]))
    lo, hi = tape.contract([(np.array([[-3.0]]), np.array([[3.0]]))])[0]
    assert lo[0, 0] <= -2 and hi[0, 0] >= 2
    lo, hi = tape.contract([(np.array([[0.0]]), np.array([[3.0]]))])[0]
    assert lo[0, 0] <= 2 <= hi[0, 0] and lo[0, 0] > 1.9 and hi[0, 0] < 2.1
    lo, hi = tape.contract([(np.array([[0.0]]), np.array([[1.0]]))])[0]
    assert I.is_empty(lo, hi).all()


def test_gauss_seidel_leaves_an_unconstrained_component_alone():
    from crosscert.verifier.linalg import gauss_seidel

    # 0 * y = 0: any y solves it; the box must not shrink to [0, 0]
    A = np.array([[[0.0, 0.0], [0.0, 1.0]]])
    b = np.zeros((1, 2))
    yl, yh = gauss_seidel(A, A, b, b, np.array([[-1.0, -1.0]]), np.array([[1.0, 1.0]]))
    assert yl[0, 0] == -1.0 and yh[0, 0] == 1.0
    assert yl[0, 1] <= 0.0 <= yh[0, 1]
