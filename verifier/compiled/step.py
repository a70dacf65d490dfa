"""The tracker's step, compiled: one sample for every scenario, in place on the
arrays of :class:`verifier.step.TrackerState`.

The maths is that of the numpy reference step in :mod:`verifier.step`
(prediction with Lagrange remainder, measurement boxes, velocity
information, contraction to a per-row fixpoint, mode, branch and prune,
hypotheses combined); this kernel must agree with it bit for bit.  Rows
``r = b P + p`` are the geometry hypotheses ``p`` of scenario ``b``; a
scenario and its rows are independent of every other scenario.

Kernels take a few structured arguments: the robot's
:class:`~verifier.compiled.tape.Program`, the
:class:`~verifier.constants.StepConstants` (read by name), the velocity
model's strategy (:func:`velocity_strategy`), the state as
:class:`Rows` and :class:`Scenarios`, per-thread :class:`Scratch` allocated
once per tracker, the readings, and the optional record and prior boxes.
The per-sample path neither allocates nor slices: boxes are indices into the
state arrays, temporaries live in the thread's scratch.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange, types
from numba.extending import overload

from ..constants import JOINT_FD, PAPER, SOUND
from ..state import ROW_FIELDS, SCENARIO_FIELDS
from . import interval as ops
from .contractors import (
    TB_ACC,
    TB_DQ,
    TB_Q0,
    TB_QD,
    TB_QN,
    TB_QS,
    TB_XDS,
    TB_XIW,
    TB_XS,
    I0,
    NO,
    ONE,
    TWO,
    YES,
    copy_box,
    empty_box,
    hc4_pose,
    mode_of,
    newton,
    set_input,
    split_prune,
    thread_scratch,
    velocity_displacement,
    velocity_gs,
)
from .linalg import linear_enclosure, solve_preconditioned
from .interval import KERNEL_FLAGS, NO_WRAPPERS, inline_jit, jit
from .tape import T_ACCEL, T_JQ, T_JX_XD, forward, output


#: The state's row arrays as the kernels receive them, field by field under the names of
#: :class:`verifier.state.TrackerState` (its schema: :data:`verifier.state.ROW_FIELDS`).
Rows = NamedTuple("Rows", [(name, np.ndarray) for name in ROW_FIELDS])
#: The state's scenario arrays, likewise (:data:`verifier.state.SCENARIO_FIELDS`).
Scenarios = NamedTuple("Scenarios", [(name, np.ndarray) for name in SCENARIO_FIELDS])


class Record(NamedTuple):
    """Every sample's boxes of a block: ``x``, ``xd`` ``(B, Kc, 2, n)``,
    ``mode`` ``(B, Kc)``, ``qdd`` ``(B, Kc, n)`` (empty arrays: not recorded)."""

    x: np.ndarray
    xd: np.ndarray
    mode: np.ndarray
    qdd: np.ndarray


class Prior(NamedTuple):
    """Boxes known to hold the truth at each sample, ``(B, Kc, 2, n)`` (empty: none)."""

    x: np.ndarray
    xd: np.ndarray


@inline_jit
def _wsum(B, b, k):
    s = 0.0
    for i in range(k):
        s += ops.width(B[b, 0, i], B[b, 1, i])
    return s


@jit
def _qdd_over_step(prog, c, X, r, XD, past_q, pq, XI, n, m, sc, qdd, iqdd):
    """Joint-acceleration bound over the sampling interval (``JOINT_FD``), see
    :func:`verifier.step._qdd_over_step`; writes the box ``qdd[iqdd]``.
    Uses the scratch boxes ``TB_XS .. TB_QS`` and ``sc.w`` after Newton's part."""
    tb = sc.tb
    w = sc.w
    il = sc.il
    ih = sc.ih
    nn = n * n
    o = 7 * n + 7 * nn  # after newton's temporaries
    jl = o
    jh = o + nn
    bl = o + 2 * nn
    bh = bl + n
    dl = bh + n
    dh = dl + n
    ts = c.step_hi  # the whole step: [0, t] for every t it may last
    h2l, h2h = ops.scale(0.5, *ops.mul(ts, ts, ts, ts))
    h2l, h2h = ops.hull(0.0, 0.0, h2l, h2h)
    for i in range(n):
        a = c.axis[i].a_max
        tb[TB_ACC, 0, i] = -a
        tb[TB_ACC, 1, i] = a
        pl, ph = ops.mul(0.0, ts, XD[r, 0, i], XD[r, 1, i])
        xl, xh = ops.add(X[r, 0, i], X[r, 1, i], pl, ph)
        pl, ph = ops.mul(h2l, h2h, -a, a)
        tb[TB_XS, 0, i], tb[TB_XS, 1, i] = ops.add(xl, xh, pl, ph)
        pl, ph = ops.mul(0.0, ts, -a, a)
        tb[TB_XDS, 0, i], tb[TB_XDS, 1, i] = ops.add(XD[r, 0, i], XD[r, 1, i], pl, ph)
        ql, qh = ops.hull(past_q[r, pq, 0, i], past_q[r, pq, 1, i], tb[TB_QN, 0, i], tb[TB_QN, 1, i])
        tb[TB_Q0, 0, i] = ql - 0.05  # rad; the result must land strictly inside this box
        tb[TB_Q0, 1, i] = qh + 0.05
    copy_box(tb, TB_Q0, tb, TB_QS, n)
    for _ in range(3):
        newton(prog, tb, TB_XS, tb, TB_QS, XI, r, NO, n, m, sc)
        for i in range(n):
            if tb[TB_QS, 0, i] > tb[TB_QS, 1, i]:
                tb[TB_QS, 0, i] = tb[TB_Q0, 0, i]
                tb[TB_QS, 1, i] = tb[TB_Q0, 1, i]
    inside = True
    for i in range(n):
        inside &= tb[TB_QS, 0, i] > tb[TB_Q0, 0, i] and tb[TB_QS, 1, i] < tb[TB_Q0, 1, i]
    set_input(il, ih, I0, tb, TB_XS, n)
    set_input(il, ih, n, tb, TB_QS, n)
    set_input(il, ih, 2 * n, XI, r, m)
    set_input(il, ih, 2 * n + m, tb, TB_XDS, n)
    forward(prog, T_JQ, il, ih, sc.nl, sc.nh, sc.mk, sc.mv)
    for e in range(nn):
        w[jl + e], w[jh + e] = output(prog, T_JQ, e, sc.nl, sc.nh)
    forward(prog, T_JX_XD, il, ih, sc.nl, sc.nh, sc.mk, sc.mv)
    for i in range(n):
        rl, rh = output(prog, T_JX_XD, i, sc.nl, sc.nh)
        w[bl + i] = -rh
        w[bh + i] = -rl
    t = dh + n
    linear_enclosure(w, jl, jh, bl, bh, dl, dh, n, NO, TWO, t)
    for i in range(n):
        il[3 * n + m + i] = w[dl + i]
        ih[3 * n + m + i] = w[dh + i]
        il[4 * n + m + i] = tb[TB_ACC, 0, i]
        ih[4 * n + m + i] = tb[TB_ACC, 1, i]
    forward(prog, T_ACCEL, il, ih, sc.nl, sc.nh, sc.mk, sc.mv)
    for i in range(n):
        rl, rh = output(prog, T_ACCEL, i, sc.nl, sc.nh)
        w[bl + i] = -rh
        w[bh + i] = -rl
    solve_preconditioned(w, bl, bh, dl, dh, n, NO, TWO, t)  # the same [J_q]: its preconditioning is still at t
    for i in range(n):
        lo = w[dl + i]
        hi = w[dh + i]
        ok = inside and math.isfinite(lo) and math.isfinite(hi) and not (lo > hi)
        qdd[iqdd, 0, i] = lo if ok else -np.inf
        qdd[iqdd, 1, i] = hi if ok else np.inf


# ---------------------------------------------------------------------------- velocity information
# One strategy per velocity model, chosen by the *type* of the drivers' ``vel``
# argument (:func:`velocity_strategy`): numba compiles a driver per type and
# in it only that model's kernels (the joint-acceleration bound and the
# Gauss-Seidel contractor are not compiled for the default model).  A named
# tuple rather than a kernel passed as an argument: numba's on-disk cache
# compares such an argument's type by object identity, so a driver taking a
# kernel missed the cache in every new process (numba 0.68).  The row step is
# one kernel for every model, inlined into the driver (:data:`inline_jit`); it
# calls the model's two hooks through :func:`velocity_info` and
# :func:`velocity_contract`, overloads chosen by the strategy's type.  Each
# hook is a compiled function of its own, with its contractor inlined into it
# (``velocity_displacement``), so no wrapper adds a level to the call chain: a
# level costs the optimisation and machine code of all it calls once more.


class Displacement(NamedTuple):
    """The ``SOUND`` model: mean joint rates over the displacement baselines
    (:func:`verifier.contractors.velocity_displacement`)."""

    code: np.int64  # the model's code (verifier.constants); the type, not the value, selects the kernels


class JointRates(NamedTuple):
    """The ``PAPER`` model: finite differences of the last two readings, quantisation only (unsound)."""

    code: np.int64


class JointRatesQdd(NamedTuple):
    """The ``JOINT_FD`` model: finite differences plus ``(t_s/2) [qdd]``, a joint-acceleration bound
    over the sampling interval (:func:`_qdd_over_step`)."""

    code: np.int64


_STRATEGIES = {SOUND: Displacement, PAPER: JointRates, JOINT_FD: JointRatesQdd}


def velocity_strategy(code: int):
    """The compiled strategy of the velocity model ``code`` (:data:`verifier.constants.SOUND`, ...)."""
    return _STRATEGIES[code](np.int64(code))


# Each strategy is two hooks (the strategy ``vel`` comes first, for the overloads' signatures):
#   info(vel, prog, c, rows, r, k, q, b, kk, sc, qdd, iqdd) -> int, before the prediction (from the boxes of
#     sample k - 1, the window and the reading q[b, kk]): the velocity information into the scratch, and
#     what ``contract`` reads; may write a joint-acceleration bound to qdd[iqdd];
#   contract(vel, prog, c, rows, r, sc, info): contracts the velocity box of row r in place, every round.


def _displacement_info(vel, prog, c, rows, r, k, q, b, kk, sc, qdd, iqdd):
    """``SOUND``: the displacement baselines' mean joint rates, from past boxes and readings only, into
    ``sc.tb[TB_DQ + j]`` (rad/s), and the window slots ``sc.wi[j]`` of the baselines that reach back;
    returns their number."""
    past_r = rows.past_r
    tb = sc.tb
    idx = sc.wi
    n = rows.x.shape[2]
    D = rows.past_x.shape[1]
    n_past = min(k, D)
    n_base = I0  # not the literal 0: see contractors.I0
    for jb in range(c.baseline.shape[0]):
        j = c.baseline[jb].j
        if j > n_past:
            break
        p = (k - j) % D
        idx[jb] = p
        for i in range(n):
            qk = q[b, kk, i]
            qp = past_r[r, p, i]
            dl, dh = ops.sub(qk, qk, qp, qp)
            dl, dh = ops.add(dl, dh, c.diff_err[jb, 0, i], c.diff_err[jb, 1, i])
            tb[TB_DQ + jb, 0, i], tb[TB_DQ + jb, 1, i] = ops.div(dl, dh, c.baseline[jb].h_lo, c.baseline[jb].h_hi)
        n_base += 1
    return n_base


def _displacement_contract(vel, prog, c, rows, r, sc, info):
    """``SOUND``: contract with the ``info`` baselines of :func:`_displacement_info`."""
    velocity_displacement(prog, rows.x, r, rows.q, r, rows.xi, r, rows.xd, r, rows.past_x, rows.past_q, r, sc.tb,
                          TB_DQ, c.baseline, sc.wi, info, c.axis, rows.x.shape[2], rows.xi.shape[2], sc)


@jit
def _joint_rates(c, rows, r, k, q, b, kk, sc, qdd, iqdd, with_qdd):
    """Joint rates ``sc.tb[TB_QD]`` (rad/s) from the last two readings, plus ``(t_s/2) qdd[iqdd]`` when
    ``with_qdd``; returns 1 when a component is finite, else 0 (nothing to contract with)."""
    tb = sc.tb
    n = rows.x.shape[2]
    D = rows.past_x.shape[1]
    sl, sh = c.step_lo, c.step_hi
    for i in range(n):
        tb[TB_QD, 0, i] = -np.inf
        tb[TB_QD, 1, i] = np.inf
    if k > 0:
        prev = (k - 1) % D
        for i in range(n):
            qk = q[b, kk, i]
            qp = rows.past_r[r, prev, i]
            dl, dh = ops.sub(qk, qk, qp, qp)
            fl, fh = ops.div(dl, dh, sl, sh)
            ql, qh = ops.add(fl, fh, c.axis[i].quant_lo, c.axis[i].quant_hi)
            if with_qdd:
                tl, th = ops.mul(0.5 * sl, 0.5 * sh, qdd[iqdd, 0, i], qdd[iqdd, 1, i])
                ql, qh = ops.add(ql, qh, tl, th)
                ql = -np.inf if ql != ql else ql
                qh = np.inf if qh != qh else qh
            tb[TB_QD, 0, i] = ql
            tb[TB_QD, 1, i] = qh
    has_qd = I0
    for i in range(n):
        if math.isfinite(tb[TB_QD, 0, i]):
            has_qd = ONE
    return has_qd


def _paper_info(vel, prog, c, rows, r, k, q, b, kk, sc, qdd, iqdd):
    """``PAPER``: :func:`_joint_rates` with the quantisation error only."""
    return _joint_rates(c, rows, r, k, q, b, kk, sc, qdd, iqdd, NO)


def _joint_fd_info(vel, prog, c, rows, r, k, q, b, kk, sc, qdd, iqdd):
    """``JOINT_FD``: the joint-acceleration bound over the last interval into ``qdd[iqdd]`` (intersected with
    the given ``|qdd|`` bound), then :func:`_joint_rates` with it."""
    if k > 0:
        n = rows.x.shape[2]
        prev = (k - 1) % rows.past_x.shape[1]
        _qdd_over_step(prog, c, rows.x, r, rows.xd, rows.past_q, prev, rows.xi, n, rows.xi.shape[2], sc, qdd, iqdd)
        if c.has_qdd_bound:
            for i in range(n):
                g = c.axis[i].qdd_bound
                qdd[iqdd, 0, i], qdd[iqdd, 1, i] = ops.intersect(qdd[iqdd, 0, i], qdd[iqdd, 1, i], -g, g)
    return _joint_rates(c, rows, r, k, q, b, kk, sc, qdd, iqdd, YES)


def _joint_rates_contract(vel, prog, c, rows, r, sc, info):
    """``PAPER``, ``JOINT_FD``: contract with the joint rates ``sc.tb[TB_QD]`` (when ``info``: one is finite)."""
    if info > 0:
        velocity_gs(prog, rows.x, r, rows.q, r, rows.xi, r, rows.xd, r, sc.tb, TB_QD, rows.x.shape[2],
                    rows.xi.shape[2], sc)


def velocity_info(vel, prog, c, rows, r, k, q, b, kk, sc, qdd, iqdd):
    """The info hook of the velocity strategy ``vel``, chosen by its type when the caller is compiled.
    Compiled code only."""
    raise NotImplementedError("compiled code only")


def velocity_contract(vel, prog, c, rows, r, sc, info):
    """The contract hook of the velocity strategy ``vel``, chosen by its type when the caller is compiled.
    Compiled code only."""
    raise NotImplementedError("compiled code only")


_HOOKS = {Displacement: (_displacement_info, _displacement_contract),
          JointRates: (_paper_info, _joint_rates_contract),
          JointRatesQdd: (_joint_fd_info, _joint_rates_contract)}


def _hook(vel, which):
    """Hook ``which`` (0: info, 1: contract) of the strategy whose numba type is ``vel`` (None: not a strategy)."""
    hooks = _HOOKS.get(vel.instance_class) if isinstance(vel, types.BaseNamedTuple) else None
    return None if hooks is None else hooks[which]


@overload(velocity_info, jit_options={**KERNEL_FLAGS, **NO_WRAPPERS})
def _velocity_info_of(vel, prog, c, rows, r, k, q, b, kk, sc, qdd, iqdd):
    return _hook(vel, 0)


@overload(velocity_contract, jit_options={**KERNEL_FLAGS, **NO_WRAPPERS})
def _velocity_contract_of(vel, prog, c, rows, r, sc, info):
    return _hook(vel, 1)


# ---------------------------------------------------------------------------- one row, one sample


@inline_jit
def row_begin(vel, prog, c, rows, r, k, q, b, kk, sc, use_prior, prior, qdd, iqdd):
    """The part of :func:`row_step` before the contraction rounds: the reading's box into ``rows.q[r]``,
    the velocity information (returned: what :func:`velocity_contract` reads), the prediction, the
    prior, the calibration sub-box into the scratch slot ``TB_XIW``."""
    X, XD, XI, Q = rows.x, rows.xd, rows.xi, rows.q
    tb = sc.tb
    n = X.shape[2]
    m = XI.shape[2]
    point = c.step_lo == c.step_hi  # a constant period: one float, no interval product
    for i in range(n):
        qk = q[b, kk, i]
        e = c.axis[i].eps_q
        tb[TB_QN, 0, i] = ops.sub(qk, qk, e, e)[0]
        tb[TB_QN, 1, i] = ops.add(qk, qk, e, e)[1]
        qdd[iqdd, 0, i] = -np.inf
        qdd[iqdd, 1, i] = np.inf
    # from the boxes of the last sample: before the prediction overwrites them
    info = velocity_info(vel, prog, c, rows, r, k, q, b, kk, sc, qdd, iqdd)
    if k > 0:
        for i in range(n):
            ax = c.axis[i]
            vl, vh = XD[r, 0, i], XD[r, 1, i]
            pl, ph = ops.scale(c.step_lo, vl, vh) if point else ops.mul(c.step_lo, c.step_hi, vl, vh)
            xl, xh = ops.add(X[r, 0, i], X[r, 1, i], pl, ph)
            X[r, 0, i], X[r, 1, i] = ops.add(xl, xh, ax.half_ts2_a_lo, ax.half_ts2_a_hi)
            vl, vh = ops.add(XD[r, 0, i], XD[r, 1, i], ax.ts_a_lo, ax.ts_a_hi)
            XD[r, 0, i], XD[r, 1, i] = ops.intersect(vl, vh, -ax.v_max, ax.v_max)
    if use_prior:
        for i in range(n):
            X[r, 0, i], X[r, 1, i] = ops.intersect(X[r, 0, i], X[r, 1, i], prior.x[b, kk, 0, i], prior.x[b, kk, 1, i])
            XD[r, 0, i], XD[r, 1, i] = ops.intersect(XD[r, 0, i], XD[r, 1, i], prior.xd[b, kk, 0, i],
                                                     prior.xd[b, kk, 1, i])
    copy_box(tb, TB_QN, Q, r, n)
    copy_box(XI, r, tb, TB_XIW, m)
    return info


@inline_jit
def hc4_round(prog, c, rows, r, sc):
    """The first part of a contraction round of row ``r``: HC4Revise on the loop closure (on the
    calibration sub-box of the scratch slot ``TB_XIW``, refreshed from ``rows.xi[r]`` unless
    ``c.keep_xi``); returns the widths of the pose and velocity boxes before the round."""
    X = rows.x
    XI = rows.xi
    tb = sc.tb
    n = X.shape[2]
    m = XI.shape[2]
    wx0 = _wsum(X, r, n)
    wv0 = _wsum(rows.xd, r, n)
    if not c.keep_xi:
        copy_box(XI, r, tb, TB_XIW, m)
    hc4_pose(prog, X, r, rows.q, r, tb, TB_XIW, n, m, sc, YES)
    if c.keep_xi:
        copy_box(tb, TB_XIW, XI, r, m)
    return wx0, wv0


@inline_jit
def round_end(c, rows, r, wx0, wv0):
    """After a round of row ``r``: whether a box is empty (the row is dead), and whether another round
    is due (some relative width gain above ``c.rel_tol``)."""
    X = rows.x
    XD = rows.xd
    n = X.shape[2]
    if empty_box(X, r, n) or empty_box(XD, r, n) or empty_box(rows.xi, r, rows.xi.shape[2]) or empty_box(rows.q, r, n):
        return True, False
    wx1 = _wsum(X, r, n)
    wv1 = _wsum(XD, r, n)
    gx = (wx0 - wx1) / ops.maxn(wx0, 1e-300)
    gv = (wv0 - wv1) / ops.maxn(wv0, 1e-300) if math.isfinite(wv0) else 1.0
    return False, ops.maxn(gx, gv) > c.rel_tol


@inline_jit
def row_end(prog, c, rows, r, k, q, b, kk, sc, dead, modes, qdd, iqdd):
    """The part of :func:`row_step` after the rounds: the mode (branch and prune when undecided and
    narrow), the row's death, this sample into the window of past boxes and readings; writes the mode
    to ``modes[iqdd]`` and ``|qdd|`` to row 0 of ``qdd[iqdd]``."""
    X = rows.x
    Q = rows.q
    XI = rows.xi
    past_x = rows.past_x
    past_q = rows.past_q
    past_r = rows.past_r
    n = X.shape[2]
    m = XI.shape[2]
    D = past_x.shape[1]
    mode = 0
    if not dead:
        mode = mode_of(prog, X, r, Q, r, XI, r, n, m, sc)
        if c.split_boxes > 0 and mode == 0:
            narrow = True
            for i in range(n):
                narrow &= X[r, 1, i] - X[r, 0, i] <= c.split_max_width
            if narrow:
                mode = split_prune(prog, X, r, Q, r, XI, r, c.split_boxes, c.split_tol, TWO, n, m, sc,
                                   c.baseline.shape[0])
                dead = empty_box(X, r, n)
    if dead:
        rows.row_bad[r] = k
        mode = 0
    # this sample joins the window of past boxes and readings
    slot = k % D
    for i in range(n):
        past_x[r, slot, 0, i] = X[r, 0, i]
        past_x[r, slot, 1, i] = X[r, 1, i]
        past_q[r, slot, 0, i] = Q[r, 0, i]
        past_q[r, slot, 1, i] = Q[r, 1, i]
        past_r[r, slot, i] = q[b, kk, i]
        qdd[iqdd, 0, i] = max(abs(qdd[iqdd, 0, i]), abs(qdd[iqdd, 1, i]))
    modes[iqdd] = mode


@inline_jit
def row_step(vel, prog, c, rows, r, k, q, b, kk, sc, use_prior, prior, modes, qdd, iqdd):
    """Advance row ``r`` by the reading ``q[b, kk]`` ``(n,)`` with the velocity strategy ``vel`` (its hooks
    :func:`velocity_info`, :func:`velocity_contract`, chosen by its type).  Writes its mode to
    ``modes[iqdd]`` and the magnitude of the joint-acceleration bound used to row 0 of ``qdd[iqdd]``
    (rad/s^2, ``inf``: none; row 1 is scratch).  Results are written rather than returned because an
    assignment of a call's result inside a ``prange`` body went wrong (test_backends); with ``use_prior``,
    the boxes ``prior.x[b, kk]``, ``prior.xd[b, kk]`` known to hold the truth at this sample are
    intersected with the prediction.
    Its parts (:func:`row_begin`, :func:`hc4_round`, :func:`round_end`, :func:`row_end`) are those the
    rows-in-lanes driver (:mod:`verifier.compiled.lanes.step`) runs row by row around its Newton step
    and velocity contraction over lanes."""
    info = row_begin(vel, prog, c, rows, r, k, q, b, kk, sc, use_prior, prior, qdd, iqdd)
    dead = False
    for _ in range(c.max_iter):
        wx0, wv0 = hc4_round(prog, c, rows, r, sc)
        newton(prog, rows.x, r, rows.q, r, rows.xi, r, YES, rows.x.shape[2], rows.xi.shape[2], sc)
        velocity_contract(vel, prog, c, rows, r, sc, info)
        dead, more = round_end(c, rows, r, wx0, wv0)
        if dead or not more:
            break
    row_end(prog, c, rows, r, k, q, b, kk, sc, dead, modes, qdd, iqdd)


@inline_jit
def combine(b, k, kk, P, rows, scen, modes, row_qdd, use_record, rec):
    """Combine the geometry hypotheses of scenario ``b`` after sample ``k``:
    hull of the consistent rows, their common mode, streaks, widths, record."""
    X = rows.x
    XD = rows.xd
    row_bad = rows.row_bad
    xh = scen.x_hull
    vh = scen.xd_hull
    qh = scen.qdd_hull
    n = X.shape[2]
    live = 0
    mn = 2
    mx = -2
    for i in range(n):
        xh[b, 0, i] = np.inf
        xh[b, 1, i] = -np.inf
        vh[b, 0, i] = np.inf
        vh[b, 1, i] = -np.inf
        qh[b, i] = 0.0
    for p in range(P):
        r = b * P + p
        if row_bad[r] >= 0:
            continue
        live += 1
        mn = min(mn, modes[p])
        mx = max(mx, modes[p])
        for i in range(n):
            xh[b, 0, i] = ops.minn(xh[b, 0, i], X[r, 0, i])
            xh[b, 1, i] = ops.maxn(xh[b, 1, i], X[r, 1, i])
            vh[b, 0, i] = ops.minn(vh[b, 0, i], XD[r, 0, i])
            vh[b, 1, i] = ops.maxn(vh[b, 1, i], XD[r, 1, i])
            qh[b, i] = max(qh[b, i], row_qdd[p, 0, i])
    if live == 0 and scen.bad_at[b] < 0:
        scen.bad_at[b] = k
    mode = mn if (live > 0 and mn == mx) else 0
    if k == 0:
        scen.init_mode[b] = mode
    if mode != scen.mode[b]:
        scen.streak[b] = k
    scen.mode[b] = mode
    if scen.bad_at[b] < 0:
        wx = ops.width(xh[b, 0, 0], xh[b, 1, 0])
        wv = ops.width(vh[b, 0, 0], vh[b, 1, 0])
        for i in range(1, n):
            wx = ops.maxn(wx, ops.width(xh[b, 0, i], xh[b, 1, i]))
            wv = ops.maxn(wv, ops.width(vh[b, 0, i], vh[b, 1, i]))
        scen.max_width_pose[b] = ops.maxn(scen.max_width_pose[b], wx)
        scen.max_width_velocity[b] = ops.maxn(scen.max_width_velocity[b], wv)
    if use_record:
        for i in range(n):
            rec.x[b, kk, 0, i] = xh[b, 0, i]
            rec.x[b, kk, 1, i] = xh[b, 1, i]
            rec.xd[b, kk, 0, i] = vh[b, 0, i]
            rec.xd[b, kk, 1, i] = vh[b, 1, i]
            rec.qdd[b, kk, i] = qh[b, i]
        rec.mode[b, kk] = mode


@njit(cache=True, **KERNEL_FLAGS)
def run_slot(prog, c, vel, rows, scen, S, t, T, k0, q, use_record, rec, use_prior, prior):
    """Advance scenarios ``t, t + T, ...`` of the batch over the readings ``q``
    ``(B, Kc, n)`` with scratch slot ``t`` (``t = 0, T = 1``: every scenario)
    and the velocity strategy ``vel`` (:func:`velocity_strategy`).
    The one driver of batches: several threads call it at once, each with its
    own slot (``verifier.step``), since it releases the GIL and the scenarios
    of different slots share no array element.  Each scenario advances over
    its readings ``q[b]`` ``(Kc, n)``, samples ``k0 .. k0 + Kc - 1``, its
    hypotheses one after the other (in this body rather than a callee of its
    own: typing the arguments again cost a second of the first compilation)."""
    sc = thread_scratch(S, t)
    P = c.hypotheses
    for b in range(t, q.shape[0], T):
        for kk in range(q.shape[1]):
            k = k0 + kk
            for p in range(P):
                r = b * P + p
                if rows.row_bad[r] < 0:
                    row_step(vel, prog, c, rows, r, k, q, b, kk, sc, use_prior, prior, sc.modes, sc.row_qdd, p)
            combine(b, k, kk, P, rows, scen, sc.modes, sc.row_qdd, use_record, rec)


@jit
def _row_step_apart(vel, prog, c, rows, r, k, q, b, kk, sc, use_prior, prior, modes, qdd, iqdd):
    """:func:`row_step` as a function of its own, for the body of a ``prange`` loop: inlined there, its
    assignments of calls' results came out wrong (tests/test_backends.py)."""
    row_step(vel, prog, c, rows, r, k, q, b, kk, sc, use_prior, prior, modes, qdd, iqdd)


def run_hypotheses_parallel(prog, c, vel, rows, scen, S, k0, q, use_record, rec, use_prior, prior):
    """As :func:`run_slot` over every scenario, the geometry hypotheses of each sample spread
    over the threads (one scenario online: its latency, not throughput);
    thread slot ``t`` runs hypotheses ``t, t + T, ...`` with its scratch."""
    T = S.w.shape[0]
    P = c.hypotheses
    s0 = thread_scratch(S, I0)
    for kk in range(q.shape[1]):
        k = k0 + kk
        for b in range(q.shape[0]):
            for t in prange(T):
                sc = thread_scratch(S, t)
                for p in range(t, P, T):
                    r = b * P + p
                    if rows.row_bad[r] < 0:
                        _row_step_apart(vel, prog, c, rows, r, k, q, b, kk, sc, use_prior, prior, s0.modes,
                                        s0.row_qdd, p)
            combine(b, k, kk, P, rows, scen, s0.modes, s0.row_qdd, use_record, rec)


run_hypotheses_parallel = njit(cache=True, parallel=True, **KERNEL_FLAGS)(run_hypotheses_parallel)
