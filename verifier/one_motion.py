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
(HiGHS, through highspy) looks for the most violated system; its verdict is never
trusted: its dual multipliers ``y >= 0`` are checked with interval arithmetic
(:func:`prove_infeasible`, a Farkas certificate), and only a proved row is
refuted.  The linear systems, the solver and the proofs are
:mod:`verifier.certified_lp`'s (:class:`LinearSystem`, :func:`prove_infeasible`
and :func:`certified_minimum` re-exported here); this module builds the rows.  Shapes: ``K`` samples, pose and joint dimension ``n``, ``m``
geometry parameters; SI units.
"""

from __future__ import annotations

import functools

import numpy as np

from . import interval as I
from .certified_lp import (HighsSolver, LinearSystem, certified_minimum, one_motion_kernels, prove_infeasible,
                           tree_sum)
from .step import kernel_array, reading_box

__all__ = ["LinearSystem", "prove_infeasible", "loop_closure_rows", "motion_rows", "drift_rows", "row_system",
           "refute_row", "refute_rows", "one_motion_rows", "certified_minimum", "ONE_MOTION_SAMPLES", "CUT_SLOPES"]

#: Samples of the range a row is refuted over, centred on the widest pose box of its tube (the default of
#: ``track_window(one_motion=...)``).  Measured on the certify plan at 0.9557 m/s: 40, 60, 80, 120 and all 196
#: samples refute the same 10 rows, at 0.1 to 1.2 s a row; the time grows faster than the sample count.
ONE_MOTION_SAMPLES = 40


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


def _enclose_dot(J, c):
    """Enclosure of ``J c`` for float ``J`` ``(B, n, N)`` and float ``c`` ``(B, N)``: ``(B, n)``."""
    p = I.mul(J, J, c[:, None, :], c[:, None, :])
    return tree_sum(*p)


def _mul_up(a, b):
    """Upper bound of the product of non-negative floats ``a``, ``b`` (broadcast), exactly 0 where either is 0
    (also for an infinite other factor: the interval convention ``0 * inf = 0``); NaN propagates."""
    with np.errstate(invalid="ignore", over="ignore", under="ignore"):
        p = a * b
    return np.where((a == 0.0) | (b == 0.0), 0.0, I.next_up(p))


def _sum_up(v):
    """Upper bound of the sum of non-negative floats along the last axis (pairwise, every addition rounded up;
    an exact 0 stays 0); NaN propagates."""
    while v.shape[-1] > 1:
        if v.shape[-1] % 2:
            v = np.concatenate([v, np.zeros(v.shape[:-1] + (1,))], axis=-1)  # + 0: exact
        with np.errstate(over="ignore"):
            v = I.next_up_keep0(v[..., 0::2] + v[..., 1::2])
    return v[..., 0]


def evaluate_tape(tape, inputs, compiled: bool = False):
    """``tape.evaluate(inputs)`` (:meth:`verifier.tape.Tape.evaluate`); ``compiled``: by
    :func:`verifier.compiled.one_motion.evaluate` (the same floats, the boxes as lanes)."""
    return one_motion_kernels().evaluate(tape, inputs) if compiled else tape.evaluate(inputs)


def loop_closure_rows(model, X, Q, XI, *, compiled: bool = False):
    """Linear inequalities implied by ``f(x_k, q_k, ξ) = 0`` for every ``(x_k, q_k, ξ)`` of the boxes.

    Parameters
    ----------
    model : verifier.model.IntervalModel
    X, Q : (lo, hi), arrays ``(S, n)``
        Pose (m) and joint (rad) boxes of ``S`` samples.
    XI : (lo, hi), arrays ``(m,)`` or ``(S, m)``
        The geometry box (shared by the samples, or one per sample: the rows of several window rows are
        computed in one call).
    compiled : bool
        The tapes' enclosures by :func:`evaluate_tape`, the rows from them by
        :func:`verifier.compiled.one_motion.taylor_rows` (the same floats).

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
    r_j r_l]`` (a square is not negative: the diagonal terms are one-sided).  Every term of the remainder is
    a non-negative magnitude times ``r_j r_l`` (``|[H_jl]|`` off the diagonal, ``max(H̄_jj, 0)`` for the
    upper and ``max(−H_jj, 0)`` for the lower side on it), so both sides are sums of products rounded up.
    A NaN in an enclosure (outside the tapes' domain) makes both sides of its equation infinite.
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
        F = evaluate_tape(model.tape_f, [(cx, cx), (cq, cq), (cxi, cxi)], compiled)[0]
        Jp = evaluate_tape(model.tape_jac, [(cx, cx), (cq, cq), (cxi, cxi)], compiled)[0]
        Hlo, Hhi = evaluate_tape(model.tape_hess, [(X[0], X[1]), (Q[0], Q[1]), XIb], compiled)[0]
        Hlo, Hhi = Hlo.reshape(S, n, N, N), Hhi.reshape(S, n, N, N)
    return (_taylor_rows_compiled if compiled else _taylor_rows)(c, r, F, Jp, Hlo, Hhi)


def _taylor_rows(c, r, F, Jp, Hlo, Hhi):
    """:func:`loop_closure_rows`'s ``(Jc, blo, bhi)`` from the box midpoints ``c`` and radii ``r`` ``(S, N)``
    and the enclosures of ``f(c)`` ``(S, n)``, of the gradient at ``c`` ``(S, n, N)`` and of the Hessians
    over the box ``(S, n, N, N)`` (each a ``(lo, hi)`` pair but ``c``, ``r``; the notes there give the maths)."""
    S, N = c.shape
    n = F[0].shape[1]
    with I.quiet_fp():
        Jc = I.midpoint(*Jp)
        Jc = np.where(np.isfinite(Jc), Jc, 0.0)
        # ([g] - Jc) d, |d_j| <= r_j: within +-e1
        Elo, Ehi = I.sub(*Jp, Jc, Jc)
        e1 = _sum_up(_mul_up(np.maximum(np.abs(Elo), np.abs(Ehi)), r[:, None, :]))
        # 1/2 d' H d: d_j d_l in [-r_j r_l, r_j r_l], and in [0, r_j^2] on the diagonal
        rr = _mul_up(r[:, :, None], r[:, None, :])[:, None]  # (S, 1, N, N)
        diag = np.eye(N, dtype=bool)
        mag = np.maximum(np.abs(Hlo), np.abs(Hhi))
        up = _sum_up(_mul_up(np.where(diag, np.maximum(Hhi, 0.0), mag), rr).reshape(S, n, N * N))
        down = _sum_up(_mul_up(np.where(diag, np.maximum(-Hlo, 0.0), mag), rr).reshape(S, n, N * N))
        # 0.5 x is exact unless subnormal: rounded up anyway (an exact 0, a point box, stays 0)
        Rhi, Rlo = I.next_up_keep0(0.5 * up), -I.next_up_keep0(0.5 * down)
        Jcc = _enclose_dot(Jc, c)
        b = I.sub(*Jcc, *F)
        blo = I.sub(b[0], b[0], Rhi, Rhi)[0]
        bhi = I.sub(b[1], b[1], Rlo, Rlo)[1]
        blo = I.sub(blo, blo, e1, e1)[0]
        bhi = I.add(bhi, bhi, e1, e1)[1]
    bad = np.isnan(blo) | np.isnan(bhi) | np.isnan(Hlo).any(axis=(2, 3)) | np.isnan(Hhi).any(axis=(2, 3))
    blo = np.where(bad, -np.inf, blo)
    bhi = np.where(bad, np.inf, bhi)
    return Jc, blo, bhi


def _taylor_rows_compiled(c, r, F, J, Hlo, Hhi):
    """:func:`loop_closure_rows`'s ``(Jc, blo, bhi)`` from the enclosures, by the compiled kernel."""
    taylor_rows = one_motion_kernels().taylor_rows

    S, N = c.shape
    n = F[0].shape[1]
    w = 1 << max(N - 1, 0).bit_length()
    Jc, blo, bhi = np.empty((S, n, N)), np.empty((S, n)), np.empty((S, n))
    k = kernel_array
    taylor_rows(k(c), k(r), k(F[0]), k(F[1]), k(J[0]), k(J[1]), k(Hlo), k(Hhi), Jc, blo, bhi,
                np.empty(max(N * N, 1)), np.empty(w), np.empty(w))
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
def _motion_rows_of(t_s: float, a: tuple, S: int, n: int, velocity: bool):
    """:func:`motion_rows` once per window's settings and sample count (the same blocks for every row; not
    modified by their users)."""
    return motion_rows(t_s, np.array(a, dtype=np.float64), S, n, velocity)


def drift_rows(settings, q, S: int, n: int):
    """Inequalities of the drift model of the reading error (A9, when the settings have one) on the joint
    unknowns ``q_k`` and the slow part ``s_k`` of the error: ``e_k = q̃_k − q_k = s_k + f_k`` with
    ``|f_k| <= eps_q_fast`` and ``|s_{k+1} − s_k| <= drift_rate t_s``, readings ``q`` ``(S, n)``.

    Returns ``(blocks, bound)``: blocks ``(rows, cols, vals, b)`` with ``q_k`` at column ``k n + i`` and
    ``s_k`` at ``S n + k n + i`` (the caller offsets them), and ``bound`` ``(n,)``, ``|s_k| <= bound``
    (``eps_q + eps_q_fast`` rounded up: ``|e_k| <= eps_q``, A3); ``([], None)`` without a drift model.
    The chain of consecutive ``s`` implies the bound of every pair ``j`` samples apart
    (``2 eps_q_fast + drift_rate j t_s``, the tracker's difference bound), with ``O(S)`` rows.
    """
    if settings.eps_q_fast is None:
        return [], None
    fast = np.broadcast_to(np.asarray(settings.eps_q_fast, np.float64), (n,))
    rate = np.broadcast_to(np.asarray(settings.drift_rate, np.float64), (n,))
    eps = np.broadcast_to(np.asarray(settings.eps_q, np.float64), (n,))
    step = I.mul(rate, rate, settings.t_s, settings.t_s)[1]  # drift_rate t_s, rounded up
    bound = I.add(eps, eps, fast, fast)[1]
    blocks = []
    kk, ii = np.meshgrid(np.arange(S), np.arange(n), indexing="ij")
    kk, ii = kk.ravel(), ii.ravel()
    nr = len(kk)
    # q_k + s_k = q̃_k - f_k in [q̃_k - fast, q̃_k + fast]
    hi = I.add(q[kk, ii], q[kk, ii], fast[ii], fast[ii])[1]
    lo = I.sub(q[kk, ii], q[kk, ii], fast[ii], fast[ii])[0]
    cols = np.stack([kk * n + ii, S * n + kk * n + ii], 1).ravel()
    rr = np.repeat(np.arange(nr), 2)
    blocks.append((rr, cols, np.ones(2 * nr), hi))
    blocks.append((rr, cols, -np.ones(2 * nr), -lo))
    if S >= 2:
        kk, ii = np.meshgrid(np.arange(S - 1), np.arange(n), indexing="ij")
        kk, ii = kk.ravel(), ii.ravel()
        nr = len(kk)
        cols = np.stack([S * n + (kk + 1) * n + ii, S * n + kk * n + ii], 1).ravel()
        rr = np.repeat(np.arange(nr), 2)
        for sign in (1.0, -1.0):
            blocks.append((rr, cols, np.tile(np.array([sign, -sign]), nr), step[ii]))
    return blocks, bound


def row_system(model, settings, q, XI, X, XD, samples, velocity: bool = True, closure=None) -> LinearSystem | None:
    """The linear system of one row over the samples ``samples`` (a contiguous ``range``).

    Unknowns, in order: ``ξ`` (``m``), then per sample ``x_k`` (``S n``), ``q_k`` (``S n``), with
    ``velocity`` ``v_k`` (``S n``), and with a drift model the slow part ``s_k`` of the reading error
    (``S n``, :func:`drift_rows`); bounds: ``XI``, the tube boxes ``X``, ``XD`` ``(K, 2, n)``, the reading
    boxes ``q_k ± eps_q`` and ``|s_k| <= eps_q + eps_q_fast``.  ``closure``: :func:`loop_closure_rows` of
    these boxes when computed already.  ``None`` when a bound is not finite (no certificate could use it).
    """
    ks = np.asarray(samples)
    S, n, m = len(ks), model.n, len(XI[0])
    qs = q[ks]
    Q = reading_box(qs, settings.eps_q)
    Xs = (X[ks, 0], X[ks, 1])
    nv = S * n if velocity else 0
    drift, sbound = drift_rows(settings, qs, S, n)
    ns = 0 if sbound is None else S * n
    lo = [XI[0], Xs[0].ravel(), Q[0].ravel()] + ([XD[ks, 0].ravel()] if velocity else [])
    hi = [XI[1], Xs[1].ravel(), Q[1].ravel()] + ([XD[ks, 1].ravel()] if velocity else [])
    if ns:
        lo.append(np.tile(-sbound, S))
        hi.append(np.tile(sbound, S))
    lo, hi = np.concatenate(lo), np.concatenate(hi)
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
    # drift of the reading error: q_k at m + S n + k n + i, s_k at m + 2 S n + nv + k n + i
    for r, c, v, b in drift:
        c = np.asarray(c)
        blocks.append((r, m + S * n + c + np.where(c >= S * n, nv, 0), v, b))
    # motion: x at m + k n + i, v at m + 2 S n + k n + i
    for r, c, v, b in _motion_rows_of(float(settings.t_s), tuple(np.ravel(settings.a_max).tolist()), S, n, velocity):
        c = np.asarray(c)
        c = np.where(c < S * n, m + c, m + S * n + c)  # v columns: S n + ... -> m + 2 S n + ...
        blocks.append((r, c, v, b))
    return _stack(blocks, m + 2 * S * n + nv + ns, lo, hi)


def _samples(X, size):
    """The ``size`` contiguous samples centred on the widest pose box of the tube ``X`` ``(K, 2, n)``."""
    K = X.shape[0]
    size = min(size, K)
    w = np.nan_to_num((X[:, 1] - X[:, 0]).sum(axis=1), nan=0.0, posinf=1e300)
    start = int(np.clip(np.argmax(w) - size // 2, 0, K - size))
    return range(start, start + size)


def one_motion_rows(model, settings, q, XI, X, XD, size: int = ONE_MOTION_SAMPLES, velocity: bool = False,
                    contract: bool = True, *, compiled: bool = False):
    """Refute and contract rows, one geometry and one motion at a time.

    Row ``r`` is the geometry box ``(XI[0][r], XI[1][r])`` (``(R, m)``) with the tubes ``X[r]``, ``XD[r]``
    (``(R, K, 2, n)``); it is refuted when no single geometry of its box and single motion within ``a_max``
    in its tubes explain the readings ``q`` ``(K, n)`` over ``size`` samples around its widest pose box
    (proved: :func:`prove_infeasible`).  With ``contract``, the geometry box of a row not refuted is narrowed
    to proved bounds of each parameter over the same relaxation
    (:meth:`~verifier.certified_lp.HighsSolver.bounds`): every geometry that explains the row with one motion
    stays in it.  The loop closure of every row is linearised in one
    batch.  ``velocity``: velocity unknowns in ``XD`` and their rows (:func:`motion_rows`); off by default:
    on the runs of docs/tracker.md they refuted no more rows, at 1.5 times the cost.  ``compiled``: the
    certificates' interval arithmetic by :mod:`verifier.compiled.one_motion` (the window's compiled backend; the same
    floats).

    Returns
    -------
    refuted : ndarray ``(R,)`` bool
    xi_lo, xi_hi : ndarray ``(R, m)``
        The rows' geometry boxes, contracted (inside ``XI``; meaningless for a refuted row).
    """
    q = np.asarray(q, np.float64)
    R = len(XI[0])
    out = np.zeros(R, dtype=bool)
    xlo, xhi = np.array(XI[0], dtype=np.float64), np.array(XI[1], dtype=np.float64)
    if R == 0:
        return out, xlo, xhi
    m = xlo.shape[1]
    ks = [np.asarray(_samples(X[r], size)) for r in range(R)]
    S = len(ks[0])
    idx = np.concatenate(ks)
    rows = np.repeat(np.arange(R), S)
    Xb = (X[rows, idx, 0], X[rows, idx, 1])
    with I.quiet_fp():
        closure = loop_closure_rows(model, Xb, reading_box(q[idx], settings.eps_q), (XI[0][rows], XI[1][rows]),
                                    compiled=compiled)
    solver = HighsSolver(compiled)
    for r in range(R):
        part = tuple(v[r * S:(r + 1) * S] for v in closure)
        system = row_system(model, settings, q, (xlo[r], xhi[r]), X[r], XD[r], ks[r], velocity, part)
        if system is None:
            continue
        y = solver.phase_one(system)
        if y is not None:
            out[r] = prove_infeasible(system, y, compiled=compiled)
        elif contract and solver.feasible:
            lo, hi = solver.bounds(system, np.arange(m))  # ξ: the first m unknowns
            xlo[r], xhi[r] = np.maximum(xlo[r], lo), np.minimum(xhi[r], hi)
            out[r] = bool(np.any(xlo[r] > xhi[r]))  # no geometry left: refuted too
    return out, xlo, xhi


def refute_rows(model, settings, q, XI, X, XD, size: int = ONE_MOTION_SAMPLES, velocity: bool = False, *,
                compiled: bool = False):
    """Which rows no single geometry and single motion explain: ``(R,)`` bool, True where proved
    (:func:`one_motion_rows` without contraction)."""
    return one_motion_rows(model, settings, q, XI, X, XD, size, velocity, contract=False, compiled=compiled)[0]


def refute_row(model, settings, q, XI, X, XD, size: int = ONE_MOTION_SAMPLES, velocity: bool = False, *,
               compiled: bool = False) -> bool:
    """:func:`refute_rows` for one row: geometry box ``XI`` ``(m,)`` pair, tubes ``X``, ``XD`` ``(K, 2, n)``."""
    XIr = (np.asarray(XI[0], np.float64)[None], np.asarray(XI[1], np.float64)[None])
    return bool(refute_rows(model, settings, q, XIr, X[None], XD[None], size, velocity, compiled=compiled)[0])
