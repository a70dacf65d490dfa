"""The interval Newton step on the pose over lanes.

:func:`verifier.compiled.contractors.newton` in ``x`` (``on_x``) for every active lane at once: the
loop closure ``f`` at the pose box's midpoint and ``J_x`` over the box, each tape over the lanes
(:func:`.tape.forward`), the midpoint inverse ``C``, ``[A] = C [J_x]``, ``[b] = -C f(mid)``, one
Gauss–Seidel sweep on ``[A] y = [b]`` from ``[y] = [x] - mid``, then ``[x] <- [x] ∩ (mid + [y])``: the
operations of the per-row step in the same order, so each lane's floats are its row's.
"""

from __future__ import annotations

from .. import interval as ops
from ..interval import jit
from ..tape import T_F, T_JX
from . import interval as lane
from .linalg import gauss_seidel, midpoint_inverse, pmat_imat, pmat_ivec
from .tape import forward

__all__ = ["newton_x"]


@jit
def _pose_inputs(rows, lane_row, L, il, ih, n, m):
    """Tape inputs ``x, q, xi`` of the rows ``lane_row[:L]``, lane by lane."""
    X, Q, XI = rows.x, rows.q, rows.xi
    for i in range(n):
        for l in range(L):
            r = lane_row[l]
            il[i, l] = X[r, 0, i]
            ih[i, l] = X[r, 1, i]
            il[n + i, l] = Q[r, 0, i]
            ih[n + i, l] = Q[r, 1, i]
    for i in range(m):
        for l in range(L):
            r = lane_row[l]
            il[2 * n + i, l] = XI[r, 0, i]
            ih[2 * n + i, l] = XI[r, 1, i]


@jit
def newton_x(prog, rows, lane_row, L, n, m, ls, mk, mv):
    """Contract the pose boxes ``rows.x[lane_row[l]]``, ``l < L``, in place by one preconditioned
    Hansen–Sengupta step on ``f(x, q, xi) = 0`` (``q`` and ``xi`` the rows' boxes)."""
    if L == 0:
        return
    X = rows.x
    il, ih, nl, nh, w = ls.il, ls.ih, ls.nl, ls.nh, ls.w
    nn = n * n
    MID, FL, FH, BL, BH, YL, YH = 0, n, 2 * n, 3 * n, 4 * n, 5 * n, 6 * n
    JL = 7 * n
    JH = JL + nn
    C = JL + 2 * nn
    AL = JL + 3 * nn
    AH = JL + 4 * nn
    outs = prog.outs
    _pose_inputs(rows, lane_row, L, il, ih, n, m)
    for i in range(n):
        for l in range(L):
            v = ops.midpoint(X[lane_row[l], 0, i], X[lane_row[l], 1, i])
            w[MID + i, l] = v
            il[i, l] = v
            ih[i, l] = v
    forward(prog, T_F, il, ih, nl, nh, L, mk, mv, ls.flag)
    f0 = prog.meta[T_F, 2]
    for i in range(n):
        node = outs[f0 + i]
        for l in range(L):
            w[FL + i, l] = 0.0 if node < 0 else nl[node, l]
            w[FH + i, l] = 0.0 if node < 0 else nh[node, l]
    for i in range(n):
        for l in range(L):
            il[i, l] = X[lane_row[l], 0, i]
            ih[i, l] = X[lane_row[l], 1, i]
    forward(prog, T_JX, il, ih, nl, nh, L, mk, mv, ls.flag)
    j0 = prog.meta[T_JX, 2]
    for e in range(nn):
        node = outs[j0 + e]
        for l in range(L):
            w[JL + e, l] = 0.0 if node < 0 else nl[node, l]
            w[JH + e, l] = 0.0 if node < 0 else nh[node, l]
    midpoint_inverse(w, JL, JH, C, n, L, ls.mat)
    pmat_imat(w, C, JL, JH, AL, AH, n, L)
    pmat_ivec(w, C, FL, FH, BL, BH, n, L)
    for i in range(n):
        for l in range(L):
            w[BL + i, l], w[BH + i, l] = -w[BH + i, l], -w[BL + i, l]
            r = lane_row[l]
            w[YL + i, l], w[YH + i, l] = lane.sub(X[r, 0, i], X[r, 1, i], w[MID + i, l], w[MID + i, l])
    gauss_seidel(w, AL, AH, BL, BH, YL, YH, n, L)
    for i in range(n):
        for l in range(L):
            r = lane_row[l]
            vl, vh = lane.add(w[MID + i, l], w[MID + i, l], w[YL + i, l], w[YH + i, l])
            X[r, 0, i], X[r, 1, i] = ops.intersect(X[r, 0, i], X[r, 1, i], vl, vh)
