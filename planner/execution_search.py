"""Steps 2 to 4 of the proof of the ``cartesian`` execution class over ``[xi]``: the search.

The argument is :mod:`planner.execution_proof`'s (its docstring, and
docs/soundness.md, "The execution class of a certificate"); this module
holds its machinery, for one planned path at a time: the loop closure
written in the effective joints (:func:`loop_closure_tapes`), the root
boxes proved along the path and the slope changes between samples
(:func:`setup_path`, step 2), the mean-value bounds of ``C``, ``e`` and
``d`` on a sub-box of the free parameters (``_Path.evaluate``, step 3), and
the branch and bound over ``[xi]``, one search per joint run in lockstep
(:func:`branch_and_bound_joints`, step 4).  Nothing here names a robot.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from crosscert.verifier import interval as I
from crosscert.verifier.implicit import (ImplicitTapes, contract_roots, inflate_roots, krawczyk, root_gradient,
                                         slope_change, strictly_inside)
from crosscert.verifier.linalg import imat_ivec

__all__ = ["offset_split", "loop_closure_tapes", "offset_joints", "setup_path", "branch_and_bound_joints"]


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
def loop_closure_tapes(robot):
    """Tapes of the loop closure in the effective joints and the free parameters, or why there are none."""
    x = ca.SX.sym("x", robot.n)
    u = ca.SX.sym("u", robot.n)
    xi = ca.SX.sym("xi", robot.m)
    offs = offset_joints(robot)
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
    # the tapes and the linear systems by the compiled kernels: numpy's floats (benchmarks/README.md: the proof
    # in about 0.6 of the time)
    return (ImplicitTapes(x, u, xi, g, free, compiled=True), free, numeric), ""


def offset_joints(robot) -> dict[int, int]:
    """Joint index -> index in ``xi`` of its offset parameter, for the joints that have one (``Robot.joint_offsets``)."""
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
        self.off = np.array([i in offset_joints(robot) for i in range(self.n)])
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


def setup_path(tapes, numeric, robot, free, x, u_plan, remainder):
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



def _branch_and_bound(path: _Path, tol: float, max_boxes: int, i: int):
    """Step 4 on one path for joint ``i``: a dict of proved bounds, or the reason (str) why nothing is proved."""
    return branch_and_bound_joints(path, tol, max_boxes, [i])[0]


def branch_and_bound_joints(path: _Path, tol: float, max_boxes: int, joints) -> list:
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
    """Step 4 on one path for joint ``i``, one round per :meth:`advance` (:func:`branch_and_bound_joints`).

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
