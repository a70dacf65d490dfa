"""Interval linear algebra of one scenario, compiled: the loops of
:mod:`verifier.linalg` in the same order, on ``(n, n)`` and ``(n,)`` arrays."""

from __future__ import annotations

import math

import numpy as np

from . import ops
from .ops import jit


@jit
def work(ws, off, shape0, shape1):
    """A ``(shape0, shape1)`` view of the scratch vector ``ws`` from ``off``
    (kernels carve their temporaries from one buffer instead of allocating)."""
    return ws[off:off + shape0 * shape1].reshape((shape0, shape1))


@jit
def point_inverse(A, C, ws, off):
    """``C <- inv(A)`` by Gauss–Jordan with partial pivoting; identity where
    ``A`` is singular or not finite (any preconditioner is sound).

    The same float operations as :func:`verifier.linalg.point_inverse`;
    ``ws[off:]`` is scratch (``n^2`` floats).
    """
    n = A.shape[0]
    M = work(ws, off, n, n)
    M[:] = A
    ok = True
    for i in range(n):
        for j in range(n):
            C[i, j] = 1.0 if i == j else 0.0
            if not math.isfinite(M[i, j]):
                ok = False
    if ok:
        for col in range(n):
            p = col
            best = abs(M[col, col])
            for r in range(col + 1, n):
                if abs(M[r, col]) > best:
                    best = abs(M[r, col])
                    p = r
            if best == 0.0:
                ok = False
                break
            if p != col:
                for j in range(n):
                    M[p, j], M[col, j] = M[col, j], M[p, j]
                    C[p, j], C[col, j] = C[col, j], C[p, j]
            piv = M[col, col]
            for j in range(n):
                M[col, j] = M[col, j] / piv
                C[col, j] = C[col, j] / piv
            for r in range(n):
                if r != col:
                    f = M[r, col]
                    for j in range(n):
                        M[r, j] = M[r, j] - f * M[col, j]
                        C[r, j] = C[r, j] - f * C[col, j]
    if ok:
        for i in range(n):
            for j in range(n):
                if not math.isfinite(C[i, j]):
                    ok = False
    if not ok:
        for i in range(n):
            for j in range(n):
                C[i, j] = 1.0 if i == j else 0.0


@jit
def pmat_imat(C, Ml, Mh, Gl, Gh):
    """``[G] <- C [M]``, sums accumulated over ``k`` in order."""
    n = C.shape[0]
    for i in range(n):
        for j in range(n):
            lo, hi = ops.mul(C[i, 0], C[i, 0], Ml[0, j], Mh[0, j])
            for k in range(1, n):
                pl, ph = ops.mul(C[i, k], C[i, k], Ml[k, j], Mh[k, j])
                lo, hi = ops.add(lo, hi, pl, ph)
            Gl[i, j] = lo
            Gh[i, j] = hi


@jit
def pmat_ivec(C, vl, vh, ol, oh):
    """``[o] <- C [v]``."""
    n = C.shape[0]
    for i in range(n):
        lo, hi = ops.mul(C[i, 0], C[i, 0], vl[0], vh[0])
        for k in range(1, n):
            pl, ph = ops.mul(C[i, k], C[i, k], vl[k], vh[k])
            lo, hi = ops.add(lo, hi, pl, ph)
        ol[i] = lo
        oh[i] = hi


@jit
def gauss_seidel(Al, Ah, bl, bh, yl, yh, sweeps):
    """Interval Gauss–Seidel on ``[A] y = [b]``, contracting ``[y]`` in place."""
    n = Al.shape[0]
    for _ in range(sweeps):
        for i in range(n):
            sl = bl[i]
            sh = bh[i]
            for j in range(n):
                if j == i:
                    continue
                pl, ph = ops.mul(Al[i, j], Ah[i, j], yl[j], yh[j])
                sl, sh = ops.sub(sl, sh, pl, ph)
            dl = Al[i, i]
            dh = Ah[i, i]
            ql, qh = ops.div(sl, sh, dl, dh)
            if dl <= 0.0 and dh >= 0.0 and sl <= 0.0 and sh >= 0.0:
                ql = -np.inf
                qh = np.inf
            yl[i], yh[i] = ops.intersect(yl[i], yh[i], ql, qh)


@jit
def linear_enclosure(Al, Ah, bl, bh, yl, yh, has_y, sweeps, ws, off):
    """Enclose ``{y : A y = b}`` into ``[y]`` in place (see
    :func:`verifier.linalg.linear_enclosure`); ``has_y`` False: ``[y]`` is
    only the Neumann-series bound.  ``ws[off:]`` is scratch (``5 n^2 + 2 n``)."""
    n = Al.shape[0]
    nn = n * n
    mid = work(ws, off, n, n)
    C = work(ws, off + nn, n, n)
    Gl = work(ws, off + 2 * nn, n, n)
    Gh = work(ws, off + 3 * nn, n, n)
    cl = ws[off + 4 * nn:off + 4 * nn + n]
    ch = ws[off + 4 * nn + n:off + 4 * nn + 2 * n]
    for i in range(n):
        for j in range(n):
            mid[i, j] = ops.midpoint(Al[i, j], Ah[i, j])
    point_inverse(mid, C, ws, off + 4 * nn + 2 * n)
    pmat_imat(C, Al, Ah, Gl, Gh)
    pmat_ivec(C, bl, bh, cl, ch)
    beta = 0.0
    cmag = 0.0
    for i in range(n):
        row = 0.0
        for k in range(n):
            el, eh = ops.sub(1.0 if i == k else 0.0, 1.0 if i == k else 0.0, Gl[i, k], Gh[i, k])
            mag = ops.maxn(abs(el), abs(eh))
            row = mag if k == 0 else ops.add(row, row, mag, mag)[1]
        beta = row if i == 0 else ops.maxn(beta, row)
        cm = ops.maxn(abs(cl[i]), abs(ch[i]))
        cmag = cm if i == 0 else ops.maxn(cmag, cm)
    denom = ops.sub(1.0, 1.0, beta, beta)[0]
    r = np.inf
    if beta < 1.0 and denom > 0.0:
        r = ops.div(cmag, cmag, denom, denom)[1]
        if not math.isfinite(r):
            r = np.inf
    for i in range(n):
        if has_y:
            yl[i], yh[i] = ops.intersect(yl[i], yh[i], -r, r)
        else:
            yl[i] = -r
            yh[i] = r
    gauss_seidel(Gl, Gh, cl, ch, yl, yh, sweeps)
