"""Batched interval linear algebra: products, Gauss–Seidel, linear enclosures.

Interval matrices are pairs ``(lo, hi)`` of shape ``(B, n, n)``; interval
vectors ``(B, n)``; point (float) preconditioners ``(B, n, n)``.  Every sum
is accumulated term by term with outward rounding.
"""

from __future__ import annotations

import numpy as np

from . import interval as I

__all__ = [
    "point_inverse",
    "pmat_imat",
    "pmat_ivec",
    "imat_ivec",
    "gauss_seidel",
    "linear_enclosure",
]


def point_inverse(A):
    """``inv(A)`` for a batch of float matrices ``(B, n, n)``; identity where
    singular or not finite.

    Gauss–Jordan elimination with partial pivoting (the first largest pivot),
    the very float operations of :func:`verifier.compiled.linalg.point_inverse`
    so that both backends precondition identically.  Any preconditioner keeps
    the preconditioned system equivalent, so the fallback identity is sound
    (only weaker).
    """
    A = np.asarray(A, dtype=np.float64)
    n = A.shape[-1]
    M = A.reshape(-1, n, n).copy()
    rows = np.arange(len(M))
    C = np.broadcast_to(np.eye(n), M.shape).copy()
    ok = np.all(np.isfinite(M), axis=(-2, -1))
    M[~ok] = np.eye(n)
    with np.errstate(all="ignore"):
        for col in range(n):
            p = col + np.argmax(np.abs(M[:, col:, col]), axis=-1)
            ok &= M[rows, p, col] != 0.0
            for X in (M, C):
                top = X[rows, col].copy()
                X[rows, col] = X[rows, p]
                X[rows, p] = top
            piv = M[:, col, col][:, None].copy()
            M[:, col] = M[:, col] / piv
            C[:, col] = C[:, col] / piv
            for r in range(n):
                if r != col:
                    f = M[:, r, col][:, None].copy()
                    M[:, r] = M[:, r] - f * M[:, col]
                    C[:, r] = C[:, r] - f * C[:, col]
    ok &= np.all(np.isfinite(C), axis=(-2, -1))
    C[~ok] = np.eye(n)
    return C.reshape(A.shape)


def pmat_imat(C, Ml, Mh):
    """``C [M]`` for a point matrix ``C`` and an interval matrix ``[M]``."""
    n = C.shape[-1]
    lo, hi = I.mul(C[..., :, 0, None], C[..., :, 0, None], Ml[..., 0, None, :], Mh[..., 0, None, :])
    for k in range(1, n):
        pl, ph = I.mul(C[..., :, k, None], C[..., :, k, None], Ml[..., k, None, :], Mh[..., k, None, :])
        lo, hi = I.add(lo, hi, pl, ph)
    return lo, hi


def pmat_ivec(C, vl, vh):
    """``C [v]`` for a point matrix ``C`` and an interval vector ``[v]``."""
    n = C.shape[-1]
    lo, hi = I.mul(C[..., :, 0], C[..., :, 0], vl[..., 0, None], vh[..., 0, None])
    for k in range(1, n):
        pl, ph = I.mul(C[..., :, k], C[..., :, k], vl[..., k, None], vh[..., k, None])
        lo, hi = I.add(lo, hi, pl, ph)
    return lo, hi


def imat_ivec(Al, Ah, vl, vh):
    """``[A] [v]`` for an interval matrix and an interval vector."""
    n = Al.shape[-1]
    lo, hi = I.mul(Al[..., :, 0], Ah[..., :, 0], vl[..., 0, None], vh[..., 0, None])
    for k in range(1, n):
        pl, ph = I.mul(Al[..., :, k], Ah[..., :, k], vl[..., k, None], vh[..., k, None])
        lo, hi = I.add(lo, hi, pl, ph)
    return lo, hi


def gauss_seidel(Al, Ah, bl, bh, yl, yh, sweeps: int = 1):
    """Interval Gauss–Seidel on ``[A] y = [b]`` starting from the box ``[y]``.

    ``y_i <- y_i ∩ (b_i - sum_{j != i} A_ij y_j) / A_ii`` for each ``i`` in
    turn.  Every ``y`` in ``[y]`` solving ``A y = b`` for some ``A in [A]``,
    ``b in [b]`` stays in the result.  A diagonal entry containing 0 gives an
    unbounded quotient (or, when the numerator contains 0 too, no constraint
    at all), i.e. no contraction of that component.

    Returns the contracted ``(yl, yh)`` (empty components have ``lo > hi``).
    """
    yl = np.array(yl, dtype=np.float64)
    yh = np.array(yh, dtype=np.float64)
    n = Al.shape[-1]
    for _ in range(sweeps):
        for i in range(n):
            sl, sh = bl[..., i], bh[..., i]
            for j in range(n):
                if j == i:
                    continue
                pl, ph = I.mul(Al[..., i, j], Ah[..., i, j], yl[..., j], yh[..., j])
                sl, sh = I.sub(sl, sh, pl, ph)
            dl, dh = Al[..., i, i], Ah[..., i, i]
            ql, qh = I.div(sl, sh, dl, dh)
            # 0 in A_ii and 0 in the numerator: y_i = anything solves it (A_ii = 0)
            free = (dl <= 0.0) & (dh >= 0.0) & (sl <= 0.0) & (sh >= 0.0)
            ql = np.where(free, -np.inf, ql)
            qh = np.where(free, np.inf, qh)
            yl[..., i], yh[..., i] = I.intersect(yl[..., i], yh[..., i], ql, qh)
    return yl, yh


def linear_enclosure(Al, Ah, bl, bh, yl=None, yh=None, sweeps: int = 2):
    """Enclose ``{y : A y = b, A in [A], b in [b]}`` (intersected with ``[y]``).

    Preconditions with ``C = inv(mid [A])``: with ``[G] = C [A]`` and
    ``beta = ||I - [G]||_inf < 1``, every solution satisfies
    ``||y||_inf <= ||C [b]||_inf / (1 - beta)`` (the Neumann-series bound), which
    gives a starting box for Gauss–Seidel on ``[G] y = C [b]``.  Where
    ``beta >= 1`` the bound is infinite and only the given ``[y]`` (if any)
    is contracted.

    Returns ``(lo, hi)`` of shape ``(B, n)``.
    """
    n = Al.shape[-1]
    C = point_inverse(I.midpoint(Al, Ah))
    Gl, Gh = pmat_imat(C, Al, Ah)
    cl, ch = pmat_ivec(C, bl, bh)
    eye = np.eye(n)
    El, Eh = I.sub(eye, eye, Gl, Gh)
    mag = np.maximum(np.abs(El), np.abs(Eh))
    # row sums of magnitudes, rounded up term by term
    beta = mag[..., 0]
    for k in range(1, n):
        beta = I.add(beta, beta, mag[..., k], mag[..., k])[1]
    beta = beta.max(axis=-1)
    cmag = np.maximum(np.abs(cl), np.abs(ch)).max(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        denom = I.sub(1.0, 1.0, beta, beta)[0]  # lower bound of 1 - beta
        r = I.div(cmag, cmag, denom, denom)[1]
    # no bound (NaN included) is +inf itself: never the largest float, which the true solutions of a
    # system holding a singular matrix exceed
    r = np.where((beta < 1.0) & (denom > 0.0) & np.isfinite(r), r, np.inf)
    if yl is None:
        yl = np.broadcast_to(-r[..., None], cl.shape)
        yh = np.broadcast_to(r[..., None], cl.shape)
    else:
        yl, yh = I.intersect(yl, yh, -r[..., None], r[..., None])
    return gauss_seidel(Gl, Gh, cl, ch, yl, yh, sweeps=sweeps)
