"""Enclosures of an implicitly defined function and of its parameter gradient.

For ``n`` equations ``g(x, u, p) = 0`` in ``n`` unknowns ``u``, a point ``x``
and parameters ``p`` in a box ``[p]``:

* :func:`krawczyk` — the Krawczyk operator
  ``K(U) = m - C g(x, m, [p]) + (I - C J_u(x, U, [p])) (U - m)`` with
  ``m = mid(U)`` and ``C = inv(mid J_u)``.  Every root in ``U`` (for any
  ``p`` in ``[p]``) lies in ``K(U)`` (mean-value theorem, row by row); and
  when ``K(U)`` lies strictly inside ``U``, each ``p`` in ``[p]`` has exactly
  one root in ``U`` and every matrix of ``J_u(x, U, [p])`` is regular
  (Krawczyk 1969; Rump 1983 for the regularity).
* :func:`inflate_roots` — boxes around approximate roots, inflated until
  that strict inclusion proves them (existence and uniqueness);
* :func:`contract_roots` — ``U <- K(U) ∩ U`` a few times: never loses a root.
* :func:`root_gradient` — an enclosure of ``du/dp = -J_u^{-1} J_p`` over the
  boxes (implicit function theorem), the slope of a mean-value form;
* :func:`slope_change` — an enclosure of how that slope changes between two
  nearby points ``x`` (its derivative along the segment): the difference of
  the slopes at two samples without the cancellation of two wide enclosures.

Every operation is the outward-rounded interval arithmetic of
:mod:`verifier.interval` (the tapes and the linear systems optionally by kernels that
compute the same floats, :class:`ImplicitTapes`); batches are rows, as in :mod:`verifier.contractors`.
Nothing here names a robot.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from . import interval as I
from .linalg import imat_ivec, linear_enclosure, pmat_imat, pmat_ivec, point_inverse
from .one_motion import evaluate_tape
from .step import kernel_array
from .tape import Tape

__all__ = ["ImplicitTapes", "krawczyk", "strictly_inside", "inflate_roots", "contract_roots", "root_gradient",
           "slope_change"]


class ImplicitTapes:
    """Interval tapes of ``g(x, u, p)``, ``J_u = dg/du`` and ``J_p = dg/dp`` (CasADi AD of one definition).

    Parameters
    ----------
    x, u, p : casadi.SX
        Column symbols of sizes ``n_x``, ``n``, ``n_p``.
    g : casadi.SX
        ``(n,)`` expression in them.
    compiled : bool
        Evaluate the tapes by :func:`verifier.one_motion.evaluate_tape`'s compiled kernel and solve the linear
        systems by :func:`verifier.compiled.implicit.solve_columns` (the same floats).
    """

    def __init__(self, x, u, p, g, columns=None, *, compiled: bool = False):
        self.compiled = compiled
        g = ca.vec(g)
        self.n = int(u.numel())
        ju, jp = ca.jacobian(g, u), ca.jacobian(g, p)
        self.tape_g = Tape(ca.Function("g", [x, u, p], [g]))
        self.tape_ju = Tape(ca.Function("ju", [x, u, p], [ju]))
        self.tape_jac = Tape(ca.Function("jac_u_p", [x, u, p], [ju, jp]))
        # along a path x(s) with root u(s): J_u u' = -J_x x', and for the slope
        # G = du/dp[:, columns] (J_u G + J_p = 0): J_u G' = -(J_u' G + J_p'),
        # the primes being directional derivatives along (x', u') with G held
        self.columns = list(range(int(p.numel()))) if columns is None else list(columns)
        c = len(self.columns)
        xd = ca.SX.sym("xd", x.numel())
        ud = ca.SX.sym("ud", self.n)
        G = ca.SX.sym("G", self.n, c)
        F = ca.mtimes(ju, G) + jp[:, self.columns]
        dF = ca.reshape(ca.jtimes(ca.vec(F), ca.vertcat(x, u), ca.vertcat(xd, ud)), self.n, c)
        self.tape_path = Tape(ca.Function("path_u", [x, u, p, xd], [ju, ca.jtimes(g, x, xd)]))
        self.tape_slope_change = Tape(ca.Function("slope_change", [x, u, p, xd, ud, G], [dF]))


    def evaluate(self, tape, inputs):
        """``tape.evaluate(inputs)`` for one of these tapes, by the kernel when :attr:`compiled`."""
        return evaluate_tape(tape, inputs, self.compiled)


def krawczyk(tapes: ImplicitTapes, X, U, P):
    """The Krawczyk image ``K(U)`` (rows of boxes ``(B, n)``); ``X`` points as ``(lo, hi)``, ``P`` boxes."""
    m = I.midpoint(*U)
    G = tapes.evaluate(tapes.tape_g, [X, (m, m), P])[0]
    Ju = tapes.evaluate(tapes.tape_ju, [X, U, P])[0]
    C = point_inverse(I.midpoint(*Ju))
    CJl, CJh = pmat_imat(C, *Ju)
    eye = np.eye(tapes.n)
    El, Eh = I.sub(eye, eye, CJl, CJh)
    Cg = pmat_ivec(C, *G)
    dl, dh = I.sub(U[0], U[1], m, m)
    ul, uh = imat_ivec(El, Eh, dl, dh)
    kl, kh = I.sub(m, m, *Cg)
    return I.add(kl, kh, ul, uh)


def strictly_inside(inner, outer) -> np.ndarray:
    """Row mask: ``inner`` lies in the interior of ``outer`` (every component, strict)."""
    return np.all((inner[0] > outer[0]) & (inner[1] < outer[1]), axis=-1)


def inflate_roots(tapes: ImplicitTapes, X, center, r, P, *, attempts: int = 8):
    """Boxes ``center +- r`` (B, n) proved to hold exactly one root for every x in ``X`` and p in ``P``.

    The proof is the Krawczyk image lying strictly inside the box; the radius
    of a row not proved is multiplied by 4 and tried again, ``attempts``
    times in all (epsilon-inflation).  The radius is widened by a few ulp of
    ``center`` so that a point root is never assumed exact.

    Returns
    -------
    U : boxes (B, n)
        The proved boxes, contracted (``K(U) ∩ U``); meaningless where not proved.
    ok : bool array (B,)
        Rows proved.
    """
    r = np.where(np.isfinite(r), r, 1e-3) + 64.0 * np.spacing(np.abs(center)) + 1e-15
    ok = np.zeros(len(center), bool)
    for _ in range(attempts):
        U = (I.sub(center, center, r, r)[0], I.add(center, center, r, r)[1])
        K = krawczyk(tapes, X, U, P)
        ok = strictly_inside(K, U)
        if ok.all():
            break
        r = np.where(ok[:, None], r, 4.0 * r)
    U = I.intersect(U[0], U[1], K[0], K[1])
    return contract_roots(tapes, X, U, P, sweeps=2), ok


def contract_roots(tapes: ImplicitTapes, X, U, P, sweeps: int = 2):
    """``U <- K(U) ∩ U``, ``sweeps`` times: every root in ``U`` for a ``p`` in ``P`` stays.

    A row whose box becomes empty (``lo > hi``) has no root in ``U`` for any ``p`` in ``P``.
    """
    for _ in range(sweeps):
        K = krawczyk(tapes, X, U, P)
        U = I.intersect(U[0], U[1], K[0], K[1])
    return U


def root_gradient(tapes: ImplicitTapes, X, U, P, columns):
    """Enclose ``du/dp_j`` for ``j`` in ``columns`` at every ``(u, p)`` in ``U x P`` with ``g = 0``.

    ``J_u du/dp_j = -J_p[:, j]`` (implicit function theorem), solved as an
    interval linear system (:func:`verifier.linalg.linear_enclosure`: a
    Neumann-series start box, then Gauss–Seidel).  Unbounded components mean
    ``J_u`` could not be proved regular over the box.

    Returns
    -------
    (lo, hi) of shape ``(B, n, len(columns))``.
    """
    Ju, Jp = tapes.evaluate(tapes.tape_jac, [X, U, P])
    cols = list(columns)
    return _solve_columns(Ju, (-Jp[1][:, :, cols], -Jp[0][:, :, cols]), tapes.compiled)


def slope_change(tapes: ImplicitTapes, X, dX, U, P, G):
    """Enclose ``G(x_b) - G(x_a)`` for the slope ``G = du/dp[:, tapes.columns]`` along the segment ``x_a -> x_b``.

    Parameters
    ----------
    X : boxes (B, n_x)
        Hulls of the segments.
    dX : boxes (B, n_x)
        ``x_b - x_a``, enclosed.
    U : boxes (B, n)
        Holding the root ``u(x, p)`` for every ``x`` of the segment and ``p`` in ``P``
        (proved, e.g. by :func:`krawczyk` strictly inside).
    G : boxes (B, n, c)
        Slopes over ``X x U x P`` (:func:`root_gradient`).

    The change is the integral over the segment of ``dG/ds``, which solves
    ``J_u G' = -(J_u' G + J_p')`` (derivative of ``J_u G + J_p = 0`` along
    ``x' = dX``, ``u' = -J_u^{-1} J_x dX``); each is enclosed over the boxes,
    and an integral over ``[0, 1]`` of a function with values in a box lies
    in that box.
    """
    Ju, JxdX = tapes.evaluate(tapes.tape_path, [X, U, P, dX])
    ud = _solve_columns(Ju, (-JxdX[1][..., None], -JxdX[0][..., None]), tapes.compiled)
    ud = (ud[0][..., 0], ud[1][..., 0])
    B, n, c = G[0].shape
    flat = [np.transpose(g, (0, 2, 1)).reshape(B, n * c) for g in G]  # CasADi's column-major order
    dF = tapes.evaluate(tapes.tape_slope_change, [X, U, P, dX, ud, flat])[0]
    return _solve_columns(Ju, (-dF[1], -dF[0]), tapes.compiled)


def _solve_columns(A, R, compiled: bool = False):
    """Enclose ``Y`` with ``A Y = R`` column by column: ``A`` boxes (B, n, n), ``R`` boxes (B, n, c); a NaN
    bound (the arithmetic lost) is unbounded.  ``compiled``: by
    :func:`verifier.compiled.implicit.solve_columns` (the same floats)."""
    # one matrix per row broadcast over the c right-hand sides: preconditioned once, not c times
    bl = np.transpose(R[0], (0, 2, 1))
    bh = np.transpose(R[1], (0, 2, 1))
    if compiled:
        from .compiled.implicit import scratch_size, solve_columns  # numba loaded on first use only

        B, c, n = bl.shape
        yl, yh = np.empty((B, c, n)), np.empty((B, c, n))
        k = kernel_array
        solve_columns(k(A[0]), k(A[1]), k(bl), k(bh), yl, yh, 2, np.empty(scratch_size(n)))
    else:
        yl, yh = linear_enclosure(A[0][:, None], A[1][:, None], bl, bh, sweeps=2)
    yl = np.where(np.isnan(yl), -np.inf, yl)
    yh = np.where(np.isnan(yh), np.inf, yh)
    return np.transpose(yl, (0, 2, 1)), np.transpose(yh, (0, 2, 1))
