"""Interval operations written to vectorise in a loop over lanes.

The same floats as :mod:`verifier.compiled.interval`'s ``add``, ``sub``,
``mul`` and ``pmul`` (the nearest-rounded result, then one ``nextafter`` step
outward; exact zeros kept), written as selects and inlined into the caller's
loop: numba does not inline a called kernel, and a loop with a call does not
vectorise.  The outward step is computed on the bit pattern (:func:`dn`,
:func:`up`): positive floats are ordered as their patterns, negative ones in
reverse, so the neighbour is the pattern plus or minus one; ``+-0``, the
infinities and NaN are selected apart.  It is ``np.nextafter``'s float for
every input (tests/test_lanes.py checks it on the special values and on
seeded floats of every binade), so no bound widens by a further ulp.

A product's common case (every bound nonzero and a number, no rounded extreme
equal to 0) is computed over all lanes; :func:`mul_fast` flags the lanes
outside it, for the general path (:func:`verifier.compiled.interval._mul_general`)
in a second loop over those lanes only.
"""

from __future__ import annotations

import numpy as np

from .. import interval as ops
from ..interval import inline_jit

__all__ = ["dn", "up", "add", "sub", "mul_fast", "mul", "pmul"]

_INF = np.inf
_TINY = 5e-324  # the smallest positive subnormal: the neighbour of +-0


@inline_jit
def dn(c):
    """The float below ``c`` (``np.nextafter(c, -inf)``), without a branch."""
    b = ops._bits(c)
    stepped = ops._float(b - 1 if b > 0 else b + 1)
    r = -_TINY if c == 0.0 else stepped
    return c if (c != c or c == -_INF) else r


@inline_jit
def up(c):
    """The float above ``c`` (``np.nextafter(c, inf)``), without a branch."""
    b = ops._bits(c)
    stepped = ops._float(b + 1 if b > 0 else b - 1)
    r = _TINY if c == 0.0 else stepped
    return c if (c != c or c == _INF) else r


@inline_jit
def _lo(x, y):
    return x if x < y else y


@inline_jit
def _hi(x, y):
    return x if x > y else y


@inline_jit
def add(al, ah, bl, bh):
    """``[a] + [b]``; a sum that rounds to 0 is exactly 0 (gradual underflow) and is kept."""
    lo = al + bl
    hi = ah + bh
    return (0.0 if lo == 0.0 else dn(lo)), (0.0 if hi == 0.0 else up(hi))


@inline_jit
def sub(al, ah, bl, bh):
    """``[a] - [b]``."""
    lo = al - bh
    hi = ah - bl
    return (0.0 if lo == 0.0 else dn(lo)), (0.0 if hi == 0.0 else up(hi))


@inline_jit
def mul_fast(al, ah, bl, bh):
    """``[a] * [b]`` in the common case, and whether the lane was in it (False: take :func:`mul`'s
    general path for this lane; the bounds returned are then meaningless)."""
    p1 = al * bl
    p2 = al * bh
    p3 = ah * bl
    p4 = ah * bh
    lo = dn(_lo(_lo(p1, p2), _lo(p3, p4)))
    hi = up(_hi(_hi(p1, p2), _hi(p3, p4)))
    ok = (al != 0.0) & (ah != 0.0) & (bl != 0.0) & (bh != 0.0) & (al == al) & (ah == ah) & (bl == bl) & (bh == bh)
    return lo, hi, ok & (lo != 0.0) & (hi != 0.0)


@inline_jit
def mul(al, ah, bl, bh):
    """``[a] * [b]`` with ``0 * inf = 0`` (the general path on the lanes outside the common case)."""
    lo, hi, ok = mul_fast(al, ah, bl, bh)
    if not ok:
        lo, hi = ops._mul_general(al, ah, bl, bh)
    return lo, hi


@inline_jit
def pmul(c, bl, bh):
    """``c [b]`` for a float ``c``: :func:`mul` ``(c, c, bl, bh)``, the same floats."""
    p1 = c * bl
    p2 = c * bh
    lo = dn(_lo(p1, p2))
    hi = up(_hi(p1, p2))
    if not ((c != 0.0) & (bl != 0.0) & (bh != 0.0) & (c == c) & (bl == bl) & (bh == bh) & (lo != 0.0) & (hi != 0.0)):
        lo, hi = ops._mul_general(c, c, bl, bh)
    return lo, hi
