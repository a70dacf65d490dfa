"""Kinematic model derived once, symbolically, from a robot's loop-closure equations.

:class:`KinematicModel` turns :attr:`Robot.loop_closure` into CasADi SX
expressions (``f``, ``J_x = df/dx``, ``J_q = df/dq``, ``det J_x``) and CasADi
Functions, and offers float (numpy) solvers used by the simulator and the
tests: damped-Newton IK and FK, all FK solutions, the assembly mode, IK by
continuation along a path, and the first/second-order joint kinematics.

Shapes: a pose ``x`` and joints ``q`` are ``(n,)``, parameters ``xi`` are
``(m,)``; batched variants take ``(N, n)`` arrays (one row per point) and one
shared ``xi``.  Units are SI (m, rad, s).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .errors import ModelError, SimulationError

from .base import Robot

__all__ = ["KinematicModel", "RESIDUAL_TOL"]

#: Absolute residual ``max_i |f_i|`` at which the Newton solvers stop.
RESIDUAL_TOL = 1e-13
#: A Jacobian whose smallest singular value is below this fraction of the
#: largest singular value of ``[J_x, J_q]`` is treated as singular.
SINGULAR_RTOL = 1e-9
#: ``|det J_x|`` below this fraction of Hadamard's bound (product of the row
#: norms of ``J_x``) gives assembly mode 0 (on the Type 2 singular locus).
MODE_RTOL = 1e-10
#: Full Newton steps taken after the residual tolerance is met.
_POLISH_STEPS = 2


class KinematicModel:
    """Symbolic and numeric kinematics of a :class:`~robots.base.Robot`.

    Built once; immutable afterwards.  All quantities derive from the single
    definition ``robot.loop_closure``.

    Parameters
    ----------
    robot : Robot
        The robot description.

    Attributes
    ----------
    robot : Robot
    n, m : int
        Pose/joint dimension and number of geometric parameters.
    sx_x, sx_q, sx_xi : casadi.SX
        Symbols: pose ``(n, 1)``, joints ``(n, 1)``, parameters ``(m, 1)``.
    sx_f : casadi.SX
        Loop-closure residual ``(n, 1)``.
    sx_jx, sx_jq : casadi.SX
        ``df/dx`` and ``df/dq``, each ``(n, n)``.
    sx_det : casadi.SX
        ``det J_x`` ``(1, 1)``.
    sx_mode : casadi.SX
        ``mode_sign * det J_x`` ``(1, 1)``: positive in assembly mode +1.
    sx_hadamard : casadi.SX
        ``prod_i ||row_i J_x||`` ``(1, 1)``, Hadamard's bound on ``|det J_x|``;
        ``sx_mode / sx_hadamard`` is the normalised mode, dimensionless in [-1, 1].
    sx_xd, sx_qd : casadi.SX
        Velocity symbols ``(n, 1)`` used by :attr:`jdot_term`.
    sx_jdot : casadi.SX
        ``(dJ_x/dt) x' + (dJ_q/dt) q'`` ``(n, 1)``: the second-order term of
        the time derivative of eq. (2).
    f, jac_x, jac_q, det_jx, mode_value : casadi.Function
        ``(x, q, xi) ->`` the corresponding expression.
    jdot_term : casadi.Function
        ``(x, q, xi, xd, qd) -> sx_jdot``.

    Raises
    ------
    ModelError
        If ``loop_closure`` fails on symbols, returns the wrong shape, uses
        symbols other than its arguments, or has a structurally singular
        ``J_x`` or ``J_q``.
    """

    def __init__(self, robot: Robot) -> None:
        if not isinstance(robot, Robot):
            raise ModelError(f"KinematicModel needs a Robot, got {type(robot).__name__}")
        n, m = robot.n, robot.m
        x = ca.SX.sym("x", n)
        q = ca.SX.sym("q", n)
        xi = ca.SX.sym("xi", m)
        try:
            f = robot.loop_closure(x, q, xi)
        except Exception as exc:  # any failure of user code is a model defect
            raise ModelError(f"Robot {robot.name}: loop_closure failed on CasADi symbols: {exc}") from exc
        if isinstance(f, (list, tuple)):
            f = ca.vertcat(*f)
        if not isinstance(f, ca.SX):
            raise ModelError(
                f"Robot {robot.name}: loop_closure must return casadi.SX, got {type(f).__name__}"
            )
        if f.shape == (1, n):
            f = f.T
        if f.shape != (n, 1):
            raise ModelError(f"Robot {robot.name}: loop_closure returned shape {f.shape}, expected ({n}, 1)")
        try:
            f_fun = ca.Function("f", [x, q, xi], [f], ["x", "q", "xi"], ["f"])
        except RuntimeError as exc:
            raise ModelError(
                f"Robot {robot.name}: loop_closure uses symbols other than (x, q, xi)"
            ) from exc
        jx = ca.jacobian(f, x)
        jq = ca.jacobian(f, q)
        for nm, jac in (("J_x", jx), ("J_q", jq)):
            if ca.sprank(jac.sparsity()) < n:
                raise ModelError(f"Robot {robot.name}: {nm} is structurally singular")
        det = ca.det(jx)
        mode_expr = robot.mode_sign * det
        hadamard = 1
        for i in range(n):
            hadamard = hadamard * ca.norm_2(jx[i, :])
        xd = ca.SX.sym("xd", n)
        qd = ca.SX.sym("qd", n)
        # d/dt(J_x xd + J_q qd) with xd, qd frozen = directional derivative along (xd, qd).
        jdot = ca.jtimes(ca.mtimes(jx, xd) + ca.mtimes(jq, qd), ca.vertcat(x, q), ca.vertcat(xd, qd))

        ins, names = [x, q, xi], ["x", "q", "xi"]
        d = self.__dict__
        d["robot"] = robot
        d["n"], d["m"] = n, m
        d["sx_x"], d["sx_q"], d["sx_xi"] = x, q, xi
        d["sx_f"], d["sx_jx"], d["sx_jq"], d["sx_det"] = f, jx, jq, det
        d["sx_mode"], d["sx_xd"], d["sx_qd"], d["sx_jdot"] = mode_expr, xd, qd, jdot
        d["sx_hadamard"] = hadamard
        d["f"] = f_fun
        d["jac_x"] = ca.Function("jac_x", ins, [jx], names, ["jx"])
        d["jac_q"] = ca.Function("jac_q", ins, [jq], names, ["jq"])
        d["det_jx"] = ca.Function("det_jx", ins, [det], names, ["det"])
        d["normalised_mode"] = ca.Function("normalised_mode", ins, [mode_expr / hadamard], names, ["mode"])
        d["mode_value"] = ca.Function("mode_value", ins, [mode_expr], names, ["mode"])
        d["jdot_term"] = ca.Function("jdot_term", ins + [xd, qd], [jdot], names + ["xd", "qd"], ["jdot"])
        # Fused evaluations for the Newton loops (one CasADi call per iteration).
        d["_f_jq"] = ca.Function("f_jq", ins, [f, jq])
        d["_f_jx"] = ca.Function("f_jx", ins, [f, jx])
        d["_jx_jq"] = ca.Function("jx_jq", ins, [jx, jq])
        d["_frozen"] = True

    def __setattr__(self, name, value):
        raise AttributeError("KinematicModel is immutable")

    def __delattr__(self, name):
        raise AttributeError("KinematicModel is immutable")

    def __repr__(self) -> str:
        return f"KinematicModel({self.robot.name!r}, n={self.n}, m={self.m})"

    # ------------------------------------------------------------ batching
    def _xi(self, xi) -> np.ndarray:
        xi = np.asarray(xi, dtype=float).reshape(-1)
        if xi.shape != (self.m,):
            raise ModelError(f"xi must have shape ({self.m},), got {xi.shape}")
        return xi

    def _rows(self, a, what: str) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        if a.ndim == 1:
            a = a[None, :]
        if a.ndim != 2 or a.shape[1] != self.n:
            raise ModelError(f"{what} must have shape (N, {self.n}), got {np.shape(a)}")
        return a

    def _call(self, fun: ca.Function, *args) -> list[np.ndarray]:
        """Evaluate ``fun`` at N points: args are (N, k) row arrays or shared 1-D xi.

        CasADi maps a Function over horizontally concatenated arguments, so one
        call serves the whole batch.  Returns, per output, an array of shape
        ``(N, rows)`` for column outputs or ``(N, rows, cols)`` for matrices.
        """
        npts = max(a.shape[0] for a in args if a.ndim == 2)
        cas_args = [a.T if a.ndim == 2 else a for a in args]
        res = fun(*cas_args)
        if not isinstance(res, (list, tuple)):
            res = [res]
        out = []
        for k, r in enumerate(res):
            r = np.asarray(r, dtype=float)
            rows = fun.size1_out(k)
            cols = fun.size2_out(k)
            r = r.reshape(rows, npts, cols).transpose(1, 0, 2)
            out.append(r[:, :, 0] if cols == 1 else r)
        return out

    def f_batch(self, X, Q, xi) -> np.ndarray:
        """Residuals ``f`` at N points. X, Q: (N, n); xi: (m,). Returns (N, n)."""
        return self._call(self.f, self._rows(X, "X"), self._rows(Q, "Q"), self._xi(xi))[0]

    def jac_x_batch(self, X, Q, xi) -> np.ndarray:
        """``J_x`` at N points. X, Q: (N, n); xi: (m,). Returns (N, n, n)."""
        return self._call(self.jac_x, self._rows(X, "X"), self._rows(Q, "Q"), self._xi(xi))[0].reshape(-1, self.n, self.n)

    def jac_q_batch(self, X, Q, xi) -> np.ndarray:
        """``J_q`` at N points. X, Q: (N, n); xi: (m,). Returns (N, n, n)."""
        return self._call(self.jac_q, self._rows(X, "X"), self._rows(Q, "Q"), self._xi(xi))[0].reshape(-1, self.n, self.n)

    def det_batch(self, X, Q, xi) -> np.ndarray:
        """``det J_x`` at N points. X, Q: (N, n); xi: (m,). Returns (N,)."""
        return self._call(self.det_jx, self._rows(X, "X"), self._rows(Q, "Q"), self._xi(xi))[0][:, 0]

    def normalised_mode_batch(self, X, Q, xi) -> np.ndarray:
        """``mode_sign * det J_x / prod_i ||row_i J_x||`` at N points, (N,).

        Dimensionless and in [-1, 1] by Hadamard's inequality; 0 on the Type 2
        locus, NaN where a row of ``J_x`` vanishes.  X, Q: (N, n); xi: (m,).
        """
        with np.errstate(invalid="ignore", divide="ignore"):
            return self._call(self.normalised_mode, self._rows(X, "X"), self._rows(Q, "Q"), self._xi(xi))[0][:, 0]

    def mode_batch(self, X, Q, xi, *, rtol: float = MODE_RTOL) -> np.ndarray:
        """Assembly modes at N points, int array (N,) of +1, -1 or 0.

        0 is returned where the normalised mode (:meth:`normalised_mode_batch`,
        ``|det J_x|`` over Hadamard's bound) is at most ``rtol``, i.e. on the
        singular locus up to rounding.
        """
        nm = self.normalised_mode_batch(X, Q, xi)
        sgn = np.sign(nm)
        sgn[~(np.abs(nm) > rtol)] = 0.0
        return sgn.astype(int)

    def mode(self, x, q, xi, *, rtol: float = MODE_RTOL) -> int:
        """Assembly mode ``mode_sign * sign(det J_x)`` at one point: +1, -1, or 0 on the locus.

        Parameters
        ----------
        x, q : array_like, shape (n,)
            Pose (SI) and joints (rad) satisfying ``f(x, q, xi) = 0``.
        xi : array_like, shape (m,)
        rtol : float
            Relative threshold of ``|det J_x|`` (see :meth:`mode_batch`).
        """
        return int(self.mode_batch(x, q, xi, rtol=rtol)[0])

    # ------------------------------------------------------------- Newton
    def _newton(self, solve_q: bool, Z0, W, xi, *, tol, max_iter, max_step):
        """Damped Newton on ``f`` in q (``solve_q``) or x, batched over rows.

        Returns ``(Z, resid, ok)``: solutions (N, n), final ``max|f|`` (N,) and
        a convergence mask.  Steps are clipped to ``max_step`` (inf-norm) and
        halved until the residual decreases, so a guess keeps its branch.
        """
        fun = self._f_jq if solve_q else self._f_jx
        Z = np.array(Z0, dtype=float, copy=True)
        W = np.asarray(W, dtype=float)

        def ev(Zr, Wr):
            Xr, Qr = (Wr, Zr) if solve_q else (Zr, Wr)
            F, J = self._call(fun, Xr, Qr, xi)
            return F, J.reshape(-1, self.n, self.n)

        F, J = ev(Z, W)
        r = np.max(np.abs(F), axis=1)
        r[~np.isfinite(r)] = np.inf
        polish = np.zeros(r.shape, dtype=int)
        live = np.ones(r.shape, dtype=bool)
        for _ in range(max_iter + _POLISH_STEPS):
            # Rows below tol take _POLISH_STEPS more full steps: reaching tol
            # leaves up to tol/|J| of error that one quadratic step removes.
            act = np.nonzero(live & ((r >= tol) | (polish < _POLISH_STEPS)))[0]
            if act.size == 0:
                break
            Ja, Fa = J[act], F[act]
            step = np.zeros_like(Fa)
            good = np.isfinite(Ja).all(axis=(1, 2)) & np.isfinite(Fa).all(axis=1)
            gi = np.nonzero(good)[0]
            try:  # one stacked solve; row by row only when a matrix is singular
                step[gi] = np.linalg.solve(Ja[gi], -Fa[gi][:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:
                for i in gi:
                    try:
                        step[i] = np.linalg.solve(Ja[i], -Fa[i])
                    except np.linalg.LinAlgError:
                        step[i] = np.linalg.lstsq(Ja[i], -Fa[i], rcond=None)[0]
            size = np.max(np.abs(step), axis=1)
            clip = np.where(size > max_step, max_step / np.maximum(size, 1e-300), 1.0)
            step *= clip[:, None]
            conv = r[act] < tol
            t = np.ones(act.size)
            pending = good.copy()
            for _ls in range(30):
                idx = np.nonzero(pending)[0]
                if idx.size == 0:
                    break
                Zt = Z[act[idx]] + t[idx, None] * step[idx]
                Ft, Jt = ev(Zt, W[act[idx]])
                rt = np.max(np.abs(Ft), axis=1)
                rt[~np.isfinite(rt)] = np.inf
                r_old = r[act[idx]]
                acc = np.where(conv[idx], rt <= r_old, rt < r_old)
                sel = act[idx[acc]]
                Z[sel], F[sel], J[sel], r[sel] = Zt[acc], Ft[acc], Jt[acc], rt[acc]
                pending[idx[acc]] = False
                pending[idx[conv[idx]]] = False  # polishing: one full step only
                t[idx[~acc]] *= 0.5
            polish[act[conv]] += 1
            # A non-converged row whose line search found no decrease is stuck.
            live[act[~conv & pending]] = False
            live[act[~conv & ~good]] = False
        return Z, r, r < tol

    def _nonsingular(self, X, Q, xi, which: str) -> np.ndarray:
        """Mask (N,) of points where J_q (``which="q"``) or J_x is numerically regular."""
        jx, jq = self._call(self._jx_jq, X, Q, xi)
        jx = jx.reshape(-1, self.n, self.n)
        jq = jq.reshape(-1, self.n, self.n)
        big = np.linalg.norm(np.concatenate([jx, jq], axis=2), ord=2, axis=(1, 2))
        target = jq if which == "q" else jx
        small = np.linalg.svd(target, compute_uv=False)[:, -1]
        return small > SINGULAR_RTOL * big

    def ik_batch(self, X, xi, Q_guess, *, tol: float = RESIDUAL_TOL, max_iter: int = 60,
                 max_step: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
        """Inverse kinematics at N poses, each from its own guess, without raising.

        Parameters
        ----------
        X : array_like, shape (N, n)
            Poses, SI.
        xi : array_like, shape (m,)
        Q_guess : array_like, shape (N, n)
            Newton starting joints, rad; select the leg branches.
        tol, max_iter, max_step
            Residual tolerance, iteration cap, largest Newton step (rad).

        Returns
        -------
        Q : ndarray, shape (N, n)
            Joints, rad.
        ok : ndarray of bool, shape (N,)
            Converged to ``max|f| < tol`` with ``J_q`` regular.
        """
        X, Qg, xi = self._rows(X, "X"), self._rows(Q_guess, "Q_guess"), self._xi(xi)
        if Qg.shape != X.shape:
            raise ModelError(f"Q_guess shape {Qg.shape} differs from X shape {X.shape}")
        Q, _r, ok = self._newton(True, Qg, X, xi, tol=tol, max_iter=max_iter, max_step=max_step)
        if ok.any():
            ok[ok] = self._nonsingular(X[ok], Q[ok], xi, "q")
        return Q, ok

    def ik(self, x, xi, q_guess, *, tol: float = RESIDUAL_TOL, max_iter: int = 60,
           max_step: float = 0.3) -> np.ndarray:
        """Inverse kinematics: joints ``q`` (n,) rad with ``f(x, q, xi) = 0``.

        Damped Newton in ``q`` from ``q_guess``; the guess selects the branch
        (working mode of the legs).

        Parameters
        ----------
        x : array_like, shape (n,)
            Pose, SI.
        xi : array_like, shape (m,)
            Geometric parameters, SI.
        q_guess : array_like, shape (n,)
            Starting joints, rad.

        Raises
        ------
        SimulationError
            If Newton does not reach ``max|f| < tol`` (pose unreachable) or
            ``J_q`` is singular at the solution (Type 1 singularity).
        """
        x = np.asarray(x, dtype=float).reshape(-1)
        Q, ok = self.ik_batch(x[None, :], xi, np.asarray(q_guess, dtype=float).reshape(1, -1),
                              tol=tol, max_iter=max_iter, max_step=max_step)
        if not ok[0]:
            raise SimulationError(
                f"{self.robot.name}: IK failed at x = {x.tolist()} from q_guess = "
                f"{np.asarray(q_guess).tolist()} (pose unreachable, or J_q singular there)"
            )
        return Q[0]

    def fk_batch(self, Q, xi, X_guess, *, tol: float = RESIDUAL_TOL, max_iter: int = 60,
                 max_step: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics at N joint vectors from N guesses, without raising.

        Parameters
        ----------
        Q : array_like, shape (N, n)
            Joints, rad.
        xi : array_like, shape (m,)
        X_guess : array_like, shape (N, n)
            Newton starting poses, SI; select the assembly mode.
        max_step : float, optional
            Largest Newton step (inf-norm, SI); default a quarter of the
            smallest side of ``robot.x_bounds``.

        Returns
        -------
        X : ndarray, shape (N, n)
        ok : ndarray of bool, shape (N,)
            Converged to ``max|f| < tol`` with ``J_x`` regular.
        """
        Q, Xg, xi = self._rows(Q, "Q"), self._rows(X_guess, "X_guess"), self._xi(xi)
        if Xg.shape != Q.shape:
            raise ModelError(f"X_guess shape {Xg.shape} differs from Q shape {Q.shape}")
        if max_step is None:
            max_step = 0.25 * float(np.min(self.robot.x_hi_array - self.robot.x_lo_array))
        X, _r, ok = self._newton(False, Xg, Q, xi, tol=tol, max_iter=max_iter, max_step=max_step)
        if ok.any():
            ok[ok] = self._nonsingular(X[ok], Q[ok], xi, "x")
        return X, ok

    def fk(self, q, xi, x_guess, *, tol: float = RESIDUAL_TOL, max_iter: int = 60) -> np.ndarray:
        """Forward kinematics: pose ``x`` (n,) SI with ``f(x, q, xi) = 0``, by Newton from ``x_guess``.

        Raises
        ------
        SimulationError
            If Newton does not converge or ``J_x`` is singular at the solution.
        """
        q = np.asarray(q, dtype=float).reshape(-1)
        X, ok = self.fk_batch(q[None, :], xi, np.asarray(x_guess, dtype=float).reshape(1, -1),
                              tol=tol, max_iter=max_iter)
        if not ok[0]:
            raise SimulationError(
                f"{self.robot.name}: FK failed at q = {q.tolist()} from x_guess = "
                f"{np.asarray(x_guess).tolist()} (no nearby solution, or J_x singular)"
            )
        return X[0]

    def fk_all(self, q, xi, *, grid: int = 9, dedup_tol: float = 1e-9) -> np.ndarray:
        """All distinct real FK solutions found by multi-start Newton.

        Starts on a ``grid**n`` lattice of cell centres of ``robot.x_bounds``.
        Solutions where ``J_x`` is singular (double roots) are not returned.

        Parameters
        ----------
        q : array_like, shape (n,)
            Joints, rad.
        xi : array_like, shape (m,)
        grid : int
            Starts per pose coordinate.
        dedup_tol : float
            Solutions closer than this (inf-norm, SI) are merged.

        Returns
        -------
        ndarray, shape (k, n)
            Solutions sorted lexicographically (first coordinate first).
        """
        q = np.asarray(q, dtype=float).reshape(-1)
        lo, hi = self.robot.x_lo_array, self.robot.x_hi_array
        axes = [lo[i] + (hi[i] - lo[i]) * (np.arange(grid) + 0.5) / grid for i in range(self.n)]
        starts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, self.n)
        X, ok = self.fk_batch(np.tile(q, (starts.shape[0], 1)), xi, starts)
        X = X[ok]
        X = X[np.lexsort(X.T[::-1])] if X.size else X.reshape(0, self.n)
        sols: list[np.ndarray] = []
        for row in X:
            if not any(np.max(np.abs(row - s)) <= dedup_tol for s in sols):
                sols.append(row)
        return np.array(sols, dtype=float).reshape(-1, self.n)

    def ik_path(self, X, xi, q0_guess, *, tol: float = RESIDUAL_TOL, spacing: float = 2e-3) -> np.ndarray:
        """IK along a path by continuation.

        Anchors are the first pose and each pose at least ``spacing`` away
        (inf-norm, pose units) from the previous anchor; each anchor is solved
        from the previous anchor's joints, then every pose in one batch from
        its last anchor's joints (less than ``spacing`` away), so Newton stays
        on the branch as a pose-by-pose continuation would.

        Parameters
        ----------
        X : array_like, shape (N, n)
            Consecutive poses, SI, close enough for Newton to stay on the branch.
        xi : array_like, shape (m,)
        q0_guess : array_like, shape (n,)
            Guess for the first pose, rad.
        spacing : float
            Largest continuation step between anchors, pose units (m).

        Returns
        -------
        ndarray, shape (N, n)
            Joints, rad.

        Raises
        ------
        SimulationError
            At the first pose where IK fails (index reported).
        """
        X, xi = self._rows(X, "X"), self._xi(xi)
        N = X.shape[0]
        owner = np.zeros(N, dtype=int)
        anchors = [0]
        for k in range(1, N):
            if np.max(np.abs(X[k] - X[anchors[-1]])) >= spacing:
                anchors.append(k)
            owner[k] = anchors[-1]
        QA = np.empty((len(anchors), self.n))
        guess = np.asarray(q0_guess, dtype=float).reshape(1, -1)
        for i, k in enumerate(anchors):
            Qk, ok = self.ik_batch(X[k:k + 1], xi, guess, tol=tol)
            if not ok[0]:
                raise SimulationError(
                    f"{self.robot.name}: IK continuation failed at path point {k}, x = {X[k].tolist()}"
                )
            QA[i] = Qk[0]
            guess = Qk
        slot = np.searchsorted(anchors, owner)
        Q, ok = self.ik_batch(X, xi, QA[slot], tol=tol)
        if not np.all(ok):
            k = int(np.nonzero(~ok)[0][0])
            raise SimulationError(f"{self.robot.name}: IK continuation failed at path point {k}, x = {X[k].tolist()}")
        return Q

    # ------------------------------------------------------ differential
    def joint_velocity(self, X, Q, xi, XD) -> np.ndarray:
        """Joint velocities from eq. (2): ``q' = -J_q^{-1} J_x x'``.

        X, Q, XD: (N, n) poses (SI), joints (rad), pose velocities (SI/s);
        xi: (m,).  Returns (N, n) rad/s.  Valid wherever ``J_q`` is regular,
        including on the Type 2 locus.
        """
        X, Q, XD, xi = self._rows(X, "X"), self._rows(Q, "Q"), self._rows(XD, "XD"), self._xi(xi)
        jx, jq = self._call(self._jx_jq, X, Q, xi)
        jx, jq = jx.reshape(-1, self.n, self.n), jq.reshape(-1, self.n, self.n)
        return -np.linalg.solve(jq, np.einsum("kij,kj->ki", jx, XD)[..., None])[..., 0]

    def joint_acceleration(self, X, Q, xi, XD, QD, XDD) -> np.ndarray:
        """Joint accelerations from the time derivative of eq. (2).

        ``J_x x'' + J_q q'' + (J_x' x' + J_q' q') = 0`` with the last term from
        :attr:`jdot_term` (exact, by CasADi AD).  All arrays (N, n) in SI;
        xi (m,).  Returns (N, n) rad/s^2.
        """
        X, Q, xi = self._rows(X, "X"), self._rows(Q, "Q"), self._xi(xi)
        XD, QD, XDD = self._rows(XD, "XD"), self._rows(QD, "QD"), self._rows(XDD, "XDD")
        jx, jq = self._call(self._jx_jq, X, Q, xi)
        jx, jq = jx.reshape(-1, self.n, self.n), jq.reshape(-1, self.n, self.n)
        h = self._call(self.jdot_term, X, Q, xi, XD, QD)[0]
        rhs = np.einsum("kij,kj->ki", jx, XDD) + h
        return -np.linalg.solve(jq, rhs[..., None])[..., 0]
