"""Contractors on the kinematic constraints, batched over scenarios.

* :func:`hc4_pose` — forward–backward propagation (HC4Revise) on ``f = 0``;
* :func:`newton` — preconditioned interval Newton (Hansen–Sengupta form) on
  ``f = 0`` in either the pose ``x`` or the joints ``q``;
* :func:`velocity` — preconditioned interval Gauss–Seidel on
  ``J_x xd = -J_q qd`` (eq. 2 of the paper);
* :func:`pose_solutions` — a small branch-and-prune that encloses every
  forward-kinematics solution in a search box.

Each contractor returns boxes that contain every solution of its constraint
inside the boxes it was given; a box can only shrink.  Boxes are pairs
``(lo, hi)`` of shape ``(B, n)`` for ``x``, ``q``, ``xd``, ``qd`` and
``(B, m)`` or ``(m,)`` for ``xi``.
"""

from __future__ import annotations

import numpy as np

from . import interval as I
from .linalg import gauss_seidel, linear_enclosure, pmat_imat, pmat_ivec, point_inverse

__all__ = [
    "hc4_pose",
    "newton",
    "velocity",
    "velocity_displacement",
    "mode_of",
    "pose_solutions",
    "split_prune",
]


def hc4_pose(model, X, Q, XI):
    """HC4Revise on ``f(x, q, xi) = 0``; returns contracted ``(X, Q, XI)``."""
    Xc, Qc, XIc = model.tape_f.contract([X, Q, XI])
    return Xc, Qc, XIc


def newton(model, X, Q, XI, var: str = "x"):
    """One Hansen–Sengupta step on ``f = 0`` in ``var`` (``"x"`` or ``"q"``).

    With ``m = mid([v])`` and ``C = inv(mid J_v)``, every solution ``v`` in
    ``[v]`` satisfies ``C J_v([v]) (v - m) in -C f(m, other boxes)`` (mean-value
    theorem, componentwise), which Gauss–Seidel contracts.  Returns the
    contracted box of ``var``.
    """
    if var == "x":
        V = X
        mid = I.midpoint(*X)
        F = model.tape_f.evaluate([(mid, mid), Q, XI])[0]
        J = model.tape_jx.evaluate([X, Q, XI])[0]
    else:
        V = Q
        mid = I.midpoint(*Q)
        F = model.tape_f.evaluate([X, (mid, mid), XI])[0]
        J = model.tape_jq.evaluate([X, Q, XI])[0]
    C = point_inverse(I.midpoint(*J))
    Al, Ah = pmat_imat(C, *J)
    bl, bh = pmat_ivec(C, *F)
    bl, bh = -bh, -bl
    yl, yh = I.sub(V[0], V[1], mid, mid)
    yl, yh = gauss_seidel(Al, Ah, bl, bh, yl, yh)
    nl, nh = I.add(mid, mid, yl, yh)
    return I.intersect(V[0], V[1], nl, nh)


def velocity(model, X, Q, XI, XD, QD):
    """Contract ``[xd]`` with ``J_x xd + J_q qd = 0`` (preconditioned Gauss–Seidel).

    ``J_q qd`` is enclosed as one expression; an unbounded ``[xd]`` is first
    replaced by the Neumann-series bound of :func:`verifier.linalg.linear_enclosure`.
    """
    J, R = model.tape_vel.evaluate([X, Q, XI, QD])
    return linear_enclosure(J[0], J[1], -R[1], -R[0], XD[0], XD[1], sweeps=1)


def velocity_displacement(model, X, Q, pasts, XI, XD, a_max):
    """Contract ``[xd]_k`` with the displacements over several baselines ``h = j t_s``.

    Subtracting ``f = 0`` at ``t_k - h`` from ``f = 0`` at ``t_k`` (same
    geometry ``xi``) and applying the mean-value theorem row by row on the
    segment joining the two configurations (inside the hull of their boxes)::

        J_x(.) (x_k - x_{k-j}) + J_q(.) (q_k - q_{k-j}) = 0.

    Taylor with Lagrange remainder, per component, gives
    ``(x_k - x_{k-j}) / h = xd_k - (h / 2) xdd(zeta)``, so
    ``u = xd_k - (h/2) xdd(zeta)`` solves ``J_x u = -J_q (q_k - q_{k-j}) / h``
    with ``q_k - q_{k-j}`` in ``DQ`` (measured difference plus ``2 eps_q``).
    Then ``xd_k in u + (h/2) [-a_max, a_max]``.  The finite difference's
    truncation error stays in Cartesian space, where ``a_max`` bounds it,
    instead of being amplified by ``J_x^{-1}`` near the singularity.  Each
    baseline gives a sound enclosure; all are computed in one batched pass
    and intersected.

    Parameters
    ----------
    X, Q : boxes (B, n) at ``t_k``.
    pasts : list of (X_past, Q_past, DQ, h)
        Boxes (B, n) at ``t_k - h``, the enclosure of ``q_k - q_{k-j}`` (rad)
        and the baseline ``h`` (s) as an interval ``(lo, hi)``.
    XI : box (B, m).
    XD : box (B, n), current velocity enclosure at ``t_k``, m/s.
    a_max : array (n,), m/s^2.

    Returns
    -------
    The contracted ``[xd]_k``.
    """
    J = len(pasts)
    if J == 0:
        return XD
    B, n = X[0].shape
    # baselines h as intervals (J B, 1): j t_s need not be a float
    h_lo = np.repeat(np.array([float(np.min(p[3][0])) for p in pasts]), B)[:, None]
    h_hi = np.repeat(np.array([float(np.max(p[3][1])) for p in pasts]), B)[:, None]
    st = lambda boxes: (np.concatenate([b[0] for b in boxes]), np.concatenate([b[1] for b in boxes]))  # noqa: E731
    Xp = st([p[0] for p in pasts])
    Qp = st([p[1] for p in pasts])
    DQ = st([p[2] for p in pasts])
    Xk = (np.tile(X[0], (J, 1)), np.tile(X[1], (J, 1)))
    Qk = (np.tile(Q[0], (J, 1)), np.tile(Q[1], (J, 1)))
    XIk = (np.tile(XI[0], (J, 1)), np.tile(XI[1], (J, 1)))
    H = I.hull(*Xk, *Xp)
    HQ = I.hull(*Qk, *Qp)
    rate = I.div(*DQ, h_lo, h_hi)
    Jx, R = model.tape_vel.evaluate([H, HQ, XIk, rate])
    half_h = I.scale(0.5, h_hi, h_hi)[1]  # upper bound of h / 2
    slack = I.mul(-half_h, half_h, -a_max, a_max)
    U0 = I.add(np.tile(XD[0], (J, 1)), np.tile(XD[1], (J, 1)), *slack)
    U = linear_enclosure(Jx[0], Jx[1], -R[1], -R[0], U0[0], U0[1], sweeps=1)
    Vl, Vh = I.add(*U, *slack)
    lo = np.maximum(XD[0], Vl.reshape(J, B, n).max(axis=0))
    hi = np.minimum(XD[1], Vh.reshape(J, B, n).min(axis=0))
    return lo, hi


def mode_of(model, X, Q, XI):
    """Certified assembly mode per scenario: +1, -1, or 0 (not certified).

    The mode is the sign of ``mode_sign * det J_x`` over the whole box.
    """
    D = model.tape_det.evaluate([X, Q, XI])[0]
    D = (D[0][..., 0], D[1][..., 0])  # scalar output, shape (B, 1)
    return np.where(D[0] > 0.0, 1, np.where(D[1] < 0.0, -1, 0)).astype(np.int8)


def pose_solutions(model, Q, XI, X_search, tol: float = 1e-7, small: float = 5e-3, max_boxes: int = 20000, sweeps: int = 30):
    """Enclose all solutions ``x`` of ``f(x, q, xi) = 0`` in ``X_search``.

    Branch and prune for ONE scenario: ``Q`` is ``(n,)`` boxes, ``XI`` ``(m,)``.
    Boxes are contracted with HC4 and Newton, discarded when empty (only then:
    no solution is ever lost) and bisected along their widest side until they
    are narrower than ``small`` with a certified mode, or narrower than ``tol``.

    Returns
    -------
    list of ((lo, hi), mode)
        Disjoint-ish solution boxes ``(n,)`` and their certified mode (0 when
        undecided).  ``None`` if the budget ``max_boxes`` was exhausted.
    """
    stack = [(np.array(X_search[0], dtype=float), np.array(X_search[1], dtype=float))]
    Qb = (np.asarray(Q[0], dtype=float)[None], np.asarray(Q[1], dtype=float)[None])
    XIb = (np.asarray(XI[0], dtype=float)[None], np.asarray(XI[1], dtype=float)[None])
    out = []
    seen = 0
    while stack:
        seen += 1
        if seen > max_boxes:
            return None
        lo, hi = stack.pop()
        X = (lo[None], hi[None])
        for _ in range(sweeps):
            w0 = X[1] - X[0]
            X, _, _ = hc4_pose(model, X, Qb, XIb)
            if np.any(X[0] > X[1]):
                break
            X = newton(model, X, Qb, XIb, "x")
            if np.any(X[0] > X[1]):
                break
            if np.all(X[1] - X[0] >= 0.9 * w0):
                break
        if np.any(X[0] > X[1]):
            continue
        mode = int(mode_of(model, X, Qb, XIb)[0])
        w = X[1][0] - X[0][0]
        if (mode != 0 and np.max(w) < small) or np.max(w) < tol:
            out.append(((X[0][0], X[1][0]), mode))
            continue
        i = int(np.argmax(w))
        mid = 0.5 * (X[0][0][i] + X[1][0][i])
        a_hi = X[1][0].copy()
        a_hi[i] = mid
        b_lo = X[0][0].copy()
        b_lo[i] = mid
        stack.append((X[0][0].copy(), a_hi))
        stack.append((b_lo, X[1][0].copy()))
    return out


def _settled(lo, hi, mode, owner, final, B):
    """The pieces ``(lo, hi)`` ``(N, n)`` of :func:`split_prune`, not ``final``, whose splitting can change
    neither of its results: their scenario's ``final`` pieces (left unsplit in this generation: unchanged from now on)
    include one of mode 0 or both modes, so the common mode is 0 whatever the others' descendants are, and
    the hull of those final pieces contains the piece (a comparison of floats: no rounding).  A NaN
    bound or a scenario without final pieces settles nothing."""
    n = lo.shape[1]
    f_owner = owner[final]
    mn = np.full(B, 2, np.int64)
    mx = np.full(B, -2, np.int64)
    np.minimum.at(mn, f_owner, mode[final])
    np.maximum.at(mx, f_owner, mode[final])
    f_lo = np.full((B, n), np.inf)
    f_hi = np.full((B, n), -np.inf)
    np.minimum.at(f_lo, f_owner, lo[final])
    np.maximum.at(f_hi, f_owner, hi[final])
    no_common = (mn <= 0) & (mx >= 0)
    inside = np.all((lo >= f_lo[owner]) & (hi <= f_hi[owner]), -1)
    return no_common[owner] & inside & ~final


def split_prune(model, X, Q, XI, max_pieces: int = 64, tol: float = 2e-4, sweeps: int = 2):
    """Batched branch and prune of pose boxes whose mode is undecided.

    Every piece whose mode is not certified and which is wider than ``tol``
    is bisected along its widest side; both halves are contracted (HC4 then
    Newton, ``sweeps`` times) and dropped only when proved empty.  A scenario
    stops splitting once it holds ``max_pieces`` pieces.

    A piece is not split either once splitting it can change neither result
    (:func:`_settled`): the pieces left unsplit in this generation (they never
    change again) already have no common mode, and their hull contains the
    piece.  Its descendants would lie inside it, hence inside that hull, and
    could only be of the same uncertain mode.  Near the singular locus this
    spares most of the halves (the pieces along the locus, between the
    certified pieces of both modes).  The results differ from splitting them
    only when ``max_pieces`` stops a scenario, which then counts the piece
    once instead of its descendants.

    Parameters
    ----------
    X, Q : boxes (B, n); XI : box (B, m).

    Returns
    -------
    (lo, hi) : the hull of each scenario's surviving pieces (empty, ``lo > hi``,
        when none survives), and ``mode`` (B,): the common certified mode of the
        pieces, or 0.
    """
    B, n = X[0].shape
    owner = np.arange(B)
    lo, hi = X[0].copy(), X[1].copy()
    while True:
        mode = mode_of(model, (lo, hi), (Q[0][owner], Q[1][owner]), (XI[0][owner], XI[1][owner]))
        counts = np.bincount(owner, minlength=B)
        split = (mode == 0) & ((hi - lo).max(-1) >= tol) & (counts[owner] < max_pieces)
        split &= ~_settled(lo, hi, mode, owner, ~split, B)
        if not split.any():
            break
        keep = ~split
        sl, sh, so = lo[split], hi[split], owner[split]
        d = np.argmax(sh - sl, axis=-1)
        rows = np.arange(len(so))
        mid = 0.5 * sl[rows, d] + 0.5 * sh[rows, d]
        left_hi = sh.copy()
        left_hi[rows, d] = mid
        right_lo = sl.copy()
        right_lo[rows, d] = mid
        nl = np.concatenate([sl, right_lo])
        nh = np.concatenate([left_hi, sh])
        no = np.concatenate([so, so])
        Qn = (Q[0][no], Q[1][no])
        XIn = (XI[0][no], XI[1][no])
        P = (nl, nh)
        alive = np.ones(len(no), bool)
        for _ in range(sweeps):
            P, _, _ = hc4_pose(model, P, Qn, XIn)
            alive &= ~np.any(P[0] > P[1], -1)
            P = (np.where(alive[:, None], P[0], nl), np.where(alive[:, None], P[1], nh))
            P = newton(model, P, Qn, XIn, "x")
            alive &= ~np.any(P[0] > P[1], -1)
            P = (np.where(alive[:, None], P[0], nl), np.where(alive[:, None], P[1], nh))
        lo = np.concatenate([lo[keep], P[0][alive]])
        hi = np.concatenate([hi[keep], P[1][alive]])
        owner = np.concatenate([owner[keep], no[alive]])
    out_lo = np.full((B, n), np.inf)
    out_hi = np.full((B, n), -np.inf)
    np.minimum.at(out_lo, owner, lo)
    np.maximum.at(out_hi, owner, hi)
    mode = mode_of(model, (lo, hi), (Q[0][owner], Q[1][owner]), (XI[0][owner], XI[1][owner]))
    mn = np.full(B, 2, np.int64)
    mx = np.full(B, -2, np.int64)
    np.minimum.at(mn, owner, mode)
    np.maximum.at(mx, owner, mode)
    common = np.where((mn == mx) & (mn != 2), mn, 0).astype(np.int8)
    return (out_lo, out_hi), common
