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

__all__ = ["hc4_pose", "newton", "velocity", "velocity_displacement", "mode_of", "pose_solutions"]


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
    R = model.tape_jq_qd.evaluate([X, Q, XI, QD])[0]
    J = model.tape_jx.evaluate([X, Q, XI])[0]
    return linear_enclosure(J[0], J[1], -R[1], -R[0], XD[0], XD[1], sweeps=1)


def velocity_displacement(model, X, Q, X_past, Q_past, XI, XD, DQ, h, a_max):
    """Contract ``[xd]_k`` with the displacement over a baseline ``h = j t_s``.

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
    instead of being amplified by ``J_x^{-1}`` near the singularity.

    Parameters
    ----------
    X, Q, X_past, Q_past : boxes (B, n) at ``t_k`` and ``t_k - h``.
    XD : box (B, n), current velocity enclosure at ``t_k``, m/s.
    DQ : box (B, n), enclosure of ``q_k - q_{k-j}``, rad.
    h : float, baseline, s.
    a_max : array (n,), m/s^2.

    Returns
    -------
    The contracted ``[xd]_k``.
    """
    H = I.hull(*X, *X_past)
    HQ = I.hull(*Q, *Q_past)
    rate = I.div(*DQ, h, h)
    R = model.tape_jq_qd.evaluate([H, HQ, XI, rate])[0]
    J = model.tape_jx.evaluate([H, HQ, XI])[0]
    slack = I.scale(0.5 * h, -a_max, a_max)
    U0 = I.add(*XD, *slack)
    U = linear_enclosure(J[0], J[1], -R[1], -R[0], U0[0], U0[1], sweeps=1)
    return I.intersect(*XD, *I.add(*U, *slack))


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
    n = model.n
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
