"""Interval linear algebra over lanes: :mod:`verifier.compiled.linalg`'s loops, the same order of
operations, with the lanes as the inner loop.

A matrix or vector lives in rows of the lanes' temporaries ``w[entry, lane]`` from an offset (entry
``(i, j)`` of an ``n x n`` matrix at ``o`` is row ``o + i n + j``).  Sums and point products run the
select-form operations of :mod:`.interval`; the midpoint inverse and the Gauss–Seidel divisions run
lane by lane on today's operations.
"""

from __future__ import annotations

import numpy as np

from .. import interval as ops
from ..interval import jit
from ..linalg import point_inverse
from . import interval as lane

__all__ = ["midpoint_inverse", "pmat_imat", "pmat_ivec", "gauss_seidel"]


@jit
def midpoint_inverse(w, ML, MH, C, n, L, mat):
    """``C <- inv(mid [M])`` lane by lane (:func:`verifier.compiled.linalg.point_inverse` on the flat
    scratch ``mat`` ``(3 n^2,)``; the identity where the midpoint is singular)."""
    nn = n * n
    for l in range(L):
        for e in range(nn):
            mat[e] = ops.midpoint(w[ML + e, l], w[MH + e, l])
        point_inverse(mat, 0, nn, 2 * nn, n)
        for e in range(nn):
            w[C + e, l] = mat[nn + e]


@jit
def pmat_imat(w, C, ML, MH, GL, GH, n, L):
    """``[G] <- C [M]``, the sums accumulated over ``k`` in order."""
    for i in range(n):
        for j in range(n):
            for l in range(L):
                lo, hi = lane.pmul(w[C + i * n, l], w[ML + j, l], w[MH + j, l])
                for k in range(1, n):
                    pl, ph = lane.pmul(w[C + i * n + k, l], w[ML + k * n + j, l], w[MH + k * n + j, l])
                    lo, hi = lane.add(lo, hi, pl, ph)
                w[GL + i * n + j, l] = lo
                w[GH + i * n + j, l] = hi


@jit
def pmat_ivec(w, C, VL, VH, OL, OH, n, L):
    """``[o] <- C [v]``."""
    for i in range(n):
        for l in range(L):
            lo, hi = lane.pmul(w[C + i * n, l], w[VL, l], w[VH, l])
            for k in range(1, n):
                pl, ph = lane.pmul(w[C + i * n + k, l], w[VL + k, l], w[VH + k, l])
                lo, hi = lane.add(lo, hi, pl, ph)
            w[OL + i, l] = lo
            w[OH + i, l] = hi


@jit
def gauss_seidel(w, AL, AH, BL, BH, YL, YH, n, L):
    """One interval Gauss–Seidel sweep on ``[A] y = [b]``, contracting ``[y]`` in place."""
    for i in range(n):
        for l in range(L):
            sl = w[BL + i, l]
            sh = w[BH + i, l]
            for j in range(n):
                if j != i:
                    pl, ph = lane.mul(w[AL + i * n + j, l], w[AH + i * n + j, l], w[YL + j, l], w[YH + j, l])
                    sl, sh = lane.sub(sl, sh, pl, ph)
            dl = w[AL + i * n + i, l]
            dh = w[AH + i * n + i, l]
            ql, qh = ops.div(sl, sh, dl, dh)
            if dl <= 0.0 and dh >= 0.0 and sl <= 0.0 and sh >= 0.0:
                ql = -np.inf
                qh = np.inf
            w[YL + i, l], w[YH + i, l] = ops.intersect(w[YL + i, l], w[YH + i, l], ql, qh)
