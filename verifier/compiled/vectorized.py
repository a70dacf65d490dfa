"""Array API over the compiled scalar operations of :mod:`verifier.compiled.interval`.

The functions have the names and signatures of :mod:`verifier.interval` and
broadcast like numpy, but each element is computed by the scalar kernel that
the compiled tracker uses, inside an ``@njit`` loop (default flags, no
``fastmath``).  This module exists so that the interval test-suites can check
the compiled arithmetic against the same exact oracles as the numpy core.

numba's cache of these loops is keyed by this file only: after a change of
``interval.py`` it may keep the old kernels (``tests/test_compiled_interval.py`` notices)
until ``__pycache__/vectorized.*`` is removed.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import interval as ops
from .interval import TRIG_ULPS

__all__ = [
    "TRIG_ULPS", "add", "sub", "neg", "mul", "scale", "div", "sqr", "pown", "sqrt",
    "absolute", "sin", "cos", "intersect", "hull", "is_empty", "width", "midpoint",
]

# One loop per arity, the operation picked by an index into these names: a loop
# taking the scalar op as an argument would be recompiled (never found in the
# cache) in every process, since numba keys it by the op's dispatcher object.
_UNARY = ("neg", "sqr", "sqrt", "absolute", "sin", "cos")
_BINARY = ("add", "sub", "mul", "div", "intersect", "hull")
_SCALAR = ("width", "midpoint", "is_empty")


@njit(cache=True)
def _unary_loop(k, al, ah, lo, hi):
    for i in range(lo.size):
        x, y = al[i], ah[i]
        if k == 0:
            r = ops.neg(x, y)
        elif k == 1:
            r = ops.sqr(x, y)
        elif k == 2:
            r = ops.sqrt(x, y)
        elif k == 3:
            r = ops.absolute(x, y)
        elif k == 4:
            r = ops.sin(x, y)
        else:
            r = ops.cos(x, y)
        lo[i], hi[i] = r


@njit(cache=True)
def _binary_loop(k, al, ah, bl, bh, lo, hi):
    for i in range(lo.size):
        x, y, u, v = al[i], ah[i], bl[i], bh[i]
        if k == 0:
            r = ops.add(x, y, u, v)
        elif k == 1:
            r = ops.sub(x, y, u, v)
        elif k == 2:
            r = ops.mul(x, y, u, v)
        elif k == 3:
            r = ops.div(x, y, u, v)
        elif k == 4:
            r = ops.intersect(x, y, u, v)
        else:
            r = ops.hull(x, y, u, v)
        lo[i], hi[i] = r


@njit(cache=True)
def _scalar_loop(k, al, ah, out):
    # is_empty is stored as 0.0/1.0: one float output type for all three
    for i in range(out.size):
        if k == 0:
            out[i] = ops.width(al[i], ah[i])
        elif k == 1:
            out[i] = ops.midpoint(al[i], ah[i])
        else:
            out[i] = 1.0 if ops.is_empty(al[i], ah[i]) else 0.0


@njit(cache=True)
def _scale_loop(c, al, ah, lo, hi):
    for i in range(lo.size):
        lo[i], hi[i] = ops.scale(c[i], al[i], ah[i])


@njit(cache=True)
def _pown_loop(al, ah, n, lo, hi):
    for i in range(lo.size):
        lo[i], hi[i] = ops.pown(al[i], ah[i], n)


def _flat(*vs):
    """The common broadcast shape and the operands as flat float64 arrays
    (float64 first: integer arrays would wrap around)."""
    arrs = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in vs))
    return arrs[0].shape, [np.ascontiguousarray(a).reshape(-1) for a in arrs]


def _unary(name, al, ah):
    shape, (al, ah) = _flat(al, ah)
    lo, hi = np.empty(al.size), np.empty(al.size)
    _unary_loop(_UNARY.index(name), al, ah, lo, hi)
    return lo.reshape(shape), hi.reshape(shape)


def _binary(name, al, ah, bl, bh):
    shape, (al, ah, bl, bh) = _flat(al, ah, bl, bh)
    lo, hi = np.empty(al.size), np.empty(al.size)
    _binary_loop(_BINARY.index(name), al, ah, bl, bh, lo, hi)
    return lo.reshape(shape), hi.reshape(shape)


def _scalar(name, al, ah):
    shape, (al, ah) = _flat(al, ah)
    out = np.empty(al.size)
    _scalar_loop(_SCALAR.index(name), al, ah, out)
    return out.reshape(shape)


def add(al, ah, bl, bh):
    """``[a] + [b]``."""
    return _binary("add", al, ah, bl, bh)


def sub(al, ah, bl, bh):
    """``[a] - [b]``."""
    return _binary("sub", al, ah, bl, bh)


def mul(al, ah, bl, bh):
    """``[a] * [b]`` with ``0 * inf = 0``."""
    return _binary("mul", al, ah, bl, bh)


def div(al, ah, bl, bh):
    """``[a] / [b]`` (see :func:`verifier.interval.div`)."""
    return _binary("div", al, ah, bl, bh)


def intersect(al, ah, bl, bh):
    """``[a] ∩ [b]`` (empty when ``lo > hi``)."""
    return _binary("intersect", al, ah, bl, bh)


def hull(al, ah, bl, bh):
    """Hull of ``[a] ∪ [b]``, an empty operand ignored."""
    return _binary("hull", al, ah, bl, bh)


def neg(al, ah):
    """``-[a]`` (exact)."""
    return _unary("neg", al, ah)


def sqr(al, ah):
    """``[a]^2``, lower bound clamped at 0."""
    return _unary("sqr", al, ah)


def sqrt(al, ah):
    """``sqrt([a] ∩ [0, inf))``; empty when ``[a] < 0``."""
    return _unary("sqrt", al, ah)


def absolute(al, ah):
    """``|[a]|`` (exact)."""
    return _unary("absolute", al, ah)


def sin(al, ah):
    """``sin([a])`` with the :data:`TRIG_ULPS` margin."""
    return _unary("sin", al, ah)


def cos(al, ah):
    """``cos([a])`` with the :data:`TRIG_ULPS` margin."""
    return _unary("cos", al, ah)


def scale(c, al, ah):
    """``c [a]`` for a float (array) ``c``."""
    shape, (c, al, ah) = _flat(c, al, ah)
    lo, hi = np.empty(al.size), np.empty(al.size)
    _scale_loop(c, al, ah, lo, hi)
    return lo.reshape(shape), hi.reshape(shape)


def pown(al, ah, n: int):
    """``[a]^n`` for an integer ``n``."""
    shape, (al, ah) = _flat(al, ah)
    lo, hi = np.empty(al.size), np.empty(al.size)
    _pown_loop(al, ah, int(n), lo, hi)
    return lo.reshape(shape), hi.reshape(shape)


def width(al, ah):
    """Upper bound of ``hi - lo`` (0 for an empty or degenerate interval)."""
    return _scalar("width", al, ah)


def midpoint(al, ah):
    """A float inside each non-empty interval (finite whenever possible)."""
    return _scalar("midpoint", al, ah)


def is_empty(al, ah):
    """Boolean mask of empty intervals."""
    return _scalar("is_empty", al, ah).astype(bool)
