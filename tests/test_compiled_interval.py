"""The compiled scalar operations (:mod:`verifier.compiled.interval`) against the numpy core.

* Every operation, called as a scalar function and through the array API of
  :mod:`verifier.compiled.vectorized`, gives the same floats as
  :mod:`verifier.interval` bit for bit (sign of zero included) on seeded random
  and special inputs.  The array API is checked too because numba's cache of a
  caller does not notice a change of a callee in another file: a stale cache of
  the vectorized loops would show up here as a disagreement.
* sin/cos may differ only where numpy's and libm's (called by numba) sin/cos
  differ at a bound; there both results must contain the values at the bounds
  (Arb, python-flint).  The number and size (ulp) of such differences is printed.
* No FMA contraction under numba's default flags, the directed steps survive
  compilation, and no ``fastmath`` is enabled in ``verifier/compiled``.
"""

from __future__ import annotations

import math
import re
from fractions import Fraction
from pathlib import Path

import flint
import numpy as np
import pytest
from numba import njit

from problems import libm_trig
from crosscert.verifier import interval as I
from crosscert.verifier.compiled import interval as ops
from crosscert.verifier.compiled import vectorized as V

INF = math.inf
MAX = float(np.finfo(np.float64).max)
TINY = float(np.finfo(np.float64).tiny)
SUB = 5e-324
# |x| / (2 pi) near 2**63: an int64 conversion of k = x / (2 pi) overflows there
K63 = 2.0**63 * 2.0 * math.pi

SPECIAL = [0.0, -0.0, SUB, -SUB, 3 * SUB, TINY, -TINY, 1e-300, -1e-300, 0.1, -0.1, 0.5,
           1.0, -1.0, 3.0, -3.0, math.pi / 2, 1e20, K63, -K63, 1e300, -1e300, MAX, -MAX, INF, -INF]
EMPTIES = [(INF, -INF), (1.0, 0.0), (0.0, -1.0)]


def _pairs(values):
    """All valid intervals (lo <= hi, not [inf, inf] nor [-inf, -inf])."""
    return [(a, b) for a in values for b in values if a <= b and a < INF and b > -INF]


def _random_bounds(rng, n):
    """Floats from several scales: O(1), all magnitudes, small integers, subnormals."""
    pick = rng.integers(0, 5, n)
    pools = [
        rng.uniform(-10.0, 10.0, n),
        rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-323.0, 308.0, n),
        rng.integers(-5, 6, n).astype(float),
        rng.integers(-2**20, 2**20, n) * SUB,
        rng.choice(np.array(SPECIAL[:-2]), n),
    ]
    return np.choose(pick, pools)


def _random_intervals(rng, n):
    lo, hi = np.sort(np.stack([_random_bounds(rng, n), _random_bounds(rng, n)]), axis=0)
    hi = np.where(rng.random(n) < 0.25, lo, hi)  # degenerate intervals are frequent
    lo = np.where(rng.random(n) < 0.1, -INF, lo)
    hi = np.where(rng.random(n) < 0.1, INF, hi)
    return lo, hi


def _columns(ivs):
    lo, hi = zip(*ivs)
    return np.array(lo), np.array(hi)


RNG = np.random.default_rng(20250611)
R_LO, R_HI = _random_intervals(RNG, 20_000)


def _operands(ivs):
    """Unary operands (the intervals ``ivs``, then random ones) and binary ones
    (every pair of ``ivs``, then random pairs)."""
    lo, hi = _columns(ivs)
    i, j = (g.ravel() for g in np.meshgrid(np.arange(lo.size), np.arange(lo.size)))
    unary = np.concatenate([lo, R_LO]), np.concatenate([hi, R_HI])
    binary = (np.concatenate([lo[i], R_LO]), np.concatenate([hi[i], R_HI]),
              np.concatenate([lo[j], R_LO[::-1]]), np.concatenate([hi[j], R_HI[::-1]]))
    return unary, binary


UNARY_ARGS, BINARY_ARGS = _operands(_pairs(SPECIAL))
# the set operations, is_empty and width also take empty intervals
UNARY_ARGS_E, BINARY_ARGS_E = _operands(_pairs(SPECIAL) + EMPTIES)


def _scalar(f, *cols, extra=()):
    """``f`` called once per element (Python floats in, as the kernels get them)."""
    out = [f(*args, *extra) for args in zip(*(c.tolist() for c in cols))]
    return tuple(np.array(v) for v in zip(*out)) if isinstance(out[0], tuple) else np.array(out)


def _mismatch(got, want) -> np.ndarray:
    """Elements whose bits differ (-0.0 vs 0.0 counts; NaN equals NaN)."""
    got = np.asarray(got, dtype=np.float64)
    want = np.broadcast_to(np.asarray(want, dtype=np.float64), got.shape)
    return (got.view(np.int64) != want.view(np.int64)) & ~(np.isnan(got) & np.isnan(want))


def _assert_same(name, got, want, args):
    if not isinstance(want, tuple):
        got, want = (got,), (want,)
    for k, (g, w) in enumerate(zip(got, want)):
        bad = np.flatnonzero(_mismatch(g, w))
        examples = [(tuple(float(a[i]) for a in args), float(g[i]), float(w[i])) for i in bad[:5]]
        assert bad.size == 0, f"{name} output {k}: {bad.size} differ, e.g. (args, compiled, numpy) {examples}"


def _check_both(name, want, args, extra=()):
    _assert_same(name, _scalar(getattr(ops, name), *args, extra=extra), want, args)
    _assert_same(f"vectorized.{name}", getattr(V, name)(*args, *extra), want, args)


# ---------------------------------------------------------------------------
# bit-for-bit agreement with verifier.interval
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["add", "sub", "mul", "div", "intersect", "hull"])
def test_binary_ops_bitwise(name):
    args = BINARY_ARGS_E if name in ("intersect", "hull") else BINARY_ARGS
    _check_both(name, getattr(I, name)(*args), args)


@pytest.mark.parametrize("name", ["neg", "sqr", "sqrt", "absolute", "width", "midpoint", "is_empty"])
def test_unary_ops_bitwise(name):
    args = UNARY_ARGS_E if name in ("width", "is_empty") else UNARY_ARGS
    _check_both(name, getattr(I, name)(*args), args)


@pytest.mark.parametrize("n", range(-9, 10))
def test_pown_bitwise(n):
    args = tuple(a[:6000] for a in UNARY_ARGS)
    _check_both("pown", I.pown(*args, n), args, extra=(n,))


def test_scale_bitwise():
    cs = np.concatenate([np.array(SPECIAL[:-2]), _random_bounds(RNG, 40)])
    c, k = (g.ravel() for g in np.meshgrid(cs, np.arange(1500)))
    args = (c, UNARY_ARGS[0][k], UNARY_ARGS[1][k])
    _check_both("scale", I.scale(*args), args)


def test_point_times_interval_is_mul_bitwise():
    """``pmul(c, [b])``, two products instead of four, is ``mul([c, c], [b])`` float for float."""
    cs = np.concatenate([np.array(SPECIAL), _random_bounds(RNG, 40)])
    c, k = (g.ravel() for g in np.meshgrid(cs, np.arange(1500)))
    args = (c, UNARY_ARGS[0][k], UNARY_ARGS[1][k])
    _assert_same("pmul", _scalar(ops.pmul, *args), I.mul(c, c, args[1], args[2]), args)


def _trig_intervals(rng):
    x = np.concatenate([
        rng.uniform(-10.0, 10.0, 10_000),
        rng.uniform(-1e6, 1e6, 2_000),
        rng.choice([-1.0, 1.0], 2_000) * 10.0 ** rng.uniform(-310.0, 22.0, 2_000),
        rng.integers(-400, 400, 4_000) * (np.pi / 2) + rng.uniform(-1e-9, 1e-9, 4_000),
        np.array(SPECIAL[:-2]),
    ])
    w = rng.choice([0.0, 0.0, 1e-12, 1e-6, 1e-3, 0.5, 3.0, 6.3], x.size) * rng.random(x.size)
    return np.concatenate([x, UNARY_ARGS[0]]), np.concatenate([x + w, UNARY_ARGS[1]])


def _arb_inside(fname: str, x: float, rl: float, rh: float) -> bool:
    """``f(x) in [rl, rh]`` decided with Arb (precision raised while undecided)."""
    old = flint.ctx.prec
    try:
        for prec in (200, 800, 2400, 4400):
            flint.ctx.prec = prec
            v = getattr(flint.arb(x), fname)()
            if v < flint.arb(rl) or flint.arb(rh) < v:
                return False
            if flint.arb(rl) <= v and v <= flint.arb(rh):
                return True
        return False
    finally:
        flint.ctx.prec = old


@pytest.mark.parametrize("name", ["sin", "cos"])
def test_sin_cos_bitwise_or_both_sound(name):
    """Equal bits, except where numpy's and libm's sin/cos differ at a bound:
    there both results must contain the value at the bounds (Arb)."""
    args = _trig_intervals(np.random.default_rng(7))
    x = np.unique(np.concatenate(args))
    x = x[np.isfinite(x)]
    v_np, v_nb = getattr(np, name)(x), libm_trig(x, name == "cos")
    differ = _mismatch(v_nb, v_np)
    ulp = np.abs(v_nb - v_np)[differ] / np.spacing(np.abs(v_np[differ]))
    print(f"{name}: numpy and libm differ at {differ.sum()} of {x.size} points,"
          f" max {ulp.max(initial=0.0):.1f} ulp")
    libm_differs = set(x[differ].tolist())
    want = getattr(I, name)(*args)
    for label, got in (("ops", _scalar(getattr(ops, name), *args)), ("vectorized", getattr(V, name)(*args))):
        bad = np.flatnonzero(_mismatch(got[0], want[0]) | _mismatch(got[1], want[1]))
        for i in bad:
            lo, hi = float(args[0][i]), float(args[1][i])
            where = (label, name, lo, hi, got[0][i], got[1][i], want[0][i], want[1][i])
            assert {lo, hi} & libm_differs, where
            for rl, rh in ((got[0][i], got[1][i]), (want[0][i], want[1][i])):
                for b in {lo, hi} & libm_differs:
                    assert _arb_inside(name, b, float(rl), float(rh)), (label, name, lo, hi, b, rl, rh)


def test_ops_of_int64_overflowing_phase():
    """sin/cos of |x| around 2**63 * 2 pi: the phase test stays in floats as in numpy."""
    for x in (K63, -K63, math.nextafter(K63, INF), 1e20, 1e300):
        assert ops.sin(x, x) == tuple(float(v) for v in I.sin(x, x))
        assert ops.cos(x, x) == tuple(float(v) for v in I.cos(x, x))


# ---------------------------------------------------------------------------
# compilation: no FMA contraction, directed steps kept, no fastmath
# ---------------------------------------------------------------------------


def _fused(a: float, b: float, c: float) -> float:
    """``fma(a, b, c)``: the exact ``a * b + c`` rounded once (float(Fraction)
    rounds correctly)."""
    return float(Fraction(a) * Fraction(b) + Fraction(c))


def _fma_sensitive_inputs(n: int = 500):
    """Seeded (a, b, c) with ``fma(a, b, c) != fl(fl(a * b) + c)``."""
    rng = np.random.default_rng(11)
    found = [(0.1, 10.0, -1.0)]  # fl(0.1 * 10) = 1 exactly; the fused value is 2**-54
    while len(found) < n:
        a, b = rng.uniform(-4.0, 4.0, 2).tolist()
        c = -a * b * rng.choice([1.0, 0.5, 1e-3])  # cancellation exposes the rounding of a*b
        if _fused(a, b, c) != a * b + c:
            found.append((a, b, c))
    return np.array(found).T


def test_no_fma_contraction():
    a, b, c = _fma_sensitive_inputs()
    unfused = a * b + c  # numpy: two rounded operations
    assert np.all(unfused != np.array([_fused(*t) for t in zip(a, b, c)]))
    f = njit(cache=False)(lambda a, b, c: a * b + c)  # numba's default flags

    @njit(cache=False)
    def loop(a, b, c, out):  # a vectorisable loop: no fused instruction either
        for i in range(out.size):
            out[i] = a[i] * b[i] + c[i]

    scalar = np.array([f(*t) for t in zip(a.tolist(), b.tolist(), c.tolist())])
    looped = np.empty_like(a)
    loop(a, b, c, looped)
    assert not _mismatch(scalar, unfused).any()
    assert not _mismatch(looped, unfused).any()


def test_directed_steps_survive_compilation():
    s = 0.1 + 0.2  # 0.30000000000000004, inexact
    lo, hi = ops.add(0.1, 0.1, 0.2, 0.2)
    assert lo < s < hi and lo < Fraction(0.1) + Fraction(0.2) < hi
    assert (lo, hi) == (np.nextafter(s, -INF), np.nextafter(s, INF))
    p = 0.1 * 3.0
    assert ops.mul(0.1, 0.1, 3.0, 3.0) == (np.nextafter(p, -INF), np.nextafter(p, INF))
    assert ops.add(1.0, 1.0, 1.0, 1.0) == (math.nextafter(2.0, 0.0), math.nextafter(2.0, 3.0))


def test_no_fastmath_in_compiled():
    """No ``fastmath`` other than ``False`` anywhere in verifier/compiled: it
    would allow FMA contraction and reassociation (unsound directed rounding)."""
    folder = Path(__file__).resolve().parents[1] / "verifier" / "compiled"
    files = sorted(folder.rglob("*.py"))
    assert files
    offending = [f"{p.name}:{n}: {line.strip()}"
                 for p in files for n, line in enumerate(p.read_text().splitlines(), 1)
                 if re.search(r"fastmath\s*=\s*(?!False\b)", line)]
    assert not offending, offending


def test_outward_steps_equal_nextafter():
    """The bit-pattern steps ``ops.up``/``ops.dn`` are ``np.nextafter`` toward
    ``+-inf``, bit for bit (signed zeros, subnormals, the largest floats,
    infinities, NaN, and seeded random floats of every magnitude)."""
    rng = np.random.default_rng(11)
    values = SPECIAL + [math.nan, 2 * SUB, -2 * SUB, math.nextafter(TINY, 0.0), -math.nextafter(TINY, 0.0)]
    values += list(rng.standard_normal(2000) * 10.0 ** rng.integers(-320, 308, 2000))
    with np.errstate(over="ignore"):
        for v in values:
            for step, toward in ((ops.up, INF), (ops.dn, -INF)):
                got = np.float64(step(v))
                want = np.nextafter(np.float64(v), toward)
                assert got.tobytes() == want.tobytes() or (math.isnan(got) and math.isnan(want)), (v, got, want)


# ---------------------------------------------------------------------------
# containment of exact results (not a comparison with the numpy core: a slip
# made in both backends fails here)
# ---------------------------------------------------------------------------

_EXACT = {"add": lambda a, b: a + b, "sub": lambda a, b: a - b, "mul": lambda a, b: a * b,
          "div": lambda a, b: a / b}


@pytest.mark.parametrize("name", sorted(_EXACT))
def test_compiled_ops_contain_the_exact_result_of_point_operands(name):
    """``[x, x] op [y, y]`` from the compiled scalar op holds the exact rational ``x op y``, and its
    bounds are distinct floats whenever that value is not a float: removing the outward step of one
    operation fails this test (the rounded-to-nearest result misses the exact value)."""
    rng = np.random.default_rng(20261202)
    x = rng.uniform(-4.0, 4.0, 400) * 10.0 ** rng.integers(-6, 6, 400)
    y = rng.uniform(-4.0, 4.0, 400) * 10.0 ** rng.integers(-6, 6, 400)
    f, exact_of = getattr(ops, name), _EXACT[name]
    inexact = 0
    for a, b in zip(x.tolist(), y.tolist()):
        lo, hi = f(a, a, b, b)
        exact = exact_of(Fraction(a), Fraction(b))
        assert Fraction(lo) <= exact <= Fraction(hi), (name, a, b, lo, hi)
        if Fraction(exact_of(a, b)) != exact:
            inexact += 1
            assert lo < hi, (name, a, b, lo, hi)
    assert inexact > 100  # the rounding matters on most of these operands


def _signed_interval(rng, cls, n):
    """``n`` intervals of sign class ``cls`` (+1 positive, -1 negative, 0 straddling 0), nonzero bounds of
    magnitudes over the whole exponent range (their products and quotients underflow and overflow)."""
    a, b = (10.0 ** rng.uniform(-320.0, 308.0, n) for _ in range(2))
    if cls == 0:
        return -a, b
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return (lo, hi) if cls > 0 else (-hi, -lo)


@pytest.mark.parametrize("name", ["mul", "div"])
def test_mul_div_every_sign_class_bitwise_and_containing(name):
    """``mul`` and ``div`` on intervals of every pair of sign classes: their straight-line path (nonzero
    bounds: the corners named by the signs) and the general path it falls back to (a bound rounded to
    0) give the numpy core's floats bit for bit, and the bounds hold every exact finite corner; empty
    (inverted) operands give the reference's floats too."""
    rng = np.random.default_rng(20261203)
    exact_of = _EXACT[name]
    for ca in (1, -1, 0):
        for cb in (1, -1, 0):
            if name == "div" and cb == 0:
                continue  # a divisor straddling 0 is the general path's (half-lines)
            args = (*_signed_interval(rng, ca, 300), *_signed_interval(rng, cb, 300))
            want = getattr(I, name)(*args)
            _check_both(name, want, args)
            for al, ah, bl, bh, lo, hi in zip(*(v.tolist() for v in (*args, *want))):
                for x in (al, ah):
                    for y in (bl, bh):
                        exact = exact_of(Fraction(x), Fraction(y))
                        assert math.isinf(lo) or Fraction(lo) <= exact, (name, x, y, lo)
                        assert math.isinf(hi) or exact <= Fraction(hi), (name, x, y, hi)
            # empty (inverted) operands, as a kernel meets them before its emptiness test: the reference's floats
            a_lo, a_hi = _signed_interval(rng, ca, 300)
            b_lo, b_hi = _signed_interval(rng, cb, 300)
            for args in ((a_hi, a_lo, b_lo, b_hi), (a_lo, a_hi, b_hi, b_lo), (a_hi * 0 + INF, a_lo * 0 - INF, b_lo, b_hi)):
                _check_both(name, getattr(I, name)(*args), args)
