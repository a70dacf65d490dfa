"""Certified bounds from a linear program: what HiGHS's multipliers prove about ``A z <= b`` over a box.

A :class:`LinearSystem` is a set of linear inequalities ``A z <= b`` with float
coefficients and finite bounds ``lo <= z <= hi`` (built by
:mod:`verifier.one_motion`, whose every rounding error is in ``b``).  HiGHS
(through highspy, :class:`HighsSolver`) only proposes dual multipliers
``y >= 0``; they are never trusted: :func:`prove_infeasible` checks a Farkas
certificate and :func:`certified_minimum` a weak-duality bound with
outward-rounded interval arithmetic (docs/soundness.md, "Window reasoning",
step 9), by numpy or by the compiled kernels of
:mod:`verifier.compiled.one_motion` (the same floats).  Shapes: ``M`` rows,
``N`` unknowns, ``B`` multiplier rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import highspy

from . import interval as I
from .step import kernel_array

__all__ = ["LinearSystem", "prove_infeasible", "certified_minimum", "tree_sum", "one_motion_kernels", "HighsSolver"]


@dataclass(frozen=True)
class LinearSystem:
    """``A z <= b`` with ``lo <= z <= hi``: ``A`` as coordinates ``(rows, cols, vals)`` (repeated entries add),
    ``b`` ``(M,)``, ``lo``, ``hi`` ``(N,)`` (finite)."""

    rows: np.ndarray
    cols: np.ndarray
    vals: np.ndarray
    b: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    @property
    def shape(self):
        return len(self.b), len(self.lo)


def tree_sum(lo, hi, axis=-1):
    """Outward-rounded sum of intervals along ``axis`` (pairwise, every addition rounded outward; padded once
    with exact zeros to a power of two)."""
    lo, hi = np.moveaxis(lo, axis, -1), np.moveaxis(hi, axis, -1)
    size = lo.shape[-1]
    full = 1 << max(size - 1, 0).bit_length()
    if full != size:
        pad = [(0, 0)] * (lo.ndim - 1) + [(0, full - size)]
        lo, hi = np.pad(lo, pad), np.pad(hi, pad)  # + [0, 0]: exact
    while lo.shape[-1] > 1:
        lo, hi = I.add(lo[..., 0::2], hi[..., 0::2], lo[..., 1::2], hi[..., 1::2])
    return lo[..., 0], hi[..., 0]


def _dual_bound(system: LinearSystem, y, cost=None, compiled: bool = False):
    """``(left, yb)`` for multipliers ``y`` ``(M,)`` or ``(B, M)``: ``left`` a lower bound of ``min over the
    box of (cost + yᵀA) z`` and ``yb`` an upper bound of ``yᵀb``, enclosed with outward rounding (``()`` or
    ``(B,)``).  Every ``z`` of the box with ``A z <= b`` has ``cost·z >= left − yb`` (weak duality:
    ``yᵀ(A z − b) <= 0`` for ``y >= 0``).  ``y`` is any float array: negative or non-finite entries are
    replaced by 0 (any ``y >= 0`` is admissible), so the solver that produced it is not trusted.
    ``cost`` ``(N,)`` or ``(B, N)`` floats (exact as given), 0 by default.  ``compiled``: the same floats
    from :func:`verifier.compiled.one_motion.dual_bound` (a few microseconds instead of about a millisecond)."""
    s = system
    M, N = s.shape
    y = np.asarray(y, dtype=np.float64)
    one = y.ndim == 1
    y = np.atleast_2d(y)
    y = np.where(np.isfinite(y) & (y > 0), y, 0.0)
    B = y.shape[0]
    if compiled:
        left, yb = _dual_bound_compiled(s, y, cost)
        return (left[0], yb[0]) if one else (left, yb)
    with I.quiet_fp():
        # cost + yᵀA column by column: products enclosed, then summed per column with the cost (padded with 0)
        # only the entries of rows some y uses: the others' products are exactly 0
        use = np.any(y > 0, axis=0)[s.rows]
        rows, cols, vals = s.rows[use], s.cols[use], s.vals[use]
        plo, phi = I.mul(y[:, rows], y[:, rows], vals, vals)
        order = np.argsort(cols, kind="stable")
        cols = cols[order]
        plo, phi = plo[:, order], phi[:, order]
        counts = np.bincount(cols, minlength=N)
        start = np.concatenate(([0], np.cumsum(counts)[:-1]))
        slot = np.arange(len(cols)) - start[cols] + 1  # slot 0: the cost
        cost = np.zeros((B, N)) if cost is None else np.broadcast_to(np.asarray(cost, dtype=np.float64), (B, N))
        clo, chi = np.empty((B, N)), np.empty((B, N))
        # columns grouped by their count rounded up to a power of two: a few dense blocks, little padding
        group = np.array([(int(c)).bit_length() for c in counts])
        for g in np.unique(group):
            mine = np.nonzero(group == g)[0]
            where = np.full(N, -1)
            where[mine] = np.arange(len(mine))
            Clo, Chi = np.zeros((B, len(mine), 1 << int(g))), np.zeros((B, len(mine), 1 << int(g)))
            Clo[:, :, 0] = Chi[:, :, 0] = cost[:, mine]
            e = where[cols] >= 0
            Clo[:, where[cols[e]], slot[e]], Chi[:, where[cols[e]], slot[e]] = plo[:, e], phi[:, e]
            clo[:, mine], chi[:, mine] = tree_sum(Clo, Chi)
        # min over z_j in [lo_j, hi_j] of c_j z_j, c_j in [clo_j, chi_j]: the lower bound of the product
        tlo = I.mul(clo, chi, s.lo, s.hi)[0]
        left = tree_sum(tlo, tlo)[0]
        live = np.any(y > 0, axis=0)
        yb = tree_sum(*I.mul(y[:, live], y[:, live], s.b[live], s.b[live]))[1]
    return (left[0], yb[0]) if one else (left, yb)


def one_motion_kernels():
    """:mod:`verifier.compiled.one_motion` (numba loaded on first use only), once the first run's compilation
    child is done with its kernels: this process then loads them from the cache instead of compiling them
    beside the child (:func:`verifier.compiled.warm.finish`)."""
    from .compiled import one_motion, warm

    warm.finish()
    return one_motion


def _dual_bound_compiled(system: LinearSystem, y, cost):
    """:func:`_dual_bound`'s ``(left, yb)`` ``(B,)`` for sanitised multipliers ``y`` ``(B, M)``, by the compiled
    kernel (its scratch allocated here: a few arrays of the system's size)."""
    dual_bound = one_motion_kernels().dual_bound

    s = system
    M, N = s.shape
    B, E = y.shape[0], len(s.rows)
    cost = np.zeros((B, N)) if cost is None else np.broadcast_to(np.asarray(cost, dtype=np.float64), (B, N))
    size = 2 * max(E + 1, N, M, 1)
    i64, k = np.int64, kernel_array
    left, yb = np.empty(B), np.empty(B)
    dual_bound(k(s.rows, i64), k(s.cols, i64), k(s.vals), k(s.b), k(s.lo), k(s.hi), k(y), k(cost), np.empty(M, i64),
               np.empty(N, i64), np.empty(N + 1, i64), np.empty(E, i64), np.empty(size), np.empty(size), np.empty(N),
               left, yb)
    return left, yb


def prove_infeasible(system: LinearSystem, y, *, compiled: bool = False) -> bool:
    """True when the multipliers ``y`` ``(M,)`` prove that no ``z`` in the box satisfies ``A z <= b``.

    For ``y >= 0`` every solution would satisfy ``yᵀ(A z − b) <= 0``; the lower bound of
    ``min over the box of (yᵀA) z − yᵀb``, with ``yᵀA`` and ``yᵀb`` enclosed by outward-rounded interval
    arithmetic and the minimum of each term ``[c_j] z_j`` taken over ``z_j``'s bounds, being positive
    proves there is none (a Farkas certificate; :func:`_dual_bound`).  ``y`` is any float vector: negative
    or non-finite entries are replaced by 0, so the solver that produced it is not trusted.  ``compiled``: the
    bounds by the compiled kernel (the same floats).
    """
    y = np.asarray(y, dtype=np.float64)
    if y.shape != (system.shape[0],) or not np.any(np.isfinite(y) & (y > 0)):
        return False
    left, yb = _dual_bound(system, y, compiled=compiled)
    return bool(np.isfinite(left) and np.isfinite(yb) and left > yb)


def certified_minimum(system: LinearSystem, y, cost, *, compiled: bool = False):
    """Lower bounds of ``cost·z`` over ``{z in the box : A z <= b}`` proved from the multipliers ``y`` (any
    floats, ``(M,)`` or one row per cost ``(B, M)``; :func:`_dual_bound`), ``-inf`` where they prove nothing
    finite.  Weak duality with outward rounding (the safe bounds of Neumaier and Shcherbina): for ``y >= 0``
    and every feasible ``z``, ``cost·z >= cost·z + yᵀ(A z − b) >= min over the box of (cost + yᵀA) z − yᵀb``."""
    left, yb = _dual_bound(system, y, cost, compiled)
    with I.quiet_fp():
        low = I.sub(left, left, yb, yb)[0]
    return np.where(np.isfinite(left) & np.isfinite(yb) & ~np.isnan(low), low, -np.inf)


#: HiGHS's codes of a row-wise matrix and of minimisation (``passModel`` from arrays takes plain integers).
_ROWWISE = int(highspy.MatrixFormat.kRowwise)
_MINIMIZE = int(highspy.ObjSense.kMinimize)


class HighsSolver:
    """One HiGHS instance for the phase-one programs of a batch of rows, each warm-started from the basis of
    the last program of the same shape (the rows of a window have the same structure, their coefficients and
    bounds differ a little).  A float search only: :func:`prove_infeasible` decides.  ``compiled``: the proofs of
    :meth:`bounds` by the compiled kernel (the same floats)."""

    def __init__(self, compiled: bool = False):
        self.compiled = compiled
        # the bare solver (no banner, no callbacks) where highspy exposes it, else its public subclass;
        # both silenced by output_flag below
        self.highs = getattr(highspy, "_Highs", highspy.Highs)()
        for name, value in (("output_flag", False), ("presolve", "off"), ("simplex_strategy", 4),
                            ("threads", 1)):
            self.highs.setOptionValue(name, value)
        self.basis = {}
        self.feasible = False

    def phase_one(self, system: LinearSystem):
        """Dual multipliers ``y`` ``(M,)`` of ``min t  s.t.  A z − t <= b`` over the box (rows and columns
        scaled, variables centred), or ``None`` when the solver found ``t <= 0`` or failed."""
        s = system
        M, N = s.shape
        c = 0.5 * (s.lo + s.hi)
        r = 0.5 * (s.hi - s.lo)
        r = np.where(r > 0, r, 1.0)
        order = np.lexsort((s.cols, s.rows))
        rows, cols = s.rows[order], s.cols[order]
        vals = s.vals[order] * r[cols]
        rhs = s.b - np.bincount(s.rows, weights=s.vals * c[s.cols], minlength=M)
        counts = np.bincount(rows, minlength=M)
        if np.all(counts > 0):  # rows sorted: each row's largest entry in one pass (max is exact)
            scale = np.maximum.reduceat(np.abs(vals), np.concatenate(([0], np.cumsum(counts)[:-1])))
        else:
            scale = np.zeros(M)
            np.maximum.at(scale, rows, np.abs(vals))
        scale = np.where(scale > 0, scale, 1.0)
        # row i: its entries scaled by 1/scale_i, then the column t with -1
        start = np.concatenate(([0], np.cumsum(counts + 1)))
        last = start[1:] - 1
        index = np.full(start[-1], N, dtype=np.int32)
        value = np.full(start[-1], -1.0)
        keep = np.ones(start[-1], dtype=bool)
        keep[last] = False
        index[keep] = cols
        value[keep] = vals / scale[rows]
        cost = np.zeros(N + 1)
        cost[-1] = 1.0
        u = np.where(s.hi > s.lo, 1.0, 0.0)  # the centred, scaled unknowns in [-1, 1] (a fixed one at 0)
        h = self.highs
        # the model as arrays (numpy buffers; a HighsLp's fields convert element by element, 0.4 ms a row);
        # integrality all continuous: an LP
        h.passModel(N + 1, M, int(start[-1]), _ROWWISE, _MINIMIZE, 0.0, cost, np.concatenate([-u, [0.0]]),
                    np.concatenate([u, [highspy.kHighsInf]]), np.full(M, -highspy.kHighsInf), rhs / scale,
                    start[:-1].astype(np.int32), index, value, np.zeros(N + 1, np.int32))
        if (M, N) in self.basis:
            h.setBasis(self.basis[(M, N)])
        h.run()
        self.feasible = False
        if h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
            return None
        self.basis[(M, N)] = h.getBasis()
        self.feasible = not h.getInfo().objective_function_value > 0
        self.scale, self.r = scale, r
        self.u = np.asarray(h.getSolution().col_value, dtype=np.float64)[:N]  # a point of the system when feasible
        if not h.getInfo().objective_function_value > 0:
            return None
        y = -np.asarray(h.getSolution().row_dual, dtype=np.float64)  # duals of <= rows are <= 0
        return y / scale

    def bounds(self, system: LinearSystem, columns):
        """Proved bounds ``(lo, hi)`` of the unknowns ``columns`` over ``{z in the box : A z <= b}``, right
        after a :meth:`phase_one` of ``system`` that found it feasible (its model and basis, ``t`` fixed at 0):
        for each column and sign the program ``min ±z_j`` proposes multipliers and :func:`certified_minimum`
        proves the bound (the box's where it proves nothing tighter)."""
        h = self.highs
        M, N = system.shape
        columns = np.asarray(columns)
        h.changeColBounds(N, 0.0, 0.0)  # t = 0: the system itself
        every = np.arange(N + 1, dtype=np.int32)
        C = len(columns)
        # a side of z_j that a point of the system found so far lies on cannot narrow (the program's minimum
        # is that bound): its program is skipped, as if it proved only the box (phase one's vertex has
        # one side of every geometry parameter: half the programs of the certify plans' rows)
        u = self.u
        at = {1.0: u[columns] <= -1.0, -1.0: u[columns] >= 1.0}  # min z_j is lo_j / max z_j is hi_j
        Y, cost = np.zeros((2 * C, M)), np.zeros((2 * C, N))
        for i, j in enumerate(columns):
            for k, sign in ((2 * i, 1.0), (2 * i + 1, -1.0)):
                if at[sign][i]:
                    continue
                c = np.zeros(N + 1)
                c[j] = sign * self.r[j]  # min ±z_j: z_j = c_j + r_j u_j
                h.changeColsCost(N + 1, every, c)
                h.run()
                cost[k, j] = sign
                if h.getModelStatus() == highspy.HighsModelStatus.kOptimal:
                    Y[k] = -np.asarray(h.getSolution().row_dual, dtype=np.float64) / self.scale
                    v = np.asarray(h.getSolution().col_value, dtype=np.float64)[columns]
                    at[1.0] |= v <= -1.0
                    at[-1.0] |= v >= 1.0
        low = np.full(2 * C, -np.inf)
        run = np.any(cost != 0.0, axis=1)
        if run.any():
            low[run] = certified_minimum(system, Y[run], cost[run], compiled=self.compiled)  # Y = 0: only the box
        lo = np.maximum(system.lo[columns], low[0::2])
        hi = np.minimum(system.hi[columns], -low[1::2])
        return lo, hi


def _phase_one(system: LinearSystem):
    """:meth:`HighsSolver.phase_one` with a solver of its own."""
    return HighsSolver().phase_one(system)
