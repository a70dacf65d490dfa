"""Interval linear algebra of one scenario, compiled: the loops of
:mod:`verifier.linalg` in the same order.

View-free: every matrix and vector lives in one flat scratch vector ``w`` at
an offset (matrix entry ``(i, j)`` of an ``n x n`` matrix at ``o`` is
``w[o + i n + j]``), so the kernels neither allocate nor build array views.
"""

from __future__ import annotations

import math

import numpy as np

from . import interval as ops
from .interval import jit


@jit
def point_inverse(w, a, c, t, n):
    """``C <- inv(A)`` (matrices at ``w[a:]``, ``w[c:]``) by Gauss–Jordan with
    partial pivoting; identity where ``A`` is singular or not finite (any
    preconditioner is sound).

    The same float operations as :func:`verifier.linalg.point_inverse`;
    ``w[t:t + n^2]`` is scratch.
    """
    if n == 2:
        _inverse_2(w, a, c)
        return
    for i in range(n * n):
        w[t + i] = w[a + i]
    ok = True
    for i in range(n):
        for j in range(n):
            w[c + i * n + j] = 1.0 if i == j else 0.0
            if not math.isfinite(w[t + i * n + j]):
                ok = False
    if ok:
        for col in range(n):
            p = col
            best = abs(w[t + col * n + col])
            for r in range(col + 1, n):
                if abs(w[t + r * n + col]) > best:
                    best = abs(w[t + r * n + col])
                    p = r
            if best == 0.0:
                ok = False
                break
            if p != col:
                for j in range(n):
                    w[t + p * n + j], w[t + col * n + j] = w[t + col * n + j], w[t + p * n + j]
                    w[c + p * n + j], w[c + col * n + j] = w[c + col * n + j], w[c + p * n + j]
            piv = w[t + col * n + col]
            for j in range(n):
                w[t + col * n + j] = w[t + col * n + j] / piv
                w[c + col * n + j] = w[c + col * n + j] / piv
            for r in range(n):
                if r != col:
                    f = w[t + r * n + col]
                    for j in range(n):
                        w[t + r * n + j] = w[t + r * n + j] - f * w[t + col * n + j]
                        w[c + r * n + j] = w[c + r * n + j] - f * w[c + col * n + j]
    if ok:
        for i in range(n * n):
            if not math.isfinite(w[c + i]):
                ok = False
    if not ok:
        for i in range(n):
            for j in range(n):
                w[c + i * n + j] = 1.0 if i == j else 0.0


@jit
def _inverse_2(w, a, c):
    """:func:`point_inverse` for ``n = 2``, its loops written out on scalars:
    the same divisions and products in the same order (the same floats,
    tests/test_linalg_compiled.py), without the index arithmetic and the scratch
    matrix of the general loops."""
    t00 = w[a]
    t01 = w[a + 1]
    t10 = w[a + 2]
    t11 = w[a + 3]
    c00 = 1.0
    c01 = 0.0
    c10 = 0.0
    c11 = 1.0
    ok = math.isfinite(t00) and math.isfinite(t01) and math.isfinite(t10) and math.isfinite(t11)
    if ok:
        # column 0: the pivot is row 1 only when strictly larger
        if abs(t10) > abs(t00):
            t00, t10 = t10, t00
            t01, t11 = t11, t01
            c00, c10 = c10, c00
            c01, c11 = c11, c01
        if t00 == 0.0:
            ok = False
        else:
            piv = t00
            t00 = t00 / piv
            c00 = c00 / piv
            t01 = t01 / piv
            c01 = c01 / piv
            f = t10
            t10 = t10 - f * t00
            c10 = c10 - f * c00
            t11 = t11 - f * t01
            c11 = c11 - f * c01
            # column 1: row 1 is the only candidate
            if t11 == 0.0:
                ok = False
            else:
                piv = t11
                t10 = t10 / piv
                c10 = c10 / piv
                t11 = t11 / piv
                c11 = c11 / piv
                f = t01
                c00 = c00 - f * c10
                c01 = c01 - f * c11
    if ok:
        ok = math.isfinite(c00) and math.isfinite(c01) and math.isfinite(c10) and math.isfinite(c11)
    if not ok:
        c00 = 1.0
        c01 = 0.0
        c10 = 0.0
        c11 = 1.0
    w[c] = c00
    w[c + 1] = c01
    w[c + 2] = c10
    w[c + 3] = c11


@jit
def pmat_imat(w, c, ml, mh, gl, gh, n):
    """``[G] <- C [M]``, sums accumulated over ``k`` in order."""
    for i in range(n):
        for j in range(n):
            ci = w[c + i * n]
            lo, hi = ops.pmul(ci, w[ml + j], w[mh + j])
            for k in range(1, n):
                ck = w[c + i * n + k]
                pl, ph = ops.pmul(ck, w[ml + k * n + j], w[mh + k * n + j])
                lo, hi = ops.add(lo, hi, pl, ph)
            w[gl + i * n + j] = lo
            w[gh + i * n + j] = hi


@jit
def pmat_ivec(w, c, vl, vh, ol, oh, n):
    """``[o] <- C [v]``."""
    for i in range(n):
        ci = w[c + i * n]
        lo, hi = ops.pmul(ci, w[vl], w[vh])
        for k in range(1, n):
            ck = w[c + i * n + k]
            pl, ph = ops.pmul(ck, w[vl + k], w[vh + k])
            lo, hi = ops.add(lo, hi, pl, ph)
        w[ol + i] = lo
        w[oh + i] = hi


@jit
def gauss_seidel(w, al, ah, bl, bh, yl, yh, n, sweeps):
    """Interval Gauss–Seidel on ``[A] y = [b]``, contracting ``[y]`` in place."""
    for _ in range(sweeps):
        for i in range(n):
            sl = w[bl + i]
            sh = w[bh + i]
            for j in range(n):
                if j == i:
                    continue
                pl, ph = ops.mul(w[al + i * n + j], w[ah + i * n + j], w[yl + j], w[yh + j])
                sl, sh = ops.sub(sl, sh, pl, ph)
            dl = w[al + i * n + i]
            dh = w[ah + i * n + i]
            ql, qh = ops.div(sl, sh, dl, dh)
            if dl <= 0.0 and dh >= 0.0 and sl <= 0.0 and sh >= 0.0:
                ql = -np.inf
                qh = np.inf
            w[yl + i], w[yh + i] = ops.intersect(w[yl + i], w[yh + i], ql, qh)


@jit
def enclosure_scratch(n):
    """Scratch floats :func:`linear_enclosure` needs after its offset ``t``."""
    return 5 * n * n + 2 * n + 1


@jit
def linear_enclosure(w, al, ah, bl, bh, yl, yh, n, has_y, sweeps, t):
    """Enclose ``{y : A y = b}`` into ``[y]`` in place (see
    :func:`verifier.linalg.linear_enclosure`); ``has_y`` False: ``[y]`` is
    only the Neumann-series bound.  ``w[t:]`` is scratch
    (:func:`enclosure_scratch`).  The two halves :func:`precondition` (of
    ``[A]`` only) and :func:`solve_preconditioned`."""
    precondition(w, al, ah, n, t)
    solve_preconditioned(w, bl, bh, yl, yh, n, has_y, sweeps, t)


@jit
def precondition(w, al, ah, n, t):
    """The part of :func:`linear_enclosure` that depends on ``[A]`` alone: the
    midpoint inverse ``C``, ``[G] = C [A]`` and the bound ``beta`` of
    ``|I - [G]|``, kept in ``w[t:]`` for :func:`solve_preconditioned` (so a
    system with the same ``[A]``, bit for bit, can skip it)."""
    nn = n * n
    mid = t
    c = t + nn
    gl = t + 2 * nn
    gh = t + 3 * nn
    ch = t + 4 * nn + n
    for i in range(nn):
        w[mid + i] = ops.midpoint(w[al + i], w[ah + i])
    point_inverse(w, mid, c, ch + n, n)
    pmat_imat(w, c, al, ah, gl, gh, n)
    beta = 0.0
    for i in range(n):
        row = 0.0
        for k in range(n):
            e = 1.0 if i == k else 0.0
            el, eh = ops.sub(e, e, w[gl + i * n + k], w[gh + i * n + k])
            mag = ops.maxn(abs(el), abs(eh))
            row = mag if k == 0 else ops.add(row, row, mag, mag)[1]
        beta = row if i == 0 else ops.maxn(beta, row)
    w[t + 5 * nn + 2 * n] = beta


@jit
def solve_preconditioned(w, bl, bh, yl, yh, n, has_y, sweeps, t):
    """The rest of :func:`linear_enclosure` for ``[b]``, after :func:`precondition` of ``[A]`` at ``t``."""
    nn = n * n
    c = t + nn
    gl = t + 2 * nn
    gh = t + 3 * nn
    cl = t + 4 * nn
    ch = cl + n
    beta = w[t + 5 * nn + 2 * n]
    pmat_ivec(w, c, bl, bh, cl, ch, n)
    cmag = 0.0
    for i in range(n):
        cm = ops.maxn(abs(w[cl + i]), abs(w[ch + i]))
        cmag = cm if i == 0 else ops.maxn(cmag, cm)
    denom = ops.sub(1.0, 1.0, beta, beta)[0]
    r = np.inf
    if beta < 1.0 and denom > 0.0:
        r = ops.div(cmag, cmag, denom, denom)[1]
        if not math.isfinite(r):
            r = np.inf
    for i in range(n):
        if has_y:
            w[yl + i], w[yh + i] = ops.intersect(w[yl + i], w[yh + i], -r, r)
        else:
            w[yl + i] = -r
            w[yh + i] = r
    gauss_seidel(w, gl, gh, cl, ch, yl, yh, n, sweeps)
