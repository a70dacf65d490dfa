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
  to 0 from non-zero factors *is* widened to the smallest subnormal.  A finite
  numerator over an infinite divisor bound gives the bound 0 (its limit);
* ``sin`` and ``cos`` are not correctly rounded by numpy (its SIMD kernels
  promise a few ulp).  Their results are widened by :data:`TRIG_ULPS` ulp of
  the result plus the smallest normal number (then rounded outward), a margin
  checked against mpmath over many random arguments in the test-suite;
  ``sin(0) = 0`` is kept exact.

Operands are converted to float64 first (integer arrays would wrap around).
Overflow to infinity and underflow are intended outcomes of the rounding and
raise no numpy floating-point warnings.

An *empty* interval is any pair with ``lo > hi``.  Arithmetic functions assume
non-empty operands (the tracker tests emptiness after every intersection);
:func:`intersect`, :func:`hull`, :func:`is_empty` accept empties.
"""

from __future__ import annotations

import contextlib
import contextvars

import numpy as np

__all__ = [
    "quiet_fp",
    "next_up",
    "next_down",
    "next_up_keep0",
    "next_down_keep0",
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
_MAX = np.finfo(np.float64).max
_TWO_PI = 2.0 * np.pi


# Stepping from +-max to +-inf (or from a subnormal to 0) raises numpy's
# overflow/underflow flags; both are intended here, so they are silenced: the
# core must not warn (or raise under np.seterr(all="raise")) on valid input.
_QUIET = dict(over="ignore", under="ignore")


_QUIET_MODE = contextvars.ContextVar("crosscert_quiet_fp", default=False)
_NULL = contextlib.nullcontext()


def _fp(**flags):
    """``np.errstate(**flags)``, or nothing inside :func:`quiet_fp` (which already
    ignores every flag): entering ``np.errstate`` costs more than a ``nextafter``."""
    return _NULL if _QUIET_MODE.get() else np.errstate(**flags)


@contextlib.contextmanager
def quiet_fp():
    """Run a block of interval operations with numpy's FP flags ignored once.

    Results are unchanged (the operations only silence flags they expect);
    this only saves the per-operation cost of ``np.errstate``.  Code in the
    block must check for NaN/inf itself, as the tracker does.
    """
    token = _QUIET_MODE.set(True)
    try:
        with np.errstate(all="ignore"):
            yield
    finally:
        _QUIET_MODE.reset(token)


def next_down(r):
    """The next float below ``r``, elementwise: one outward step of a rounded lower bound."""
    with _fp(**_QUIET):
        return np.nextafter(r, -_INF)


def next_up(r):
    """The next float above ``r``, elementwise: one outward step of a rounded upper bound."""
    with _fp(**_QUIET):
        return np.nextafter(r, _INF)


def next_down_keep0(r):
    """:func:`next_down`, but an exact 0 stays 0 (a sum or difference that rounds to 0 is exact: gradual
    underflow)."""
    return np.where(r == 0.0, 0.0, next_down(r))


def next_up_keep0(r):
    """:func:`next_up`, but an exact 0 stays 0 (see :func:`next_down_keep0`)."""
    return np.where(r == 0.0, 0.0, next_up(r))


def point(x):
    """Degenerate interval ``[x, x]`` (no widening: ``x`` is a float)."""
    x = np.asarray(x, dtype=np.float64)
    return x, x.copy()


def empty_like(lo):
    """An empty interval (``lo = +inf > hi = -inf``) with the shape of ``lo``."""
    shape = np.shape(lo)
    return np.full(shape, _INF), np.full(shape, -_INF)


def _f64(*vs):
    # float64 before any arithmetic: integer arrays would wrap around silently
    return tuple(np.asarray(v, dtype=np.float64) for v in vs)


def add(al, ah, bl, bh):
    """``[a] + [b]``."""
    al, ah, bl, bh = _f64(al, ah, bl, bh)
    with _fp(over="ignore"):
        lo, hi = al + bl, ah + bh
    return next_down_keep0(lo), next_up_keep0(hi)


def sub(al, ah, bl, bh):
    """``[a] - [b]``."""
    al, ah, bl, bh = _f64(al, ah, bl, bh)
    with _fp(over="ignore"):
        lo, hi = al - bh, ah - bl
    return next_down_keep0(lo), next_up_keep0(hi)


def neg(al, ah):
    """``-[a]`` (exact)."""
    al, ah = _f64(al, ah)
    return -ah, -al


def scale(c, al, ah):
    """``c * [a]`` for a float (array) ``c``; same rounding as :func:`mul`."""
    c = np.asarray(c, dtype=np.float64)
    return mul(c, c, al, ah)


def mul(al, ah, bl, bh):
    """``[a] * [b]`` with ``0 * inf = 0`` (interval convention)."""
    al, ah, bl, bh = np.broadcast_arrays(*_f64(al, ah, bl, bh))
    a = np.stack((al, al, ah, ah))
    b = np.stack((bl, bh, bl, bh))
    with _fp(invalid="ignore", over="ignore", under="ignore"):
        p = a * b
    zero = (a == 0.0) | (b == 0.0)  # exactly zero products, including 0*inf
    lo = np.where(zero, 0.0, next_down(p)).min(axis=0)
    hi = np.where(zero, 0.0, next_up(p)).max(axis=0)
    return lo, hi


def _quot(x, y, step):
    """``step(x / y)`` for a bound of a quotient; exactly 0 when ``x = 0`` or when
    ``y`` is infinite (``x`` finite), where 0 is the limit the bound is taken as."""
    with _fp(invalid="ignore", divide="ignore", over="ignore", under="ignore"):
        q = x / y
    return np.where((x == 0.0) | (np.isinf(y) & np.isfinite(x)), 0.0, step(q))


def div(al, ah, bl, bh):
    """``[a] / [b]``: the hull of ``{x / y : x in [a], y in [b], y != 0}``.

    A divisor containing 0 gives a half-line or the entire line; ``[b] = [0, 0]``
    gives the empty interval.
    """
    al, ah, bl, bh = np.broadcast_arrays(*_f64(al, ah, bl, bh))
    a = np.stack((al, al, ah, ah))
    b = np.stack((bl, bh, bl, bh))
    # 0 not in [b]: x / y is monotone in x and in y, so the corners bound it.
    # An inf/inf corner (NaN) is no extremum: near it the quotient is bounded by
    # the corners (inf, finite bound of [b]) and (finite bound of [a], inf), or
    # [a] is the whole line and the other corners already give -inf and inf.
    lo_c = _quot(a, b, next_down)
    hi_c = _quot(a, b, next_up)
    lo = np.where(np.isnan(lo_c), _INF, lo_c).min(axis=0)
    hi = np.where(np.isnan(hi_c), -_INF, hi_c).max(axis=0)

    bz = (bl <= 0.0) & (bh >= 0.0)
    if np.any(bz):
        pos_side = (bl == 0.0) & (bh > 0.0)  # [0, bh]: y in (0, bh]
        neg_side = (bh == 0.0) & (bl < 0.0)  # [bl, 0]: y in [bl, 0)
        a_nonneg = al >= 0.0
        a_nonpos = ah <= 0.0
        zlo = np.full_like(lo, -_INF)
        zhi = np.full_like(hi, _INF)
        # [0, bh]: a >= 0 -> [al/bh, inf]; a <= 0 -> [-inf, ah/bh]
        zlo = np.where(pos_side & a_nonneg, _quot(al, bh, next_down), zlo)
        zhi = np.where(pos_side & a_nonpos, _quot(ah, bh, next_up), zhi)
        # [bl, 0]: a >= 0 -> [-inf, al/bl]; a <= 0 -> [ah/bl, inf]
        zhi = np.where(neg_side & a_nonneg, _quot(al, bl, next_up), zhi)
        zlo = np.where(neg_side & a_nonpos, _quot(ah, bl, next_down), zlo)
        # a straddling 0 or b straddling 0 keeps the entire line, except
        # [0, 0] / b (b not [0, 0]) = [0, 0]
        a_zero = a_nonneg & a_nonpos
        zlo = np.where(a_zero, 0.0, zlo)
        zhi = np.where(a_zero, 0.0, zhi)
        # a / [0, 0] = empty
        b_zero = (bl == 0.0) & (bh == 0.0)
        zlo = np.where(b_zero, _INF, zlo)
        zhi = np.where(b_zero, -_INF, zhi)
        lo = np.where(bz, zlo, lo)
        hi = np.where(bz, zhi, hi)
    return lo, hi


def sqr(al, ah):
    """``[a]^2``: lower bound clamped at 0; exact zero when 0 is a bound."""
    al = np.asarray(al, dtype=np.float64)
    ah = np.asarray(ah, dtype=np.float64)
    with _fp(over="ignore", under="ignore"):
        l2 = al * al
        h2 = ah * ah
    has0 = (al <= 0.0) & (ah >= 0.0)
    mn = np.minimum(l2, h2)
    mx = np.maximum(l2, h2)
    lo = np.where(has0, 0.0, np.maximum(next_down(mn), 0.0))
    # an exact 0 bound squared is exactly 0: leave it, otherwise widen
    hi_exact0 = (mx == 0.0) & (al == 0.0) & (ah == 0.0)
    hi = np.where(hi_exact0, 0.0, next_up(mx))
    return lo, hi


def _point_pow(v, n: int):
    """Enclosure of ``v**n`` (``n >= 1``) for a float array ``v`` by repeated squaring."""
    bl = bh = np.asarray(v, dtype=np.float64)
    rl = rh = None
    while True:
        if n & 1:
            # the first factor is taken as is (a copy: no aliasing of the input):
            # v**1 is exact, no 1 * v rounding
            rl, rh = (np.array(bl), np.array(bh)) if rl is None else mul(rl, rh, bl, bh)
        n >>= 1
        if not n:
            return rl, rh
        bl, bh = sqr(bl, bh)


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
    with _fp(invalid="ignore"):
        sl = np.sqrt(np.maximum(al, 0.0))
        sh = np.sqrt(np.maximum(ah, 0.0))
    lo = np.where(sl == 0.0, 0.0, np.maximum(next_down(sl), 0.0))
    hi = np.where(sh == 0.0, 0.0, next_up(sh))
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
    with _fp(under="ignore"):  # the spacing of a small r is subnormal
        return TRIG_ULPS * np.spacing(np.abs(r)) + _TINY_NORMAL


def _contains_phase(al, ah, phase):
    """Whether ``[al, ah]`` may contain ``phase + 2 k pi`` for an integer k.

    Conservative: a near miss counts as a hit (it only widens the result).
    """
    slack = 1e-9 * (1.0 + np.maximum(np.abs(al), np.abs(ah)))
    with _fp(invalid="ignore", under="ignore"):
        k_lo = np.ceil((al - phase) / _TWO_PI - slack)
        k_hi = np.floor((ah - phase) / _TWO_PI + slack)
    return k_lo <= k_hi


def _enclose_value(fun, x, zero_at_0):
    """Bounds of ``fun(x)`` at the float ``x``: numpy's value +- the margin."""
    with _fp(invalid="ignore", under="ignore"):  # sin(subnormal) underflows
        f = fun(x)
    m = _trig_margin(f)
    # rounded outward so that rounding f -+ m cannot eat into the margin
    lo, hi = next_down(f - m), next_up(f + m)
    if zero_at_0:  # sin(0) = 0 exactly: an exact zero is not widened
        lo = np.where(x == 0.0, 0.0, lo)
        hi = np.where(x == 0.0, 0.0, hi)
    return lo, hi


def _periodic(fun, al, ah, max_phase, min_phase, zero_at_0=False):
    al = np.asarray(al, dtype=np.float64)
    ah = np.asarray(ah, dtype=np.float64)
    finite = np.isfinite(al) & np.isfinite(ah)
    la, ha = _enclose_value(fun, np.where(finite, al, 0.0), zero_at_0)
    lb, hb = _enclose_value(fun, np.where(finite, ah, 0.0), zero_at_0)
    lo = np.minimum(la, lb)
    hi = np.maximum(ha, hb)
    lo = np.where(_contains_phase(al, ah, min_phase), -1.0, lo)
    hi = np.where(_contains_phase(al, ah, max_phase), 1.0, hi)
    with _fp(invalid="ignore", over="ignore"):
        full = ~finite | ((ah - al) >= _TWO_PI)
    lo = np.where(full, -1.0, np.maximum(lo, -1.0))
    hi = np.where(full, 1.0, np.minimum(hi, 1.0))
    return lo, hi


def sin(al, ah):
    """``sin([a])`` with the margin :data:`TRIG_ULPS`; range-reduced soundly."""
    return _periodic(np.sin, al, ah, 0.5 * np.pi, -0.5 * np.pi, zero_at_0=True)


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
    with _fp(invalid="ignore", over="ignore"):
        w = next_up(np.asarray(ah) - np.asarray(al))
    return np.where(is_empty(al, ah), 0.0, np.where(np.asarray(ah) == np.asarray(al), 0.0, w))


def midpoint(al, ah):
    """A float inside each non-empty interval (finite whenever possible)."""
    al = np.asarray(al, dtype=np.float64)
    ah = np.asarray(ah, dtype=np.float64)
    with _fp(invalid="ignore", over="ignore", under="ignore"):
        m = 0.5 * al + 0.5 * ah  # no overflow, unlike (al + ah) / 2 (clipped below)
    m = np.where(np.isneginf(al) & np.isposinf(ah), 0.0, m)
    # half-lines: a finite point inside, away from the finite bound
    with _fp(over="ignore"):
        # (2 * bound saturated at +-max: 2 * (-1e308) overflows to -inf, not inside)
        m = np.where(np.isneginf(al) & np.isfinite(ah),
                     np.where(ah >= 0.0, 0.0, np.maximum(2.0 * ah, -_MAX)), m)
        m = np.where(np.isposinf(ah) & np.isfinite(al),
                     np.where(al <= 0.0, 0.0, np.minimum(2.0 * al, _MAX)), m)
    return np.clip(m, al, ah)


def contains(al, ah, x):
    """Boolean mask: ``x`` in ``[a]``."""
    return (np.asarray(al) <= x) & (x <= np.asarray(ah))
