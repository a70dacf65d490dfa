"""The displacement model's velocity contraction over lanes.

:func:`verifier.compiled.contractors.velocity_displacement` for every active
lane at once: per baseline, the velocity tape over the lanes
(:func:`.tape.forward`), the midpoint preconditioning of ``J_x`` and one
interval Gauss–Seidel sweep on ``J_x u = -J_q rate``, the operations of
:mod:`verifier.compiled.linalg` in the same order.  Temporaries are
structure-of-arrays, ``w[entry, lane]``; the sums and point products run the
select-form operations of :mod:`.interval` in loops over the lanes, the
midpoint inverse and the sweep's divisions run lane by lane on today's
operations.  Each lane's floats are its row's in the per-row kernel (the
per-row kernel may skip a preconditioning whose ``J_x`` has the same bits as
the last baseline's: the same floats, computed again here).
"""

from __future__ import annotations

import math

import numpy as np

from .. import interval as ops
from ..interval import jit
from ..tape import T_VEL
from . import interval as lane
from .linalg import gauss_seidel, midpoint_inverse, pmat_imat, pmat_ivec
from .tape import forward

__all__ = ["displacement", "work_rows"]


def work_rows(n):
    """Rows of the lanes' temporaries :func:`displacement` uses (its ``w`` ``(work_rows(n), lanes)``)."""
    return 5 * n * n + 10 * n + 1


@jit
def displacement(prog, rows, lane_row, lane_id, L, idx, n_base, DQ, baseline, axis, n, m, ls, mk, mv):
    """Contract ``rows.xd[lane_row[l]]`` in place for lanes ``l < L`` with the displacements over the
    ``n_base`` baselines: ``rows.past_x[r, idx[j]]``, ``rows.past_q[r, idx[j]]`` are the boxes at
    ``t_k - h_j``, ``DQ[j, :, :, lane_id[l]]`` ``(2, n)`` encloses the row's mean joint rate over baseline ``j``
    (rad/s), ``baseline[j].h_hi`` is ``h_j`` (s), ``axis[i].a_max`` the acceleration bound (m/s^2).
    ``ls`` is the thread's lanes scratch (:class:`verifier.compiled.lanes.step.LaneScratch`)."""
    if n_base == 0 or L == 0:
        return
    X, Q, XI, XD = rows.x, rows.q, rows.xi, rows.xd
    past_x, past_q = rows.past_x, rows.past_q
    il, ih, nl, nh, w, mat, flag = ls.il, ls.ih, ls.nl, ls.nh, ls.w, ls.mat, ls.flag
    nn = n * n
    JL, JH = 0, nn
    BL, BH = 2 * nn, 2 * nn + n
    YL, YH = 2 * nn + 2 * n, 2 * nn + 3 * n
    SL, SH = 2 * nn + 4 * n, 2 * nn + 5 * n  # the slack: the same for every lane
    C = 2 * nn + 6 * n
    GL, GH = C + nn, C + 2 * nn
    CL, CH = C + 3 * nn, C + 3 * nn + n
    BETA = C + 3 * nn + 2 * n
    AL, AH = BETA + 1, BETA + 1 + n
    o0 = prog.meta[T_VEL, 2]
    outs = prog.outs
    for jb in range(n_base):
        p = idx[jb]
        h_hi = baseline[jb].h_hi
        for i in range(n):
            for l in range(L):
                r = lane_row[l]
                il[i, l], ih[i, l] = ops.hull(X[r, 0, i], X[r, 1, i], past_x[r, p, 0, i], past_x[r, p, 1, i])
                il[n + i, l], ih[n + i, l] = ops.hull(Q[r, 0, i], Q[r, 1, i], past_q[r, p, 0, i], past_q[r, p, 1, i])
                il[2 * n + m + i, l] = DQ[jb, 0, i, lane_id[l]]
                ih[2 * n + m + i, l] = DQ[jb, 1, i, lane_id[l]]
        for i in range(m):
            for l in range(L):
                r = lane_row[l]
                il[2 * n + i, l] = XI[r, 0, i]
                ih[2 * n + i, l] = XI[r, 1, i]
        half_h = ops.scale(0.5, h_hi, h_hi)[1]
        for i in range(n):
            a = axis[i].a_max
            w[SL + i, 0], w[SH + i, 0] = ops.mul(-half_h, half_h, -a, a)
        forward(prog, T_VEL, il, ih, nl, nh, L, mk, mv, flag)
        # J_x and b = -(J_q rate), a structural zero as 0 (b: -0.0, as the per-row kernel negates it)
        for e in range(nn + n):
            node = outs[o0 + e]
            if e < nn:
                for l in range(L):
                    w[JL + e, l] = 0.0 if node < 0 else nl[node, l]
                    w[JH + e, l] = 0.0 if node < 0 else nh[node, l]
            else:
                for l in range(L):
                    w[BL + e - nn, l] = -0.0 if node < 0 else -nh[node, l]
                    w[BH + e - nn, l] = -0.0 if node < 0 else -nl[node, l]
        for i in range(n):
            sl = w[SL + i, 0]
            sh = w[SH + i, 0]
            for l in range(L):
                r = lane_row[l]
                w[YL + i, l], w[YH + i, l] = lane.add(XD[r, 0, i], XD[r, 1, i], sl, sh)
        _precondition(w, JL, JH, C, GL, GH, BETA, n, L, mat)
        _solve(w, BL, BH, YL, YH, C, GL, GH, CL, CH, BETA, n, L)
        for i in range(n):
            sl = w[SL + i, 0]
            sh = w[SH + i, 0]
            for l in range(L):
                ul, uh = lane.add(w[YL + i, l], w[YH + i, l], sl, sh)
                w[AL + i, l] = ul if jb == 0 else ops.maxn(w[AL + i, l], ul)
                w[AH + i, l] = uh if jb == 0 else ops.minn(w[AH + i, l], uh)
    for i in range(n):
        for l in range(L):
            r = lane_row[l]
            XD[r, 0, i] = ops.maxn(XD[r, 0, i], w[AL + i, l])
            XD[r, 1, i] = ops.minn(XD[r, 1, i], w[AH + i, l])


@jit
def _precondition(w, JL, JH, C, GL, GH, BETA, n, L, mat):
    """:func:`verifier.compiled.linalg.precondition` per lane: ``C`` the midpoint inverse of ``[J]``,
    ``[G] = C [J]``, ``beta`` ``>= |I - [G]|``."""
    midpoint_inverse(w, JL, JH, C, n, L, mat)
    pmat_imat(w, C, JL, JH, GL, GH, n, L)
    for l in range(L):
        beta = 0.0
        for i in range(n):
            row = 0.0
            for k in range(n):
                e = 1.0 if i == k else 0.0
                el, eh = lane.sub(e, e, w[GL + i * n + k, l], w[GH + i * n + k, l])
                mag = ops.maxn(abs(el), abs(eh))
                row = mag if k == 0 else lane.add(row, row, mag, mag)[1]
            beta = row if i == 0 else ops.maxn(beta, row)
        w[BETA, l] = beta


@jit
def _solve(w, BL, BH, YL, YH, C, GL, GH, CL, CH, BETA, n, L):
    """:func:`verifier.compiled.linalg.solve_preconditioned` per lane, one sweep: ``[Cb] = C [b]``, the
    Neumann bound on ``[y]``, then one Gauss–Seidel sweep on ``[G] y = [Cb]``."""
    pmat_ivec(w, C, BL, BH, CL, CH, n, L)
    for l in range(L):
        cmag = 0.0
        for i in range(n):
            cm = ops.maxn(abs(w[CL + i, l]), abs(w[CH + i, l]))
            cmag = cm if i == 0 else ops.maxn(cmag, cm)
        beta = w[BETA, l]
        denom = ops.sub(1.0, 1.0, beta, beta)[0]
        rad = np.inf
        if beta < 1.0 and denom > 0.0:
            rad = ops.div(cmag, cmag, denom, denom)[1]
            if not math.isfinite(rad):
                rad = np.inf
        for i in range(n):
            w[YL + i, l], w[YH + i, l] = ops.intersect(w[YL + i, l], w[YH + i, l], -rad, rad)
    gauss_seidel(w, GL, GH, CL, CH, YL, YH, n, L)
