"""The one-motion step's compiled arithmetic (verifier.compiled.one_motion) against numpy's and exact arithmetic.

* :func:`dual_bound` (the Farkas and weak-duality bounds) gives numpy's ``_dual_bound`` bit for bit on seeded
  random sparse systems, multipliers with zeros, negatives, NaN and infinities included, several rows of
  multipliers and costs at once; and both enclose the exact rational values, on random systems and on sums
  that cancel to an exact float zero (where no later outward step covers a product's rounding): each of its
  roundings dropped fails a containment test, not only the agreement (removal checks, 2026-12-04);
* :func:`taylor_rows` (the loop closure's rows from the tapes' enclosures) gives numpy's ``_taylor_rows`` bit
  for bit on random enclosures (NaN and infinite ones included) and on the window's boxes of every robot
  of the registry, and its bounds are outward of the exact value of the same formula.  Dropping its first-
  or second-order term fails containment; dropping one of its roundings (a product ``r_j r_l``, a sum, the
  last subtraction) fails only the agreement: every such step is followed by another outward one that
  covers half an ulp (removal checks, 2026-12-04);
* :func:`evaluate` (a tape over many boxes, as lanes) gives :meth:`Tape.evaluate`'s enclosures bit for bit;
* the window's one-motion step gives the same rows, refutations and sub-boxes with either backend.

The containment of the truth itself (true solutions at box corners, adversarial motions never refuted) is
checked for both backends in tests/test_one_motion.py.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from adversarial import near_scenarios
from problems import interval_model
from crosscert.robots import available_robots, get_entry
from crosscert.verifier import certified_lp as LP
from crosscert.verifier import one_motion as OM
from crosscert.verifier.model import IntervalModel


def _bits_equal(a, b) -> bool:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _random_system(rng, M, N, density, scale=1.0, duplicates=True):
    """A sparse ``A z <= b`` over a box: entries of mixed signs and magnitudes, some repeated coordinates."""
    mask = rng.random((M, N)) < density
    mask[np.arange(M), rng.integers(0, N, M)] = True  # no empty row
    rows, cols = np.nonzero(mask)
    if duplicates and len(rows) > 3:
        extra = rng.integers(0, len(rows), max(1, len(rows) // 10))
        rows, cols = np.concatenate([rows, rows[extra]]), np.concatenate([cols, cols[extra]])
        order = rng.permutation(len(rows))
        rows, cols = rows[order], cols[order]
    vals = scale * rng.uniform(-1, 1, len(rows)) * 10.0 ** rng.integers(-6, 3, len(rows))
    b = scale * rng.uniform(-1, 1, M) * 10.0 ** rng.integers(-4, 2, M)
    lo = rng.uniform(-2, 0, N) * 10.0 ** rng.integers(-3, 1, N)
    hi = lo + rng.uniform(0, 2, N) * 10.0 ** rng.integers(-3, 1, N)
    fixed = rng.random(N) < 0.1
    hi[fixed] = lo[fixed]
    return OM.LinearSystem(rows.astype(np.int64), cols.astype(np.int64), vals, b, lo, hi)


def _multipliers(rng, B, M, special=True):
    y = rng.uniform(0, 3, (B, M)) * 10.0 ** rng.integers(-5, 3, (B, M))
    y[rng.random((B, M)) < 0.3] = 0.0
    if special:
        y[rng.random((B, M)) < 0.05] = -1.0
        y[rng.random((B, M)) < 0.03] = np.nan
        y[rng.random((B, M)) < 0.03] = np.inf
    return y


@pytest.mark.parametrize("seed", range(6))
def test_dual_bound_is_numpys_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    for M, N, density in ((1, 1, 1.0), (7, 3, 0.5), (40, 25, 0.2), (160, 90, 0.05)):
        system = _random_system(rng, M, N, density)
        for B in (1, 3):
            y = _multipliers(rng, B, M)
            for cost in (None, rng.normal(size=N), rng.normal(size=(B, N))):
                if B == 1:  # one multiplier vector: (M,) and a cost (N,)
                    y, cost = y[0] if y.ndim == 2 else y, cost[0] if cost is not None and cost.ndim == 2 else cost
                want = LP._dual_bound(system, y, cost)
                got = LP._dual_bound(system, y, cost, compiled=True)
                assert _bits_equal(got[0], want[0]) and _bits_equal(got[1], want[1]), (seed, M, N, B)


def test_dual_bound_agrees_where_the_arithmetic_overflows_or_has_no_multiplier():
    """Products and sums that overflow (inf, and inf - inf = NaN in a column sum), an all-zero ``y``."""
    rng = np.random.default_rng(11)
    system = _random_system(rng, 30, 12, 0.3, scale=1e300)
    for y in (_multipliers(rng, 2, 30) * 1e10, np.zeros((2, 30)), np.full((1, 30), np.nan)):
        want, got = LP._dual_bound(system, y), LP._dual_bound(system, y, compiled=True)
        assert _bits_equal(got[0], want[0]) and _bits_equal(got[1], want[1])
    assert not np.all(np.isfinite(LP._dual_bound(system, _multipliers(rng, 2, 30, special=False) * 1e10)[0]))


def _exact_dual(system, y, cost):
    """``(min over the box of (cost + yᵀA) z, yᵀb)`` in rational arithmetic, ``y`` already non-negative."""
    M, N = system.shape
    col = [Fraction(float(c)) for c in cost]
    for r, c, v in zip(system.rows, system.cols, system.vals):
        if y[r] > 0:
            col[c] += Fraction(float(y[r])) * Fraction(float(v))
    left = sum(min(cj * Fraction(float(system.lo[j])), cj * Fraction(float(system.hi[j]))) for j, cj in enumerate(col))
    yb = sum(Fraction(float(y[i])) * Fraction(float(system.b[i])) for i in range(M) if y[i] > 0)
    return left, yb


@pytest.mark.parametrize("compiled", [False, True])
def test_dual_bound_encloses_the_exact_value(compiled):
    """``left`` at or below, ``yb`` at or above their exact values, on 120 random systems whose products and
    sums round in every direction: fails when a product or an addition of either backend is rounded to
    nearest instead of outward (each alone, 2026-12-04)."""
    rng = np.random.default_rng(3)
    for t in range(120):
        M, N = int(rng.integers(2, 30)), int(rng.integers(1, 12))
        system = _random_system(rng, M, N, 0.4)
        y = _multipliers(rng, 1, M, special=False)[0]
        cost = rng.normal(size=N) * 10.0 ** rng.integers(-3, 3, N)
        left, yb = LP._dual_bound(system, y, cost, compiled=compiled)
        ex_left, ex_yb = _exact_dual(system, y, cost)
        assert Fraction(float(left)) <= ex_left, t
        assert Fraction(float(yb)) >= ex_yb, t


def _product_error(y, v) -> Fraction:
    """``y v − fl(y v)``, exactly."""
    return Fraction(float(y)) * Fraction(float(v)) - Fraction(float(y) * float(v))


@pytest.mark.parametrize("compiled", [False, True])
def test_a_column_sum_cancelling_to_zero_keeps_its_products_rounding(compiled):
    """One entry ``y v`` and the cost ``−fl(y v)``: the column sum is exactly 0 in floats (an exact zero is
    not widened), so only the product's own outward rounding keeps the exact ``y v − fl(y v)`` inside; the
    box ``z = ±1`` makes ``left`` that value (or its opposite).  Fails when the products of the column sums
    are rounded to nearest (the other checks do not see it: the next addition's outward step covers it)."""
    rng = np.random.default_rng(17)
    seen = set()
    for _ in range(60):
        y, v = rng.uniform(0.5, 2.0), rng.uniform(-3.0, 3.0)
        err = _product_error(y, v)
        if err == 0:
            continue
        side = 1.0 if err < 0 else -1.0  # left = cl (z = 1) or -ch (z = -1): the bound the error is beyond
        system = OM.LinearSystem(np.array([0]), np.array([0]), np.array([v]), np.array([0.0]), np.array([side]),
                                 np.array([side]))
        left, _ = LP._dual_bound(system, np.array([y]), np.array([-(y * v)]), compiled=compiled)
        assert Fraction(float(left)) <= side * err, (y, v)
        seen.add(side)
    assert seen == {1.0, -1.0}


@pytest.mark.parametrize("compiled", [False, True])
def test_a_sum_of_yb_cancelling_to_zero_keeps_its_products_rounding(compiled):
    """Two rows with ``fl(y b_1) = −fl(y b_2)`` while ``y (b_1 + b_2) > 0`` exactly: ``yᵀb`` is 0 in floats, and
    only the products' outward rounding keeps the bound above the exact value.  Fails when the products of
    ``yᵀb`` are rounded to nearest."""
    rng = np.random.default_rng(19)
    found = 0
    while found < 20:
        y, b1 = rng.uniform(0.5, 2.0), rng.uniform(0.5, 2.0)
        b2 = -np.nextafter(b1, 0.0)
        if y * b1 != -(y * b2):
            continue
        exact = Fraction(float(y)) * (Fraction(float(b1)) + Fraction(float(b2)))
        assert exact > 0
        system = OM.LinearSystem(np.array([0, 1]), np.array([0, 0]), np.array([1.0, -1.0]), np.array([b1, b2]),
                                 np.zeros(1), np.ones(1))
        _, yb = LP._dual_bound(system, np.array([y, y]), compiled=compiled)
        assert Fraction(float(yb)) >= exact, (y, b1)
        found += 1


def _random_enclosures(rng, S, n, N, special=False):
    """Midpoints, radii and ``(lo, hi)`` enclosures of ``f(c)``, the gradient and the Hessians, mixed magnitudes."""
    c = rng.normal(size=(S, N)) * 10.0 ** rng.integers(-3, 1, (S, N))
    r = rng.uniform(0, 1e-3, (S, N)) * (rng.random((S, N)) < 0.9)

    def pair(*shape, spread=1e-6):
        mid = rng.normal(size=shape) * 10.0 ** rng.integers(-2, 2, shape)
        w = rng.uniform(0, spread, shape) * np.abs(mid) * (rng.random(shape) < 0.8)
        return mid - w, mid + w

    F, J = pair(S, n, spread=1e-9), pair(S, n, N)
    H = pair(S, n, N, N, spread=0.5)
    if special:
        J[0][0, 0, 0], H[1][1, 1, 2, 3], H[0][2, 0, 1, 1] = -np.inf, np.nan, -np.inf
        F[1][3, 1] = np.inf
    return c, r, F, J, H


@pytest.mark.parametrize("special", [False, True])
def test_taylor_rows_are_numpys_bit_for_bit(special):
    rng = np.random.default_rng(21)
    for S, n, N in ((1, 1, 1), (5, 2, 11), (30, 3, 9), (4, 6, 20)):
        c, r, F, J, H = _random_enclosures(rng, S, n, N, special and S >= 4)
        want = OM._taylor_rows(c, r, F, J, *H)
        got = OM._taylor_rows_compiled(c, r, F, J, *H)
        assert all(_bits_equal(a, b) for a, b in zip(got, want)), (S, n, N)
        if special and S >= 4:
            assert np.isinf(got[1]).any()  # the NaN rows made infinite


@pytest.mark.parametrize("name", available_robots())
def test_loop_closure_rows_are_the_same_with_either_backend_on_every_robot(name):
    """The window's boxes of each robot of the registry: the rows from both backends, bit for bit."""
    robot = get_entry(name).robot
    im = interval_model() if name == "dextar" else IntervalModel(robot)
    rng = np.random.default_rng(7)
    xi_lo, xi_hi = im.xi_box()
    S = 12
    x = rng.normal(size=(S, im.n)) * 0.05
    q = rng.normal(size=(S, im.n))
    for w in (1e-6, 1e-3, 1e-1):
        X, Q = (x - w, x + w), (q - w, q + w)
        want = OM.loop_closure_rows(im, X, Q, (xi_lo, xi_hi))
        got = OM.loop_closure_rows(im, X, Q, (xi_lo, xi_hi), compiled=True)
        assert all(_bits_equal(a, b) for a, b in zip(got, want)), (name, w)


@pytest.mark.parametrize("name", available_robots())
def test_the_tapes_over_lanes_are_numpys_bit_for_bit(name):
    """:func:`verifier.compiled.one_motion.evaluate` gives :meth:`Tape.evaluate`'s enclosures bit for bit: every
    tape the one-motion step and the window's split evaluate, on point boxes, narrow and wide ones (sines and
    cosines over their extrema), unbounded boxes, more boxes than one sweep's lanes,
    an input shared by every box (broadcast), and no box at all."""
    from crosscert.verifier.compiled import one_motion as kernels

    im = interval_model() if name == "dextar" else IntervalModel(get_entry(name).robot)
    rng = np.random.default_rng(11)
    xi_lo, xi_hi = im.xi_box()
    S = kernels.LANES + 37
    x = rng.normal(size=(S, im.n)) * 0.1
    q = rng.normal(size=(S, im.n))
    w = np.where(rng.random((S, 1)) < 0.25, 0.0, 10.0 ** rng.integers(-9, 1, (S, 1)))
    w[1], w[2] = 50.0, np.inf  # boxes far out of any pose, unbounded: the products' general path, infinities
    X, Q = (x - w, x + w), (q - w, q + w)
    cases = [[X, Q, (xi_lo, xi_hi)],  # the geometry box shared by every box
             [X, Q, (np.broadcast_to(xi_lo, (S, im.m)), np.broadcast_to(xi_hi, (S, im.m)))],
             [(x[:0], x[:0]), (q[:0], q[:0]), (xi_lo, xi_hi)]]
    for tape in (im.tape_f, im.tape_jx, im.tape_jac, im.tape_hess):
        for inputs in cases:
            want = tape.evaluate(inputs)
            got = kernels.evaluate(tape, inputs)
            assert len(got) == len(want)
            for (gl, gh), (wl, wh) in zip(got, want):
                assert gl.shape == wl.shape and _bits_equal(gl, wl) and _bits_equal(gh, wh), (name, tape.name)
    assert not np.isfinite(kernels.evaluate(im.tape_hess, cases[0])[0][0][2]).all()


def _exact_taylor(c, r, F, J, H, s, i, Jc):
    """Exact ``(lo, hi)`` of row ``(s, i)``'s formula from the same float enclosures and ``Jc``."""
    N = c.shape[1]
    fr = lambda v: Fraction(float(v))  # noqa: E731
    e1 = sum(max(abs(fr(J[0][s, i, j]) - fr(Jc[s, i, j])), abs(fr(J[1][s, i, j]) - fr(Jc[s, i, j]))) * fr(r[s, j])
             for j in range(N))
    up = down = Fraction(0)
    for j in range(N):
        for k in range(N):
            hl, hh = fr(H[0][s, i, j, k]), fr(H[1][s, i, j, k])
            rr = fr(r[s, j]) * fr(r[s, k])
            up += (max(hh, Fraction(0)) if j == k else max(abs(hl), abs(hh))) * rr
            down += (max(-hl, Fraction(0)) if j == k else max(abs(hl), abs(hh))) * rr
    jc = sum(fr(Jc[s, i, j]) * fr(c[s, j]) for j in range(N))
    return jc - fr(F[1][s, i]) - up / 2 - e1, jc - fr(F[0][s, i]) + down / 2 + e1


@pytest.mark.parametrize("compiled", [False, True])
def test_taylor_rows_bounds_are_outward_of_their_exact_formula(compiled):
    """``blo``, ``bhi`` at or outside the exact value of the formula they round (the same enclosures, the same
    ``Jc``): on enclosures whose terms are of one size, so that no rounding hides behind a later one."""
    rng = np.random.default_rng(5)
    S, n, N = 40, 2, 7
    c = rng.uniform(0.1, 1.0, (S, N))
    r = rng.uniform(0.1, 1.0, (S, N))
    Jm = rng.uniform(0.1, 1.0, (S, n, N))
    J = (Jm - rng.uniform(0, 1e-3, Jm.shape), Jm + rng.uniform(0, 1e-3, Jm.shape))
    Fm = rng.uniform(-1.0, 1.0, (S, n))
    F = (Fm - 1e-3, Fm + 1e-3)
    Hm = rng.uniform(-1.0, 1.0, (S, n, N, N))
    H = (Hm - rng.uniform(0, 0.5, Hm.shape), Hm + rng.uniform(0, 0.5, Hm.shape))
    Jc, blo, bhi = (OM._taylor_rows_compiled if compiled else OM._taylor_rows)(c, r, F, J, *H)
    for s in range(S):
        for i in range(n):
            lo, hi = _exact_taylor(c, r, F, J, H, s, i, Jc)
            assert Fraction(float(blo[s, i])) <= lo and Fraction(float(bhi[s, i])) >= hi, (s, i)


@pytest.fixture(scope="module")
def scenarios():
    return near_scenarios(3, 17, v_cross=(0.9, 1.1), v_bounce=(0.9, 1.1))


def test_the_one_motion_step_is_the_same_with_either_backend(scenarios):
    """Rows over the whole ``[ξ]`` and a sub-box, tubes around an adversarial truth and around nothing (wide):
    the same refutations and contracted sub-boxes, bit for bit."""
    from crosscert.robots import DEXTAR
    from crosscert.verifier.settings import TrackerSettings

    im = interval_model()
    settings = TrackerSettings.for_robot(DEXTAR)
    rng = np.random.default_rng(2)
    lo, hi = im.xi_box()
    for sc in scenarios:
        u = rng.random((2,) + sc.x.shape)
        for width in (3e-4, 3e-3):
            X = np.stack([sc.x - width * u[0], sc.x + width * u[1]], axis=1)
            XD = np.stack([sc.xd - 0.05 * u[1], sc.xd + 0.05 * u[0]], axis=1)
            XI = (np.stack([lo, np.minimum(sc.xi, 0.5 * (lo + hi))]), np.stack([hi, np.maximum(sc.xi, 0.5 * (lo + hi))]))
            want = OM.one_motion_rows(im, settings, sc.q_meas, XI, np.stack([X, X]), np.stack([XD, XD]))
            got = OM.one_motion_rows(im, settings, sc.q_meas, XI, np.stack([X, X]), np.stack([XD, XD]), compiled=True)
            assert all(_bits_equal(a, b) for a, b in zip(got, want)), sc.name


def test_the_compilation_child_builds_the_signatures_the_step_uses(scenarios):
    """:func:`verifier.compiled.one_motion.compile_kernels` (run by the first run's compilation child) compiles
    each kernel for exactly the argument types of the step's calls: after it, a call adds no signature."""
    from crosscert.robots import DEXTAR
    from crosscert.verifier.compiled.one_motion import compile_kernels, dual_bound, tape_points, taylor_rows
    from crosscert.verifier.settings import TrackerSettings

    compile_kernels()
    kernels = (dual_bound, taylor_rows, tape_points)
    before = [list(k.signatures) for k in kernels]
    im = interval_model()
    sc = scenarios[0]
    X = np.stack([sc.x - 1e-3, sc.x + 1e-3], axis=1)
    XD = np.stack([sc.xd - 0.1, sc.xd + 0.1], axis=1)
    lo, hi = im.xi_box()
    OM.one_motion_rows(im, TrackerSettings.for_robot(DEXTAR), sc.q_meas, (lo[None], hi[None]), X[None], XD[None],
                       compiled=True)
    assert [list(k.signatures) for k in kernels] == before
    assert [len(b) for b in before] == [1, 1, 1]
