"""Contractors of one scenario, compiled: those of :mod:`verifier.contractors`
in the same order of operations, contracting boxes in place.

View-free and allocation-free: a box is an index into an array of boxes
``(N, 2, d)`` (``[i, 0]`` lower and ``[i, 1]`` upper bounds), so a kernel
receives ``X, ix`` rather than a slice ``X[ix]``; temporaries come from the
:class:`Scratch` of the calling thread (node bounds, tape inputs, a flat
float vector ``w`` carved by offsets, scratch boxes ``tb`` whose slots are
named below, split pieces, integers).  Tape inputs are concatenated in the
order ``x, q, xi, *rest``; ``prog`` is a :class:`verifier.compiled.tape.Program`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import interval as ops
from .linalg import gauss_seidel, pmat_imat, pmat_ivec, point_inverse, precondition, solve_preconditioned
from .interval import cached_jit, inline_jit, jit
from .tape import T_DET, T_F, T_JQ, T_JX, T_VEL, forward, hc4, output, trig_memo

# slots of the scratch boxes ``Scratch.tb`` (width max(n, m)); the displacement
# differences of the baselines follow from TB_DQ on
# numpy integers: one compiled copy of the box helpers for every slot (see verifier.compiled.tape.T_F)
TB_QD, TB_XIW, TB_XS, TB_XDS, TB_ACC, TB_Q0, TB_QS, TB_PIECE, TB_SWEEP, TB_QN, TB_DQ = (np.int64(i) for i in range(11))
#: Constant arguments of callees as numpy scalars, never Python literals: numba compiles a callee
#: once more for every literal argument (``newton(..., True, ...)`` and ``newton(..., False, ...)``
#: were two compilations of the whole Newton step; 19 of 88 such copies; tests/test_kernel_compilation.py).
I0 = np.int64(0)
NO_SLACK = np.int64(-1)
ONE = np.int64(1)
TWO = np.int64(2)
YES = np.bool_(True)
NO = np.bool_(False)


class Scratch(NamedTuple):
    """Scratch of one thread (see :func:`scratch_arrays` for the sizes).

    Attributes
    ----------
    nl, nh : float64 (n_nodes,)
        Node bounds of the tape being evaluated.
    il, ih : float64 (5 n + m,)
        Tape inputs.
    w : float64 (:func:`workspace_size`,)
        Flat temporaries (matrices and vectors at offsets).
    tb : float64 (TB_DQ + J, 2, max(n, m))
        Scratch boxes, slots ``TB_*``.
    pieces : float64 (2 cap, 2, n)
        Two generations of split-and-prune pieces, ``cap = 2 max_pieces + 2``.
    wi : int64 (J + 2 cap,)
        Baseline slots, then the pieces' modes and split flags.
    modes : int64 (P,)
        Mode of each geometry hypothesis of the current sample.
    row_qdd : float64 (P, 2, n)
        Joint-acceleration bound of each hypothesis (then ``|qdd|`` in row 0).
    mk, mv : int64 (MEMO_SIZE, 3), float64 (MEMO_SIZE, 2)
        Memo of sines and cosines (:func:`verifier.compiled.tape.trig_memo`):
        per thread, since a slot is written as two keys and two values.
    """

    nl: np.ndarray
    nh: np.ndarray
    il: np.ndarray
    ih: np.ndarray
    w: np.ndarray
    tb: np.ndarray
    pieces: np.ndarray
    wi: np.ndarray
    modes: np.ndarray
    row_qdd: np.ndarray
    mk: np.ndarray
    mv: np.ndarray


def workspace_size(n):
    """Floats of ``Scratch.w`` for dimension ``n``: at most ``13 n + 14 n^2``
    (interval Newton, then the joint-acceleration bound's two solves), with room.
    Plain Python: only the allocation calls it (compiled, every process paid a
    compilation for it)."""
    return 16 * n + 16 * n * n + 64


def scratch_arrays(threads, n_nodes, n, m, baselines, max_pieces, hypotheses):
    """Per-thread scratch as numpy arrays with a leading ``threads`` axis, in
    the order of :class:`Scratch` (allocated once per tracker)."""
    cap = 2 * max(int(max_pieces), 0) + 2
    T = int(threads)
    mk, mv = trig_memo()
    return Scratch(np.zeros((T, n_nodes)), np.zeros((T, n_nodes)), np.zeros((T, 5 * n + m)),
                   np.zeros((T, 5 * n + m)), np.zeros((T, workspace_size(n))),
                   np.zeros((T, TB_DQ + max(int(baselines), 1), 2, max(n, m))), np.zeros((T, 2 * cap, 2, n)),
                   np.zeros((T, max(int(baselines), 1) + 2 * cap), np.int64), np.zeros((T, hypotheses), np.int64),
                   np.zeros((T, hypotheses, 2, n)), np.repeat(mk[None], T, axis=0), np.repeat(mv[None], T, axis=0))


@jit
def thread_scratch(S, t):
    """The :class:`Scratch` of thread slot ``t`` (rows of the arrays ``S``)."""
    return Scratch(S.nl[t], S.nh[t], S.il[t], S.ih[t], S.w[t], S.tb[t], S.pieces[t], S.wi[t], S.modes[t],
                   S.row_qdd[t], S.mk[t], S.mv[t])


@jit
def copy_box(S, s, D, d, k):
    """``D[d] <- S[s]`` over the first ``k`` components."""
    for i in range(k):
        D[d, 0, i] = S[s, 0, i]
        D[d, 1, i] = S[s, 1, i]


@jit
def set_input(in_lo, in_hi, slot, B, b, k):
    """Copy the box ``B[b]`` (``k`` components) into the input vector from ``slot`` on."""
    for i in range(k):
        in_lo[slot + i] = B[b, 0, i]
        in_hi[slot + i] = B[b, 1, i]


@jit
def _set_pose_inputs(sc, X, ix, Q, iq, XI, ixi, n, m):
    set_input(sc.il, sc.ih, I0, X, ix, n)
    set_input(sc.il, sc.ih, n, Q, iq, n)
    set_input(sc.il, sc.ih, 2 * n, XI, ixi, m)


@jit
def hc4_pose(prog, X, ix, Q, iq, XI, ixi, n, m, sc, joints_too):
    """HC4Revise on ``f(x, q, xi) = 0``: contracts ``X[ix]`` in place, and
    ``Q[iq]`` and ``XI[ixi]`` too when ``joints_too`` (else they are kept)."""
    il = sc.il
    ih = sc.ih
    _set_pose_inputs(sc, X, ix, Q, iq, XI, ixi, n, m)
    hc4(prog, T_F, n, il, ih, sc.nl, sc.nh, sc.mk, sc.mv)
    for i in range(n):
        X[ix, 0, i] = il[i]
        X[ix, 1, i] = ih[i]
    if joints_too:
        for i in range(n):
            Q[iq, 0, i] = il[n + i]
            Q[iq, 1, i] = ih[n + i]
        for i in range(m):
            XI[ixi, 0, i] = il[2 * n + i]
            XI[ixi, 1, i] = ih[2 * n + i]


@jit
def newton(prog, X, ix, Q, iq, XI, ixi, on_x, n, m, sc):
    """One preconditioned Hansen–Sengupta step on ``f = 0`` in ``x`` (``on_x``)
    or in ``q``; contracts that box in place.  Uses ``sc.w[:7 n + 7 n^2]``."""
    w = sc.w
    il = sc.il
    ih = sc.ih
    nn = n * n
    mid, fl, fh, bl, bh, yl, yh = 0, n, 2 * n, 3 * n, 4 * n, 5 * n, 6 * n
    jl = 7 * n
    jh = jl + nn
    jm = jl + 2 * nn
    c = jl + 3 * nn
    al = jl + 4 * nn
    ah = jl + 5 * nn
    V = X if on_x else Q
    iv = ix if on_x else iq
    tape_j = T_JX if on_x else T_JQ
    for i in range(n):
        w[mid + i] = ops.midpoint(V[iv, 0, i], V[iv, 1, i])
    _set_pose_inputs(sc, X, ix, Q, iq, XI, ixi, n, m)
    off = 0 if on_x else n
    for i in range(n):
        il[off + i] = w[mid + i]
        ih[off + i] = w[mid + i]
    forward(prog, T_F, il, ih, sc.nl, sc.nh, sc.mk, sc.mv)
    for i in range(n):
        w[fl + i], w[fh + i] = output(prog, T_F, i, sc.nl, sc.nh)
    set_input(il, ih, off, V, iv, n)
    forward(prog, tape_j, il, ih, sc.nl, sc.nh, sc.mk, sc.mv)
    for e in range(nn):
        lo, hi = output(prog, tape_j, e, sc.nl, sc.nh)
        w[jl + e] = lo
        w[jh + e] = hi
        w[jm + e] = ops.midpoint(lo, hi)
    point_inverse(w, jm, c, jl + 6 * nn, n)
    pmat_imat(w, c, jl, jh, al, ah, n)
    pmat_ivec(w, c, fl, fh, bl, bh, n)
    for i in range(n):
        w[bl + i], w[bh + i] = -w[bh + i], -w[bl + i]
        w[yl + i], w[yh + i] = ops.sub(V[iv, 0, i], V[iv, 1, i], w[mid + i], w[mid + i])
    gauss_seidel(w, al, ah, bl, bh, yl, yh, n, ONE)
    for i in range(n):
        vl, vh = ops.add(w[mid + i], w[mid + i], w[yl + i], w[yh + i])
        V[iv, 0, i], V[iv, 1, i] = ops.intersect(V[iv, 0, i], V[iv, 1, i], vl, vh)


@jit
def mode_of(prog, X, ix, Q, iq, XI, ixi, n, m, sc):
    """+1 / -1 when ``mode_sign det J_x`` has that sign over the box, else 0."""
    _set_pose_inputs(sc, X, ix, Q, iq, XI, ixi, n, m)
    forward(prog, T_DET, sc.il, sc.ih, sc.nl, sc.nh, sc.mk, sc.mv)
    dl, dh = output(prog, T_DET, I0, sc.nl, sc.nh)
    if dl > 0.0:
        return 1
    if dh < 0.0:
        return -1
    return 0


@inline_jit
def _solve_vel(prog, sc, y, slack, sweeps, off, n, same_a):
    # evaluate the vel tape (inputs already set), then [y] (at w[y], w[y + n])
    # <- enclosure of J_x u = -J_q qd from the start box [y] (+ slack at
    # w[slack], w[slack + n], when slack >= 0) (+ slack after).  With same_a,
    # w[off:] holds the last call's J_x and its preconditioning, untouched since:
    # when this J_x has the same bits (the baselines' hulls often coincide), the
    # preconditioning is the same floats and is not computed again
    w = sc.w
    nn = n * n
    forward(prog, T_VEL, sc.il, sc.ih, sc.nl, sc.nh, sc.mk, sc.mv)
    jl = off
    jh = off + nn
    bl = off + 2 * nn
    bh = bl + n
    yl = bh + n
    yh = yl + n
    for i in range(n):
        for j in range(n):
            lo, hi = output(prog, T_VEL, i * n + j, sc.nl, sc.nh)
            e = i * n + j
            same_a = same_a and ops._bits(lo) == ops._bits(w[jl + e]) and ops._bits(hi) == ops._bits(w[jh + e])
            w[jl + e] = lo
            w[jh + e] = hi
        rl, rh = output(prog, T_VEL, nn + i, sc.nl, sc.nh)
        w[bl + i] = -rh
        w[bh + i] = -rl
    for i in range(n):
        if slack < 0:
            w[yl + i] = w[y + i]
            w[yh + i] = w[y + n + i]
        else:
            w[yl + i], w[yh + i] = ops.add(w[y + i], w[y + n + i], w[slack + i], w[slack + n + i])
    if not same_a:
        precondition(w, jl, jh, n, yh + n)
    solve_preconditioned(w, bl, bh, yl, yh, n, YES, sweeps, yh + n)
    for i in range(n):
        if slack < 0:
            w[y + i] = w[yl + i]
            w[y + n + i] = w[yh + i]
        else:
            w[y + i], w[y + n + i] = ops.add(w[yl + i], w[yh + i], w[slack + i], w[slack + n + i])


@jit
def velocity_gs(prog, X, ix, Q, iq, XI, ixi, XD, ixd, QD, iqd, n, m, sc):
    """Contract ``XD[ixd]`` in place with ``J_x xd = -J_q qd`` (one enclosure of ``J_q qd``)."""
    w = sc.w
    _set_pose_inputs(sc, X, ix, Q, iq, XI, ixi, n, m)
    set_input(sc.il, sc.ih, 2 * n + m, QD, iqd, n)
    for i in range(n):
        w[i] = XD[ixd, 0, i]
        w[n + i] = XD[ixd, 1, i]
    _solve_vel(prog, sc, I0, NO_SLACK, ONE, 2 * n, n, NO)
    for i in range(n):
        XD[ixd, 0, i] = w[i]
        XD[ixd, 1, i] = w[n + i]


@inline_jit
def velocity_displacement(prog, X, ix, Q, iq, XI, ixi, XD, ixd, past_x, past_q, r, DQ, dq0, baseline, idx,
                          n_base, axis, n, m, sc):
    """Contract ``XD[ixd]`` in place with the displacements over ``n_base``
    baselines (see :func:`verifier.contractors.velocity_displacement`).

    ``past_x[r, idx[j]]``, ``past_q[r, idx[j]]`` are the boxes at
    ``t_k - h_j``; ``DQ[dq0 + j]`` encloses the mean joint rate
    ``(q_k - q_{k-j}) / h_j`` (rad/s; the same for every iteration of a sample, so
    the caller divides once);
    ``baseline[j]`` holds ``h_j`` (``h_lo``, ``h_hi``, s); ``axis[i].a_max``
    m/s^2.  Uses ``sc.w[:12 n + 7 n^2 + 1]``.
    """
    if n_base == 0:
        return
    w = sc.w
    il = sc.il
    ih = sc.ih
    accl, acch, u, slack = 0, n, 2 * n, 4 * n
    for jb in range(n_base):
        p = idx[jb]
        h_hi = baseline[jb].h_hi
        for i in range(n):
            il[i], ih[i] = ops.hull(X[ix, 0, i], X[ix, 1, i], past_x[r, p, 0, i], past_x[r, p, 1, i])
            il[n + i], ih[n + i] = ops.hull(Q[iq, 0, i], Q[iq, 1, i], past_q[r, p, 0, i], past_q[r, p, 1, i])
            il[2 * n + m + i] = DQ[dq0 + jb, 0, i]
            ih[2 * n + m + i] = DQ[dq0 + jb, 1, i]
        for i in range(m):
            il[2 * n + i] = XI[ixi, 0, i]
            ih[2 * n + i] = XI[ixi, 1, i]
        half_h = ops.scale(0.5, h_hi, h_hi)[1]
        for i in range(n):
            a = axis[i].a_max
            w[slack + i], w[slack + n + i] = ops.mul(-half_h, half_h, -a, a)
            w[u + i] = XD[ixd, 0, i]
            w[u + n + i] = XD[ixd, 1, i]
        # the baselines before this one wrote w[6 n:] last (nothing else runs in between)
        _solve_vel(prog, sc, u, slack, ONE, 6 * n, n, jb > 0)
        for i in range(n):
            w[accl + i] = w[u + i] if jb == 0 else ops.maxn(w[accl + i], w[u + i])
            w[acch + i] = w[u + n + i] if jb == 0 else ops.minn(w[acch + i], w[u + n + i])
    for i in range(n):
        XD[ixd, 0, i] = ops.maxn(XD[ixd, 0, i], w[accl + i])
        XD[ixd, 1, i] = ops.minn(XD[ixd, 1, i], w[acch + i])


@jit
def empty_box(B, b, k):
    """Whether the box ``B[b]`` (``k`` components) is empty: some ``not (lo <= hi)`` (a NaN bound counts)."""
    for i in range(k):
        if not (B[b, 0, i] <= B[b, 1, i]):
            return True
    return False


@jit
def same_box(A, a, B, b, k):
    """Whether the boxes ``A[a]`` and ``B[b]`` (``k`` components) have the same bit patterns (``-0.0``
    and ``0.0`` differ, a NaN matches only its own pattern): inputs a kernel cannot tell apart."""
    for i in range(k):
        if ops._bits(A[a, 0, i]) != ops._bits(B[b, 0, i]) or ops._bits(A[a, 1, i]) != ops._bits(B[b, 1, i]):
            return False
    return True


@jit
def inverted_box(B, b, k):
    """Whether some ``lo > hi``: the branch and prunes' test (as the
    reference's ``np.any(lo > hi)``, a NaN bound does not count)."""
    for i in range(k):
        if B[b, 0, i] > B[b, 1, i]:
            return True
    return False


@jit
def _hull_of_pieces(P, N, wi, pm, sp, unsplit, B, b, n):
    """``B[b]`` <- the hull of the pieces ``P[:N]`` (those whose split flag ``wi[sp + p]`` is 0 when
    ``unsplit``); returns the least and greatest of their modes ``wi[pm + p]`` (2, -2 for no piece) and
    whether every bound read is a number."""
    lo_mode = 2
    hi_mode = -2
    numbers = True
    for i in range(n):
        B[b, 0, i] = np.inf
        B[b, 1, i] = -np.inf
    for p in range(N):
        if unsplit and wi[sp + p] != 0:
            continue
        lo_mode = min(lo_mode, wi[pm + p])
        hi_mode = max(hi_mode, wi[pm + p])
        for i in range(n):
            lo, hi = P[p, 0, i], P[p, 1, i]
            numbers &= lo == lo and hi == hi
            B[b, 0, i] = min(B[b, 0, i], lo)
            B[b, 1, i] = max(B[b, 1, i], hi)
    return lo_mode, hi_mode, numbers


@jit
def _settle(P, N, wi, pm, sp, tb, n):
    """Clear the split flag ``wi[sp + p]`` of the pieces ``P[:N]`` whose splitting can change neither
    result of :func:`split_prune` (:func:`verifier.contractors._settled`: the unsplit pieces have modes
    ``wi[pm:]`` of no common value, and their hull holds the piece); returns whether a piece still splits.
    The hull is built in the scratch box ``tb[TB_SWEEP]``, free until the halves are contracted; a NaN
    bound settles nothing (numpy's minimum propagates it)."""
    lo_mode, hi_mode, numbers = _hull_of_pieces(P, N, wi, pm, sp, YES, tb, TB_SWEEP, n)
    if not (numbers and lo_mode <= 0 and hi_mode >= 0):
        return True
    any_split = False
    for p in range(N):
        if wi[sp + p] == 0:
            continue
        inside = True
        for i in range(n):
            inside &= P[p, 0, i] >= tb[TB_SWEEP, 0, i] and P[p, 1, i] <= tb[TB_SWEEP, 1, i]
        if inside:
            wi[sp + p] = 0
        else:
            any_split = True
    return any_split


@inline_jit
def split_prune(prog, X, ix, Q, iq, XI, ixi, max_pieces, tol, sweeps, n, m, sc, wi0):
    """Branch and prune of one pose box whose mode is undecided (see
    :func:`verifier.contractors.split_prune`): ``X[ix]`` becomes the hull of
    the surviving pieces (empty when none survives); returns their common mode or 0.

    Pieces are split generation by generation, in the reference's order: the
    kept pieces, then every left half, then every right half; a piece whose
    splitting can change neither result stays whole (:func:`_settle`).  The two
    generations live in ``sc.pieces[:cap]`` and ``sc.pieces[cap:]``, their
    modes and split flags in ``sc.wi[wi0:]``.  Two computations of the
    reference are skipped because their results are known bit for bit: the
    mode of a piece kept unsplit (its box, ``Q[iq]`` and ``XI[ixi]`` are those
    it was computed from), and the sweeps of a piece after one that left it
    unchanged (each would repeat it).
    """
    cap = 2 * max_pieces + 2
    P = sc.pieces
    pm = wi0
    sp = wi0 + cap
    wi = sc.wi
    tb = sc.tb
    N = ONE  # not the literal 1: passed on to _settle and _hull_of_pieces (see I0)
    known = 0  # pieces 0 .. known - 1 were kept unsplit: their boxes and modes are those of the last generation
    copy_box(X, ix, P, I0, n)
    while True:
        any_split = False
        for p in range(N):
            if p >= known:  # the mode is a function of the piece, Q[iq] and XI[ixi], none of which changed
                wi[pm + p] = mode_of(prog, P, p, Q, iq, XI, ixi, n, m, sc)
            wmax = P[p, 1, 0] - P[p, 0, 0]
            for i in range(1, n):
                wmax = ops.maxn(wmax, P[p, 1, i] - P[p, 0, i])
            s = wi[pm + p] == 0 and wmax >= tol and N < max_pieces
            wi[sp + p] = 1 if s else 0
            any_split |= s
        if any_split:
            any_split = _settle(P, N, wi, pm, sp, tb, n)
        if not any_split:
            break
        M = 0
        for p in range(N):
            if wi[sp + p] == 0:
                copy_box(P, p, P, cap + M, n)
                wi[pm + M] = wi[pm + p]  # M <= p: overwrites only modes already read
                M += 1
        known = M
        for side in range(2):
            for p in range(N):
                if wi[sp + p] == 0:
                    continue
                d = 0
                wd = P[p, 1, 0] - P[p, 0, 0]
                for i in range(1, n):
                    wv = P[p, 1, i] - P[p, 0, i]
                    if wv > wd:
                        wd = wv
                        d = i
                mid = 0.5 * P[p, 0, d] + 0.5 * P[p, 1, d]
                copy_box(P, p, tb, TB_PIECE, n)
                if side == 0:
                    tb[TB_PIECE, 1, d] = mid
                else:
                    tb[TB_PIECE, 0, d] = mid
                alive = True
                for _ in range(sweeps):
                    copy_box(tb, TB_PIECE, tb, TB_SWEEP, n)
                    hc4_pose(prog, tb, TB_PIECE, Q, iq, XI, ixi, n, m, sc, NO)
                    if inverted_box(tb, TB_PIECE, n):
                        alive = False
                        break
                    newton(prog, tb, TB_PIECE, Q, iq, XI, ixi, YES, n, m, sc)
                    if inverted_box(tb, TB_PIECE, n):
                        alive = False
                        break
                    # a sweep that left the piece as it was: the next ones would repeat it float for float
                    # (Q[iq], XI[ixi] are not contracted here), so they are skipped
                    if same_box(tb, TB_PIECE, tb, TB_SWEEP, n):
                        break
                if alive:
                    copy_box(tb, TB_PIECE, P, cap + M, n)
                    M += 1
        N = M
        for p in range(N):
            copy_box(P, cap + p, P, p, n)
        if N == 0:
            break
    lo_mode, hi_mode, _ = _hull_of_pieces(P, N, wi, pm, I0, NO, X, ix, n)
    if N > 0 and lo_mode == hi_mode:
        return lo_mode
    return 0


@cached_jit
def pose_solutions(prog, Q, XI, X_search, tol, small, max_boxes, sweeps, out, out_mode, S, work):
    """Enclose every solution of ``f(x, q, xi) = 0`` in ``X_search`` (boxes
    ``(1, 2, n)``, ``(1, 2, n)``, ``(1, 2, m)``; branch and prune of
    :func:`verifier.contractors.pose_solutions`, same order: depth first,
    left half pushed first).

    Writes the solution boxes to ``out`` ``(max_boxes, 2, n)`` and their
    modes to ``out_mode``; returns their number, or -1 when the budget of
    ``max_boxes`` boxes ran out.  Allocates nothing: ``S`` is one thread's
    scratch (:func:`scratch_arrays` with one thread) and ``work``
    ``(max_boxes + 4, 2, n)`` holds the stack (rows ``0 .. max_boxes + 1``),
    the current box (row ``max_boxes + 2``) and its widths before a sweep
    (row ``max_boxes + 3``, lower bounds).
    """
    n = X_search.shape[2]
    m = XI.shape[2]
    sc = thread_scratch(S, I0)
    stack = work
    copy_box(X_search, I0, stack, I0, n)
    top = 1
    found = I0  # a literal 0 here compiled copy_box once more
    seen = 0
    X = work[max_boxes + 2:max_boxes + 3]
    w0 = work[max_boxes + 3, 0]
    while top > 0:
        seen += 1
        if seen > max_boxes:
            return -1
        top -= 1
        copy_box(stack, top, X, I0, n)
        for _ in range(sweeps):
            for i in range(n):
                w0[i] = X[0, 1, i] - X[0, 0, i]
            hc4_pose(prog, X, I0, Q, I0, XI, I0, n, m, sc, NO)
            if inverted_box(X, I0, n):
                break
            newton(prog, X, I0, Q, I0, XI, I0, YES, n, m, sc)
            if inverted_box(X, I0, n):
                break
            stalled = True
            for i in range(n):
                stalled &= X[0, 1, i] - X[0, 0, i] >= 0.9 * w0[i]
            if stalled:
                break
        if inverted_box(X, I0, n):
            continue
        mode = mode_of(prog, X, I0, Q, I0, XI, I0, n, m, sc)
        d = 0
        wmax = X[0, 1, 0] - X[0, 0, 0]
        for i in range(1, n):
            if X[0, 1, i] - X[0, 0, i] > wmax:
                wmax = X[0, 1, i] - X[0, 0, i]
                d = i
        if (mode != 0 and wmax < small) or wmax < tol:
            copy_box(X, I0, out, found, n)
            out_mode[found] = mode
            found += 1
            continue
        mid = 0.5 * (X[0, 0, d] + X[0, 1, d])
        copy_box(X, I0, stack, top, n)
        stack[top, 1, d] = mid
        copy_box(X, I0, stack, top + 1, n)
        stack[top + 1, 0, d] = mid
        top += 2
    return found
