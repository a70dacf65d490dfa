"""The ``cartesian`` execution class proved by interval analysis over the whole calibration box.

:func:`planner.execution.cartesian_class` *measures* the class's ``C``,
``e`` and ``d`` on sampled geometries.  :func:`prove_cartesian_class`
bounds the same quantities for every geometry of ``[xi]`` at once, so that
every execution following the planned path is in the class by construction.

The argument, step by step (docs/soundness.md, "The execution class of a
certificate"):

1. *Effective joints.*  With ``Robot.joint_offsets`` (``f`` reads joint
   ``i`` only through ``u_i = q_i + xi_j``) the loop closure is rewritten in
   ``u`` by substituting ``q_i = u_i - xi_j`` in the robot's one CasADi
   definition; CasADi must then report that it no longer depends on the
   offsets (``depends_on``), else nothing is proved.  The effective
   deviation ``D_k(xi) = u_k(xi) - u_plan,k`` therefore depends only on the
   other parameters: the offsets drop out of ``C``, ``e`` and ``d``.  A joint
   without an offset parameter keeps ``u_i = q_i`` (in its own unit, rad or
   m) and its whole deviation is drift (``c_i = 0`` exactly).
2. *The branch.*  At each planned pose ``x_k`` the box
   ``U_k = u_plan,k +- r_k`` is inflated until the Krawczyk image over the
   whole box ``[xi]`` lies strictly inside it: then every geometry has
   exactly one root in ``U_k`` (the plan's branch: the planned joints are
   the root at the planning geometry), ``J_u`` is regular there, and the
   root ``u_k(xi)`` is continuously differentiable.  No inflation proved:
   ``proved: false`` with the sample.
3. *Mean-value forms.*  On a sub-box ``B`` of the free parameters with
   centre ``c``: ``u_k(c)`` is enclosed by a box Krawczyk proves at the
   point ``c``, the slope ``G_k = du_k/dxi`` over ``U_k x B`` by the interval
   solution of ``J_u G = -J_xi``.  Then for every ``xi`` in ``B``::

       D_k(xi) - D_r(xi)     in  D_k(c) - D_r(c)     + (G_k - G_r)(B) (B - c)
       D_k(xi) - D_{k-1}(xi) in  D_k(c) - D_{k-1}(c) + S_k (B - c)

   for a reference sample ``r`` (the middle one), where ``S_k`` is
   ``(G_k - G_{k-1})(B)`` intersected with the slope's change along the
   segment ``x_{k-1} -> x_k`` proved once over ``[xi]``
   (:func:`verifier.implicit.slope_change`).  For an offset joint, with
   ``m`` the midpoint of the hull of the first enclosure over ``k``, the
   constant ``c = D_r(xi) + m`` lies in ``D_r(B) + m`` and ``|D_k - c|`` is
   at most the larger distance from ``m`` to that hull
   (:func:`offset_split`): the box's ``C`` and ``e``; ``d`` is the largest
   magnitude of the second enclosure.
4. *Branch and bound*, one per joint, best first.  A sub-box is bisected
   along the parameter whose remainder exceeds the linear part most, until
   every leaf's bounds are within ``tol`` (relative) of the largest values
   met at evaluated geometries (box centres and the corners the
   linearisation points to), the exact termination rule, or until
   ``max_boxes`` sub-boxes were evaluated (the bounds are proved either way;
   only their tightness differs).  The class takes the hull of the leaves'
   ``C`` and the largest ``e`` and ``d``: the leaves partition ``[xi]``.
   The joints' searches run in lockstep, each round's sub-boxes of all of
   them evaluated in one call (each distinct one once): the bounds are
   those of the searches run one by one, bit for bit.

Every operation is outward-rounded (:mod:`verifier.interval`); an empty
enclosure contradicts step 2 and is reported as ``proved: false``
(inconsistent), never as a bound.  Nothing here names a robot.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from crosscert.robots.errors import InputError
from crosscert.verifier import interval as I
from crosscert.verifier.implicit import (ImplicitTapes, contract_roots, inflate_roots, krawczyk, root_gradient,
                                         slope_change, strictly_inside)
from crosscert.verifier.linalg import imat_ivec

from .execution import ExecutionClass, ExecutionKind, cartesian_class, joint_class, joint_error
from .task import PlannedTrajectory

__all__ = ["METHOD", "ClassProof", "prove_cartesian_class", "prove_cartesian_class_cached", "proved_class",
           "with_proof_failure", "describe", "offset_split", "execution_class"]

#: How the bounds are proved (reported in certificate.json).
METHOD = ("interval branch and bound over [xi]: Krawczyk-proved IK enclosures, mean-value forms with "
          "interval slopes du/dxi, outward rounding")


@dataclass(frozen=True, eq=False)
class ClassProof:
    """Outcome of :func:`prove_cartesian_class`.

    Attributes
    ----------
    proved : bool
    reason : str
        Why not proved (empty when proved).
    c_lo, c_hi : ndarray, shape (n,)
        Proved enclosure of the constant part per joint (rad, or m for a
        prismatic joint; exactly 0 for a joint without an offset parameter).
    drift : float
        ``e``: proved bound on ``|D_k - c|``.
    step : float
        ``d``: proved bound on the change of ``D`` per sample.
    boxes : int
        Sub-boxes of ``[xi]`` evaluated by the branch and bound.
    time_s : float
        Wall time of the proof, s.
    found : dict
        Largest values met at evaluated geometries (lower bounds of the true
        maxima): ``drift``, ``step``, ``c_lo``, ``c_hi`` and the geometries
        (full ``xi`` vectors) where the drift and step maxima were met.
    converged : bool
        Whether the termination rule was met (``False``: the box budget ran
        out first; the bounds are proved but may be looser than ``tol``).
    tol : float
        Relative tolerance of that rule.
    """

    proved: bool
    reason: str = ""
    c_lo: np.ndarray = field(default_factory=lambda: np.zeros(0))
    c_hi: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drift: float = float("nan")
    step: float = float("nan")
    boxes: int = 0
    time_s: float = 0.0
    found: dict = field(default_factory=dict)
    converged: bool = False
    tol: float = 0.0

    def summary(self) -> dict:
        """The ``execution.proof`` object of certificate.json."""
        if not self.proved:
            return {"proved": False, "reason": self.reason, "time_s": self.time_s}
        return {"proved": True, "method": METHOD, "boxes_explored": self.boxes, "time_s": self.time_s,
                "converged": self.converged, "tolerance": self.tol,
                "largest_drift_found": self.found.get("drift"),
                "largest_step_found": self.found.get("step")}


def offset_split(lo_min, hi_max, r_lo, r_hi):
    """Centre ``m``, half-width bound ``e`` and constant range of an offset joint, outward rounded.

    ``D_k - D_r`` lies in ``[lo_min, hi_max]`` for every ``k`` and ``D_r`` in
    ``[r_lo, r_hi]``; with ``c = D_r + m``: ``|D_k - c| <= e`` and ``c`` in
    ``[c_lo, c_hi]``.  Returns ``(m, e, c_lo, c_hi)``.
    """
    m = I.midpoint(lo_min, hi_max)
    e = np.maximum(I.sub(hi_max, hi_max, m, m)[1], I.sub(m, m, lo_min, lo_min)[1])
    c_lo, c_hi = I.add(r_lo, r_hi, m, m)
    return m, e, c_lo, c_hi


@functools.lru_cache(maxsize=8)
def _tapes(robot):
    """Tapes of the loop closure in the effective joints and the free parameters, or why there are none."""
    x = ca.SX.sym("x", robot.n)
    u = ca.SX.sym("u", robot.n)
    xi = ca.SX.sym("xi", robot.m)
    offs = _offsets(robot)
    q = ca.vertcat(*[u[i] - xi[offs[i]] if i in offs else u[i] for i in range(robot.n)])
    g = ca.vec(robot.loop_closure(x, q, xi))
    still = [robot.param_names[j] for j in offs.values() if ca.depends_on(g, xi[j])]
    if still:
        return None, (f"the loop closure still depends on the offsets {still} once written in q + offset "
                      "(joint_offsets does not hold symbolically)")
    # the parameters the proof branches on: those g reads whose interval is not a point
    lo, hi = robot.xi_lo_array, robot.xi_hi_array
    free = [j for j in range(robot.m) if hi[j] > lo[j] and ca.depends_on(g, xi[j])]
    numeric = ca.Function("g_ju", [x, u, xi], [g, ca.jacobian(g, u)])
    return (ImplicitTapes(x, u, xi, g, free), free, numeric), ""


def _offsets(robot) -> dict[int, int]:
    return {i: j for i, j in enumerate(robot.joint_offsets or ()) if j is not None}


def _rows(a, reps):
    return np.repeat(a, reps, axis=0)


class _Path:
    """One planned path: its proved root boxes (step 2), the slope changes between samples, and the
    evaluation of sub-boxes of the free parameters (step 3)."""

    def __init__(self, tapes, numeric, robot, free, x, u_plan, U0, slope_steps, remainder):
        self.tapes, self.numeric, self.free, self.remainder = tapes, numeric, free, remainder
        # u_plan: (lo, hi) enclosure of the planned joints plus their planning offsets (the sum is
        # rounded outward); its float midpoint centres boxes and serves the termination rule only
        self.u_lo, self.u_hi = u_plan
        self.u_plan = I.midpoint(*u_plan)
        self.x, self.U0 = x, U0
        self.lo, self.hi = robot.xi_lo_array, robot.xi_hi_array
        self.K, self.n = self.u_plan.shape
        self.r = self.K // 2  # reference sample of the constant part
        self.off = np.array([i in _offsets(robot) for i in range(self.n)])
        self.slope_steps = slope_steps  # (K-1, n, p) boxes: G_k - G_{k-1} over the whole [xi], or None

    def full(self, v):
        """Full xi vectors (N, m) with the free parameters set to ``v`` (N, p), the others at their midpoint."""
        out = np.repeat(I.midpoint(self.lo, self.hi)[None], len(v), axis=0)
        out[:, self.free] = v
        return out

    def boxes(self, blo, bhi):
        """Full xi boxes (nb K, m) of the sub-boxes ``[blo, bhi]`` (nb, p), one row per sample."""
        Plo, Phi = self.full(blo), self.full(bhi)
        keep = [j for j in range(len(self.lo)) if j not in self.free]
        Plo[:, keep], Phi[:, keep] = self.lo[keep], self.hi[keep]
        return _rows(Plo, self.K), _rows(Phi, self.K)

    def newton(self, points, U, steps: int = 3):
        """Float roots (N, K, n) at the geometries ``points`` (N, m) by Newton from the midpoints of ``U`` (N K, n).

        Floats, not enclosures: for lower bounds and as the centre of a proved box.
        """
        N = len(points)
        X = np.tile(self.x, (N, 1))
        P = _rows(points, self.K)
        u = I.midpoint(*U)
        for _ in range(steps):
            g, J = (np.asarray(v) for v in self.numeric(X.T, u.T, P.T))
            J = J.T.reshape(-1, self.n, self.n).transpose(0, 2, 1) if self.n > 1 else J.reshape(-1, 1, 1)
            try:
                u = u - np.linalg.solve(J, g.T[:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:
                break
        return u.reshape(N, self.K, self.n)

    def roots_at(self, points, U):
        """Root enclosures (N, K, n) at the geometries ``points`` (N, m), within ``U`` (N K, n) valid there.

        A tiny box around Newton's float root inside ``U`` whose Krawczyk image
        lies strictly inside it holds the root, the only one in ``U``; other
        rows are contracted from ``U``.
        """
        N, n = len(points), self.n
        X = np.tile(self.x, (N, 1))
        P = _rows(points, self.K)
        uf = self.newton(points, U).reshape(-1, n)
        r = 1e-13 + 16.0 * np.spacing(np.abs(uf))
        T = (I.sub(uf, uf, r, r)[0], I.add(uf, uf, r, r)[1])
        Kt = krawczyk(self.tapes, (X, X), T, (P, P))
        ok = strictly_inside(Kt, T) & np.all((T[0] >= U[0]) & (T[1] <= U[1]), axis=1)
        Ul, Uh = I.intersect(T[0], T[1], Kt[0], Kt[1])
        if not ok.all():
            rest = contract_roots(self.tapes, (X[~ok], X[~ok]), (U[0][~ok], U[1][~ok]), (P[~ok], P[~ok]), sweeps=3)
            Ul[~ok], Uh[~ok] = rest
        return Ul.reshape(N, self.K, n), Uh.reshape(N, self.K, n)

    def values(self, u):
        """``e``, ``d`` and the constant ``c`` (floats) of the geometries whose float roots are ``u`` (N, K, n).

        Lower bounds of the maxima for the termination rule only (never a bound of the class).
        """
        D = u - self.u_plan
        dd = D - D[:, self.r:self.r + 1]
        e = np.where(self.off, 0.5 * (dd.max(axis=1) - dd.min(axis=1)), np.abs(D).max(axis=1))
        c = np.where(self.off, D[:, self.r] + 0.5 * (dd.max(axis=1) + dd.min(axis=1)), 0.0)
        d = np.abs(np.diff(D, axis=1)).max(axis=1) if self.K > 1 else np.zeros(e.shape)
        return e, d, c

    def evaluate(self, blo, bhi, Ubox):
        """Proved bounds of the sub-boxes ``[blo, bhi]`` (nb, p), given root boxes ``Ubox`` (nb, K, n) valid on them."""
        nb, K, n, p = len(blo), self.K, self.n, len(self.free)
        N, r = nb * K, self.r
        P = self.boxes(blo, bhi)
        X = np.tile(self.x, (nb, 1))
        U = (Ubox[0].reshape(N, n), Ubox[1].reshape(N, n))
        ctr = I.midpoint(blo, bhi)
        Ucl, Uch = self.roots_at(self.full(ctr), U)
        G = root_gradient(self.tapes, (X, X), U, P, self.free)
        Gl, Gh = G[0].reshape(nb, K, n, p), G[1].reshape(nb, K, n, p)
        R = I.sub(blo, bhi, ctr, ctr)  # B - c, (nb, p)
        Rl, Rh = R[0][:, None, :], R[1][:, None, :]
        use = p > 0 and self.remainder

        def mv(Al, Ah):
            """The mean-value remainder ``[A] (B - c)``."""
            if not use:
                z = np.zeros(Al.shape[:-1])
                return z, z.copy()
            return imat_ivec(Al, Ah, Rl, Rh)

        MV = mv(Gl, Gh)  # u_k(xi) - u_k(c)
        Ul, Uh = I.intersect(U[0].reshape(nb, K, n), U[1].reshape(nb, K, n), *I.add(Ucl, Uch, *MV))
        bad = (np.any(Ucl > Uch, axis=(1, 2)) | np.any(Ul > Uh, axis=(1, 2))
               | ~np.all(np.isfinite(MV[0]) & np.isfinite(MV[1]), axis=(1, 2)))
        # D_k(c) = u_k(c) - u_plan,k
        Pl, Ph = I.sub(Ucl, Uch, self.u_lo, self.u_hi)
        # offset joints: D_k - D_r, and D_r; the constant c = D_r + m
        dGr = I.sub(Gl, Gh, Gl[:, r:r + 1], Gh[:, r:r + 1])
        dl, dh = I.add(*I.sub(Pl, Ph, Pl[:, r:r + 1], Ph[:, r:r + 1]), *mv(*dGr))
        _m, e_off, c_lo, c_hi = offset_split(dl.min(axis=1), dh.max(axis=1), *I.add(Pl[:, r], Ph[:, r],
                                                                                      MV[0][:, r], MV[1][:, r]))
        # joints without an offset: the whole deviation D_k is drift (c = 0)
        Dl, Dh = I.add(Pl, Ph, *MV)
        e = np.where(self.off, e_off, np.maximum(np.abs(Dl), np.abs(Dh)).max(axis=1))  # (nb, n)
        c_lo, c_hi = np.where(self.off, c_lo, 0.0), np.where(self.off, c_hi, 0.0)
        # steps D_k - D_{k-1}: the slopes' difference on the sub-box, intersected with the
        # slope change along the segment proved on the whole box (much tighter: no cancellation)
        if K > 1:
            s = I.sub(Pl[:, 1:], Ph[:, 1:], Pl[:, :-1], Ph[:, :-1])
            # both enclose the slope of D_k - D_{k-1} at every geometry of the sub-box: intersect them
            dG = I.sub(Gl[:, 1:], Gh[:, 1:], Gl[:, :-1], Gh[:, :-1])
            if self.slope_steps is not None:
                dG = I.intersect(*dG, self.slope_steps[0][None], self.slope_steps[1][None])
            s1 = I.add(*s, *mv(*dG))
            score_d = (dG[1] - dG[0]).max(axis=1) * (bhi - blo)[:, None]
            bad |= np.any(s1[0] > s1[1], axis=(1, 2))
            d = np.maximum(np.abs(s1[0]), np.abs(s1[1])).max(axis=1)  # (nb, n)
            S = (s1, I.midpoint(*dG))
        else:
            d = np.zeros((nb, n))
            score_d = np.zeros((nb, n, p))
            S = None
        # where to split: the parameter whose slope is least sharp times its width (the remainder's
        # excess over the linear part), for e and for d, per joint
        slope_e = np.where(self.off[None, None, :, None], dGr[1] - dGr[0], Gh - Gl)
        score_e = slope_e.max(axis=1) * (bhi - blo)[:, None]
        return dict(e=e, d=d, c_lo=c_lo, c_hi=c_hi, U=(Ul, Uh), bad=bad, ctr=ctr, Uc=(Ucl, Uch),
                    score_e=score_e, score_d=score_d, G=(Gl, Gh), dd=(dl, dh), D=(Dl, Dh), S=S)

    def candidates(self, blo, bhi, ev, i):
        """Corners (N, p) of the sub-boxes worst for joint ``i`` where its linearised drift, step and
        constant are extreme, and the index of the box each comes from.

        Only lower bounds come from them (the termination rule): which corner is tried never affects soundness.
        """
        Gm = I.midpoint(*ev["G"])  # (nb, K, n, p)
        (dl, dh), (Dl, Dh), r = ev["dd"], ev["D"], self.r
        pts, owner = [], []
        b = int(np.argmax(ev["e"][:, i]))
        if self.off[i]:
            k, l = int(np.argmax(dh[b, :, i])), int(np.argmin(dl[b, :, i]))
            dirs = [(b, Gm[b, k, i] - Gm[b, l, i])]
            dirs += [(int(np.argmin(ev["c_lo"][:, i])), -Gm[:, r, i]), (int(np.argmax(ev["c_hi"][:, i])), Gm[:, r, i])]
            dirs = [(dirs[0][0], dirs[0][1])] + [(bb, g[bb]) for bb, g in dirs[1:]]
        else:
            k = int(np.argmax(np.maximum(np.abs(Dl[b, :, i]), np.abs(Dh[b, :, i]))))
            dirs = [(b, np.sign(Dl[b, k, i] + Dh[b, k, i]) * Gm[b, k, i])]
        if ev["S"] is not None:
            (sl, sh), dGm = ev["S"]
            b = int(np.argmax(ev["d"][:, i]))
            k = int(np.argmax(np.maximum(np.abs(sl[b, :, i]), np.abs(sh[b, :, i]))))
            dirs.append((b, np.sign(sl[b, k, i] + sh[b, k, i]) * dGm[b, k, i]))
        for bb, v in dirs:
            pts.append(np.where(v > 0, bhi[bb], blo[bb]))
            owner.append(bb)
        return np.array(pts), np.array(owner)


def _setup_path(tapes, numeric, robot, free, x, u_plan, remainder):
    """Steps 2 and the slope changes along the path: a :class:`_Path`, or the reason (str) why not proved.

    ``u_plan``: ``(lo, hi)`` enclosure of the planned joints plus offsets ``(K, n)``."""
    u_bounds, u_plan = u_plan, I.midpoint(*u_plan)
    K, n = u_plan.shape
    X = (x, x)
    lo, hi = robot.xi_lo_array, robot.xi_hi_array
    P = (_rows(lo[None], K), _rows(hi[None], K))
    # first radius: twice the linear estimate of the root's motion over [xi] (a guess; the proof is Krawczyk's)
    G = root_gradient(tapes, X, (u_plan, u_plan), P, free)
    mag = np.maximum(np.abs(G[0]), np.abs(G[1]))
    r0 = 2.0 * mag @ (0.5 * (hi - lo)[free]) if free else np.zeros((K, n))
    U0, ok = inflate_roots(tapes, X, u_plan, r0, P)
    if not ok.all():
        k = int(np.nonzero(~ok)[0][0])
        return (f"the inverse kinematics at path point {k} could not be proved unique in an inflated box "
                "for every geometry of [xi] (Krawczyk)")
    if np.any(U0[0] > U0[1]):
        return "inconsistent: an inverse kinematics enclosure proved to hold a root became empty"
    steps = None
    if K > 1 and free:
        Xs = (np.minimum(x[:-1], x[1:]), np.maximum(x[:-1], x[1:]))
        dX = I.sub(x[1:], x[1:], x[:-1], x[:-1])
        Hl, Hh = I.hull(U0[0][:-1], U0[1][:-1], U0[0][1:], U0[1][1:])
        Ps = (P[0][:-1], P[1][:-1])
        Us, oks = inflate_roots(tapes, Xs, I.midpoint(Hl, Hh), 0.625 * (Hh - Hl), Ps)
        oks &= ~np.any(Us[0] > Us[1], axis=1)
        Gs = root_gradient(tapes, Xs, Us, Ps, free)
        Tl, Th = slope_change(tapes, Xs, dX, Us, Ps, Gs)
        # the segment proofs are what carry the plan's branch from sample to sample (one root per
        # geometry all along the path): without every one of them the branch is not proved
        if not oks.all():
            k = int(np.nonzero(~oks)[0][0])
            return (f"the inverse kinematics between path points {k} and {k + 1} could not be proved unique "
                    "for every geometry of [xi] (Krawczyk): the branch the executions follow is not proved")
        bad = np.isnan(Tl) | np.isnan(Th)
        steps = (np.where(bad, -np.inf, Tl), np.where(bad, np.inf, Th))
    return _Path(tapes, numeric, robot, free, x, u_bounds, U0, steps, remainder)


def prove_cartesian_class(robot, x_path, q_plan, xi_plan, *, tol: float = 0.05, max_boxes: int = 16,
                          remainder: bool = True) -> ClassProof:
    """Prove ``C``, ``e`` and ``d`` of the ``cartesian`` class over the whole box ``[xi]`` (module docstring).

    Parameters
    ----------
    robot : Robot
    x_path : array (K, n) or list of them
        Planned poses at consecutive samples, SI.
    q_plan : array (K, n) or list of them
        Planned joints there (planning geometry ``xi_plan``), rad (m for a prismatic joint).
    xi_plan : array (m,)
        Planning geometry, SI.
    tol : float
        Relative tolerance of the termination rule: a sub-box is settled when
        its bounds exceed the largest values met at evaluated geometries by
        at most ``tol`` times them (``C``: times the width of the range met).
    max_boxes : int
        Budget of evaluated sub-boxes per path and joint (the bounds are
        proved when it runs out too, only possibly looser than ``tol``).
    remainder : bool
        Keep the remainder term of the mean-value forms.  ``False`` only for
        the tests' removal check: the bounds are then *not* proved.

    Returns
    -------
    ClassProof
        ``proved`` false (with the reason) when the model is not supported or
        an inverse kinematics enclosure could not be proved.
    """
    t0 = time.perf_counter()
    xs = list(x_path) if isinstance(x_path, (list, tuple)) else [x_path]
    qs = list(q_plan) if isinstance(q_plan, (list, tuple)) else [q_plan]
    built, why = _tapes(robot)
    if built is None:
        return ClassProof(False, why, time_s=time.perf_counter() - t0)
    tapes, free, numeric = built
    if not free:
        return ClassProof(False, "no parameter of the loop closure has a calibration interval wider than a point: "
                                 "nothing to branch on (not supported)", time_s=time.perf_counter() - t0)
    offs = _offsets(robot)
    xi_plan = np.asarray(xi_plan, float)
    n = robot.n
    c_lo, c_hi = np.zeros(n), np.zeros(n)
    e = d = 0.0
    found = {"drift": 0.0, "step": 0.0, "c_lo": np.zeros(n), "c_hi": np.zeros(n), "drift_xi": None, "step_xi": None}
    boxes, converged = 0, True
    with I.quiet_fp():
        for x, q in zip(xs, qs):
            x, q = np.asarray(x, float), np.asarray(q, float)
            off = np.array([xi_plan[offs[i]] if i in offs else 0.0 for i in range(n)])
            u_plan = I.add(q, q, off, off)  # outward: the deviation D_k is taken from this enclosure
            path = _setup_path(tapes, numeric, robot, free, x, u_plan, remainder)
            if isinstance(path, str):
                return ClassProof(False, path, time_s=time.perf_counter() - t0)
            # one branch and bound per joint: each splits only the parameters its own bounds need
            for i, res in enumerate(_branch_and_bound_joints(path, tol, max_boxes, range(n))):
                if isinstance(res, str):
                    return ClassProof(False, res, time_s=time.perf_counter() - t0)
                boxes += res["boxes"]
                converged &= res["converged"]
                c_lo[i], c_hi[i] = min(c_lo[i], res["c_lo"]), max(c_hi[i], res["c_hi"])
                e, d = max(e, res["e"]), max(d, res["d"])
                f = res["found"]
                if f["drift"] >= found["drift"]:
                    found.update(drift=f["drift"], drift_xi=f["drift_xi"])
                if f["step"] >= found["step"]:
                    found.update(step=f["step"], step_xi=f["step_xi"])
                found["c_lo"][i] = min(found["c_lo"][i], f["c_lo"])
                found["c_hi"][i] = max(found["c_hi"][i], f["c_hi"])
    return ClassProof(True, "", c_lo, c_hi, float(e), float(d), boxes, time.perf_counter() - t0, found, converged,
                      float(tol))


def _branch_and_bound(path: _Path, tol: float, max_boxes: int, i: int):
    """Step 4 on one path for joint ``i``: a dict of proved bounds, or the reason (str) why nothing is proved."""
    return _branch_and_bound_joints(path, tol, max_boxes, [i])[0]


def _branch_and_bound_joints(path: _Path, tol: float, max_boxes: int, joints) -> list:
    """Step 4 for each joint of ``joints``, in lockstep: :func:`_branch_and_bound`'s results, in that order.

    Each joint's search is its own (its sub-boxes, splits, budget and termination rule), but every
    round evaluates the sub-boxes all searches asked for in one :meth:`_Path.evaluate` call, each
    distinct sub-box once (the first round's whole box is the same for every joint): the cost of an
    evaluation is mostly per call.  The bounds are those of the searches run one after the other,
    bit for bit, because every row of an evaluation depends on its own sub-box only.  (One exception,
    never met on the benchmark plans: :meth:`_Path.newton` stops for the whole call at a singular
    Jacobian, so another row may then get another float centre; what is proved stays proved, only the
    bounds' tightness can differ.)
    """
    searches = [_JointSearch(path, tol, max_boxes, i) for i in joints]
    while True:
        active = [s for s in searches if s.result is None]
        if not active:
            return [s.result for s in searches]
        blo = np.concatenate([s.blo for s in active])
        bhi = np.concatenate([s.bhi for s in active])
        Ul = np.concatenate([s.Uparent[0] for s in active])
        Uh = np.concatenate([s.Uparent[1] for s in active])
        index: dict = {}  # a sub-box's bytes -> its row among the distinct ones
        unique, where = [], np.empty(len(blo), dtype=np.int64)
        for r in range(len(blo)):
            key = b"".join(a[r].tobytes() for a in (blo, bhi, Ul, Uh))
            if key not in index:
                index[key] = len(unique)
                unique.append(r)
            where[r] = index[key]
        ev = path.evaluate(blo[unique], bhi[unique], (Ul[unique], Uh[unique]))
        at = 0
        for s in active:
            k = len(s.blo)
            s.advance(_take(ev, where[at:at + k]))
            at += k


def _take(ev, idx):
    """The rows ``idx`` of every array (also inside tuples) of an evaluation ``ev``."""
    if ev is None:
        return None
    if isinstance(ev, dict):
        return {k: _take(v, idx) for k, v in ev.items()}
    if isinstance(ev, tuple):
        return tuple(_take(v, idx) for v in ev)
    return ev[idx]


class _JointSearch:
    """Step 4 on one path for joint ``i``, one round per :meth:`advance` (:func:`_branch_and_bound_joints`).

    ``blo, bhi, Uparent``: the sub-boxes to evaluate next and their parents' root boxes; ``result``
    (None while running): a dict of proved bounds, or the reason (str) why nothing is proved.
    """

    def __init__(self, path: _Path, tol: float, max_boxes: int, i: int):
        self.path, self.tol, self.max_boxes, self.i = path, tol, max_boxes, i
        self.blo, self.bhi = path.lo[path.free][None].copy(), path.hi[path.free][None].copy()
        self.Uparent = (path.U0[0][None], path.U0[1][None])
        self.L = None  # the leaves: boxes and proved bounds
        self.best = {"drift": 0.0, "step": 0.0, "c_lo": np.inf, "c_hi": -np.inf, "drift_xi": None, "step_xi": None}
        self.boxes = 0
        self.result = None

    def _met(self, points, U=None, roots=None):
        """Update the largest values met with the geometries ``points`` (N, p) (float ``roots``, or by Newton in ``U``)."""
        path, best, i = self.path, self.best, self.i
        full = path.full(points)
        e, d, c = (v[:, i] for v in path.values(path.newton(full, U) if roots is None else roots))
        a, b = int(np.argmax(e)), int(np.argmax(d))
        if e[a] >= best["drift"]:
            best.update(drift=float(e[a]), drift_xi=full[a])
        if d[b] >= best["step"]:
            best.update(step=float(d[b]), step_xi=full[b])
        best["c_lo"] = min(best["c_lo"], float(c.min()))
        best["c_hi"] = max(best["c_hi"], float(c.max()))

    def advance(self, ev) -> None:
        """Take the evaluation ``ev`` of the pending sub-boxes; set the next ones, or the result."""
        path, tol, i, best = self.path, self.tol, self.i, self.best
        p, n = len(path.free), path.n
        blo, bhi = self.blo, self.bhi
        atol = 1e-15
        self.boxes += len(blo)
        if ev["bad"].any():
            self.result = ("inconsistent: an enclosure of the inverse kinematics became empty or unbounded on a "
                           "sub-box of [xi], which contradicts its proved existence")
            return
        Ub = ev["U"]
        self._met(ev["ctr"], roots=I.midpoint(*ev["Uc"]))
        if p:
            pts, own = path.candidates(blo, bhi, ev, i)
            self._met(pts, (Ub[0][own].reshape(-1, n), Ub[1][own].reshape(-1, n)))
        new = dict(lo=blo, hi=bhi, e=ev["e"][:, i], d=ev["d"][:, i], c_lo=ev["c_lo"][:, i], c_hi=ev["c_hi"][:, i],
                   U=Ub, score_e=ev["score_e"][:, i], score_d=ev["score_d"][:, i])
        L = new if self.L is None else {k: _cat(self.L[k], new[k]) for k in self.L}
        # the exact termination rule: a leaf is settled when its bounds are within tol of what was met
        wc = best["c_hi"] - best["c_lo"]
        settled = ((L["e"] <= (1.0 + tol) * best["drift"] + atol) & (L["d"] <= (1.0 + tol) * best["step"] + atol)
                   & (L["c_lo"] >= best["c_lo"] - tol * wc - atol) & (L["c_hi"] <= best["c_hi"] + tol * wc + atol))
        open_ = np.nonzero(~settled)[0]
        if open_.size == 0 or p == 0 or self.boxes + 2 > self.max_boxes:
            self.L = L
            self.result = self._finish(open_.size == 0)
            return
        # split the worst leaves first (best-first search, a few per round), along the parameter
        # whose remainder exceeds the linear part most, for the bound that is furthest off
        re, rd = L["e"] / max(best["drift"], atol), L["d"] / max(best["step"], atol)
        excess = np.maximum(re, rd)[open_]
        take = open_[np.argsort(-excess, kind="stable")][: max(1, min(_SPLITS, (self.max_boxes - self.boxes) // 2))]
        keep = np.setdiff1d(np.arange(len(L["e"])), take)
        sl, sh = L["lo"][take], L["hi"][take]
        by_d = (rd > re)[take]
        axis = np.argmax(np.where(by_d[:, None], L["score_d"][take], L["score_e"][take]), axis=1)
        rows = np.arange(len(take))
        mid = I.midpoint(sl[rows, axis], sh[rows, axis])
        left_hi, right_lo = sh.copy(), sl.copy()
        left_hi[rows, axis] = mid
        right_lo[rows, axis] = mid
        self.blo, self.bhi = np.concatenate([sl, right_lo]), np.concatenate([left_hi, sh])
        self.Uparent = (np.concatenate([L["U"][0][take]] * 2), np.concatenate([L["U"][1][take]] * 2))
        self.L = {k: (v[0][keep], v[1][keep]) if k == "U" else v[keep] for k, v in L.items()}

    def _finish(self, converged: bool):
        L = self.L
        if not all(np.all(np.isfinite(L[k])) for k in ("e", "d", "c_lo", "c_hi")):
            # a NaN would vanish in max() below: no bound is claimed from a leaf that is not finite
            return "a bound over a sub-box of [xi] is not finite (the enclosures diverged): not proved"
        return {"e": float(L["e"].max()), "d": float(L["d"].max()), "c_lo": float(L["c_lo"].min()),
                "c_hi": float(L["c_hi"].max()), "boxes": self.boxes, "converged": converged, "found": self.best}


def _cat(a, b):
    if isinstance(a, tuple):
        return (np.concatenate([a[0], b[0]]), np.concatenate([a[1], b[1]]))
    return np.concatenate([a, b])


#: Leaves split per round of the branch and bound, worst first (best-first search, batched a little).
_SPLITS = 4

#: Proofs of recent plans: a plan's class depends only on the plan and the robot (the speed
#: search at the robot's own a_max asks again for plans already proved).
_CACHE: dict = {}
_CACHE_SIZE = 64


def prove_cartesian_class_cached(robot, x_path, q_plan, xi_plan) -> ClassProof:
    """:func:`prove_cartesian_class` with its defaults, remembered per robot and plan (exact bytes)."""
    xs = list(x_path) if isinstance(x_path, (list, tuple)) else [x_path]
    qs = list(q_plan) if isinstance(q_plan, (list, tuple)) else [q_plan]
    key = (id(robot), robot.name, tuple(np.asarray(a, float).tobytes() for a in (*xs, *qs, xi_plan)))
    hit = _CACHE.get(key)
    if hit is not None and hit[0] is robot:
        return hit[1]
    proof = prove_cartesian_class(robot, xs, qs, xi_plan)
    if len(_CACHE) >= _CACHE_SIZE:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = (robot, proof)
    return proof


def describe(cls: ExecutionClass, joint_unit: str = "joint units") -> str:
    """One line about how the class's bounds were obtained (``crosscert certify`` prints it)."""
    if cls.kind is not ExecutionKind.CARTESIAN:
        return f"execution class: {cls.kind.value} (stated, nothing derived)"
    e, d = cls.drift, cls.drift_per_sample
    if cls.proved:
        pr = cls.proof
        return (f"execution class: cartesian, C, e and d proved for every geometry of [xi] (interval branch and "
                f"bound, {pr.get('boxes_explored')} boxes, {pr.get('time_s', 0.0):.2f} s): e = {e:.4g}, d = {d:.4g} "
                f"per sample ({joint_unit})")
    return (f"execution class: cartesian, C, e and d measured on sampled geometries, NOT proved "
            f"({cls.proof.get('reason', 'no proof')}): e = {e:.4g}, d = {d:.4g} per sample ({joint_unit})")


def proved_class(robot, proof: ClassProof, xi_plan, eps_q: float, tracking_error: float = 0.0) -> ExecutionClass:
    """The ``cartesian`` :class:`ExecutionClass` of a successful proof.

    ``C`` is ``delta_plan`` plus the proved constant range, outward rounded,
    and hulled with the robot's own offset intervals (as the measured class:
    the certifying run never assumes a narrower offset box than the run-time
    tracker has to); ``e`` and ``d`` as proved; nothing is widened by a
    safety factor.
    """
    if not proof.proved:
        raise InputError(f"proved_class needs a successful proof, got one not proved: {proof.reason}")
    xi_plan = np.asarray(xi_plan, float)
    lo, hi = robot.xi_lo_array.copy(), robot.xi_hi_array.copy()
    for i, j in _offsets(robot).items():
        cl, ch = I.add(xi_plan[j], xi_plan[j], proof.c_lo[i], proof.c_hi[i])
        lo[j], hi[j] = min(float(cl), lo[j]), max(float(ch), hi[j])
    fast = joint_error(eps_q, tracking_error)
    reading = float(I.add(fast, fast, proof.drift, proof.drift)[1])
    derivation = {
        "constant_range": [[float(a), float(b)] for a, b in zip(proof.c_lo, proof.c_hi)],
        "largest_drift": proof.drift,
        "largest_step": proof.step,
        "largest_drift_found": proof.found.get("drift"),
        "largest_step_found": proof.found.get("step"),
        "offset_box": "hull of the proved constants and the robot's offset intervals",
    }
    return ExecutionClass(ExecutionKind.CARTESIAN, reading, proof.drift, lo, hi, derivation, fast, proof.step,
                          proved=True, proof=proof.summary())


def with_proof_failure(cls: ExecutionClass, proof: ClassProof) -> ExecutionClass:
    """A measured class marked ``proved: false`` with the proof's reason."""
    return replace(cls, proved=False, proof=proof.summary())


def execution_class(kin, plans, bounds) -> ExecutionClass:
    """The admissible executions of one plan or a list of plans (union of their paths) under ``bounds``
    (:class:`planner.task.PlanningBounds`).

    See :mod:`planner.execution`; ``cartesian`` classes are proved over the
    whole box ``[xi]`` (:mod:`planner.execution_proof`) and, when the proof
    is not available for the robot's model, measured on sampled geometries
    (seeded, deterministic) and marked ``proved: false`` with the reason.
    """
    robot = kin.robot
    b = bounds.for_robot(robot)
    if b.execution is ExecutionKind.JOINT:
        return joint_class(robot, b.eps_q, b.tracking_error)
    plans = [plans] if isinstance(plans, PlannedTrajectory) else list(plans)
    xs, qs = [p.x for p in plans], [p.q for p in plans]
    proof = prove_cartesian_class_cached(robot, xs, qs, plans[0].xi_plan)
    if proof.proved:
        return proved_class(robot, proof, plans[0].xi_plan, b.eps_q, b.tracking_error)
    return with_proof_failure(cartesian_class(kin, xs, qs, plans[0].xi_plan, b.eps_q, b.tracking_error), proof)
