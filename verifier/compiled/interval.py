"""Scalar interval operations compiled with numba: the kernels' arithmetic.

Each function takes and returns bounds as plain floats (``lo, hi`` pairs) and
follows :mod:`verifier.interval` operation for operation, so that a kernel and
the numpy reference compute the same floats: round-to-nearest IEEE operations,
then one ``nextafter`` step outward; exact zeros of sums, differences,
products and quotients are kept; ``sin``/``cos`` carry :data:`TRIG_ULPS` ulp
of margin plus the smallest normal.  See docs/rounding.md.

Compiled with numba's default flags: no ``fastmath`` (which would allow
reassociation and FMA contraction, both unsound for directed steps); a test
checks that ``a * b + c`` stays two rounded operations.
"""

from __future__ import annotations

import collections
import math
import threading
import types as pytypes

import numpy as np
from llvmlite import ir
from numba import config as numba_config
from numba import njit, types
from numba.core.registry import CPUDispatcher
from numba.extending import intrinsic

from ..interval import TRIG_ULPS

INF = np.inf
TINY_NORMAL = float(np.finfo(np.float64).tiny)
MAX = float(np.finfo(np.float64).max)
TWO_PI = 2.0 * math.pi
_TRIG_ULPS = float(TRIG_ULPS)

#: The flags of every kernel.  Without numba's runtime (``_nrt=False``): the
#: kernels never allocate, and with the runtime every array passed to a callee
#: costs an atomic reference-count increment and decrement, a third of the
#: tracker's time (benchmarks/README.md).
KERNEL_FLAGS = {"nogil": True, "_nrt": False}
#: Options of a kernel only compiled code calls: no CPython wrapper (the
#: unboxing of every argument, with an inlined copy of the body) and no C
#: wrapper; numba compiles and optimises each function's library with all it
#: calls, so the wrappers cost in every caller's compilation too.
NO_WRAPPERS = {"no_cpython_wrapper": True, "no_cfunc_wrapper": True}


class Kernel(CPUDispatcher):
    """A numba dispatcher compiled without the CPython and C wrappers
    (:data:`NO_WRAPPERS`): for kernels that only other compiled code calls.

    numba would call such a function from Python through a null address, so a
    call from Python (tests, a session) runs a *twin* instead: the same Python
    function compiled with the same options and the wrappers, built on the
    first such call.  The drivers that :mod:`verifier` calls are entry points
    with wrappers (:data:`cached_jit`); :attr:`python_calls` counts the calls
    that went through a twin, by kernel name (tests check that the package's
    own calls never do)."""

    python_calls: collections.Counter = collections.Counter()
    _twin_lock = threading.Lock()

    def __call__(self, *args, **kwargs):
        twin = self.__dict__.get("_twin")
        if twin is None:
            with Kernel._twin_lock:
                twin = self.__dict__.get("_twin")
                if twin is None:
                    f = self.py_func
                    # a function object of its own: numba tells a recursion by the function object, and
                    # a recursive kernel's twin calls the kernel itself
                    fn = pytypes.FunctionType(f.__code__, f.__globals__, f.__name__, f.__defaults__, f.__closure__)
                    fn.__qualname__, fn.__module__, fn.__doc__ = f.__qualname__, f.__module__, f.__doc__
                    options = {k: v for k, v in self.targetoptions.items() if k not in NO_WRAPPERS}
                    twin = self.__dict__["_twin"] = CPUDispatcher(py_func=fn, locals=self.locals,
                                                                 targetoptions=options)
        Kernel.python_calls[self.py_func.__qualname__] += 1
        return twin(*args, **kwargs)


def kernel(**options):
    """Decorator: a :class:`Kernel` with numba's ``options`` (and :data:`NO_WRAPPERS`)."""

    def build(fn):
        if numba_config.DISABLE_JIT:
            return fn
        return Kernel(py_func=fn, locals={}, targetoptions={**options, **NO_WRAPPERS})

    return build


#: The decorator of every kernel called from other kernels.  Not cached on its
#: own: numba caches the machine code of a top-level kernel (the step drivers,
#: the first sample's branch and prune) with everything it calls, and caching
#: each callee too would generate the machine code of its whole call tree once
#: more per callee at the first run (most of the compilation time).
jit = kernel(**KERNEL_FLAGS)
#: The entry points called from Python (the step drivers of
#: :mod:`verifier.compiled.step` add ``parallel``): with numba's wrappers,
#: cached on disk with all they call; the caller allocates.
cached_jit = njit(cache=True, **KERNEL_FLAGS)
#: Kernels inlined into their callers' IR before typing (numba's ``inline="always"``): no compiled
#: function of their own.  numba optimises and generates the machine code of each compiled function's
#: library with all it calls linked in, so a large kernel called from one place only costs that work
#: once more as a function of its own (measured side by side; benchmarks/README.md's git history).
inline_jit = kernel(inline="always", **KERNEL_FLAGS)
#: IEEE division as numpy's (x / 0 is inf or NaN): numba's default raises
#: ZeroDivisionError, which an empty divisor such as [0.3, 0] reached.
_ieee_jit = kernel(error_model="numpy", **KERNEL_FLAGS)


@intrinsic
def _bits(typingctx, x):
    """The IEEE 754 bit pattern of a float64, as an int64 (no conversion)."""
    if x != types.float64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return types.int64(types.float64), codegen


@intrinsic
def _float(typingctx, i):
    """The float64 whose bit pattern is the int64 ``i``."""
    if i != types.int64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(types.int64), codegen


@jit
def up(r):
    """The float above ``r`` (``np.nextafter(r, inf)``, on the bit pattern).

    Positive floats are ordered like their bit patterns, negative ones
    reversedly; the steps from ``+-0`` and the fixed points ``inf``, NaN are
    handled first.
    """
    if r != r or r == INF:
        return r
    if r == 0.0:
        return 5e-324
    b = _bits(r)
    return _float(b + 1 if b > 0 else b - 1)


@jit
def dn(r):
    """The float below ``r`` (``np.nextafter(r, -inf)``)."""
    if r != r or r == -INF:
        return r
    if r == 0.0:
        return -5e-324
    b = _bits(r)
    return _float(b - 1 if b > 0 else b + 1)


@jit
def dn0(r):
    # sums/differences that round to 0 are exactly 0 (gradual underflow)
    return 0.0 if r == 0.0 else dn(r)


@jit
def up0(r):
    return 0.0 if r == 0.0 else up(r)


@jit
def add(al, ah, bl, bh):
    """``[a] + [b]``."""
    return dn0(al + bl), up0(ah + bh)


@jit
def sub(al, ah, bl, bh):
    """``[a] - [b]``."""
    return dn0(al - bh), up0(ah - bl)


@jit
def neg(al, ah):
    return -ah, -al


@jit
def _corner_dn(a, b):
    return 0.0 if (a == 0.0 or b == 0.0) else dn(a * b)


@jit
def _corner_up(a, b):
    return 0.0 if (a == 0.0 or b == 0.0) else up(a * b)


@jit
def mul(al, ah, bl, bh):
    """``[a] * [b]`` with ``0 * inf = 0``.

    Bounds all nonzero (the common case): the four corner products are finite
    or infinite, never NaN, and only their extremes are rounded; a rounded
    extreme that lands on 0 (underflow) takes the general path, which settles
    the sign of a zero bound as the reference does.
    """
    if al != 0.0 and ah != 0.0 and bl != 0.0 and bh != 0.0 and al == al and ah == ah and bl == bl and bh == bh:
        p1 = al * bl
        p2 = al * bh
        p3 = ah * bl
        p4 = ah * bh
        lo = dn(min(min(p1, p2), min(p3, p4)))
        hi = up(max(max(p1, p2), max(p3, p4)))
        if lo != 0.0 and hi != 0.0:
            return lo, hi
    return _mul_general(al, ah, bl, bh)


@jit
def _mul_general(al, ah, bl, bh):
    """:func:`mul` for any bounds.

    The reference rounds each of the four corner products outward and takes
    the extremes; ``nextafter`` is monotone, so rounding only the extreme
    products gives the same floats with two steps instead of eight.  Products
    with a zero factor are exactly 0 and never widened.  A bound equal to 0 is
    recomputed corner by corner, in the reference's order, so that even the
    sign of a zero bound is the reference's.
    """
    lo = INF
    hi = -INF
    regular = False
    zero = False
    for a, b in ((al, bl), (al, bh), (ah, bl), (ah, bh)):
        if a == 0.0 or b == 0.0:
            zero = True
        else:
            p = a * b
            lo = minn(lo, p)
            hi = maxn(hi, p)
            regular = True
    if regular:
        lo = dn(lo)
        hi = up(hi)
    if zero:
        lo = minn(lo, 0.0)
        hi = maxn(hi, 0.0)
    if lo == 0.0:
        lo = minn(minn(minn(_corner_dn(al, bl), _corner_dn(al, bh)), _corner_dn(ah, bl)), _corner_dn(ah, bh))
    if hi == 0.0:
        hi = maxn(maxn(maxn(_corner_up(al, bl), _corner_up(al, bh)), _corner_up(ah, bl)), _corner_up(ah, bh))
    return lo, hi


@jit
def pmul(c, bl, bh):
    """``c [b]`` for a float ``c``: :func:`mul` ``(c, c, bl, bh)``, the same floats.

    Its four corner products are two products computed twice (the same
    operands, the same rounding), so two suffice; the extremes, their
    rounding and the fallback are :func:`mul`'s.  The linear algebra's
    products by a point matrix take this path (tests/test_compiled_interval.py).
    """
    if c != 0.0 and bl != 0.0 and bh != 0.0 and c == c and bl == bl and bh == bh:
        p1 = c * bl
        p2 = c * bh
        lo = dn(min(p1, p2))
        hi = up(max(p1, p2))
        if lo != 0.0 and hi != 0.0:
            return lo, hi
    return _mul_general(c, c, bl, bh)


@jit
def scale(c, al, ah):
    """``c [a]`` for a float ``c``."""
    return pmul(c, al, ah)


@jit
def _quot_dn(x, y):
    # a lower bound of x / y; exactly 0 for x = 0 or y infinite (x finite)
    if x == 0.0 or (math.isinf(y) and math.isfinite(x)):
        return 0.0
    return dn(x / y)


@jit
def _quot_up(x, y):
    if x == 0.0 or (math.isinf(y) and math.isfinite(x)):
        return 0.0
    return up(x / y)


@jit
def _nan_inf(v, repl):
    return repl if v != v else v


@_ieee_jit
def div(al, ah, bl, bh):
    """``[a] / [b]``: hull of ``{x / y : y != 0}`` (see :func:`verifier.interval.div`).

    Ordered operands, divisor finite and of one sign, dividend bounds nonzero
    (the common case):
    the quotient is monotone in each operand, so the signs name the two
    corners where it is least and greatest; round to nearest is monotone
    too, so those two quotients, rounded outward, are the extremes of the
    reference's four (two divisions instead of four).  A bound rounded to 0
    (underflow) takes the general path, as in :func:`mul`.
    """
    if (bl > 0.0 or bh < 0.0) and bl <= bh and math.isfinite(bl) and math.isfinite(bh) and al <= ah \
            and al != 0.0 and ah != 0.0:  # ordered (not empty, not NaN) operands only
        if bl > 0.0:
            if al > 0.0:
                lo, hi = al / bh, ah / bl
            elif ah < 0.0:
                lo, hi = al / bl, ah / bh
            else:
                lo, hi = al / bl, ah / bl
        elif al > 0.0:
            lo, hi = ah / bh, al / bl
        elif ah < 0.0:
            lo, hi = ah / bl, al / bh
        else:
            lo, hi = ah / bh, al / bh
        lo = dn(lo)
        hi = up(hi)
        if lo != 0.0 and hi != 0.0:
            return lo, hi
    return _div_general(al, ah, bl, bh)


@_ieee_jit
def _div_general(al, ah, bl, bh):
    """:func:`div` for any bounds."""
    if bl <= 0.0 and bh >= 0.0:
        a_nonneg = al >= 0.0
        a_nonpos = ah <= 0.0
        if bl == 0.0 and bh == 0.0:
            return INF, -INF
        if a_nonneg and a_nonpos:
            return 0.0, 0.0
        lo = -INF
        hi = INF
        if bl == 0.0 and bh > 0.0:
            if a_nonneg:
                lo = _quot_dn(al, bh)
            if a_nonpos:
                hi = _quot_up(ah, bh)
        elif bh == 0.0 and bl < 0.0:
            if a_nonneg:
                hi = _quot_up(al, bl)
            if a_nonpos:
                lo = _quot_dn(ah, bl)
        return lo, hi
    # 0 not in [b]: the corners bound the quotient; an inf/inf corner (NaN) is
    # no extremum and is skipped; as in mul, only the extremes are rounded
    lo = INF
    hi = -INF
    regular = False
    zero = False
    for x, y in ((al, bl), (al, bh), (ah, bl), (ah, bh)):
        if x == 0.0 or (math.isinf(y) and math.isfinite(x)):
            zero = True
        else:
            q = x / y
            if q == q:
                lo = min(lo, q)
                hi = max(hi, q)
                regular = True
    if regular:
        lo = dn(lo)
        hi = up(hi)
    if zero:
        lo = min(lo, 0.0)
        hi = max(hi, 0.0)
    if lo == 0.0:  # the reference's sign of zero: corner by corner, in order
        lo = minn(minn(minn(_nan_inf(_quot_dn(al, bl), INF), _nan_inf(_quot_dn(al, bh), INF)),
                       _nan_inf(_quot_dn(ah, bl), INF)), _nan_inf(_quot_dn(ah, bh), INF))
    if hi == 0.0:
        hi = maxn(maxn(maxn(_nan_inf(_quot_up(al, bl), -INF), _nan_inf(_quot_up(al, bh), -INF)),
                       _nan_inf(_quot_up(ah, bl), -INF)), _nan_inf(_quot_up(ah, bh), -INF))
    return lo, hi


@jit
def sqr(al, ah):
    """``[a]^2``, lower bound clamped at 0."""
    l2 = al * al
    h2 = ah * ah
    mn = min(l2, h2)
    mx = max(l2, h2)
    if al <= 0.0 and ah >= 0.0:
        lo = 0.0
    else:
        lo = max(dn(mn), 0.0)
    if mx == 0.0 and al == 0.0 and ah == 0.0:
        hi = 0.0
    else:
        hi = up(mx)
    return lo, hi


@jit
def absolute(al, ah):
    """``|[a]|`` (exact)."""
    if al >= 0.0:
        lo = al
    elif ah <= 0.0:
        lo = -ah
    else:
        lo = 0.0
    return lo, max(abs(al), abs(ah))


@jit
def _point_pow(v, n):
    # repeated squaring in the order of verifier.interval._point_pow
    bl = v
    bh = v
    rl = 0.0
    rh = 0.0
    first = True
    while True:
        if n & 1:
            if first:
                rl, rh = bl, bh
                first = False
            else:
                rl, rh = mul(rl, rh, bl, bh)
        n >>= 1
        if n == 0:
            return rl, rh
        bl, bh = sqr(bl, bh)


@jit
def pown(al, ah, n):
    """``[a]^n`` for an integer ``n``."""
    if n < 0:
        lo, hi = pown(al, ah, -n)
        return div(1.0, 1.0, lo, hi)
    if n == 0:
        return 1.0, 1.0
    if n % 2 == 0:
        al, ah = absolute(al, ah)
    lo = _point_pow(al, n)[0]
    hi = _point_pow(ah, n)[1]
    if n % 2 == 0:
        lo = max(lo, 0.0)
    return lo, hi


@jit
def sqrt(al, ah):
    """``sqrt([a] ∩ [0, inf))``; empty when ``[a] < 0``."""
    if ah < 0.0:
        return INF, -INF
    sl = math.sqrt(max(al, 0.0))
    sh = math.sqrt(max(ah, 0.0))
    lo = 0.0 if sl == 0.0 else max(dn(sl), 0.0)
    hi = 0.0 if sh == 0.0 else up(sh)
    return lo, hi


@jit
def _spacing(r):
    # ulp of a finite non-negative r: the gap to the next float (exact)
    return up(r) - r


@jit
def _margin(r):
    return _TRIG_ULPS * _spacing(abs(r)) + TINY_NORMAL


@jit
def _contains_phase(al, ah, phase):
    slack = 1e-9 * (1.0 + max(abs(al), abs(ah)))
    # np.ceil/np.floor stay float as in numpy: math.ceil/floor return int64 in
    # numba, undefined beyond 2**63 (|x| > 5.8e19 gave a different answer)
    k_lo = np.ceil((al - phase) / TWO_PI - slack)
    k_hi = np.floor((ah - phase) / TWO_PI + slack)
    return k_lo <= k_hi


@jit
def _enclose_sin(x):
    f = math.sin(x)
    m = _margin(f)
    if x == 0.0:
        return 0.0, 0.0
    return dn(f - m), up(f + m)


@jit
def _enclose_cos(x):
    f = math.cos(x)
    m = _margin(f)
    return dn(f - m), up(f + m)


@jit
def _finish_periodic(al, ah, lo, hi, max_phase, min_phase):
    finite = math.isfinite(al) and math.isfinite(ah)
    if not finite or (ah - al) >= TWO_PI:
        return -1.0, 1.0
    if _contains_phase(al, ah, min_phase):
        lo = -1.0
    if _contains_phase(al, ah, max_phase):
        hi = 1.0
    return max(lo, -1.0), min(hi, 1.0)


@jit
def sin(al, ah):
    """``sin([a])`` with the :data:`TRIG_ULPS` margin."""
    if not (math.isfinite(al) and math.isfinite(ah)):
        return -1.0, 1.0
    la, ha = _enclose_sin(al)
    lb, hb = _enclose_sin(ah)
    return _finish_periodic(al, ah, min(la, lb), max(ha, hb), 0.5 * math.pi, -0.5 * math.pi)


@jit
def cos(al, ah):
    """``cos([a])`` with the :data:`TRIG_ULPS` margin."""
    if not (math.isfinite(al) and math.isfinite(ah)):
        return -1.0, 1.0
    la, ha = _enclose_cos(al)
    lb, hb = _enclose_cos(ah)
    return _finish_periodic(al, ah, min(la, lb), max(ha, hb), 0.0, math.pi)


@jit
def maxn(a, b):
    """``np.maximum(a, b)``: NaN propagates and a tie gives ``b``, as numpy's
    does (the builtin ``max`` keeps ``a``: ``max(0.0, -0.0)`` differs in sign)."""
    if a != a or b != b:
        return a + b
    return a if a > b else b


@jit
def minn(a, b):
    """``np.minimum(a, b)``: NaN propagates and a tie gives ``b``."""
    if a != a or b != b:
        return a + b
    return a if a < b else b


@jit
def intersect(al, ah, bl, bh):
    """``[a] ∩ [b]`` (empty when ``lo > hi``; NaN bounds propagate)."""
    return maxn(al, bl), minn(ah, bh)


@jit
def hull(al, ah, bl, bh):
    """Hull of ``[a] ∪ [b]``, an empty operand ignored."""
    if al > ah:
        return bl, bh
    if bl > bh:
        return al, ah
    return minn(al, bl), maxn(ah, bh)


@jit
def is_empty(al, ah):
    return not (al <= ah)


@jit
def width(al, ah):
    """Upper bound of ``hi - lo`` (0 for an empty or degenerate interval)."""
    if not (al <= ah) or ah == al:
        return 0.0
    return up(ah - al)


@jit
def midpoint(al, ah):
    """A float inside ``[a]`` (finite whenever possible)."""
    m = 0.5 * al + 0.5 * ah
    if al == -INF and ah == INF:
        m = 0.0
    elif al == -INF and math.isfinite(ah):
        m = 0.0 if ah >= 0.0 else max(2.0 * ah, -MAX)
    elif ah == INF and math.isfinite(al):
        m = 0.0 if al <= 0.0 else min(2.0 * al, MAX)
    return minn(maxn(m, al), ah)  # np.clip(m, al, ah)
