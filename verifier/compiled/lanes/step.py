"""The rows-in-lanes driver: every live row of a chunk of scenarios through a sample together.

:func:`run_lanes` is :func:`verifier.compiled.step.run_slot` with the loops
turned round: for each sample, each row of the chunk runs the per-row
kernel's parts (:func:`~verifier.compiled.step.row_begin`,
:func:`~verifier.compiled.step.hc4_round`,
:func:`~verifier.compiled.step.round_end`,
:func:`~verifier.compiled.step.row_end`) and, in every contraction round,
the Newton step and the velocity contraction run once over the rows still
contracting (:func:`.newton.newton_x`, :func:`.velocity.displacement`).  Rows are independent of each other and the
thread's scratch holds nothing from one row to the next (the calibration
sub-box of the ``TB_XIW`` slot and the velocity information are kept per
lane), so every box is the per-row driver's, bit for bit.  The ``SOUND``
velocity model only (the displacement baselines); the driver
(:class:`verifier.compiled.driver.CompiledStep`) picks this kernel for
batches of many rows.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..contractors import TB_DQ, TB_XIW, copy_box, thread_scratch
from ..interval import KERNEL_FLAGS, jit
from ..step import combine, hc4_round, round_end, row_begin, row_end
from .newton import newton_x
from .velocity import displacement, work_rows

__all__ = ["LaneScratch", "lane_scratch_arrays", "run_lanes"]


class LaneScratch(NamedTuple):
    """Scratch of one thread for a chunk of ``C`` scenarios of ``P`` rows (``N = C P`` lanes).

    Attributes
    ----------
    lane_row : int64 (N,)
        Each lane's row ``r = b P + p`` (scenario ``b``, hypothesis ``p``).
    act, act_row : int64 (N,)
        The lanes still contracting in this round, and their rows.
    dead : bool (N,)
        Whether a lane's row died in this sample.
    wx0, wv0 : float64 (N,)
        Widths of the pose and velocity boxes before the round.
    idx : int64 (J,)
        Window slots of the baselines (the same for every row at a sample).
    dq : float64 (J, 2, n, N)
        Each lane's mean joint rates over the baselines, rad/s.
    xiw : float64 (N, 2, m)
        Each lane's calibration sub-box of the ``TB_XIW`` slot.
    modes : int64 (C, P)
    qdd : float64 (C, P, 2, n)
        Modes and joint-acceleration bounds of the chunk's rows, by scenario.
    il, ih : float64 (3 n + m, N)
    nl, nh : float64 (n_nodes, N)
    w : float64 (:func:`.velocity.work_rows`, N)
    mat : float64 (3 n^2,)
    flag : bool (N,)
        The velocity contraction's tape inputs, nodes and temporaries.
    """

    lane_row: np.ndarray
    act: np.ndarray
    act_row: np.ndarray
    dead: np.ndarray
    wx0: np.ndarray
    wv0: np.ndarray
    idx: np.ndarray
    dq: np.ndarray
    xiw: np.ndarray
    modes: np.ndarray
    qdd: np.ndarray
    il: np.ndarray
    ih: np.ndarray
    nl: np.ndarray
    nh: np.ndarray
    w: np.ndarray
    mat: np.ndarray
    flag: np.ndarray


def lane_scratch_arrays(threads, chunk, hypotheses, n_nodes, n, m, baselines):
    """Per-thread :class:`LaneScratch` arrays with a leading ``threads`` axis, for chunks of ``chunk``
    scenarios of ``hypotheses`` rows (allocated once per tracker)."""
    T, C, P, J = int(threads), int(chunk), int(hypotheses), max(int(baselines), 1)
    N = C * P
    i64 = lambda *s: np.zeros((T, *s), np.int64)  # noqa: E731
    f64 = lambda *s: np.zeros((T, *s))  # noqa: E731
    return LaneScratch(i64(N), i64(N), i64(N), np.zeros((T, N), np.bool_), f64(N), f64(N), i64(J),
                       f64(J, 2, n, N), f64(N, 2, m), i64(C, P), f64(C, P, 2, n), f64(3 * n + m, N),
                       f64(3 * n + m, N), f64(n_nodes, N), f64(n_nodes, N), f64(work_rows(n), N), f64(3 * n * n),
                       np.zeros((T, N), np.bool_))


@jit
def _thread_lanes(LS, t):
    """The :class:`LaneScratch` of thread slot ``t``."""
    return LaneScratch(
        LS.lane_row[t], LS.act[t], LS.act_row[t], LS.dead[t], LS.wx0[t], LS.wv0[t],
        LS.idx[t], LS.dq[t], LS.xiw[t], LS.modes[t], LS.qdd[t], LS.il[t], LS.ih[t], LS.nl[t], LS.nh[t], LS.w[t],
        LS.mat[t], LS.flag[t])


@jit
def _sample(vel, prog, c, rows, scen, sc, ls, b0, b1, k, kk, q, use_prior, prior, use_record, rec):
    """Scenarios ``b0 .. b1 - 1`` through sample ``k`` (the reading ``q[:, kk]``)."""
    P = c.hypotheses
    n = rows.x.shape[2]
    m = rows.xi.shape[2]
    keep_xi = c.keep_xi
    # every live row: its reading, velocity information, prediction and prior, lane by lane
    L = 0
    n_base = 0
    for b in range(b0, b1):
        for p in range(P):
            r = b * P + p
            if rows.row_bad[r] >= 0:
                continue
            n_base = row_begin(vel, prog, c, rows, r, k, q, b, kk, sc, use_prior, prior, ls.qdd[b - b0], p)
            for jb in range(n_base):
                for i in range(n):
                    ls.dq[jb, 0, i, L] = sc.tb[TB_DQ + jb, 0, i]
                    ls.dq[jb, 1, i, L] = sc.tb[TB_DQ + jb, 1, i]
            copy_box(sc.tb, TB_XIW, ls.xiw, L, m)
            ls.lane_row[L] = r
            ls.dead[L] = False
            ls.act[L] = L
            L += 1
    for jb in range(n_base):
        ls.idx[jb] = sc.wi[jb]
    # contraction rounds: HC4Revise row by row, the Newton step and the velocity over the lanes still contracting
    A = L
    for _ in range(c.max_iter):
        if A == 0:
            break
        for a in range(A):
            l = ls.act[a]
            r = ls.lane_row[l]
            if keep_xi:
                copy_box(ls.xiw, l, sc.tb, TB_XIW, m)
            ls.wx0[l], ls.wv0[l] = hc4_round(prog, c, rows, r, sc)
            if keep_xi:
                copy_box(sc.tb, TB_XIW, ls.xiw, l, m)
            ls.act_row[a] = r
        newton_x(prog, rows, ls.act_row, A, n, m, ls, sc.mk, sc.mv)
        displacement(prog, rows, ls.act_row, ls.act, A, ls.idx, n_base, ls.dq, c.baseline, c.axis, n, m, ls,
                     sc.mk, sc.mv)
        kept = 0
        for a in range(A):
            l = ls.act[a]
            dead, more = round_end(c, rows, ls.lane_row[l], ls.wx0[l], ls.wv0[l])
            ls.dead[l] = dead
            if more:
                ls.act[kept] = l
                kept += 1
        A = kept
    # modes, branch and prune, the window of past boxes; then each scenario's rows combined
    for l in range(L):
        r = ls.lane_row[l]
        b = r // P
        row_end(prog, c, rows, r, k, q, b, kk, sc, ls.dead[l], ls.modes[b - b0], ls.qdd[b - b0], r - b * P)
    for b in range(b0, b1):
        combine(b, k, kk, P, rows, scen, ls.modes[b - b0], ls.qdd[b - b0], use_record, rec)


@njit(cache=True, **KERNEL_FLAGS)
def run_lanes(prog, c, vel, rows, scen, S, LS, t, T, k0, q, use_record, rec, use_prior, prior):
    """Advance the chunks ``t, t + T, ...`` of the batch (chunks of ``LS.modes.shape[1]`` scenarios) over
    the readings ``q`` ``(B, Kc, n)``, samples ``k0 .. k0 + Kc - 1``, with scratch slot ``t`` (its per-row
    :class:`~verifier.compiled.contractors.Scratch` in ``S``, its lanes in ``LS``); the arguments are
    :func:`verifier.compiled.step.run_slot`'s.  Releases the GIL: the slots run on threads at once."""
    sc = thread_scratch(S, t)
    ls = _thread_lanes(LS, t)
    chunk = ls.modes.shape[0]
    B = q.shape[0]
    for j in range(t, (B + chunk - 1) // chunk, T):
        b0 = j * chunk
        b1 = min(b0 + chunk, B)
        for kk in range(q.shape[1]):
            _sample(vel, prog, c, rows, scen, sc, ls, b0, b1, k0 + kk, kk, q, use_prior, prior, use_record, rec)
