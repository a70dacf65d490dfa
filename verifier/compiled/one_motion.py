"""The interval arithmetic of the one-motion step (:mod:`verifier.one_motion`), compiled.

* :func:`dual_bound`: the weak-duality bounds that prove a row refuted or a geometry bound
  (``verifier.certified_lp._dual_bound``);
* :func:`taylor_rows`: the loop closure's linear rows from its enclosures over the boxes
  (the part of ``verifier.one_motion.loop_closure_rows`` after the tapes);
* :func:`tape_points` (:func:`evaluate`): those enclosures, a tape over many boxes
  (:meth:`verifier.tape.Tape.evaluate`), the boxes as lanes.

Each computes what the numpy function computes, operation for operation, with the scalar interval
operations of :mod:`verifier.compiled.interval` (numpy's floats bit for bit, docs/rounding.md): the same
products, the same pairwise sums over the same zero-padded blocks, in the same order
(tests/test_one_motion.py compares the two bit for bit, and checks containment against exact rational
arithmetic).  numpy's versions cost about a millisecond a call in array overheads on the window's
systems (hundreds of rows, a few thousand entries); these a few microseconds.  Imported on first use
only, so that the numpy backend never loads numba.
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from .interval import add, cached_jit, dn0, jit, maxn, midpoint, mul, sub, up, up0
from .contractors import I0
from .lanes.tape import forward as lane_forward
from .tape import Program, trig_memo


@jit
def _pow2_at_least(s):
    """The smallest power of two ``>= s`` (1 for ``s <= 1``): the padded length of a pairwise sum."""
    p = 1
    while p < s:
        p *= 2
    return p


@jit
def _pairwise(lo, hi, w):
    """The outward-rounded pairwise sum of the intervals ``lo[:w]``, ``hi[:w]`` (``w`` a power of two),
    in place: level by level, element ``t`` of a level is the sum of elements ``2t`` and ``2t + 1`` of the
    last one (as ``verifier.certified_lp.tree_sum``)."""
    while w > 1:
        w //= 2
        for t in range(w):
            lo[t], hi[t] = add(lo[2 * t], hi[2 * t], lo[2 * t + 1], hi[2 * t + 1])
    return lo[0], hi[0]


@cached_jit
def dual_bound(rows, cols, vals, b, lo, hi, Y, cost, used, counts, start, order, buf_lo, buf_hi, tlo, left, yb):
    """``left[k]``, a lower bound of ``min over the box of (cost[k] + Y[k]ᵀA) z``, and ``yb[k]``, an upper
    bound of ``Y[k]ᵀb``, for every multiplier row ``k`` (``verifier.certified_lp._dual_bound``).

    ``A`` is given by coordinates ``rows``, ``cols``, ``vals`` ``(E,)`` (int64, int64, float64), ``b``
    ``(M,)``, the box ``lo``, ``hi`` ``(N,)``; ``Y`` ``(B, M)`` holds multipliers already made non-negative
    and finite (the caller's ``y >= 0`` check), ``cost`` ``(B, N)``.  As in numpy's version, an entry (and
    a row of ``b``) takes part when its row has a positive multiplier in *some* row of ``Y``: its products
    are then exactly 0 in the other rows, and still padded into their sums.  Scratch: ``used`` ``(M,)``,
    ``counts`` ``(N,)``, ``start`` ``(N + 1,)``, ``order`` ``(E,)`` (int64), ``buf_lo``, ``buf_hi`` (at
    least the power of two above ``max(E + 1, N, M)``), ``tlo`` ``(N,)``; results ``left``, ``yb`` ``(B,)``.
    Allocates nothing.
    """
    B = Y.shape[0]
    M = Y.shape[1]
    N = lo.shape[0]
    E = rows.shape[0]
    for i in range(M):
        u = 0
        for k in range(B):
            if Y[k, i] > 0.0:
                u = 1
        used[i] = u
    # the entries of the rows in use, column by column, each column's in their order in A (numpy's stable sort)
    for j in range(N):
        counts[j] = 0
    for e in range(E):
        if used[rows[e]] != 0:
            counts[cols[e]] += 1
    start[0] = 0
    for j in range(N):
        start[j + 1] = start[j] + counts[j]
        counts[j] = start[j]  # from here on: where the column's next entry goes
    for e in range(E):
        if used[rows[e]] != 0:
            j = cols[e]
            order[counts[j]] = e
            counts[j] += 1
    for k in range(B):
        # cost_j + sum_i y_i A_ij, each column one padded pairwise sum whose first term is the cost
        for j in range(N):
            c = start[j + 1] - start[j]
            w = _pow2_at_least(c + 1)
            buf_lo[0] = cost[k, j]
            buf_hi[0] = cost[k, j]
            for t in range(c):
                e = order[start[j] + t]
                y = Y[k, rows[e]]
                buf_lo[t + 1], buf_hi[t + 1] = mul(y, y, vals[e], vals[e])
            for t in range(c + 1, w):
                buf_lo[t] = 0.0
                buf_hi[t] = 0.0
            cl, ch = _pairwise(buf_lo, buf_hi, w)
            # min over z_j in [lo_j, hi_j] of c_j z_j, c_j in [cl, ch]: the lower bound of the product
            tlo[j] = mul(cl, ch, lo[j], hi[j])[0]
        w = _pow2_at_least(N)
        for j in range(N):
            buf_lo[j] = tlo[j]
            buf_hi[j] = tlo[j]
        for j in range(N, w):
            buf_lo[j] = 0.0
            buf_hi[j] = 0.0
        left[k] = _pairwise(buf_lo, buf_hi, w)[0]
        # y b over the rows in use, in their order
        L = 0
        for i in range(M):
            if used[i] != 0:
                buf_lo[L], buf_hi[L] = mul(Y[k, i], Y[k, i], b[i], b[i])
                L += 1
        w = _pow2_at_least(L)
        for t in range(L, w):
            buf_lo[t] = 0.0
            buf_hi[t] = 0.0
        yb[k] = _pairwise(buf_lo, buf_hi, w)[1]


@jit
def _mul_up(a, b):
    """Upper bound of the product of non-negative floats, exactly 0 when a factor is 0 (``_mul_up``)."""
    if a == 0.0 or b == 0.0:
        return 0.0
    return up(a * b)


@jit
def _sum_up(v, L):
    """Upper bound of the sum of the non-negative ``v[:L]``, in place (``verifier.one_motion._sum_up``):
    pairwise, a level of odd length padded with one exact 0, every addition rounded up (an exact 0
    stays 0)."""
    while L > 1:
        h = L // 2
        for t in range(h):
            v[t] = up0(v[2 * t] + v[2 * t + 1])
        if L % 2:
            v[h] = up0(v[L - 1] + 0.0)
            h += 1
        L = h
    return v[0]


@cached_jit
def taylor_rows(c, r, Flo, Fhi, Jlo, Jhi, Hlo, Hhi, Jc, blo, bhi, v, plo, phi):
    """The rows ``blo <= Jc z <= bhi`` of the loop closure over ``S`` boxes (``verifier.one_motion.
    loop_closure_rows``, whose notes give the maths), from the box midpoints ``c`` and radii ``r``
    ``(S, N)``, the enclosures of ``f(c)`` ``(S, n)``, of the gradient over the midpoint ``J`` ``(S, n, N)``
    and of the Hessians over the box ``H`` ``(S, n, N, N)``.  Writes ``Jc`` ``(S, n, N)``, ``blo``, ``bhi``
    ``(S, n)`` (infinite where an enclosure holds a NaN).  Scratch: ``v`` (at least ``N * N``), ``plo``,
    ``phi`` (at least the power of two above ``N``).  Allocates nothing."""
    S = c.shape[0]
    N = c.shape[1]
    n = Flo.shape[1]
    w = _pow2_at_least(N)
    for s in range(S):
        for i in range(n):
            for j in range(N):
                m = midpoint(Jlo[s, i, j], Jhi[s, i, j])
                Jc[s, i, j] = m if math.isfinite(m) else 0.0
            # ([g] - Jc) d, |d_j| <= r_j: within +-e1
            for j in range(N):
                el, eh = sub(Jlo[s, i, j], Jhi[s, i, j], Jc[s, i, j], Jc[s, i, j])
                v[j] = _mul_up(maxn(abs(el), abs(eh)), r[s, j])
            e1 = _sum_up(v, N)
            # 1/2 d' H d: d_j d_l in [-r_j r_l, r_j r_l], and in [0, r_j^2] on the diagonal
            nan = False
            for j in range(N):
                for l in range(N):
                    hl = Hlo[s, i, j, l]
                    hh = Hhi[s, i, j, l]
                    nan |= hl != hl or hh != hh
                    g = maxn(hh, 0.0) if j == l else maxn(abs(hl), abs(hh))
                    v[j * N + l] = _mul_up(g, _mul_up(r[s, j], r[s, l]))
            u = _sum_up(v, N * N)
            for j in range(N):
                for l in range(N):
                    hl = Hlo[s, i, j, l]
                    hh = Hhi[s, i, j, l]
                    g = maxn(-hl, 0.0) if j == l else maxn(abs(hl), abs(hh))
                    v[j * N + l] = _mul_up(g, _mul_up(r[s, j], r[s, l]))
            d = _sum_up(v, N * N)
            rhi = up0(0.5 * u)
            rlo = -up0(0.5 * d)
            # Jc c, enclosed: the products, then a pairwise sum padded with exact zeros
            for j in range(N):
                plo[j], phi[j] = mul(Jc[s, i, j], Jc[s, i, j], c[s, j], c[s, j])
            for j in range(N, w):
                plo[j] = 0.0
                phi[j] = 0.0
            ql, qh = _pairwise(plo, phi, w)
            bl, bh = sub(ql, qh, Flo[s, i], Fhi[s, i])
            lo = dn0(bl - rhi)
            hi = up0(bh - rlo)
            lo = dn0(lo - e1)
            hi = up0(hi + e1)
            if nan or lo != lo or hi != hi:
                lo = -math.inf
                hi = math.inf
            blo[s, i] = lo
            bhi[s, i] = hi


#: Points per sweep of :func:`tape_points`: the node bounds of one sweep, ``(n_nodes, LANES)`` twice, stay small
#: (a Hessian tape of a few thousand nodes: a few MiB) whatever the number of points.
LANES = 128


@cached_jit
def tape_points(prog, in_lo, in_hi, out_lo, out_hi, lo, hi, clo, chi, mk, mv, flag):
    """Enclose the dense outputs of tape 0 of the :class:`~verifier.compiled.tape.Program` ``prog`` over ``P``
    input boxes: inputs ``in_lo, in_hi`` ``(inputs, P)``, the tape's dense output entries into ``out_lo, out_hi``
    ``(E, P)`` (a structural zero ``[0, 0]``).  The points run ``W`` at a time as the lanes of
    :func:`verifier.compiled.lanes.tape.forward` (node for node the floats of :meth:`verifier.tape.Tape.evaluate`),
    ``W`` the width of the scratch ``lo, hi`` ``(n_nodes, W)``, ``clo, chi`` ``(inputs, W)`` and ``flag``
    ``(W,)``; ``mk, mv`` a memo of sines and cosines (:func:`verifier.compiled.tape.trig_memo`)."""
    n_in, P = in_lo.shape
    W = lo.shape[1]
    E = out_lo.shape[0]
    o0 = prog.meta[0, 2]
    for s in range(0, P, W):
        L = min(W, P - s)
        for a in range(n_in):
            for r in range(L):
                clo[a, r] = in_lo[a, s + r]
                chi[a, r] = in_hi[a, s + r]
        lane_forward(prog, I0, clo, chi, lo, hi, L, mk, mv, flag)
        for e in range(E):
            node = prog.outs[o0 + e]
            for r in range(L):
                if node < 0:
                    out_lo[e, s + r] = 0.0
                    out_hi[e, s + r] = 0.0
                else:
                    out_lo[e, s + r] = lo[node, r]
                    out_hi[e, s + r] = hi[node, r]


_PROGRAMS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _program(tape) -> Program:
    """``tape`` (:class:`verifier.tape.Tape`) alone as a :class:`Program` for :func:`tape_points`, built once per
    tape (no straight-line code: the lanes interpret it)."""
    prog = _PROGRAMS.get(tape)
    if prog is None:
        a = tape.arrays()
        prog = _PROGRAMS[tape] = Program(code=np.ascontiguousarray(a.code), value=np.ascontiguousarray(a.value),
                                         outs=np.ascontiguousarray(a.out_nodes),
                                         meta=np.array([[0, len(a.code), 0]], np.int64),
                                         n_nodes=max(len(a.code), 1), fns=np.zeros((2, 1), np.int64))
    return prog


def evaluate(tape, inputs):
    """:meth:`verifier.tape.Tape.evaluate` by :func:`tape_points`: the same inputs, the same outputs, the same
    floats (its points as lanes: one dispatch per instruction for up to :data:`LANES` points)."""
    inputs = [(np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)) for lo, hi in inputs]
    bs = np.broadcast_shapes(*(np.shape(lo)[:-1] for lo, _ in inputs)) if inputs else ()
    P = int(np.prod(bs, dtype=np.int64))
    if inputs:
        in_lo, in_hi = (np.ascontiguousarray(np.concatenate(
            [np.broadcast_to(v[k], bs + v[k].shape[-1:]).reshape(P, v[k].shape[-1]) for v in inputs], axis=1).T)
            for k in (0, 1))
    else:
        in_lo = in_hi = np.zeros((0, P))
    prog = _program(tape)
    E = len(prog.outs)
    out_lo, out_hi = np.empty((E, P)), np.empty((E, P))
    if P:
        W = min(LANES, P)
        mk, mv = trig_memo()
        tape_points(prog, in_lo, in_hi, out_lo, out_hi, np.empty((prog.n_nodes, W)), np.empty((prog.n_nodes, W)),
                    np.empty((len(in_lo), W)), np.empty((len(in_lo), W)), mk, mv, np.empty(W, np.bool_))
    result, e0 = [], 0
    for rows, cols in tape.out_shapes:
        shape = bs + ((rows,) if cols == 1 else (rows, cols))
        result.append(tuple(np.ascontiguousarray(v[e0:e0 + rows * cols].T).reshape(shape) for v in (out_lo, out_hi)))
        e0 += rows * cols
    return result


def example_arguments() -> tuple:
    """``((kernel, arguments), ...)``: each kernel with tiny arrays of the argument types
    :mod:`verifier.one_motion` passes (C-contiguous float64 and int64 arrays)."""
    f, i = np.float64, np.int64

    def z(*shape, dtype=f):
        return np.zeros(shape, dtype)

    return ((dual_bound, (z(1, dtype=i), z(1, dtype=i), z(1), z(1), z(1), z(1), z(1, 1), z(1, 1), z(1, dtype=i),
                          z(1, dtype=i), z(2, dtype=i), z(1, dtype=i), z(4), z(4), z(1), z(1), z(1))),
            (taylor_rows, (z(1, 1), z(1, 1), z(1, 1), z(1, 1), z(1, 1, 1), z(1, 1, 1), z(1, 1, 1, 1), z(1, 1, 1, 1),
                           z(1, 1, 1), z(1, 1), z(1, 1), z(1), z(1), z(1))),
            (tape_points, (Program(z(1, 3, dtype=i), z(1), z(1, dtype=i), z(1, 3, dtype=i), 1, z(2, 1, dtype=i)),
                           z(1, 1), z(1, 1), z(1, 1), z(1, 1), z(1, 1), z(1, 1), z(1, 1), z(1, 1), z(1, 3, dtype=i),
                           z(1, 2), z(1, dtype=np.bool_))))


def compile_kernels() -> None:
    """Compile (or load from numba's disk cache) the kernels for the argument types
    :mod:`verifier.one_motion` passes, by calling them on :func:`example_arguments`: the compilation child
    of a first run (:mod:`verifier.compiled.warm`) does it beside the parent's work."""
    for kernel, args in example_arguments():
        kernel(*args)
