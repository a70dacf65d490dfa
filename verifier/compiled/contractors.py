"""Contractors of one scenario, compiled: those of :mod:`verifier.contractors`
in the same order of operations, on bounds arrays ``(2, n)`` (row 0 the lower
bounds, row 1 the upper) contracted in place.

``prog`` is a :class:`verifier.compiled.tape.Program` unpacked into
``code, value, outs, meta``; ``nl, nh`` (node bounds), ``il, ih`` (tape
inputs) and ``ws`` (temporaries, :func:`workspace_size` floats) are scratch
vectors: the hot path allocates nothing.
Tape inputs are concatenated in the order ``x, q, xi, *rest``.
"""

from __future__ import annotations

import numpy as np

from . import ops
from .linalg import gauss_seidel, linear_enclosure, pmat_imat, pmat_ivec, point_inverse, work
from .ops import jit
from .tape import T_DET, T_F, T_JQ, T_JX, T_VEL, forward, hc4, output


@jit
def workspace_size(n):
    """Scratch floats the contractors need for dimension ``n``: at most
    ``12 n + 7 n^2`` (the displacement contractor's chain), with room."""
    return 16 * n + 16 * n * n + 64


@jit
def set_input(in_lo, in_hi, slot, box):
    """Copy a ``(2, len)`` box into the input vector from ``slot`` on."""
    for i in range(box.shape[1]):
        in_lo[slot + i] = box[0, i]
        in_hi[slot + i] = box[1, i]


@jit
def scratch(n_nodes, n, m):
    """The scratch vectors of one thread: node bounds ``nl, nh``, tape inputs
    ``il, ih`` (every tape's inputs, at most ``5 n + m``) and temporaries ``ws``."""
    return (np.empty(n_nodes), np.empty(n_nodes), np.empty(5 * n + m), np.empty(5 * n + m),
            np.empty(workspace_size(n)))


@jit
def hc4_pose(code, value, outs, meta, X, Q, XI, nl, nh, il, ih, joints_too):
    """HC4Revise on ``f(x, q, xi) = 0``: contracts ``X`` in place, and ``Q``
    and ``XI`` too when ``joints_too`` (else they are kept as given)."""
    n = X.shape[1]
    m = XI.shape[1]
    set_input(il, ih, 0, X)
    set_input(il, ih, n, Q)
    set_input(il, ih, 2 * n, XI)
    hc4(code, value, outs, meta, T_F, n, il, ih, nl, nh)
    for i in range(n):
        X[0, i] = il[i]
        X[1, i] = ih[i]
    if joints_too:
        for i in range(n):
            Q[0, i] = il[n + i]
            Q[1, i] = ih[n + i]
        for i in range(m):
            XI[0, i] = il[2 * n + i]
            XI[1, i] = ih[2 * n + i]


@jit
def newton(code, value, outs, meta, X, Q, XI, on_x, nl, nh, il, ih, ws):
    """One preconditioned Hansen–Sengupta step on ``f = 0`` in ``x`` (``on_x``)
    or in ``q``; contracts that box in place."""
    n = X.shape[1]
    nn = n * n
    V = X if on_x else Q
    mid = ws[0:n]
    Fl = ws[n:2 * n]
    Fh = ws[2 * n:3 * n]
    bl = ws[3 * n:4 * n]
    bh = ws[4 * n:5 * n]
    yl = ws[5 * n:6 * n]
    yh = ws[6 * n:7 * n]
    Jl = work(ws, 7 * n, n, n)
    Jh = work(ws, 7 * n + nn, n, n)
    Jm = work(ws, 7 * n + 2 * nn, n, n)
    C = work(ws, 7 * n + 3 * nn, n, n)
    Al = work(ws, 7 * n + 4 * nn, n, n)
    Ah = work(ws, 7 * n + 5 * nn, n, n)
    for i in range(n):
        mid[i] = ops.midpoint(V[0, i], V[1, i])
    set_input(il, ih, 0, X)
    set_input(il, ih, n, Q)
    set_input(il, ih, 2 * n, XI)
    off = 0 if on_x else n
    for i in range(n):
        il[off + i] = mid[i]
        ih[off + i] = mid[i]
    forward(code, value, meta, T_F, il, ih, nl, nh)
    for i in range(n):
        Fl[i], Fh[i] = output(outs, meta, T_F, i, nl, nh)
    set_input(il, ih, off, V)
    forward(code, value, meta, T_JX if on_x else T_JQ, il, ih, nl, nh)
    for i in range(n):
        for j in range(n):
            Jl[i, j], Jh[i, j] = output(outs, meta, T_JX if on_x else T_JQ, i * n + j, nl, nh)
            Jm[i, j] = ops.midpoint(Jl[i, j], Jh[i, j])
    point_inverse(Jm, C, ws, 7 * n + 6 * nn)
    pmat_imat(C, Jl, Jh, Al, Ah)
    pmat_ivec(C, Fl, Fh, bl, bh)
    for i in range(n):
        bl[i], bh[i] = -bh[i], -bl[i]
        yl[i], yh[i] = ops.sub(V[0, i], V[1, i], mid[i], mid[i])
    gauss_seidel(Al, Ah, bl, bh, yl, yh, 1)
    for i in range(n):
        vl, vh = ops.add(mid[i], mid[i], yl[i], yh[i])
        V[0, i], V[1, i] = ops.intersect(V[0, i], V[1, i], vl, vh)


@jit
def mode_of(code, value, outs, meta, X, Q, XI, nl, nh, il, ih):
    """+1 / -1 when ``mode_sign det J_x`` has that sign over the box, else 0."""
    n = X.shape[1]
    set_input(il, ih, 0, X)
    set_input(il, ih, n, Q)
    set_input(il, ih, 2 * n, XI)
    forward(code, value, meta, T_DET, il, ih, nl, nh)
    dl, dh = output(outs, meta, T_DET, 0, nl, nh)
    if dl > 0.0:
        return 1
    if dh < 0.0:
        return -1
    return 0


@jit
def velocity_gs(code, value, outs, meta, X, Q, XI, XD, QD, nl, nh, il, ih, ws):
    """Contract ``XD`` in place with ``J_x xd = -J_q qd`` (one enclosure of ``J_q qd``)."""
    n = X.shape[1]
    m = XI.shape[1]
    set_input(il, ih, 0, X)
    set_input(il, ih, n, Q)
    set_input(il, ih, 2 * n, XI)
    set_input(il, ih, 2 * n + m, QD)
    _solve_vel(code, value, outs, meta, XD, nl, nh, il, ih, None, 1, ws, 0)


@jit
def _solve_vel(code, value, outs, meta, Y, nl, nh, il, ih, slack, sweeps, ws, off):
    # evaluate the vel tape (inputs already set), then Y <- enclosure of
    # J_x u = -J_q qd from the start box Y (+ slack when given) (+ slack after)
    n = Y.shape[1]
    nn = n * n
    forward(code, value, meta, T_VEL, il, ih, nl, nh)
    Jl = work(ws, off, n, n)
    Jh = work(ws, off + nn, n, n)
    o = off + 2 * nn
    bl = ws[o:o + n]
    bh = ws[o + n:o + 2 * n]
    yl = ws[o + 2 * n:o + 3 * n]
    yh = ws[o + 3 * n:o + 4 * n]
    for i in range(n):
        for j in range(n):
            Jl[i, j], Jh[i, j] = output(outs, meta, T_VEL, i * n + j, nl, nh)
        rl, rh = output(outs, meta, T_VEL, n * n + i, nl, nh)
        bl[i] = -rh
        bh[i] = -rl
    for i in range(n):
        if slack is None:
            yl[i] = Y[0, i]
            yh[i] = Y[1, i]
        else:
            yl[i], yh[i] = ops.add(Y[0, i], Y[1, i], slack[0, i], slack[1, i])
    linear_enclosure(Jl, Jh, bl, bh, yl, yh, True, sweeps, ws, o + 4 * n)
    for i in range(n):
        if slack is None:
            Y[0, i] = yl[i]
            Y[1, i] = yh[i]
        else:
            Y[0, i], Y[1, i] = ops.add(yl[i], yh[i], slack[0, i], slack[1, i])


@jit
def velocity_displacement(code, value, outs, meta, X, Q, XI, XD, past_x, past_q, DQ, h, idx, n_base, a_max,
                          nl, nh, il, ih, ws):
    """Contract ``XD`` in place with the displacements over ``n_base`` baselines
    (see :func:`verifier.contractors.velocity_displacement`).

    ``past_x[idx[j]]``, ``past_q[idx[j]]`` are the boxes ``(2, n)`` at
    ``t_k - h_j``; ``DQ[j]`` encloses ``q_k - q_{k-j}``; ``h[j]`` the baseline
    ``(lo, hi)``, s; ``a_max`` ``(n,)``, m/s^2.
    """
    if n_base == 0:
        return
    n = X.shape[1]
    m = XI.shape[1]
    accl = ws[0:n]
    acch = ws[n:2 * n]
    U = work(ws, 2 * n, 2, n)
    slack = work(ws, 4 * n, 2, n)
    for jb in range(n_base):
        Xp = past_x[idx[jb]]
        Qp = past_q[idx[jb]]
        for i in range(n):
            il[i], ih[i] = ops.hull(X[0, i], X[1, i], Xp[0, i], Xp[1, i])
            il[n + i], ih[n + i] = ops.hull(Q[0, i], Q[1, i], Qp[0, i], Qp[1, i])
            il[2 * n + m + i], ih[2 * n + m + i] = ops.div(DQ[jb, 0, i], DQ[jb, 1, i], h[jb, 0], h[jb, 1])
        for i in range(m):
            il[2 * n + i] = XI[0, i]
            ih[2 * n + i] = XI[1, i]
        half_h = ops.scale(0.5, h[jb, 1], h[jb, 1])[1]
        for i in range(n):
            slack[0, i], slack[1, i] = ops.mul(-half_h, half_h, -a_max[i], a_max[i])
            U[0, i] = XD[0, i]
            U[1, i] = XD[1, i]
        _solve_vel(code, value, outs, meta, U, nl, nh, il, ih, slack, 1, ws, 6 * n)
        for i in range(n):
            accl[i] = U[0, i] if jb == 0 else ops.maxn(accl[i], U[0, i])
            acch[i] = U[1, i] if jb == 0 else ops.minn(acch[i], U[1, i])
    for i in range(n):
        XD[0, i] = ops.maxn(XD[0, i], accl[i])
        XD[1, i] = ops.minn(XD[1, i], acch[i])


@jit
def empty_box(B):
    """Whether the box ``(2, n)`` is empty: some ``not (lo <= hi)`` (a NaN bound counts)."""
    for i in range(B.shape[1]):
        if not (B[0, i] <= B[1, i]):
            return True
    return False


@jit
def inverted_box(B):
    """Whether some ``lo > hi``: the branch and prunes' test (as the
    reference's ``np.any(lo > hi)``, a NaN bound does not count)."""
    for i in range(B.shape[1]):
        if B[0, i] > B[1, i]:
            return True
    return False


@jit
def split_prune(code, value, outs, meta, X, Q, XI, max_pieces, tol, sweeps, nl, nh, il, ih, ws):
    """Branch and prune of one pose box whose mode is undecided (see
    :func:`verifier.contractors.split_prune`): ``X`` becomes the hull of the
    surviving pieces (empty when none survives); returns their common mode or 0.

    Pieces are split generation by generation, in the reference's order: the
    kept pieces, then every left half, then every right half.
    """
    n = X.shape[1]
    cap = 2 * max_pieces + 2
    P = np.empty((cap, 2, n))
    Pm = np.empty(cap, np.int64)
    N = 1
    P[0] = X
    Nw = np.empty((cap, 2, n))
    split = np.empty(cap, np.bool_)
    box = np.empty((2, n))
    while True:
        any_split = False
        for p in range(N):
            Pm[p] = mode_of(code, value, outs, meta, P[p], Q, XI, nl, nh, il, ih)
            wmax = P[p, 1, 0] - P[p, 0, 0]
            for i in range(1, n):
                wmax = ops.maxn(wmax, P[p, 1, i] - P[p, 0, i])
            split[p] = Pm[p] == 0 and wmax >= tol and N < max_pieces
            any_split |= split[p]
        if not any_split:
            break
        M = 0
        for p in range(N):
            if not split[p]:
                Nw[M] = P[p]
                M += 1
        for side in range(2):
            for p in range(N):
                if not split[p]:
                    continue
                d = 0
                wd = P[p, 1, 0] - P[p, 0, 0]
                for i in range(1, n):
                    w = P[p, 1, i] - P[p, 0, i]
                    if w > wd:
                        wd = w
                        d = i
                mid = 0.5 * P[p, 0, d] + 0.5 * P[p, 1, d]
                box[:] = P[p]
                if side == 0:
                    box[1, d] = mid
                else:
                    box[0, d] = mid
                alive = True
                for _ in range(sweeps):
                    hc4_pose(code, value, outs, meta, box, Q, XI, nl, nh, il, ih, False)
                    if inverted_box(box):
                        alive = False
                        break
                    newton(code, value, outs, meta, box, Q, XI, True, nl, nh, il, ih, ws)
                    if inverted_box(box):
                        alive = False
                        break
                if alive:
                    Nw[M] = box
                    M += 1
        N = M
        P[:N] = Nw[:N]
        if N == 0:
            break
    lo_mode = 2
    hi_mode = -2
    for i in range(n):
        X[0, i] = np.inf
        X[1, i] = -np.inf
    for p in range(N):
        for i in range(n):
            X[0, i] = min(X[0, i], P[p, 0, i])
            X[1, i] = max(X[1, i], P[p, 1, i])
        lo_mode = min(lo_mode, Pm[p])
        hi_mode = max(hi_mode, Pm[p])
    if N > 0 and lo_mode == hi_mode:
        return lo_mode
    return 0


@jit
def pose_solutions(code, value, outs, meta, n_nodes, Q, XI, X_search, tol, small, max_boxes, sweeps, out, out_mode):
    """Enclose every solution of ``f(x, q, xi) = 0`` in ``X_search`` ``(2, n)``
    (branch and prune of :func:`verifier.contractors.pose_solutions`, same
    order: depth first, left half pushed first).

    Writes the solution boxes to ``out`` ``(max_boxes, 2, n)`` and their
    modes to ``out_mode``; returns their number, or -1 when the budget of
    ``max_boxes`` boxes ran out.
    """
    n = X_search.shape[1]
    nl, nh, il, ih, ws = scratch(n_nodes, n, XI.shape[1])
    stack = np.empty((max_boxes + 2, 2, n))
    stack[0] = X_search
    top = 1
    found = 0
    seen = 0
    X = np.empty((2, n))
    w0 = np.empty(n)
    while top > 0:
        seen += 1
        if seen > max_boxes:
            return -1
        top -= 1
        X[:] = stack[top]
        for _ in range(sweeps):
            for i in range(n):
                w0[i] = X[1, i] - X[0, i]
            hc4_pose(code, value, outs, meta, X, Q, XI, nl, nh, il, ih, False)
            if inverted_box(X):
                break
            newton(code, value, outs, meta, X, Q, XI, True, nl, nh, il, ih, ws)
            if inverted_box(X):
                break
            stalled = True
            for i in range(n):
                stalled &= X[1, i] - X[0, i] >= 0.9 * w0[i]
            if stalled:
                break
        if inverted_box(X):
            continue
        mode = mode_of(code, value, outs, meta, X, Q, XI, nl, nh, il, ih)
        d = 0
        wmax = X[1, 0] - X[0, 0]
        for i in range(1, n):
            if X[1, i] - X[0, i] > wmax:
                wmax = X[1, i] - X[0, i]
                d = i
        if (mode != 0 and wmax < small) or wmax < tol:
            out[found] = X
            out_mode[found] = mode
            found += 1
            continue
        mid = 0.5 * (X[0, d] + X[1, d])
        stack[top] = X
        stack[top, 1, d] = mid
        stack[top + 1] = X
        stack[top + 1, 0, d] = mid
        top += 2
    return found
