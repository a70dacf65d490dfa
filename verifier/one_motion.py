"""One motion, one geometry: refuting a window row with a linear relaxation over many samples.

A row of the window (:mod:`verifier.window`) is a geometry sub-box ``[Ξ]`` with
pose and velocity tubes ``[x]_k``, ``[xd]_k``.  Each tube box may hold a pose of
a *different* geometry of ``[Ξ]`` at every sample, and the acceleration bound
is checked on the boxes only: a row survives when some sequence of geometries
explains it, although the true geometry is one constant vector.  Here one
geometry ``ξ`` and one motion ``x_k`` (velocities ``v_k``) are unknowns shared
by every sample of a range ``S`` of samples, each bounded by its box, with

* the loop closure ``f(x_k, q_k, ξ) = 0`` (``q_k`` within the reading's
  error ``eps_q``), linearised in mean-value form over the box of
  ``(x_k, q_k, ξ)`` with its remainder (:func:`loop_closure_rows`);
* the acceleration bound between consecutive samples (:func:`motion_rows`).

Every constraint is a linear inequality ``A z <= b`` with float coefficients
``A`` used as they are and every rounding error put into ``b`` (outward), so
the true ``(ξ, x_k, q_k, v_k)`` satisfies all of them when the row holds the
truth (docs/soundness.md, "Window reasoning", step 9).  A linear program
(scipy's HiGHS) looks for the most violated system; its verdict is never
trusted: its dual multipliers ``y >= 0`` are checked with interval arithmetic
(:func:`prove_infeasible`, a Farkas certificate), and only a proved row is
refuted.  Shapes: ``K`` samples, pose and joint dimension ``n``, ``m``
geometry parameters; SI units.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import linprog
from scipy.sparse import coo_matrix, diags, hstack

from . import interval as I
from .constants import pack_constants
from .step import reading_box

__all__ = ["LinearSystem", "prove_infeasible", "loop_closure_rows", "motion_rows", "drift_rows", "row_system",
           "refute_row", "refute_rows", "ONE_MOTION_SAMPLES", "CUT_SLOPES", "DRIFT_OFFSETS"]

#: Samples of the range a row is refuted over, centred on the widest pose box of its tube (the default of
#: ``track_window(one_motion=...)``).  Measured on the certify plan at 0.9557 m/s: 40, 60, 80, 120 and all 196
#: samples refute the same 10 rows, at 0.1 to 1.2 s a row; the time grows faster than the sample count.
ONE_MOTION_SAMPLES = 40


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


def _stack(parts, n_cols, lo, hi):
    """One :class:`LinearSystem` of blocks ``(rows, cols, vals, b)`` (row indices local to each block)."""
    rows, cols, vals, bs, m = [], [], [], [], 0
    for r, c, v, b in parts:
        rows.append(np.asarray(r, np.int64) + m)
        cols.append(np.asarray(c, np.int64))
        vals.append(np.asarray(v, np.float64))
        bs.append(np.asarray(b, np.float64))
        m += len(b)
    assert len(lo) == len(hi) == n_cols
    return LinearSystem(np.concatenate(rows), np.concatenate(cols), np.concatenate(vals), np.concatenate(bs),
                        np.asarray(lo, np.float64), np.asarray(hi, np.float64))


def _tree_sum(lo, hi, axis=-1):
    """Outward-rounded sum of intervals along ``axis`` (pairwise, every addition rounded outward)."""
    lo, hi = np.moveaxis(lo, axis, -1), np.moveaxis(hi, axis, -1)
    while lo.shape[-1] > 1:
        if lo.shape[-1] % 2:
            pad = [(0, 0)] * (lo.ndim - 1) + [(0, 1)]
            lo, hi = np.pad(lo, pad), np.pad(hi, pad)  # + [0, 0]: exact
        lo, hi = I.add(lo[..., 0::2], hi[..., 0::2], lo[..., 1::2], hi[..., 1::2])
    return lo[..., 0], hi[..., 0]


def prove_infeasible(system: LinearSystem, y) -> bool:
    """True when the multipliers ``y`` ``(M,)`` prove that no ``z`` in the box satisfies ``A z <= b``.

    For ``y >= 0`` every solution would satisfy ``yᵀ(A z − b) <= 0``; the lower bound of
    ``min over the box of (yᵀA) z − yᵀb``, with ``yᵀA`` and ``yᵀb`` enclosed by outward-rounded interval
    arithmetic and the minimum of each term ``[c_j] z_j`` taken over ``z_j``'s bounds, being positive
    proves there is none (a Farkas certificate).  ``y`` is any float vector: negative or non-finite
    entries are replaced by 0 (any ``y >= 0`` is admissible), so the solver that produced it is not
    trusted.
    """
    s = system
    y = np.asarray(y, dtype=np.float64)
    y = np.where(np.isfinite(y) & (y > 0), y, 0.0)
    M, N = s.shape
    if y.shape != (M,) or not np.any(y > 0):
        return False
    with I.quiet_fp():
        # yᵀA column by column: products enclosed, then summed per column (padded to equal counts with 0)
        plo, phi = I.mul(y[s.rows], y[s.rows], s.vals, s.vals)
        order = np.argsort(s.cols, kind="stable")
        cols = s.cols[order]
        counts = np.bincount(cols, minlength=N)
        width = max(int(counts.max()) if counts.size else 0, 1)
        start = np.concatenate(([0], np.cumsum(counts)[:-1]))
        slot = np.arange(len(cols)) - start[cols]
        Clo, Chi = np.zeros((N, width)), np.zeros((N, width))
        Clo[cols, slot], Chi[cols, slot] = plo[order], phi[order]
        clo, chi = _tree_sum(Clo, Chi)
        # min over z_j in [lo_j, hi_j] of c_j z_j, c_j in [clo_j, chi_j]: the lower bound of the product
        tlo = I.mul(clo, chi, s.lo, s.hi)[0]
        left = _tree_sum(tlo, tlo)[0]
        yb = _tree_sum(*I.mul(y, y, s.b, s.b))[1]
    return bool(np.isfinite(left) and np.isfinite(yb) and left > yb)


def _phase_one(system: LinearSystem):
    """Dual multipliers ``y`` ``(M,)`` of ``min t  s.t.  A z − t <= b`` over the box (rows and columns
    scaled, variables centred), or ``None`` when the solver found ``t <= 0`` or failed.  A float search only:
    :func:`prove_infeasible` decides."""
    s = system
    M, N = s.shape
    c = 0.5 * (s.lo + s.hi)
    r = 0.5 * (s.hi - s.lo)
    r = np.where(r > 0, r, 1.0)
    A = coo_matrix((s.vals, (s.rows, s.cols)), shape=(M, N)).tocsr()
    As = A.multiply(r[None, :]).tocsr()
    rhs = s.b - A @ c
    scale = np.asarray(abs(As).max(axis=1).todense()).ravel()
    scale = np.where(scale > 0, scale, 1.0)
    As = diags(1.0 / scale) @ As
    rhs = rhs / scale
    Aub = hstack([As, coo_matrix(-np.ones((M, 1)))]).tocsr()
    u = np.where(s.hi > s.lo, 1.0, 0.0)  # the centred, scaled unknowns in [-1, 1] (a fixed one at 0)
    bounds = [(-w, w) for w in u] + [(0.0, None)]
    cost = np.zeros(N + 1)
    cost[-1] = 1.0
    res = linprog(cost, A_ub=Aub, b_ub=rhs, bounds=bounds, method="highs")
    if res.status != 0 or not res.fun > 0:
        return None
    y = -np.asarray(res.ineqlin.marginals, dtype=np.float64)  # marginals of <= rows are <= 0
    return y / scale


def _enclose_dot(J, c):
    """Enclosure of ``J c`` for float ``J`` ``(B, n, N)`` and float ``c`` ``(B, N)``: ``(B, n)``."""
    p = I.mul(J, J, c[:, None, :], c[:, None, :])
    return _tree_sum(*p)


def loop_closure_rows(model, X, Q, XI):
    """Linear inequalities implied by ``f(x_k, q_k, ξ) = 0`` for every ``(x_k, q_k, ξ)`` of the boxes.

    Parameters
    ----------
    model : verifier.model.IntervalModel
    X, Q : (lo, hi), arrays ``(S, n)``
        Pose (m) and joint (rad) boxes of ``S`` samples.
    XI : (lo, hi), arrays ``(m,)`` or ``(S, m)``
        The geometry box (shared by the samples, or one per sample: the rows of several window rows are
        computed in one call).

    Returns
    -------
    Jc : ndarray ``(S, n, 2n + m)``
        The float coefficients (columns: ``x``, ``q``, ``ξ``).
    blo, bhi : ndarray ``(S, n)``
        ``blo <= Jc z <= bhi`` holds for every solution ``z = (x, q, ξ)`` in the box (infinite where the
        enclosures are not finite).

    Notes
    -----
    Second-order Taylor form about the midpoint ``c`` of the box, ``d = z − c``, ``|d| <= r``: for each
    equation ``f_i(z) = f_i(c) + g·d + ½ dᵀ H(ζ) d`` with the gradient ``g`` at ``c`` and the Hessian at a
    point ``ζ`` of the segment, so in the enclosures ``[g]``, ``[H]`` over the box.  With ``Jc`` the midpoint
    of ``[g]``: ``Jc z ∈ Jc c − [f(c)] − ([g] − Jc)[−r, r] − ½ Σ_j [H_jj][0, r_j²] − ½ Σ_{j≠l} [H_jl][−r_j r_l,
    r_j r_l]`` (a square is not negative: the diagonal terms are one-sided).
    """
    S, n = X[0].shape
    m = np.shape(XI[0])[-1]
    N = 2 * n + m
    XIb = tuple(np.broadcast_to(v, (S, m)) for v in XI)
    lo = np.concatenate([X[0], Q[0], XIb[0]], axis=1)
    hi = np.concatenate([X[1], Q[1], XIb[1]], axis=1)
    with I.quiet_fp():
        c = I.midpoint(lo, hi)
        r = np.maximum(I.sub(c, c, lo, lo)[1], I.sub(hi, hi, c, c)[1])  # >= |z - c| on the box
        cx, cq, cxi = np.split(c, np.cumsum([n, n]), axis=1)
        F = model.tape_f.evaluate([(cx, cx), (cq, cq), (cxi, cxi)])[0]
        Jp = model.tape_jac.evaluate([(cx, cx), (cq, cq), (cxi, cxi)])[0]
        Hlo, Hhi = model.tape_hess.evaluate([(X[0], X[1]), (Q[0], Q[1]), XIb])[0]
        Hlo, Hhi = Hlo.reshape(S, n, N, N), Hhi.reshape(S, n, N, N)
        Jc = I.midpoint(*Jp)
        Jc = np.where(np.isfinite(Jc), Jc, 0.0)
        # ([g] - Jc) d
        Elo, Ehi = I.sub(*Jp, Jc, Jc)
        mag = np.maximum(np.abs(Elo), np.abs(Ehi))
        e1 = _tree_sum(*I.mul(mag, mag, r[:, None, :], r[:, None, :]))[1]
        # 1/2 d' H d: every product d_j d_l in [-r_j r_l, r_j r_l], and in [0, r_j^2] on the diagonal
        rr = I.mul(r[:, :, None], r[:, :, None], r[:, None, :], r[:, None, :])[1]
        dd_lo = np.where(np.eye(N, dtype=bool), 0.0, -rr)
        half = I.scale(0.5, Hlo, Hhi)  # exact
        Rlo, Rhi = I.mul(*half, dd_lo[:, None], rr[:, None])
        Rlo, Rhi = _tree_sum(Rlo.reshape(S, n, N * N), Rhi.reshape(S, n, N * N))
        Jcc = _enclose_dot(Jc, c)
        b = I.sub(*I.sub(*Jcc, *F), Rlo, Rhi)
        blo = I.sub(*b, e1, e1)[0]
        bhi = I.add(*b, e1, e1)[1]
    blo = np.where(np.isnan(blo), -np.inf, blo)
    bhi = np.where(np.isnan(bhi), np.inf, bhi)
    return Jc, blo, bhi


def _up(*factors):
    """Upper bound of the product of non-negative floats."""
    lo = hi = np.float64(1.0)
    for f in factors:
        lo, hi = I.mul(lo, hi, f, f)
    return hi


#: Slopes ``c`` of the linear cuts of the two-sample bound (as fractions of ``t_s``; see :func:`motion_rows`).
CUT_SLOPES = (-0.5, -0.25, 0.0, 0.25, 0.5)


def motion_rows(t_s: float, a, S: int, n: int, velocity: bool):
    """Inequalities of the acceleration bound ``|x''| <= a`` (per coordinate, ``a`` ``(n,)``, m/s^2) between
    consecutive samples of one motion, on the unknowns ``x_k`` (and ``v_k = x'(t_k)`` when ``velocity``).

    Returned as blocks ``(rows, cols, vals, b)`` with columns of sample ``k``'s coordinate ``i``: ``x`` at
    ``k n + i``, ``v`` at ``S n + k n + i`` (the caller offsets them).

    * ``|x_{k+1} − 2 x_k + x_{k−1}| <= a t_s²``: the second difference is
      ``∫_0^{t_s} (t_s − s)(x''(t_k + s) + x''(t_k − s)) ds``;
    * with velocities, for each ``c`` of :data:`CUT_SLOPES` (times ``t_s``):
      ``±(x_{k+1} − x_k − (v_k + v_{k+1}) t_s/2) + c (v_{k+1} − v_k) <= a t_s²/4 + a c²``, from
      ``|x_l − x_k − (v_k + v_l) τ/2| <= a τ²/4 − (v_l − v_k)²/(4a)`` (soundness.md, window step 8)
      and ``−d²/(4a) <= −c d + a c²`` for every real ``c``; and ``|v_{k+1} − v_k| <= a t_s``.
    """
    a = np.asarray(a, dtype=np.float64)
    blocks = []
    rows_i = np.arange(n)
    # second differences
    if S >= 3:
        k = np.arange(1, S - 1)
        kk, ii = np.meshgrid(k, rows_i, indexing="ij")
        kk, ii = kk.ravel(), ii.ravel()
        cap = _up(a, t_s, t_s)[ii]
        for sign in (1.0, -1.0):
            nr = len(kk)
            rr = np.repeat(np.arange(nr), 3)
            cc = np.stack([(kk - 1) * n + ii, kk * n + ii, (kk + 1) * n + ii], axis=1).ravel()
            vv = np.tile(np.array([1.0, -2.0, 1.0]) * sign, nr)
            blocks.append((rr, cc, vv, cap))
    if velocity and S >= 2:
        k = np.arange(S - 1)
        kk, ii = np.meshgrid(k, rows_i, indexing="ij")
        kk, ii = kk.ravel(), ii.ravel()
        nr = len(kk)
        xk, xl = kk * n + ii, (kk + 1) * n + ii
        vk, vl = S * n + xk, S * n + xl
        half = 0.5 * t_s  # exact
        dv_cap = _up(a, t_s)[ii]
        for sign in (1.0, -1.0):
            blocks.append((np.repeat(np.arange(nr), 2), np.stack([vl, vk], 1).ravel(),
                           np.tile(np.array([sign, -sign]), nr), dv_cap))
            for frac in CUT_SLOPES:
                cs = frac * t_s  # a float: the inequality holds for it exactly as it is
                cap = I.add(*I.mul(*I.scale(0.25, *I.mul(a, a, t_s, t_s)), t_s, t_s),
                            *I.mul(a, a, *I.sqr(cs, cs)))[1][ii]
                cv = np.stack([np.full(nr, sign), np.full(nr, -sign), np.full(nr, -sign * half + cs),
                               np.full(nr, -sign * half - cs)], 1).ravel()
                cc = np.stack([xl, xk, vl, vk], 1).ravel()
                blocks.append((np.repeat(np.arange(nr), 4), cc, cv, cap))
    return blocks


@functools.lru_cache(maxsize=8)
def _difference_bounds(settings, offsets: tuple, n: int):
    """The error intervals ``(J, 2, n)`` of a difference of two readings ``j`` samples apart, ``j`` in
    ``offsets``, as the tracker's constants hold them (their one owner: ``verifier.constants``); remembered
    per settings object (frozen), since every row of a window asks for the same."""
    return pack_constants(replace(settings, baselines=offsets), n).diff_err


#: Sample distances of the coupled readings of the drift model (:func:`drift_rows`).
DRIFT_OFFSETS = (1, 2, 4, 8, 16, 32, 64)


def drift_rows(settings, q, S: int, n: int):
    """Inequalities of the drift model of the reading error (when the settings have one) on the joint unknowns
    ``q_k`` (column ``k n + i``): ``|(q_l − q̃_l) − (q_k − q̃_k)| <= D_j`` for ``l = k + j``, ``j`` in
    :data:`DRIFT_OFFSETS`, ``D_j`` the bound of a difference of two readings ``j`` samples apart (its owner:
    ``verifier.constants``), readings ``q`` ``(S, n)``.  As blocks ``(rows, cols, vals, b)``."""
    if settings.eps_q_fast is None:
        return []
    blocks = []
    offsets = tuple(j for j in DRIFT_OFFSETS if j < S)
    if not offsets:
        return []
    two_eps = I.scale(2.0, -settings.eps_q, settings.eps_q)[1]
    for j, (_, D) in zip(offsets, _difference_bounds(settings, offsets, n)):
        if np.all(D >= two_eps):
            break  # no tighter than the boxes of the two readings
        k = np.arange(S - j)
        kk, ii = np.meshgrid(k, np.arange(n), indexing="ij")
        kk, ii = kk.ravel(), ii.ravel()
        ql, qk = q[kk + j, ii], q[kk, ii]
        dlo, dhi = I.sub(ql, ql, qk, qk)
        nr = len(kk)
        cols = np.stack([(kk + j) * n + ii, kk * n + ii], 1).ravel()
        for sign, bound in ((1.0, I.add(dlo, dhi, -D[ii], D[ii])[1]), (-1.0, -I.sub(dlo, dhi, D[ii], D[ii])[0])):
            blocks.append((np.repeat(np.arange(nr), 2), cols, np.tile(np.array([sign, -sign]), nr), bound))
    return blocks


def row_system(model, settings, q, XI, X, XD, samples, velocity: bool = True, closure=None) -> LinearSystem | None:
    """The linear system of one row over the samples ``samples`` (a contiguous ``range``).

    Unknowns, in order: ``ξ`` (``m``), then per sample ``x_k`` (``S n``), ``q_k`` (``S n``) and, with
    ``velocity``, ``v_k`` (``S n``); bounds: ``XI``, the tube boxes ``X``, ``XD`` ``(K, 2, n)`` and the
    reading boxes ``q_k ± eps_q``.  ``closure``: :func:`loop_closure_rows` of these boxes when computed
    already.  ``None`` when a bound is not finite (no certificate could use it).
    """
    ks = np.asarray(samples)
    S, n, m = len(ks), model.n, len(XI[0])
    qs = q[ks]
    Q = reading_box(qs, settings.eps_q)
    Xs = (X[ks, 0], X[ks, 1])
    nv = S * n if velocity else 0
    lo = np.concatenate([XI[0], Xs[0].ravel(), Q[0].ravel()] + ([XD[ks, 0].ravel()] if velocity else []))
    hi = np.concatenate([XI[1], Xs[1].ravel(), Q[1].ravel()] + ([XD[ks, 1].ravel()] if velocity else []))
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)):
        return None
    Jc, blo, bhi = loop_closure_rows(model, Xs, Q, XI) if closure is None else closure
    blocks = []
    # loop closure: columns x_k, q_k, ξ
    kk, ii = np.meshgrid(np.arange(S), np.arange(n), indexing="ij")
    kk, ii = kk.ravel(), ii.ravel()
    xcol = m + kk[:, None] * n + np.arange(n)[None, :]
    qcol = m + S * n + kk[:, None] * n + np.arange(n)[None, :]
    xicol = np.broadcast_to(np.arange(m), (len(kk), m))
    cols = np.concatenate([xcol, qcol, xicol], axis=1)
    coef = Jc[kk, ii]  # (S n, 2n + m)
    ok = np.isfinite(blo[kk, ii]) & np.isfinite(bhi[kk, ii])
    nr = int(ok.sum())
    width = cols.shape[1]
    rr = np.repeat(np.arange(nr), width)
    blocks.append((rr, cols[ok].ravel(), coef[ok].ravel(), bhi[kk, ii][ok]))
    blocks.append((rr, cols[ok].ravel(), -coef[ok].ravel(), -blo[kk, ii][ok]))
    # drift of the reading error: q_l - q_k within the readings' difference and its error bound
    for r, c, v, b in drift_rows(settings, qs, S, n):
        blocks.append((r, m + S * n + np.asarray(c), v, b))
    # motion: x at m + k n + i, v at m + 2 S n + k n + i
    for r, c, v, b in motion_rows(settings.t_s, settings.a_max, S, n, velocity):
        c = np.asarray(c)
        c = np.where(c < S * n, m + c, m + S * n + c)  # v columns: S n + ... -> m + 2 S n + ...
        blocks.append((r, c, v, b))
    return _stack(blocks, m + 2 * S * n + nv, lo, hi)


def _samples(X, size):
    """The ``size`` contiguous samples centred on the widest pose box of the tube ``X`` ``(K, 2, n)``."""
    K = X.shape[0]
    size = min(size, K)
    w = np.nan_to_num((X[:, 1] - X[:, 0]).sum(axis=1), nan=0.0, posinf=1e300)
    start = int(np.clip(np.argmax(w) - size // 2, 0, K - size))
    return range(start, start + size)


def refute_rows(model, settings, q, XI, X, XD, size: int = ONE_MOTION_SAMPLES, velocity: bool = False):
    """Which rows no single geometry and single motion explain: ``(R,)`` bool, True where proved.

    Row ``r`` is the geometry box ``(XI[0][r], XI[1][r])`` (``(R, m)``) with the tubes ``X[r]``, ``XD[r]``
    (``(R, K, 2, n)``); it is refuted when no single geometry of its box and single motion within ``a_max``
    in its tubes explain the readings ``q`` ``(K, n)`` over ``size`` samples around its widest pose box
    (proved: :func:`prove_infeasible`).  The loop closure of every row is linearised in one batch.
    ``velocity``: velocity unknowns in ``XD`` and their rows (:func:`motion_rows`); off by default: on the
    runs of docs/tracker.md they refuted no more rows, at 1.5 times the cost.
    """
    q = np.asarray(q, np.float64)
    R = len(XI[0])
    out = np.zeros(R, dtype=bool)
    if R == 0:
        return out
    ks = [np.asarray(_samples(X[r], size)) for r in range(R)]
    S = len(ks[0])
    idx = np.concatenate(ks)
    rows = np.repeat(np.arange(R), S)
    Xb = (X[rows, idx, 0], X[rows, idx, 1])
    with I.quiet_fp():
        closure = loop_closure_rows(model, Xb, reading_box(q[idx], settings.eps_q), (XI[0][rows], XI[1][rows]))
    for r in range(R):
        part = tuple(v[r * S:(r + 1) * S] for v in closure)
        system = row_system(model, settings, q, (XI[0][r], XI[1][r]), X[r], XD[r], ks[r], velocity, part)
        if system is not None:
            y = _phase_one(system)
            out[r] = y is not None and prove_infeasible(system, y)
    return out


def refute_row(model, settings, q, XI, X, XD, size: int = ONE_MOTION_SAMPLES, velocity: bool = False) -> bool:
    """:func:`refute_rows` for one row: geometry box ``XI`` ``(m,)`` pair, tubes ``X``, ``XD`` ``(K, 2, n)``."""
    XIr = (np.asarray(XI[0], np.float64)[None], np.asarray(XI[1], np.float64)[None])
    return bool(refute_rows(model, settings, q, XIr, X[None], XD[None], size, velocity)[0])
