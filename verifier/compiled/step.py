"""The tracker's step, compiled: one sample for every scenario, in place on the
arrays of :class:`verifier.tracker.TrackerState`.

The maths is that of :mod:`verifier.tracker` (prediction with Lagrange
remainder, measurement boxes, velocity information, contraction to a per-row
fixpoint, mode, branch and prune, hypotheses combined); the numpy step there is
the reference this kernel must agree with.  Rows ``r = b P + p`` are the
geometry hypotheses ``p`` of scenario ``b``; a scenario and its rows are
independent of every other scenario, so :func:`run_parallel` spreads
scenarios over threads (``prange``) with the sample loop inside.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from . import ops
from .contractors import (
    empty_box,
    hc4_pose,
    mode_of,
    newton,
    split_prune,
    velocity_displacement,
    velocity_gs,
    scratch,
    workspace_size,
)
from .linalg import linear_enclosure
from .ops import jit
from .tape import T_ACCEL, T_JQ, T_JX_XD, forward, output

# indices into the constant arrays built by verifier.tracker._Constants
F_TS, F_REL_TOL, F_SPLIT_TOL, F_SPLIT_MAX_W = range(4)
I_VMODEL, I_MAX_ITER, I_SPLIT_BOXES, I_KEEP_XI, I_P, I_HAS_QDD, I_RECORD, I_PRIOR = range(8)
V_EPS, V_AMAX, V_VMAX, V_H2A_LO, V_H2A_HI, V_TSA_LO, V_TSA_HI, V_QUANT_LO, V_QUANT_HI, V_QDD = range(10)
SOUND, JOINT_FD, PAPER = range(3)


@jit
def _wsum(B):
    s = 0.0
    for i in range(B.shape[1]):
        s += ops.width(B[0, i], B[1, i])
    return s


@jit
def _qdd_over_step(code, value, outs, meta, X, XD, Qp, Qn, XI, vec, ts, QDD, nl, nh, il, ih, ws):
    """Joint-acceleration bound over the sampling interval (``JOINT_FD``), see
    :func:`verifier.tracker._qdd_over_step`; writes ``QDD`` ``(2, n)``."""
    n = X.shape[1]
    m = XI.shape[1]
    Xs = np.empty((2, n))
    XDs = np.empty((2, n))
    A = np.empty((2, n))
    h2l, h2h = ops.scale(0.5, *ops.mul(ts, ts, ts, ts))
    h2l, h2h = ops.hull(0.0, 0.0, h2l, h2h)
    Q0 = np.empty((2, n))
    for i in range(n):
        A[0, i] = -vec[V_AMAX, i]
        A[1, i] = vec[V_AMAX, i]
        pl, ph = ops.mul(0.0, ts, XD[0, i], XD[1, i])
        xl, xh = ops.add(X[0, i], X[1, i], pl, ph)
        pl, ph = ops.mul(h2l, h2h, A[0, i], A[1, i])
        Xs[0, i], Xs[1, i] = ops.add(xl, xh, pl, ph)
        pl, ph = ops.mul(0.0, ts, A[0, i], A[1, i])
        XDs[0, i], XDs[1, i] = ops.add(XD[0, i], XD[1, i], pl, ph)
        ql, qh = ops.hull(Qp[0, i], Qp[1, i], Qn[0, i], Qn[1, i])
        Q0[0, i] = ql - 0.05  # rad; the result must land strictly inside this box
        Q0[1, i] = qh + 0.05
    Qs = Q0.copy()
    for _ in range(3):
        newton(code, value, outs, meta, Xs, Qs, XI, False, nl, nh, il, ih, ws)
        for i in range(n):
            if Qs[0, i] > Qs[1, i]:
                Qs[0, i] = Q0[0, i]
                Qs[1, i] = Q0[1, i]
    inside = True
    for i in range(n):
        inside &= Qs[0, i] > Q0[0, i] and Qs[1, i] < Q0[1, i]
    for s_, B in ((0, Xs), (n, Qs), (2 * n, XI)):
        for i in range(B.shape[1]):
            il[s_ + i] = B[0, i]
            ih[s_ + i] = B[1, i]
    for i in range(n):
        il[2 * n + m + i] = XDs[0, i]
        ih[2 * n + m + i] = XDs[1, i]
    Jl = np.empty((n, n))
    Jh = np.empty((n, n))
    forward(code, value, meta, T_JQ, il, ih, nl, nh)
    for i in range(n):
        for j in range(n):
            Jl[i, j], Jh[i, j] = output(outs, meta, T_JQ, i * n + j, nl, nh)
    forward(code, value, meta, T_JX_XD, il, ih, nl, nh)
    bl = np.empty(n)
    bh = np.empty(n)
    for i in range(n):
        rl, rh = output(outs, meta, T_JX_XD, i, nl, nh)
        bl[i] = -rh
        bh[i] = -rl
    QDl = np.empty(n)
    QDh = np.empty(n)
    linear_enclosure(Jl, Jh, bl, bh, QDl, QDh, False, 2, ws, 0)
    for i in range(n):
        il[3 * n + m + i] = QDl[i]
        ih[3 * n + m + i] = QDh[i]
        il[4 * n + m + i] = A[0, i]
        ih[4 * n + m + i] = A[1, i]
    forward(code, value, meta, T_ACCEL, il, ih, nl, nh)
    for i in range(n):
        rl, rh = output(outs, meta, T_ACCEL, i, nl, nh)
        bl[i] = -rh
        bh[i] = -rl
    linear_enclosure(Jl, Jh, bl, bh, QDl, QDh, False, 2, ws, 0)
    for i in range(n):
        ok = inside and math.isfinite(QDl[i]) and math.isfinite(QDh[i]) and not (QDl[i] > QDh[i])
        QDD[0, i] = QDl[i] if ok else -np.inf
        QDD[1, i] = QDh[i] if ok else np.inf


@jit
def _row_step(code, value, outs, meta, r, k, qk, X, XD, XI, Q, past_x, past_q, past_r, row_bad, n_past,
              fpar, ipar, vec, base, diff_err, h, QDD, nl, nh, il, ih, ws, pri_x, pri_xd):
    """Advance row ``r`` by the reading ``qk`` ``(n,)``; returns its mode.
    ``QDD`` ``(2, n)`` receives the joint-acceleration bound used; when
    ``ipar[I_PRIOR]``, the boxes ``pri_x``, ``pri_xd`` ``(2, n)`` known to hold
    the truth at this sample are intersected with the prediction."""
    n = qk.shape[0]
    D = past_x.shape[1]
    ts = fpar[F_TS]
    vmodel = ipar[I_VMODEL]
    Xr = X[r]
    XDr = XD[r]
    XIr = XI[r]
    Qr = Q[r]
    Qn = np.empty((2, n))
    QD = np.empty((2, n))
    for i in range(n):
        Qn[0, i] = ops.sub(qk[i], qk[i], vec[V_EPS, i], vec[V_EPS, i])[0]
        Qn[1, i] = ops.add(qk[i], qk[i], vec[V_EPS, i], vec[V_EPS, i])[1]
        QDD[0, i] = -np.inf
        QDD[1, i] = np.inf
        QD[0, i] = -np.inf
        QD[1, i] = np.inf
    if k > 0 and vmodel != SOUND:
        prev = (k - 1) % D
        if vmodel == JOINT_FD:
            _qdd_over_step(code, value, outs, meta, Xr, XDr, past_q[r, prev], Qn, XIr, vec, ts, QDD,
                           nl, nh, il, ih, ws)
            if ipar[I_HAS_QDD]:
                for i in range(n):
                    QDD[0, i], QDD[1, i] = ops.intersect(QDD[0, i], QDD[1, i], -vec[V_QDD, i], vec[V_QDD, i])
        for i in range(n):
            qp = past_r[r, prev, i]
            dl, dh = ops.sub(qk[i], qk[i], qp, qp)
            fl, fh = ops.div(dl, dh, ts, ts)
            ql, qh = ops.add(fl, fh, vec[V_QUANT_LO, i], vec[V_QUANT_HI, i])
            if vmodel == JOINT_FD:
                tl, th = ops.mul(0.5 * ts, 0.5 * ts, QDD[0, i], QDD[1, i])
                ql, qh = ops.add(ql, qh, tl, th)
                ql = -np.inf if ql != ql else ql
                qh = np.inf if qh != qh else qh
            QD[0, i] = ql
            QD[1, i] = qh
    if k > 0:
        for i in range(n):
            pl, ph = ops.scale(ts, XDr[0, i], XDr[1, i])
            xl, xh = ops.add(Xr[0, i], Xr[1, i], pl, ph)
            Xr[0, i], Xr[1, i] = ops.add(xl, xh, vec[V_H2A_LO, i], vec[V_H2A_HI, i])
            vl, vh = ops.add(XDr[0, i], XDr[1, i], vec[V_TSA_LO, i], vec[V_TSA_HI, i])
            XDr[0, i], XDr[1, i] = ops.intersect(vl, vh, -vec[V_VMAX, i], vec[V_VMAX, i])
    if ipar[I_PRIOR]:
        for i in range(n):
            Xr[0, i], Xr[1, i] = ops.intersect(Xr[0, i], Xr[1, i], pri_x[0, i], pri_x[1, i])
            XDr[0, i], XDr[1, i] = ops.intersect(XDr[0, i], XDr[1, i], pri_xd[0, i], pri_xd[1, i])
    for i in range(n):
        Qr[0, i] = Qn[0, i]
        Qr[1, i] = Qn[1, i]
    # displacement baselines: past boxes and readings only, built once per sample
    J = base.shape[0]
    idx = np.empty(J, np.int64)
    DQ = np.empty((J, 2, n))
    n_base = 0
    if vmodel == SOUND:
        for jb in range(J):
            j = base[jb]
            if j > n_past:
                break
            p = (k - j) % D
            idx[jb] = p
            for i in range(n):
                qp = past_r[r, p, i]
                dl, dh = ops.sub(qk[i], qk[i], qp, qp)
                DQ[jb, 0, i], DQ[jb, 1, i] = ops.add(dl, dh, diff_err[jb, 0, i], diff_err[jb, 1, i])
            n_base += 1
    keep_xi = ipar[I_KEEP_XI] != 0
    XIw = XIr.copy()
    has_qd = False
    for i in range(n):
        has_qd |= math.isfinite(QD[0, i])
    dead = False
    for _ in range(ipar[I_MAX_ITER]):
        wx0 = _wsum(Xr)
        wv0 = _wsum(XDr)
        if not keep_xi:
            XIw[:] = XIr
        hc4_pose(code, value, outs, meta, Xr, Qr, XIw, nl, nh, il, ih, True)
        if keep_xi:
            XIr[:] = XIw
        newton(code, value, outs, meta, Xr, Qr, XIr, True, nl, nh, il, ih, ws)
        if vmodel == SOUND:
            velocity_displacement(code, value, outs, meta, Xr, Qr, XIr, XDr, past_x[r], past_q[r], DQ, h, idx,
                                  n_base, vec[V_AMAX], nl, nh, il, ih, ws)
        elif has_qd:
            velocity_gs(code, value, outs, meta, Xr, Qr, XIr, XDr, QD, nl, nh, il, ih, ws)
        if empty_box(Xr) or empty_box(XDr) or empty_box(XIr) or empty_box(Qr):
            dead = True
            break
        wx1 = _wsum(Xr)
        wv1 = _wsum(XDr)
        gx = (wx0 - wx1) / ops.maxn(wx0, 1e-300)
        gv = (wv0 - wv1) / ops.maxn(wv0, 1e-300) if math.isfinite(wv0) else 1.0
        if not (ops.maxn(gx, gv) > fpar[F_REL_TOL]):
            break
    mode = 0
    if not dead:
        mode = mode_of(code, value, outs, meta, Xr, Qr, XIr, nl, nh, il, ih)
        if ipar[I_SPLIT_BOXES] > 0 and mode == 0:
            narrow = True
            for i in range(n):
                narrow &= Xr[1, i] - Xr[0, i] <= fpar[F_SPLIT_MAX_W]
            if narrow:
                mode = split_prune(code, value, outs, meta, Xr, Qr, XIr, ipar[I_SPLIT_BOXES],
                                   fpar[F_SPLIT_TOL], 2, nl, nh, il, ih, ws)
                dead = empty_box(Xr)
    if dead:
        row_bad[r] = k
        mode = 0
    # this sample joins the window of past boxes and readings
    slot = k % D
    past_x[r, slot] = Xr
    past_q[r, slot] = Qr
    past_r[r, slot] = qk
    return mode


@jit
def _combine(b, k, kk, P, X, XD, row_bad, modes, row_qdd, init_mode, cur_mode, streak, bad_at, mwx, mwv,
             x_hull, xd_hull, qdd_hull, record, rec_x, rec_xd, rec_mode, rec_qdd):
    """Combine the geometry hypotheses of scenario ``b`` after sample ``k``:
    hull of the consistent rows, their common mode, streaks, widths, record."""
    n = X.shape[2]
    live = 0
    mn = 2
    mx = -2
    for i in range(n):
        x_hull[b, 0, i] = np.inf
        x_hull[b, 1, i] = -np.inf
        xd_hull[b, 0, i] = np.inf
        xd_hull[b, 1, i] = -np.inf
        qdd_hull[b, i] = 0.0
    for p in range(P):
        r = b * P + p
        if row_bad[r] >= 0:
            continue
        live += 1
        mn = min(mn, modes[p])
        mx = max(mx, modes[p])
        for i in range(n):
            x_hull[b, 0, i] = ops.minn(x_hull[b, 0, i], X[r, 0, i])
            x_hull[b, 1, i] = ops.maxn(x_hull[b, 1, i], X[r, 1, i])
            xd_hull[b, 0, i] = ops.minn(xd_hull[b, 0, i], XD[r, 0, i])
            xd_hull[b, 1, i] = ops.maxn(xd_hull[b, 1, i], XD[r, 1, i])
            qdd_hull[b, i] = max(qdd_hull[b, i], row_qdd[p, i])
    if live == 0 and bad_at[b] < 0:
        bad_at[b] = k
    mode = mn if (live > 0 and mn == mx) else 0
    if k == 0:
        init_mode[b] = mode
    if mode != cur_mode[b]:
        streak[b] = k
    cur_mode[b] = mode
    if bad_at[b] < 0:
        wx = ops.width(x_hull[b, 0, 0], x_hull[b, 1, 0])
        wv = ops.width(xd_hull[b, 0, 0], xd_hull[b, 1, 0])
        for i in range(1, n):
            wx = ops.maxn(wx, ops.width(x_hull[b, 0, i], x_hull[b, 1, i]))
            wv = ops.maxn(wv, ops.width(xd_hull[b, 0, i], xd_hull[b, 1, i]))
        mwx[b] = ops.maxn(mwx[b], wx)
        mwv[b] = ops.maxn(mwv[b], wv)
    if record:
        rec_x[b, kk] = x_hull[b]
        rec_xd[b, kk] = xd_hull[b]
        rec_mode[b, kk] = mode
        rec_qdd[b, kk] = qdd_hull[b]


@jit
def _one_row(code, value, outs, meta, r, k, qk, X, XD, XI, Q, past_x, past_q, past_r, row_bad, fpar, ipar, vec,
             base, diff_err, h, QDD, nl, nh, il, ih, ws, modes, row_qdd, p, pri_x, pri_xd):
    # one hypothesis of one sample; its mode and |qdd| bound land in modes[p], row_qdd[p]
    n = qk.shape[0]
    modes[p] = _row_step(code, value, outs, meta, r, k, qk, X, XD, XI, Q, past_x, past_q, past_r, row_bad,
                         min(k, past_x.shape[1]), fpar, ipar, vec, base, diff_err, h, QDD, nl, nh, il, ih, ws,
                         pri_x, pri_xd)
    for i in range(n):
        row_qdd[p, i] = max(abs(QDD[0, i]), abs(QDD[1, i]))


@jit
def scenario_steps(code, value, outs, meta, n_nodes, b, k0, q, X, XD, XI, Q, past_x, past_q, past_r, row_bad,
                   init_mode, cur_mode, streak, bad_at, mwx, mwv, x_hull, xd_hull, qdd_hull,
                   fpar, ipar, vec, base, diff_err, h, rec_x, rec_xd, rec_mode, rec_qdd, prior_x, prior_xd):
    """Advance scenario ``b`` over the readings ``q[b]`` ``(Kc, n)``, samples
    ``k0 .. k0 + Kc - 1``, its hypotheses one after the other (``prior_x``,
    ``prior_xd`` ``(B, Kc, 2, n)``: see :func:`_row_step`)."""
    P = ipar[I_P]
    n = q.shape[2]
    nl, nh, il, ih, ws = scratch(n_nodes, n, XI.shape[2])
    QDD = np.empty((2, n))
    modes = np.empty(P, np.int64)
    row_qdd = np.empty((P, n))
    record = ipar[I_RECORD] != 0
    no_prior = np.empty((2, n))
    for kk in range(q.shape[1]):
        k = k0 + kk
        px = prior_x[b, kk] if ipar[I_PRIOR] else no_prior
        pxd = prior_xd[b, kk] if ipar[I_PRIOR] else no_prior
        for p in range(P):
            r = b * P + p
            if row_bad[r] < 0:
                _one_row(code, value, outs, meta, r, k, q[b, kk], X, XD, XI, Q, past_x, past_q, past_r, row_bad,
                         fpar, ipar, vec, base, diff_err, h, QDD, nl, nh, il, ih, ws, modes, row_qdd, p, px, pxd)
        _combine(b, k, kk, P, X, XD, row_bad, modes, row_qdd, init_mode, cur_mode, streak, bad_at, mwx, mwv,
                 x_hull, xd_hull, qdd_hull, record, rec_x, rec_xd, rec_mode, rec_qdd)


def run_hypotheses_parallel(code, value, outs, meta, n_nodes, k0, q, X, XD, XI, Q, past_x, past_q, past_r, row_bad,
                            init_mode, cur_mode, streak, bad_at, mwx, mwv, x_hull, xd_hull, qdd_hull,
                            fpar, ipar, vec, base, diff_err, h, rec_x, rec_xd, rec_mode, rec_qdd, prior_x, prior_xd):
    """As :func:`run_serial`, the geometry hypotheses of each sample spread
    over numba's threads (one scenario online: its latency, not throughput)."""
    B = q.shape[0]
    P = ipar[I_P]
    n = q.shape[2]
    m = XI.shape[2]
    NL = np.empty((P, n_nodes))
    NH = np.empty((P, n_nodes))
    IL = np.empty((P, 5 * n + m))
    IH = np.empty((P, 5 * n + m))
    QDD = np.empty((P, 2, n))
    WS = np.empty((P, workspace_size(n)))
    modes = np.empty((B, P), np.int64)
    row_qdd = np.empty((B, P, n))
    record = ipar[I_RECORD] != 0
    no_prior = np.empty((2, n))
    for kk in range(q.shape[1]):
        k = k0 + kk
        for b in range(B):
            px = prior_x[b, kk] if ipar[I_PRIOR] else no_prior
            pxd = prior_xd[b, kk] if ipar[I_PRIOR] else no_prior
            for p in prange(P):
                r = b * P + p
                if row_bad[r] < 0:
                    _one_row(code, value, outs, meta, r, k, q[b, kk], X, XD, XI, Q, past_x, past_q, past_r,
                             row_bad, fpar, ipar, vec, base, diff_err, h, QDD[p], NL[p], NH[p], IL[p], IH[p], WS[p],
                             modes[b], row_qdd[b], p, px, pxd)
            _combine(b, k, kk, P, X, XD, row_bad, modes[b], row_qdd[b], init_mode, cur_mode, streak, bad_at, mwx,
                     mwv, x_hull, xd_hull, qdd_hull, record, rec_x, rec_xd, rec_mode, rec_qdd)


run_hypotheses_parallel = njit(cache=True, nogil=True, parallel=True)(run_hypotheses_parallel)


def _make_driver(parallel: bool):
    def run(code, value, outs, meta, n_nodes, k0, q, X, XD, XI, Q, past_x, past_q, past_r, row_bad,
            init_mode, cur_mode, streak, bad_at, mwx, mwv, x_hull, xd_hull, qdd_hull,
            fpar, ipar, vec, base, diff_err, h, rec_x, rec_xd, rec_mode, rec_qdd, prior_x, prior_xd):
        for b in prange(q.shape[0]):
            scenario_steps(code, value, outs, meta, n_nodes, b, k0, q, X, XD, XI, Q, past_x, past_q, past_r,
                           row_bad, init_mode, cur_mode, streak, bad_at, mwx, mwv, x_hull, xd_hull, qdd_hull,
                           fpar, ipar, vec, base, diff_err, h, rec_x, rec_xd, rec_mode, rec_qdd, prior_x, prior_xd)
    run.__name__ = run.__qualname__ = "run_parallel" if parallel else "run_serial"
    return njit(cache=True, nogil=True, parallel=parallel)(run)


#: Every scenario in this thread (one scenario, or a few).
run_serial = _make_driver(False)
#: Scenarios spread over numba's threads.
run_parallel = _make_driver(True)
