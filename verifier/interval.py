"""Batched float64 interval arithmetic with outward rounding.

An interval ``[a]`` is a pair of numpy arrays ``(lo, hi)`` of the same shape;
every function here works elementwise on whole batches, so one call advances
many scenarios (or many vector components) at once.  A box of dimension ``n``
for ``B`` scenarios is a pair of arrays of shape ``(B, n)``.

Rounding model
--------------
numpy evaluates ``+ - * / sqrt`` in round-to-nearest, which IEEE 754 makes
correctly rounded: the computed value is within half an ulp of the exact one.
Moving a lower bound one float down (``nextafter(r, -inf)``) and an upper bound
one float up therefore always yields a rigorous enclosure.  Two refinements:

* a result that is *exactly* zero is not widened: a sum or difference that
  rounds to 0 is exactly 0 (gradual underflow), and a product or quotient is
  exactly 0 only when a factor (the numerator) is 0; a product that underflows
  to 0 from non-zero factors *is* widened to the smallest subnormal;
* ``sin`` and ``cos`` are not correctly rounded by numpy (its SIMD kernels
  promise a few ulp).  Their results are widened by :data:`TRIG_ULPS` ulp of
  the result plus the smallest normal number, a margin checked against
  mpmath over many random arguments in the test-suite.

An *empty* interval is any pair with ``lo > hi``.  Arithmetic functions assume
non-empty operands (the tracker tests emptiness after every intersection);
:func:`intersect`, :func:`hull`, :func:`is_empty` accept empties.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "TRIG_ULPS",
    "add",
    "sub",
    "neg",
    "mul",
    "div",
    "sqr",
    "pown",
    "sqrt",
    "absolute",
    "sin",
    "cos",
    "scale",
    "intersect",
    "hull",
    "is_empty",
    "width",
    "midpoint",
    "contains",
    "point",
    "empty_like",
]

_INF = np.inf
#: Margin (in ulp of the result) added on both sides of numpy's sin/cos.
TRIG_ULPS = 4
_TINY_NORMAL = np.finfo(np.float64).tiny
_TWO_PI = 2.0 * np.pi


def _dn(r):
    return np.nextafter(r, -_INF)


def _up(r):
    return np.nextafter(r, _INF)


def _dn_keep0(r):
    # Sums/differences that round to 0 are exactly 0 (gradual underflow).
    return np.where(r == 0.0, 0.0, np.nextafter(r, -_INF))


def _up_keep0(r):
    return np.where(r == 0.0, 0.0, np.nextafter(r, _INF))


def point(x):
    """Degenerate interval ``[x, x]`` (no widening: ``x`` is a float)."""
    x = np.asarray(x, dtype=np.float64)
    return x, x.copy()


def empty_like(lo):
    """An empty interval (``lo = +inf > hi = -inf``) with the shape of ``lo``."""
    shape = np.shape(lo)
    return np.full(shape, _INF), np.full(shape, -_INF)


def add(al, ah, bl, bh):
    """``[a] + [b]``."""
    return _dn_keep0(al + bl), _up_keep0(ah + bh)


def sub(al, ah, bl, bh):
    """``[a] - [b]``."""
    return _dn_keep0(al - bh), _up_keep0(ah - bl)


def neg(al, ah):
    """``-[a]`` (exact)."""
    return -ah, -al


def scale(c, al, ah):
    """``c * [a]`` for a float (array) ``c``; same rounding as :func:`mul`."""
    c = np.asarray(c, dtype=np.float64)
    return mul(c, c, al, ah)


def mul(al, ah, bl, bh):
    """``[a] * [b]`` with ``0 * inf = 0`` (interval convention)."""
    al, ah, bl, bh = np.broadcast_arrays(al, ah, bl, bh)
    a = np.stack((al, al, ah, ah))
    b = np.stack((bl, bh, bl, bh))
    with np.errstate(invalid="ignore", over="ignore", under="ignore"):
        p = a * b
    zero = (a == 0.0) | (b == 0.0)  # exactly zero products, including 0*inf
    lo = np.where(zero, 0.0, np.nextafter(p, -_INF)).min(axis=0)
    hi = np.where(zero, 0.0, np.nextafter(p, _INF)).max(axis=0)
    return lo, hi


def div(al, ah, bl, bh):
    """``[a] / [b]``: the hull of ``{x / y : x in [a], y in [b], y != 0}``.

    A divisor containing 0 gives a half-line or the entire line; ``[b] = [0, 0]``
    gives the empty interval.
    """
    al, ah, bl, bh = np.broadcast_arrays(
        *(np.asarray(v, dtype=np.float64) for v in (al, ah, bl, bh))
    )
    a = np.stack((al, al, ah, ah))
    b = np.stack((bl, bh, bl, bh))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore", under="ignore"):
        qt = a / b
    zero = a == 0.0
    # inf/inf quotients only arise with unbounded operands; they bound nothing.
    bad = np.isnan(qt)
    lo = np.where(zero, 0.0, np.where(bad, -_INF, np.nextafter(qt, -_INF))).min(axis=0)
    hi = np.where(zero, 0.0, np.where(bad, _INF, np.nextafter(qt, _INF))).max(axis=0)

    bz = (bl <= 0.0) & (bh >= 0.0)
    if np.any(bz):
        with np.errstate(invalid="ignore", divide="ignore", over="ignore", under="ignore"):
            a_zero = (al == 0.0) & (ah == 0.0)
            a_has0 = (al <= 0.0) & (ah >= 0.0)
            b_zero = (bl == 0.0) & (bh == 0.0)
            pos_side = bz & (bl == 0.0) & (bh > 0.0)  # [0, bh]
            neg_side = bz & (bh == 0.0) & (bl < 0.0)  # [bl, 0]
            zlo = np.full_like(lo, -_INF)
            zhi = np.full_like(hi, _INF)
            # [0, bh]: a > 0 -> [al/bh, inf]; a < 0 -> [-inf, ah/bh]
            m = pos_side & (al > 0.0)
            zlo = np.where(m, _dn(al / bh), zlo)
            m = pos_side & (ah < 0.0)
            zhi = np.where(m, _up(ah / bh), zhi)
            # [bl, 0]: a > 0 -> [-inf, al/bl]; a < 0 -> [ah/bl, inf]
            m = neg_side & (al > 0.0)
            zhi = np.where(m, _up(al / bl), zhi)
            m = neg_side & (ah < 0.0)
            zlo = np.where(m, _dn(ah / bl), zlo)
            # a containing 0 (not only 0) or b straddling 0: entire line.
            straddle = bz & ((bl < 0.0) & (bh > 0.0) | (a_has0 & ~a_zero))
            zlo = np.where(straddle, -_INF, zlo)
            zhi = np.where(straddle, _INF, zhi)
            # [0, 0] / b (b not [0, 0]) = [0, 0]
            zlo = np.where(a_zero, 0.0, zlo)
            zhi = np.where(a_zero, 0.0, zhi)
            # a / [0, 0] = empty
            zlo = np.where(b_zero, _INF, zlo)
            zhi = np.where(b_zero, -_INF, zhi)
            lo = np.where(bz, zlo, lo)
            hi = np.where(bz, zhi, hi)
    return lo, hi


def sqr(al, ah):
    """``[a]^2``: lower bound clamped at 0; exact zero when 0 is a bound."""
    al = np.asarray(al, dtype=np.float64)
    ah = np.asarray(ah, dtype=np.float64)
    with np.errstate(over="ignore", under="ignore"):
        l2 = al * al
        h2 = ah * ah
    has0 = (al <= 0.0) & (ah >= 0.0)
    mn = np.minimum(l2, h2)
    mx = np.maximum(l2, h2)
    lo = np.where(has0, 0.0, np.maximum(np.nextafter(mn, -_INF), 0.0))
    # an exact 0 bound squared is exactly 0: leave it, otherwise widen
    hi_exact0 = (mx == 0.0) & (al == 0.0) & (ah == 0.0)
    hi = np.where(hi_exact0, 0.0, np.nextafter(mx, _INF))
    return lo, hi


def _point_pow(v, n: int):
    """Enclosure of ``v**n`` for a float array ``v`` by repeated squaring."""
    rl, rh = np.ones(np.shape(v)), np.ones(np.shape(v))
    bl, bh = np.asarray(v, dtype=np.float64), np.asarray(v, dtype=np.float64)
    while n:
        if n & 1:
            rl, rh = mul(rl, rh, bl, bh)
        n >>= 1
        if n:
            bl, bh = sqr(bl, bh)
    return rl, rh


def pown(al, ah, n: int):
    """``[a]^n`` for an integer ``n`` (even powers are non-negative).

    ``x -> x^n`` is monotone on ``[0, inf)`` (even ``n``, applied to ``|[a]|``)
    or on the whole line (odd ``n``), so only the bounds are powered.
    """
    al = np.asarray(al, dtype=np.float64)
    ah = np.asarray(ah, dtype=np.float64)
    if n < 0:
        lo, hi = pown(al, ah, -n)
        return div(1.0, 1.0, lo, hi)
    if n == 0:
        one = np.ones(np.broadcast(al, ah).shape)
        return one, one.copy()
    if n % 2 == 0:
        al, ah = absolute(al, ah)
    lo = _point_pow(al, n)[0]
    hi = _point_pow(ah, n)[1]
    if n % 2 == 0:
        lo = np.maximum(lo, 0.0)
    return lo, hi


def sqrt(al, ah):
    """``sqrt([a] ∩ [0, inf))``; empty when ``[a] < 0``."""
    al = np.asarray(al, dtype=np.float64)
    ah = np.asarray(ah, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        sl = np.sqrt(np.maximum(al, 0.0))
        sh = np.sqrt(np.maximum(ah, 0.0))
    lo = np.where(sl == 0.0, 0.0, np.maximum(np.nextafter(sl, -_INF), 0.0))
    hi = np.where(sh == 0.0, 0.0, np.nextafter(sh, _INF))
    neg_only = ah < 0.0
    lo = np.where(neg_only, _INF, lo)
    hi = np.where(neg_only, -_INF, hi)
    return lo, hi


def absolute(al, ah):
    """``|[a]|`` (exact)."""
    al = np.asarray(al, dtype=np.float64)
    ah = np.asarray(ah, dtype=np.float64)
    lo = np.where(al >= 0.0, al, np.where(ah <= 0.0, -ah, 0.0))
    hi = np.maximum(np.abs(al), np.abs(ah))
    return lo, hi


def _trig_margin(r):
    return TRIG_ULPS * np.spacing(np.abs(r)) + _TINY_NORMAL


def _contains_phase(al, ah, phase):
    """Whether ``[al, ah]`` may contain ``phase + 2 k pi`` for an integer k.

    Conservative: a near miss counts as a hit (it only widens the result).
    """
    slack = 1e-9 * (1.0 + np.maximum(np.abs(al), np.abs(ah)))
    with np.errstate(invalid="ignore"):
        k_lo = np.ceil((al - phase) / _TWO_PI - slack)
        k_hi = np.floor((ah - phase) / _TWO_PI + slack)
    return k_lo <= k_hi


def _periodic(fun, al, ah, max_phase, min_phase):
    al = np.asarray(al, dtype=np.float64)
    ah = np.asarray(ah, dtype=np.float64)
    finite = np.isfinite(al) & np.isfinite(ah)
    with np.errstate(invalid="ignore"):
        fa = fun(np.where(finite, al, 0.0))
        fb = fun(np.where(finite, ah, 0.0))
    lo = np.minimum(fa - _trig_margin(fa), fb - _trig_margin(fb))
    hi = np.maximum(fa + _trig_margin(fa), fb + _trig_margin(fb))
    lo = np.where(_contains_phase(al, ah, min_phase), -1.0, lo)
    hi = np.where(_contains_phase(al, ah, max_phase), 1.0, hi)
    full = ~finite | ((ah - al) >= _TWO_PI)
    lo = np.where(full, -1.0, np.maximum(lo, -1.0))
    hi = np.where(full, 1.0, np.minimum(hi, 1.0))
    return lo, hi


def sin(al, ah):
    """``sin([a])`` with the margin :data:`TRIG_ULPS`; range-reduced soundly."""
    return _periodic(np.sin, al, ah, 0.5 * np.pi, -0.5 * np.pi)


def cos(al, ah):
    """``cos([a])`` with the margin :data:`TRIG_ULPS`; range-reduced soundly."""
    return _periodic(np.cos, al, ah, 0.0, np.pi)


def intersect(al, ah, bl, bh):
    """``[a] ∩ [b]`` (empty when ``lo > hi``)."""
    return np.maximum(al, bl), np.minimum(ah, bh)


def hull(al, ah, bl, bh):
    """Interval hull of ``[a] ∪ [b]``; an empty operand is ignored."""
    ea = al > ah
    eb = bl > bh
    lo = np.where(ea, bl, np.where(eb, al, np.minimum(al, bl)))
    hi = np.where(ea, bh, np.where(eb, ah, np.maximum(ah, bh)))
    return lo, hi


def is_empty(al, ah):
    """Boolean mask of empty intervals."""
    return ~(np.asarray(al) <= np.asarray(ah))


def width(al, ah):
    """Upper bound of ``hi - lo`` (0 for an empty interval)."""
    with np.errstate(invalid="ignore"):
        w = np.nextafter(np.asarray(ah) - np.asarray(al), _INF)
    return np.where(is_empty(al, ah), 0.0, np.where(np.asarray(ah) == np.asarray(al), 0.0, w))


def midpoint(al, ah):
    """A float inside each non-empty interval (finite whenever possible)."""
    al = np.asarray(al, dtype=np.float64)
    ah = np.asarray(ah, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        m = 0.5 * al + 0.5 * ah  # no overflow, unlike (al + ah) / 2
    m = np.where(np.isneginf(al) & np.isposinf(ah), 0.0, m)
    # half-lines: a finite point inside, away from the finite bound
    with np.errstate(over="ignore"):
        m = np.where(np.isneginf(al) & np.isfinite(ah), np.where(ah >= 0.0, 0.0, 2.0 * ah), m)
        m = np.where(np.isposinf(ah) & np.isfinite(al), np.where(al <= 0.0, 0.0, 2.0 * al), m)
    return np.clip(m, al, ah)


def contains(al, ah, x):
    """Boolean mask: ``x`` in ``[a]``."""
    return (np.asarray(al) <= x) & (x <= np.asarray(ah))
