"""Property tests of the interval cores against exact oracles.

Every test runs on both cores (the ``core`` fixture): the numpy reference
:mod:`verifier.interval` and the compiled scalar operations of
:mod:`verifier.compiled.interval` through :mod:`verifier.compiled.vectorized`.

Every operation is checked for *containment*: for random intervals (with 0 as a
bound, subnormal, tiny and huge bounds, some unbounded ones) and random real
points inside them, the exact result -- computed with :class:`fractions.Fraction`
for the rational operations, exact squaring for ``sqrt`` and Arb balls
(python-flint, 200 bits) for ``sin``/``cos`` -- lies in the computed interval.
Further checks: exact zeros are not widened, inexact results are, lower bounds of
``sqr``/``sqrt``/``abs`` are non-negative, batched calls equal elementwise ones,
the core raises no floating-point warnings, and the sin/cos margin
:data:`~verifier.interval.TRIG_ULPS` covers the error of the core's sin/cos
(numpy's; libm's as called by numba) measured with mpmath.

Hypothesis runs derandomized (fixed seed derived from each test), so the suite
is reproducible and takes a few seconds.
"""

from __future__ import annotations

import math
import warnings
from fractions import Fraction

import flint
import mpmath
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from problems import libm_trig
from crosscert.verifier import interval as I
from crosscert.verifier.compiled import vectorized as V

MAX = float(np.finfo(np.float64).max)
TINY = float(np.finfo(np.float64).tiny)  # smallest normal
SUB = 5e-324  # smallest subnormal
INF = math.inf

PROPS = settings(
    derandomize=True,
    database=None,
    deadline=None,
    max_examples=400,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)


@pytest.fixture(scope="module", params=["numpy", "compiled"])
def core(request):
    """The interval core under test (module scope: hypothesis allows no
    function-scoped fixture in a ``@given`` test)."""
    return {"numpy": I, "compiled": V}[request.param]


@pytest.fixture(autouse=True)
def _fp_warnings_are_errors():
    """The core must silence its own floating-point events (no RuntimeWarning)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        yield


# ---------------------------------------------------------------------------
# strategies
# ---------------------------------------------------------------------------

SPECIAL = [0.0, -0.0, SUB, -SUB, 2 * SUB, TINY, -TINY, 1e-300, -1e-300, 0.5, 1.0, -1.0,
           2.0, 3.0, -3.0, 0.1, -0.1, 1e300, -1e300, MAX, -MAX, math.nextafter(MAX, 0.0)]

finite_bound = st.one_of(
    st.sampled_from(SPECIAL),
    st.floats(allow_nan=False, allow_infinity=False),  # whole range incl. subnormals
    st.floats(-4.0, 4.0),
    st.floats(min_value=-1e-305, max_value=1e-305),  # near the underflow range
    st.integers(-1000, 1000).map(float),
)


@st.composite
def intervals(draw, unbounded: bool = False):
    """A non-empty interval (lo, hi); optionally with infinite bounds."""
    a, b = sorted((draw(finite_bound), draw(finite_bound)))
    if draw(st.booleans()):
        b = a  # degenerate intervals are frequent in the tracker
    if unbounded:
        if draw(st.integers(0, 3)) == 0:
            a = -INF
        if draw(st.integers(0, 3)) == 0:
            b = INF
    return float(a), float(b)


@st.composite
def points_in(draw, iv, n: int = 4):
    """Exact (rational) points of the interval: its finite bounds and a few more."""
    lo, hi = iv
    pts = [Fraction(v) for v in (lo, hi) if math.isfinite(v)]
    for _ in range(n):
        if math.isfinite(lo) and math.isfinite(hi):
            t = Fraction(draw(st.integers(0, 2**64)), 2**64)
            pts.append(Fraction(lo) + t * (Fraction(hi) - Fraction(lo)))
        c = Fraction(draw(finite_bound))
        if math.isfinite(lo):
            c = max(c, Fraction(lo))
        if math.isfinite(hi):
            c = min(c, Fraction(hi))
        pts.append(c)
    return pts


def inside(q: Fraction, lo, hi) -> bool:
    """Exact ``q in [lo, hi]`` for float bounds (possibly infinite, never NaN)."""
    lo, hi = float(lo), float(hi)
    if math.isnan(lo) or math.isnan(hi) or lo == INF or hi == -INF:
        return False
    return (lo == -INF or Fraction(lo) <= q) and (hi == INF or q <= Fraction(hi))


def is_empty(r) -> bool:
    return bool(I.is_empty(*r))


# ---------------------------------------------------------------------------
# containment of + - * / neg abs sqr pown sqrt
# ---------------------------------------------------------------------------


@PROPS
@given(st.data(), intervals(unbounded=True), intervals(unbounded=True))
def test_add_sub_mul_contain_exact(core, data, a, b):
    ra, rb = core.add(*a, *b), core.sub(*a, *b)
    rm = core.mul(*a, *b)
    for x in data.draw(points_in(a)):
        for y in data.draw(points_in(b)):
            assert inside(x + y, *ra), (a, b, x, y, ra)
            assert inside(x - y, *rb), (a, b, x, y, rb)
            assert inside(x * y, *rm), (a, b, x, y, rm)


@PROPS
@given(st.data(), intervals(unbounded=True), intervals(unbounded=True))
def test_div_contains_exact(core, data, a, b):
    r = core.div(*a, *b)
    if b == (0.0, 0.0):
        assert is_empty(r)  # {x / y : y in [0, 0], y != 0} is empty
        return
    ys = [y for y in data.draw(points_in(b)) if y != 0]
    for x in data.draw(points_in(a)):
        for y in ys:
            assert inside(x / y, *r), (a, b, x, y, r)


@settings(PROPS, max_examples=200)
@given(st.data(), intervals(), st.sampled_from([-1.0, 1.0]), st.floats(0.0, 1e300))
def test_div_by_interval_containing_zero(core, data, a, s, w):
    """Divisors [0, w], [-w, 0], [-w, w] and [0, 0] (with signed zeros)."""
    for b in ((0.0, w), (-w, 0.0), (-w, w), (-0.0, w), (-w, -0.0), (s * 0.0, s * 0.0)):
        r = core.div(*a, *b)
        ys = [y for y in data.draw(points_in(b)) if y != 0]
        if not ys:
            assert is_empty(r), (a, b, r)
            continue
        for x in data.draw(points_in(a)):
            for y in ys:
                assert inside(x / y, *r), (a, b, x, y, r)


@PROPS
@given(st.data(), intervals(unbounded=True))
def test_unary_contain_exact(core, data, a):
    rn, rabs, rsq = core.neg(*a), core.absolute(*a), core.sqr(*a)
    assert rabs[0] >= 0.0 and rsq[0] >= 0.0
    for x in data.draw(points_in(a)):
        assert inside(-x, *rn)
        assert inside(abs(x), *rabs)
        assert inside(x * x, *rsq), (a, x, rsq)


@PROPS
@given(st.data(), intervals(unbounded=True), st.integers(-9, 9))
def test_pown_contains_exact(core, data, a, n):
    r = core.pown(*a, n)
    if n < 0 and a == (0.0, 0.0):
        assert is_empty(r)
        return
    if n % 2 == 0 and n != 0:
        assert r[0] >= 0.0
    for x in data.draw(points_in(a)):
        if x == 0 and n < 0:
            continue
        assert inside(x**n, *r), (a, n, x, r)


@PROPS
@given(st.data(), intervals(unbounded=True))
def test_sqrt_contains_exact(core, data, a):
    lo, hi = (float(v) for v in core.sqrt(*a))
    if a[1] < 0.0:
        assert lo > hi  # empty
        return
    assert 0.0 <= lo <= hi
    for x in data.draw(points_in(a)):
        if x < 0:
            continue
        # lo <= sqrt(x) <= hi, decided exactly by squaring the bounds
        assert Fraction(lo) ** 2 <= x, (a, x, lo)
        assert hi == INF or x <= Fraction(hi) ** 2, (a, x, hi)


@PROPS
@given(intervals(unbounded=True), intervals(unbounded=True))
def test_intersect_hull_exact(core, a, b):
    lo, hi = core.intersect(*a, *b)
    if max(a[0], b[0]) <= min(a[1], b[1]):
        assert (lo, hi) == (max(a[0], b[0]), min(a[1], b[1]))
    else:
        assert is_empty((lo, hi))
    assert core.hull(*a, *b) == (min(a[0], b[0]), max(a[1], b[1]))
    e = I.empty_like(0.0)
    assert core.hull(*a, *e) == a and core.hull(*e, *b) == b
    assert is_empty(core.intersect(*a, *e)) and is_empty(core.hull(*e, *e))


@PROPS
@given(st.data(), intervals(unbounded=True), st.floats(allow_nan=False, allow_infinity=False))
def test_width_midpoint_scale_contains(core, data, a, c):
    w = core.width(*a)
    if math.isfinite(a[0]) and math.isfinite(a[1]):
        assert w == INF or Fraction(a[1]) - Fraction(a[0]) <= Fraction(float(w))
    else:
        assert w == INF
    m = float(core.midpoint(*a))
    assert a[0] <= m <= a[1] and math.isfinite(m), (a, m)
    assert I.contains(*a, m)
    r = core.scale(c, *a)
    for x in data.draw(points_in(a)):
        assert inside(Fraction(c) * x, *r)


# ---------------------------------------------------------------------------
# exact zeros are kept, inexact results are widened
# ---------------------------------------------------------------------------


def test_exact_zeros_not_widened(core):
    assert core.add(0.0, 1.0, 0.0, 0.0)[0] == 0.0
    assert core.sub(0.0, 1.0, 0.0, 0.0)[0] == 0.0
    assert core.sub(1.0, 1.0, 1.0, 1.0) == (0.0, 0.0)
    assert core.add(-2.5, 1.0, 2.5, 3.0)[0] == 0.0
    assert core.mul(0.0, 2.0, 3.0, 4.0)[0] == 0.0
    assert core.mul(-2.0, 0.0, 3.0, 4.0)[1] == 0.0
    assert core.mul(0.0, 0.0, -INF, INF) == (0.0, 0.0)  # 0 * inf = 0
    assert core.scale(0.0, -1e300, 1e300) == (0.0, 0.0)
    assert core.div(0.0, 0.0, 1.0, 2.0) == (0.0, 0.0)
    assert core.div(0.0, 3.0, 1.0, 2.0)[0] == 0.0
    assert core.div(-3.0, 0.0, 1.0, 2.0)[1] == 0.0
    assert core.sqr(0.0, 0.0) == (0.0, 0.0)
    assert core.sqr(0.0, 3.0)[0] == 0.0 and core.sqr(-2.0, 0.0)[0] == 0.0
    assert core.sqr(-2.0, 3.0)[0] == 0.0
    assert core.pown(0.0, 2.0, 3)[0] == 0.0 and core.pown(-2.0, 0.0, 3)[1] == 0.0
    assert core.pown(0.0, 0.0, 5) == (0.0, 0.0)
    assert core.sqrt(0.0, 4.0)[0] == 0.0 and core.sqrt(-1.0, 0.0) == (0.0, 0.0)
    assert core.absolute(0.0, 1.0)[0] == 0.0 and core.absolute(-1.0, 1.0)[0] == 0.0
    assert core.sin(0.0, 0.0) == (0.0, 0.0)  # sin(0) = 0 exactly
    assert core.sin(-0.0, 1.0)[0] == 0.0
    assert core.width(3.0, 3.0) == 0.0


def test_exact_nonzero_results_are_widened(core):
    # the model widens every non-zero rounded result, exact or not
    lo, hi = core.add(0.1, 0.1, 0.2, 0.2)
    assert lo < Fraction(0.1) + Fraction(0.2) < hi
    lo, hi = core.mul(3.0, 3.0, 1.0 / 3.0, 1.0 / 3.0)
    assert lo < Fraction(3) * Fraction(1.0 / 3.0) < hi
    assert core.add(1.0, 1.0, 1.0, 1.0) == (math.nextafter(2.0, 0.0), math.nextafter(2.0, 3.0))
    # products that underflow to 0 from non-zero factors are widened
    lo, hi = core.mul(1e-200, 1e-200, 1e-200, 1e-200)
    assert lo <= 0.0 and hi >= SUB
    lo, hi = core.mul(-1e-200, -1e-200, 1e-200, 1e-200)
    assert lo <= -SUB and hi >= 0.0
    lo, hi = core.sqr(1e-200, 1e-200)
    assert lo == 0.0 and hi >= SUB
    lo, hi = core.div(1e-300, 1e-300, 1e300, 1e300)
    assert lo <= 0.0 and hi >= SUB
    assert core.sqrt(2.0, 2.0)[0] ** 2 < 2.0 < core.sqrt(2.0, 2.0)[1] ** 2
    # sums that round to zero are exactly zero (gradual underflow)
    assert core.add(SUB, SUB, -SUB, -SUB) == (0.0, 0.0)


@PROPS
@given(intervals(), intervals())
def test_inexact_results_strictly_enclosed(core, a, b):
    """A result that is not a float is strictly inside (so it was widened)."""
    x, y = Fraction(a[0]), Fraction(b[1])
    for op, exact in ((core.add, x + y), (core.sub, x - y), (core.mul, x * y)):
        lo, hi = (float(v) for v in op(a[0], a[0], b[1], b[1]))
        if math.isfinite(lo) and math.isfinite(hi):
            assert Fraction(lo) < exact < Fraction(hi) or Fraction(float(exact)) == exact
    if y != 0:
        lo, hi = (float(v) for v in core.div(a[0], a[0], b[1], b[1]))
        if math.isfinite(lo) and math.isfinite(hi):
            assert Fraction(lo) < x / y < Fraction(hi) or Fraction(float(x / y)) == x / y


def test_regressions(core):
    """Defects found by this suite (see the history of verifier/interval.py)."""
    # integer arrays used to wrap around (1e10 * 1e10 -> 7.8e18; 2**62 + 2**62 < 0)
    lo, hi = core.mul(*(np.array([10**10]),) * 4)
    assert inside(Fraction(10**20), lo[0], hi[0])
    lo, hi = core.add(*(np.array([2**62]),) * 4)
    assert inside(Fraction(2**63), lo[0], hi[0])
    # midpoint of a half-line with a huge bound used to be -inf / inf
    for a in ((-INF, -MAX), (-INF, -1e308), (MAX, INF), (1e308, INF), (-INF, -SUB)):
        m = float(core.midpoint(*a))
        assert math.isfinite(m) and a[0] <= m <= a[1], (a, m)
    # inf/inf corners used to make the quotient the entire line
    assert core.div(-INF, -15.0, -INF, -3.0) == (0.0, INF)
    assert core.div(15.0, INF, 3.0, INF) == (0.0, INF)
    assert core.div(1.0, 2.0, 1.0, INF)[0] == 0.0
    # a dividend with 0 as a bound over a divisor with 0 as a bound: a half-line
    assert core.div(0.0, 30.0, 0.0, 3.0) == (0.0, INF)
    assert core.div(-30.0, -0.0, 0.0, 3.0) == (-INF, 0.0)
    assert core.div(0.0, 30.0, -3.0, 0.0) == (-INF, 0.0)
    assert core.div(-30.0, 0.0, -INF, 0.0) == (0.0, INF)
    assert core.div(0.0, 30.0, -3.0, 3.0) == (-INF, INF)
    # even powers are non-negative (1 / [0, inf] used to give -5e-324)
    assert core.pown(-INF, INF, -2)[0] == 0.0
    assert core.pown(0.1, 0.3, 1) == (0.1, 0.3)  # v**1 is exact


def test_no_floating_point_exceptions(core):
    """Overflow to inf and underflow are intended: no numpy FP event escapes."""
    bounds = np.array([-INF, -MAX, -1e300, -1.0, -SUB, -0.0, 0.0, SUB, TINY, 1e-300, 1.0, 1e300, MAX, INF])
    al, bl = np.meshgrid(bounds, bounds)
    al, bl = al.ravel(), bl.ravel()
    ok = (al <= bl) & (al < INF) & (bl > -INF)
    lo, hi = al[ok], bl[ok]  # every valid pair of bounds ([inf, inf] is not one)
    i, j = np.meshgrid(np.arange(lo.size), np.arange(lo.size))
    i, j = i.ravel(), j.ravel()
    with np.errstate(all="raise"):
        for f in (core.add, core.sub, core.mul, core.div, core.intersect, core.hull):
            f(lo[i], hi[i], lo[j], hi[j])
        for f in (core.neg, core.sqr, core.sqrt, core.absolute, core.sin, core.cos, core.width,
                  core.midpoint):
            f(lo, hi)
        for n in (-3, -2, -1, 0, 1, 2, 3, 8):
            core.pown(lo, hi, n)
        core.scale(-MAX, lo, hi)


# ---------------------------------------------------------------------------
# batched == elementwise
# ---------------------------------------------------------------------------

def _unary(core):
    return {
        "neg": core.neg, "sqr": core.sqr, "sqrt": core.sqrt, "absolute": core.absolute,
        "sin": core.sin, "cos": core.cos, "pown3": lambda l, h: core.pown(l, h, 3),
        "pown-2": lambda l, h: core.pown(l, h, -2), "pown4": lambda l, h: core.pown(l, h, 4),
        "width": lambda l, h: (core.width(l, h),) * 2,
        "midpoint": lambda l, h: (core.midpoint(l, h),) * 2,
    }


def _binary(core):
    return {"add": core.add, "sub": core.sub, "mul": core.mul, "div": core.div,
            "intersect": core.intersect, "hull": core.hull}


interval_lists = st.lists(intervals(unbounded=True), min_size=1, max_size=12)


def _same(u, v) -> bool:
    u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
    return bool(np.all((u == v) | (np.isnan(u) & np.isnan(v))))


@settings(PROPS, max_examples=200)
@given(interval_lists, interval_lists)
def test_batched_equals_elementwise(core, la, lb):
    n = min(len(la), len(lb))
    la, lb = la[:n], lb[:n]
    al, ah = (np.array(v) for v in zip(*la))
    bl, bh = (np.array(v) for v in zip(*lb))
    for name, f in _unary(core).items():
        lo, hi = f(al, ah)
        for i, a in enumerate(la):
            el, eh = f(*a)
            assert _same(lo[i], el) and _same(hi[i], eh), (name, a)
    for name, f in _binary(core).items():
        lo, hi = f(al, ah, bl, bh)
        for i, (a, b) in enumerate(zip(la, lb)):
            el, eh = f(*a, *b)
            assert _same(lo[i], el) and _same(hi[i], eh), (name, a, b)
    # a (B, n) box with broadcasting against a scalar interval
    lo, hi = core.mul(al[:, None], ah[:, None], np.array([[2.0, -3.0]]), np.array([[2.5, 0.5]]))
    assert lo.shape == (n, 2)
    for i in range(n):
        assert _same(lo[i, 1], core.mul(al[i], ah[i], -3.0, 0.5)[0])


# ---------------------------------------------------------------------------
# sin / cos
# ---------------------------------------------------------------------------


def _trig_arguments() -> np.ndarray:
    rng = np.random.default_rng(20240611)
    k = np.arange(-4000, 4001, dtype=float)
    near = np.concatenate([k * (np.pi / 2), k * np.pi / 2 + rng.uniform(-1e-7, 1e-7, k.size)])
    near = np.concatenate([near, np.nextafter(near, INF), np.nextafter(near, -INF)])
    return np.concatenate([
        rng.uniform(-10.0, 10.0, 170_000),
        rng.uniform(-1e6, 1e6, 10_000),
        rng.uniform(-1.0, 1.0, 2_000) * 10.0 ** rng.uniform(-300, 22, 2_000),
        near,
        [1e6, -1e6, 1e15, 2.0**52, 1e22, 1e300, MAX, SUB, TINY, 1e-310, 0.0],
    ])


def _point_trig(core):
    """(sin, cos) on float arrays as the core evaluates them at a point."""
    if core is I:
        return np.sin, np.cos
    return (lambda x: libm_trig(x, False)), (lambda x: libm_trig(x, True))


def test_numpy_trig_error_within_margin(core):
    """The core's sin/cos stay within TRIG_ULPS ulp (+ smallest normal) of mpmath.

    This documents the margin of :func:`verifier.interval.sin`/``cos``: over
    ~200k seeded arguments (uniform in [-10, 10], up to 1e6 and beyond, and
    next to multiples of pi/2) the error of numpy (compiled core: of libm as
    called by numba), measured against mpmath with 200 bits, must not exceed
    ``TRIG_ULPS * spacing(|result|) + tiny``.  Both a whole-array call and short
    calls (SIMD tails) are measured.
    """
    x = _trig_arguments()
    assert x.size >= 200_000
    worst = {}
    with mpmath.workprec(200):
        mpf = mpmath.mpf
        for name, npf, mpfun in zip(("sin", "cos"), _point_trig(core), (mpmath.sin, mpmath.cos)):
            xs = np.concatenate([x, x[:3000]])
            y = np.concatenate([npf(x), *(npf(x[i : i + 3]) for i in range(0, 3000, 3))])
            err = [abs(mpf(yi) - mpfun(xi)) for xi, yi in zip(xs.tolist(), y.tolist())]
            ulp = np.spacing(np.abs(y))
            margin = core.TRIG_ULPS * ulp
            err_f = np.array([float(e) for e in err])
            # exact check wherever the rounded error is not far below the margin
            for k in np.flatnonzero(err_f > 0.5 * (margin + TINY)):
                assert err[k] <= mpf(float(margin[k])) + TINY, (name, xs[k], y[k], err_f[k] / ulp[k])
            worst[name] = float(np.max(err_f / ulp))
    print(f"{core.__name__} worst error in ulp: {worst} (TRIG_ULPS = {core.TRIG_ULPS})")


@st.composite
def trig_intervals(draw):
    kind = draw(st.sampled_from(["uniform", "near_half_pi", "large", "any"]))
    if kind == "uniform":
        c = draw(st.floats(-10.0, 10.0))
    elif kind == "near_half_pi":
        c = draw(st.integers(-50, 50)) * (np.pi / 2) + draw(st.floats(-1e-9, 1e-9))
    elif kind == "large":
        c = draw(st.floats(-1e6, 1e6))
    else:
        c = draw(st.floats(-1e17, 1e17))
    w = draw(st.sampled_from([0.0, 1e-15, 1e-9, 1e-6, 1e-3, 0.5, 2.0, 3.2, 6.2, 6.3, 10.0]))
    w *= draw(st.floats(0.0, 1.0))
    lo = float(c)
    return lo, max(lo, float(lo + w))


def _extrema_inside(lo: float, hi: float, phase: flint.arb):
    """(has_max, has_min) of phase + k pi, k even/odd, certainly in [lo, hi]."""
    pi = flint.arb.pi()
    k0 = math.floor((lo - float(phase.mid())) / math.pi) - 2
    k1 = math.ceil((hi - float(phase.mid())) / math.pi) + 2
    has = [False, False]
    if k1 - k0 > 8:
        return True, True
    for k in range(k0, k1 + 1):
        t = phase + k * pi
        if flint.arb(lo) <= t and t <= flint.arb(hi):
            has[k % 2] = True
    return tuple(has)


def _trig_inside(fname: str, x: float, rl: float, rh: float) -> bool:
    """Rigorously decide ``f(x) in [rl, rh]`` with Arb, raising the precision
    while a bound is within the ball (cos(1e-300) = 1 - 5e-601 needs ~2000 bits)."""
    old = flint.ctx.prec
    try:
        for prec in (200, 800, 2400, 4400):
            flint.ctx.prec = prec
            v = getattr(flint.arb(x), fname)()
            ok_lo, bad_lo = flint.arb(rl) <= v, v < flint.arb(rl)
            ok_hi, bad_hi = v <= flint.arb(rh), flint.arb(rh) < v
            if bad_lo or bad_hi:
                return False
            if ok_lo and ok_hi:
                return True
        return False  # undecided at 4400 bits: x is far beyond float reach
    finally:
        flint.ctx.prec = old


@settings(PROPS, max_examples=1500)
@given(st.data(), trig_intervals())
def test_sin_cos_contain_exact(core, data, iv):
    lo, hi = iv
    pts = {lo, hi}
    for t in data.draw(st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3)):
        pts.add(float(min(hi, max(lo, lo + t * (hi - lo)))))
    old = flint.ctx.prec
    flint.ctx.prec = 200
    try:
        half_pi = flint.arb.pi() / 2
        for f, af, max_phase in ((core.sin, "sin", half_pi), (core.cos, "cos", flint.arb(0))):
            rl, rh = f(lo, hi)
            assert -1.0 <= rl <= rh <= 1.0
            for x in pts:
                assert _trig_inside(af, x, float(rl), float(rh)), (af, iv, x, rl, rh)
            has_max, has_min = _extrema_inside(lo, hi, max_phase)
            if has_max:
                assert rh == 1.0, (af, iv, rh)
            if has_min:
                assert rl == -1.0, (af, iv, rl)
            if hi - lo >= 2 * math.pi:
                assert (rl, rh) == (-1.0, 1.0)
    finally:
        flint.ctx.prec = old


#: The margin of sin/cos that docs/soundness.md (assumption E2) and docs/rounding.md state, in ulp of the result.
DOCUMENTED_TRIG_ULPS = 4


def test_sin_cos_apply_their_margin(core):
    """At a point ``x``, ``sin([x, x])`` and ``cos([x, x])`` reach at least the documented margin
    ``TRIG_ULPS * spacing(|f|) + tiny`` beyond the core's own point value ``f`` on both sides (clipped
    to ``[-1, 1]``; ``sin(0) = 0`` is exact), checked in exact rational arithmetic.

    The margin covers the error of numpy's (libm's) sin/cos, about half an ulp measured: containment
    tests against Arb pass with a quarter of it, so only this test notices a margin that is not
    applied in full (it fails in either backend with the margin halved).  Arguments: seeded, from
    every scale, next to the zeros and extrema, subnormal and huge.
    """
    assert core.TRIG_ULPS == DOCUMENTED_TRIG_ULPS  # a change of the margin changes docs and this test together
    rng = np.random.default_rng(43)
    k = rng.integers(-2000, 2001, 2000).astype(float)
    x = np.concatenate([
        rng.uniform(-10.0, 10.0, 4000),
        rng.choice([-1.0, 1.0], 2000) * 10.0 ** rng.uniform(-320.0, 300.0, 2000),
        k * (np.pi / 2) + rng.uniform(-1e-6, 1e-6, k.size),  # sin or cos near 0 or near +-1
        np.nextafter(k * np.pi, INF),
        [SUB, -SUB, 3 * SUB, TINY, -TINY, 1e-310, 0.5, 1.0, 2.0**52, 1e22, MAX, -MAX, -0.0, 0.0],
    ])
    tiny = Fraction(TINY)
    for name, point in zip(("sin", "cos"), _point_trig(core)):
        lo, hi = getattr(core, name)(x, x)
        f = point(x)
        binding = 0
        for xi, fi, li, hi_ in zip(x.tolist(), f.tolist(), lo.tolist(), hi.tolist()):
            if name == "sin" and xi == 0.0:
                assert li == hi_ == 0.0, (name, xi, li, hi_)
                continue
            m = DOCUMENTED_TRIG_ULPS * Fraction(float(np.spacing(abs(fi)))) + tiny
            want_lo, want_hi = max(Fraction(fi) - m, Fraction(-1)), min(Fraction(fi) + m, Fraction(1))
            assert Fraction(li) <= want_lo, (name, xi, fi, li, float(want_lo))
            assert Fraction(hi_) >= want_hi, (name, xi, fi, hi_, float(want_hi))
            binding += -1.0 < li or hi_ < 1.0
        # not vacuous: most enclosures have a bound not clipped to +-1 (the phase test clips huge arguments
        # and those next to an extremum)
        assert binding > 0.75 * x.size, (name, binding)


def test_sin_cos_special_intervals(core):
    assert core.sin(-INF, 0.0) == (-1.0, 1.0) and core.cos(0.0, INF) == (-1.0, 1.0)
    assert core.cos(0.0, 0.0)[1] == 1.0 and core.cos(-0.1, 0.1)[1] == 1.0
    assert core.sin(1.5, 1.6)[1] == 1.0 and core.sin(4.7, 4.8)[0] == -1.0
    assert core.cos(3.1, 3.2)[0] == -1.0
    lo, hi = core.sin(0.1, 0.2)
    assert 0.0 < lo < math.sin(0.1) and math.sin(0.2) < hi < 0.2
