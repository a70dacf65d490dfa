"""Lumped-mass inverse dynamics of a parallel robot, and the Type 2 crossing criterion.

A :class:`~robots.mass_model.LumpedMassModel` is *data*: point masses at named points whose
positions are a CasADi-compatible function of ``(x, q, xi)``, the reflected
inertias of the motors, a gravity vector and the actuator torque limits.  A
user replaces the DexTAR's assumed values (:data:`DEXTAR_DYNAMICS`) by
building another instance; nothing else changes.

:class:`LumpedDynamics` derives, once and symbolically, the inverse dynamics
of such a model on a robot's kinematics (:class:`~robots.kinematics.KinematicModel`).
With generalised coordinates ``z = (x, q)`` (pose and actuated joints, both
``(n,)``) and the ``n`` loop-closure constraints ``f(x, q, xi) = 0`` (eq. (1)
of the paper) with multipliers ``lambda``, Lagrange's equations read

    ``w_x(z, zd, zdd) = J_x^T lambda``
    ``w_q(z, zd, zdd) = tau + J_q^T lambda``

where ``w = (w_x, w_q) = sum_j m_j P_j^T (pdd_j - g) + (0, I_m qdd)`` is the
generalised inertial-plus-gravity force, ``p_j`` the position of mass ``j``,
``P_j = dp_j/dz`` and ``pdd_j = P_j zdd + Pd_j zd`` its acceleration.  Hence

    ``tau = w_q - J_q^T J_x^{-T} w_x``                              (1)

away from Type 2 singularities.  On the Type 2 locus ``J_x`` has a right
null vector ``t_s`` (unit; the direction of the motion the locked actuators
do not control, ``J_x t_s = 0``), ``J_x^T lambda = w_x`` is solvable iff

    ``t_s^T w_x = 0``                                              (2)

which is the crossing criterion of Briot and Arakelian (ref. [11] of the
paper, Section III-B): the wrench the platform dynamics require must have no
component along the uncontrolled direction.  When every mass that moves with
``x`` is attached to the end-effector point itself (the DexTAR with its distal
links lumped at their ends), ``w_x = m_E (xdd - g)`` and (2) reduces to the
paper's statement: the end-effector acceleration (minus gravity) is normal to
the uncontrolled direction.

When (2) holds at the singular instant and the motion crosses the locus
transversally with a continuous jerk, the multipliers have a finite limit;
differentiating ``J_x^T lambda = w_x`` once in time and projecting on
``t_s`` gives one more equation, and ``lambda`` solves the square system

    ``(J_x^T + t_s (Jd_x t_s)^T) lambda = (I - t_s t_s^T) w_x + t_s (t_s^T wd_x)``   (3)

(:meth:`LumpedDynamics.singular_torques`), regular iff
``nu^T Jd_x t_s != 0`` for the left null vector ``nu`` of ``J_x`` (the
determinant changes sign at the crossing).  Equation (3) needs the jerk.

Units: SI (kg, m, rad, s, N, N m).  Shapes: ``x, q`` ``(n,)``; ``xi``
``(m,)``; positions of the ``P`` masses in ``d``-dimensional space, ``(d, P)``.
"""

from __future__ import annotations


import casadi as ca
import numpy as np

from .errors import InputError, ModelError

from .kinematics import KinematicModel
from .mass_model import LumpedMassModel

__all__ = [
    "LumpedMassModel",
    "LumpedDynamics",
    "uncontrolled_direction",
    "criterion_residual",
]

#: ``|det J_x|`` below this fraction of Hadamard's bound (product of the row
#: norms of ``J_x``): eq. (1) is not evaluated (torques reported as NaN).
SINGULAR_RTOL = 1e-12


# ---------------------------------------------------------------------- derivation
def _svd_null(jx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit right and left singular vectors of the smallest singular value, sign-normalised."""
    u, _s, vt = np.linalg.svd(jx)
    t, nu = vt[-1].copy(), u[:, -1].copy()
    for v in (t, nu):
        if v[np.argmax(np.abs(v))] < 0:
            v *= -1.0
    return t, nu


def uncontrolled_direction(kin: KinematicModel, x, q, xi) -> np.ndarray:
    """Unit direction ``t_s`` of the uncontrolled motion at a configuration.

    The right singular vector of the smallest singular value of ``J_x``: on
    the Type 2 locus, ``J_x t_s = 0`` (the end-effector can move along
    ``t_s`` with the actuators locked).  Its sign is fixed so that its
    largest-magnitude component is positive.

    Parameters
    ----------
    kin : KinematicModel
    x, q : array_like, shape (n,)
        Pose (SI) and joints (rad).
    xi : array_like, shape (m,)

    Returns
    -------
    ndarray, shape (n,)
    """
    jx = kin.jac_x_batch(np.asarray(x, float).reshape(1, -1), np.asarray(q, float).reshape(1, -1), xi)[0]
    return _svd_null(jx)[0]


class LumpedDynamics:
    """Inverse dynamics of a :class:`LumpedMassModel` on a robot's kinematics.

    Built once, symbolically (see the module docstring for the equations);
    immutable afterwards.  The numeric methods take one configuration
    (``(n,)`` arrays) or a batch (``(N, n)``) and one shared ``xi``.

    Parameters
    ----------
    kin : KinematicModel
    model : LumpedMassModel

    Attributes
    ----------
    kin : KinematicModel
    model : LumpedMassModel
    wrench_fun : casadi.Function
        ``(x, q, xd, qd, xdd, qdd, xi) -> (w_x, w_q)``, each ``(n, 1)``: the
        generalised inertial-plus-gravity forces, N (per unit of ``x``) and
        N m (per rad of ``q``).
    rates_fun : casadi.Function
        ``(x, q, xd, xdd, xi) -> (qd, qdd)``: joint rates from eq. (2) and its
        derivative, ``J_q`` inverted (regular away from Type 1 singularities).
    reduced_wrench_fun : casadi.Function
        ``(x, q, xd, xdd, xi) -> (w_x, w_q)`` with the joint rates eliminated.
    torque_fun : casadi.Function
        ``(x, q, xd, xdd, xi) -> tau`` ``(n, 1)``, N m, eq. (1); undefined on
        the Type 2 locus.
    singular_torque_fun : casadi.Function
        ``(x, q, xd, xdd, xddd, xi, t) -> (tau, lambda)``: eq. (3) with the
        uncontrolled direction ``t`` (unit, ``(n, 1)``) as an input.

    Raises
    ------
    ModelError
        If the model is for another robot, has the wrong number of joints,
        or its positions have the wrong shape or use other symbols.
    """

    def __init__(self, kin: KinematicModel, model: LumpedMassModel) -> None:
        pos = _checked_positions(kin, model)
        n = kin.n
        x, q, xi = kin.sx_x, kin.sx_q, kin.sx_xi
        xd, qd = kin.sx_xd, kin.sx_qd
        xdd, qdd = ca.SX.sym("xdd", n), ca.SX.sym("qdd", n)
        xddd, qddd = ca.SX.sym("xddd", n), ca.SX.sym("qddd", n)
        w = _wrench(kin, model, pos, xdd, qdd)
        w_x, w_q = w[:n], w[n:]

        jx, jq = kin.sx_jx, kin.sx_jq
        qd_e, qdd_e, qddd_e, allv = _joint_rates(kin, xdd, qdd, xddd)

        def reduce(expr):
            """Eliminate qd, qdd (and qddd) in favour of pose rates."""
            expr = ca.substitute(expr, qddd, qddd_e)
            expr = ca.substitute(expr, qdd, qdd_e)
            return ca.substitute(expr, qd, qd_e)

        w_x_r, w_q_r = reduce(w_x), reduce(w_q)
        lam = ca.solve(jx.T, w_x_r)
        tau = w_q_r - ca.mtimes(jq.T, lam)

        # eq. (3): finite multipliers at the singular instant
        t, tau_s, lam_s = _singular_torque(kin, w, w_x_r, w_q_r, reduce, allv, xdd, qdd, xddd, qddd)

        names = ["x", "q", "xd", "xdd", "xi"]
        dct = self.__dict__
        dct["kin"], dct["model"] = kin, model
        dct["wrench_fun"] = ca.Function("wrench", [x, q, xd, qd, xdd, qdd, xi], [w_x, w_q],
                                        ["x", "q", "xd", "qd", "xdd", "qdd", "xi"], ["w_x", "w_q"])
        dct["rates_fun"] = ca.Function("rates", [x, q, xd, xdd, xi], [qd_e, qdd_e], names, ["qd", "qdd"])
        dct["reduced_wrench_fun"] = ca.Function("reduced_wrench", [x, q, xd, xdd, xi], [w_x_r, w_q_r], names,
                                                ["w_x", "w_q"])
        dct["torque_fun"] = ca.Function("torque", [x, q, xd, xdd, xi], [tau], names, ["tau"])
        dct["singular_torque_fun"] = ca.Function(
            "singular_torque", [x, q, xd, xdd, xddd, xi, t], [tau_s, lam_s],
            ["x", "q", "xd", "xdd", "xddd", "xi", "t"], ["tau", "lambda"])
        dct["_frozen"] = True

    def __setattr__(self, name, value):
        raise AttributeError("LumpedDynamics is immutable")

    def __delattr__(self, name):
        raise AttributeError("LumpedDynamics is immutable")

    def __repr__(self) -> str:
        return f"LumpedDynamics({self.kin.robot.name!r}, {len(self.model.masses)} masses)"

    # -------------------------------------------------------------- numeric
    def _rows(self, *arrays):
        out = [np.atleast_2d(np.asarray(a, dtype=float)) for a in arrays]
        for a in out:
            if a.ndim != 2 or a.shape[1] != self.kin.n:
                raise InputError(f"expected (N, {self.kin.n}) or ({self.kin.n},) arrays, got shape {a.shape}")
        npts = max(a.shape[0] for a in out)
        return [np.broadcast_to(a, (npts, self.kin.n)) for a in out], npts

    def _xi(self, xi) -> np.ndarray:
        xi = self.kin.robot.xi_nominal_array if xi is None else np.asarray(xi, dtype=float).reshape(-1)
        if xi.shape != (self.kin.m,):
            raise InputError(f"xi must have shape ({self.kin.m},), got {xi.shape}")
        return xi

    def _eval(self, fun: ca.Function, arrays, xi, extra=()):
        (arrs, npts) = self._rows(*arrays)
        args = [a.T for a in arrs] + [xi] + [np.asarray(e, float).reshape(-1, 1) for e in extra]
        res = fun.map(npts)(*args) if npts > 1 else fun(*args)
        if not isinstance(res, (list, tuple)):
            res = [res]
        return [np.asarray(r, dtype=float).T.reshape(npts, -1) for r in res]

    def joint_rates(self, x, q, xd, xdd, xi=None) -> tuple[np.ndarray, np.ndarray]:
        """Joint velocities (rad/s) and accelerations (rad/s^2), each ``(N, n)``, from pose rates (SI)."""
        qd, qdd = self._eval(self.rates_fun, (x, q, xd, xdd), self._xi(xi))
        return qd, qdd

    def wrench(self, x, q, xd, xdd, xi=None) -> tuple[np.ndarray, np.ndarray]:
        """Generalised forces ``(w_x, w_q)``, each ``(N, n)``: N (translational pose) and N m.

        ``w_x`` is the wrench the platform dynamics require along the pose
        coordinates, ``w_q`` the one along the joints (module docstring).
        """
        w_x, w_q = self._eval(self.reduced_wrench_fun, (x, q, xd, xdd), self._xi(xi))
        return w_x, w_q

    def criterion_residual(self, x, q, xd, xdd, xi=None, *, direction=None) -> np.ndarray:
        """``t_s^T w_x``: the component of the platform wrench along the uncontrolled direction, N.

        On the Type 2 locus the inverse dynamics are consistent iff it is 0
        (eq. (2) of the module docstring).  Off the locus ``t_s`` is the
        right singular vector of the smallest singular value of ``J_x``.

        Parameters
        ----------
        x, q, xd, xdd : array_like, shape (n,) or (N, n)
            Pose (m), joints (rad), pose velocity (m/s) and acceleration (m/s^2).
        xi : array_like, shape (m,), optional
            Geometry (default nominal).
        direction : array_like, shape (n,) or (N, n), optional
            Use this (normalised) ``t_s`` instead of the SVD of ``J_x``.

        Returns
        -------
        ndarray, shape (N,)
            Residual, N (for a translational pose and unit ``t_s``).
        """
        xi = self._xi(xi)
        (X, Q, XD, XDD), npts = self._rows(x, q, xd, xdd)
        w_x, _ = self.wrench(X, Q, XD, XDD, xi)
        if direction is None:
            jx = self.kin.jac_x_batch(X, Q, xi)
            T = np.array([_svd_null(j)[0] for j in jx])
        else:
            (T,), _ = self._rows(direction)
            T = np.broadcast_to(T, (npts, self.kin.n))
            norm = np.linalg.norm(T, axis=1, keepdims=True)
            if np.any(norm == 0):
                raise InputError("direction must be non-zero")
            T = T / norm
        return np.einsum("ki,ki->k", T, w_x)

    def is_singular(self, x, q, xi=None, *, rtol: float = SINGULAR_RTOL) -> np.ndarray:
        """Mask ``(N,)``: ``|det J_x|`` below ``rtol`` times the product of its row norms."""
        (X, Q), _ = self._rows(x, q)
        return ~(np.abs(self.kin.normalised_mode_batch(X, Q, self._xi(xi))) > rtol)

    def torques(self, x, q, xd, xdd, xi=None) -> np.ndarray:
        """Actuator torques ``tau = w_q - J_q^T J_x^{-T} w_x``, ``(N, n)``, N m (eq. (1)).

        Valid off the Type 2 locus; NaN where :meth:`is_singular` (use
        :meth:`singular_torques` at the singular instant).
        """
        xi = self._xi(xi)
        (X, Q, XD, XDD), _ = self._rows(x, q, xd, xdd)
        tau = self._eval(self.torque_fun, (X, Q, XD, XDD), xi)[0]
        tau[self.is_singular(X, Q, xi)] = np.nan
        return tau

    def singular_torques(self, x, q, xd, xdd, xddd, xi=None, *, direction=None) -> np.ndarray:
        """Torques at the singular instant of a crossing, ``(n,)``, N m (eq. (3)).

        The limit of :meth:`torques` along a motion that crosses the Type 2
        locus at ``(x, q)`` transversally with continuous jerk ``xddd``
        (m/s^3), *provided the criterion holds* there (only the component of
        ``w_x`` normal to ``t_s`` is used; check
        :meth:`criterion_residual` separately).

        Parameters
        ----------
        x, q, xd, xdd, xddd : array_like, shape (n,)
        xi : array_like, shape (m,), optional
        direction : array_like, shape (n,), optional
            ``t_s`` (default: from the SVD of ``J_x``).

        Raises
        ------
        InputError
            If the motion does not cross the locus transversally there (the
            system of eq. (3) is singular).
        """
        xi = self._xi(xi)
        x, q = (np.asarray(v, float).reshape(-1) for v in (x, q))
        t = uncontrolled_direction(self.kin, x, q, xi) if direction is None else np.asarray(direction, float)
        t = t / np.linalg.norm(t)
        tau, _lam = self._eval(self.singular_torque_fun, (x, q, xd, xdd, xddd), xi, extra=(t,))
        if not np.all(np.isfinite(tau)):
            raise InputError("singular_torques: the motion does not cross the Type 2 locus transversally here")
        return tau[0]



def _checked_positions(kin: KinematicModel, model: LumpedMassModel):
    """The mass points' positions ``(dim, P)`` as CasADi SX in ``(x, q, xi)``, m, once the model is checked
    against the kinematics (types, robot, joints; the positions' type, shape and symbols).

    Raises
    ------
    ModelError
        On the first defect (the messages of :class:`LumpedDynamics`).
    """
    if not isinstance(kin, KinematicModel):
        raise ModelError(f"LumpedDynamics needs a KinematicModel, got {type(kin).__name__}")
    if not isinstance(model, LumpedMassModel):
        raise ModelError(f"LumpedDynamics needs a LumpedMassModel, got {type(model).__name__}")
    robot = kin.robot
    if model.robot_name != robot.name:
        raise ModelError(f"the dynamic model is for robot {model.robot_name!r}, the kinematics for {robot.name!r}")
    n = kin.n
    if model.n != n:
        raise ModelError(f"the dynamic model has {model.n} motor inertias, the robot {n} joints")
    x, q, xi = kin.sx_x, kin.sx_q, kin.sx_xi
    try:
        pos = model.positions(x, q, xi)
    except Exception as exc:  # any failure of user code is a model defect
        raise ModelError(f"{model.robot_name}: positions failed on CasADi symbols: {exc}") from exc
    if isinstance(pos, ca.MX) or not isinstance(pos, (ca.SX, ca.DM)):
        raise ModelError(f"{model.robot_name}: positions must return casadi.SX, got {type(pos).__name__}")
    pos = ca.SX(pos)
    P, d = len(model.masses), model.dim
    if pos.shape != (d, P):
        raise ModelError(f"{model.robot_name}: positions returned shape {pos.shape}, expected ({d}, {P}) "
                         "(one column per mass point, one row per gravity component)")
    try:
        ca.Function("pos", [x, q, xi], [pos])
    except RuntimeError as exc:
        raise ModelError(f"{model.robot_name}: positions use symbols other than (x, q, xi)") from exc
    return pos


def _wrench(kin: KinematicModel, model: LumpedMassModel, pos, xdd, qdd):
    """The generalised inertial-plus-gravity forces ``w = [w_x; w_q]`` ``(2n, 1)`` in ``(x, q, xd, qd, xdd,
    qdd)``: each mass point's ``m_j P_j^T (a_j - g)`` with ``P_j = d p_j / d(x, q)``, plus the motors'
    inertia times ``qdd``; N (per unit of ``x``) and N m (per rad of ``q``)."""
    n = kin.n
    x, q = kin.sx_x, kin.sx_q
    xd, qd = kin.sx_xd, kin.sx_qd
    z, zd, zdd = ca.vertcat(x, q), ca.vertcat(xd, qd), ca.vertcat(xdd, qdd)
    g = ca.DM(model.gravity)
    w = ca.SX.zeros(2 * n, 1)
    for j, mj in enumerate(model.masses):
        pj = pos[:, j]
        Pj = ca.jacobian(pj, z)
        acc = ca.mtimes(Pj, zdd) + ca.jtimes(ca.mtimes(Pj, zd), z, zd)
        w += mj * ca.mtimes(Pj.T, acc - g)
    w += ca.vertcat(ca.SX.zeros(n, 1), ca.DM(model.motor_inertia) * qdd)
    return w


def _joint_rates(kin: KinematicModel, xdd, qdd, xddd) -> tuple:
    """The joint rates in terms of pose rates: ``qd``, ``qdd`` and ``qddd`` from eq. (2) and its first two
    time derivatives (``J_q`` inverted), and ``(x, q, xd, qd, xdd, qdd)`` stacked.

    Returns ``(qd_e, qdd_e, qddd_e, allv)``; ``qddd_e`` still reads ``qd`` and ``qdd`` (eliminated by
    substitution in :class:`LumpedDynamics`).
    """
    n = kin.n
    x, q = kin.sx_x, kin.sx_q
    xd, qd = kin.sx_xd, kin.sx_qd
    jx, jq = kin.sx_jx, kin.sx_jq
    # joint rates: J_x xd + J_q qd = 0 and its time derivative
    qd_e = -ca.solve(jq, ca.mtimes(jx, xd))
    h = ca.substitute(kin.sx_jdot, qd, qd_e)
    qdd_e = -ca.solve(jq, ca.mtimes(jx, xdd) + h)
    # third order: d/dt (J_x xdd + J_q qdd + jdot) = 0, linear in qddd with J_q
    G = ca.mtimes(jx, xdd) + ca.mtimes(jq, qdd) + kin.sx_jdot
    allv = ca.vertcat(x, q, xd, qd, xdd, qdd)
    Gd = ca.jtimes(G, allv, ca.vertcat(xd, qd, xdd, qdd, xddd, ca.SX.zeros(n, 1)))
    qddd_e = -ca.solve(jq, Gd)
    return qd_e, qdd_e, qddd_e, allv


def _singular_torque(kin: KinematicModel, w, w_x_r, w_q_r, reduce, allv, xdd, qdd, xddd, qddd) -> tuple:
    """Eq. (3): the finite multipliers and torques at the singular instant with the uncontrolled direction
    ``t`` as a symbol.  ``reduce`` eliminates the joint rates; returns ``(t, tau_s, lam_s)`` (N m and the
    multipliers)."""
    n = kin.n
    x, q = kin.sx_x, kin.sx_q
    xd, qd = kin.sx_xd, kin.sx_qd
    jx, jq = kin.sx_jx, kin.sx_jq
    t = ca.SX.sym("t", n)
    wd = ca.jtimes(w, allv, ca.vertcat(xd, qd, xdd, qdd, xddd, qddd))
    wd_x = reduce(wd[:n])
    jdt = reduce(ca.jtimes(ca.mtimes(jx, t), ca.vertcat(x, q), ca.vertcat(xd, qd)))  # Jd_x t
    S = jx.T + ca.mtimes(t, jdt.T)
    rhs = w_x_r - t * ca.dot(t, w_x_r) + t * ca.dot(t, wd_x)
    lam_s = ca.solve(S, rhs)
    tau_s = w_q_r - ca.mtimes(jq.T, lam_s)
    return t, tau_s, lam_s


def criterion_residual(dynamics: LumpedDynamics, x, q, xd, xdd, xi=None, *, direction=None) -> np.ndarray:
    """Crossing-criterion residual ``t_s^T w_x`` (N); see :meth:`LumpedDynamics.criterion_residual`."""
    if not isinstance(dynamics, LumpedDynamics):
        raise InputError(f"criterion_residual needs a LumpedDynamics, got {type(dynamics).__name__}")
    return dynamics.criterion_residual(x, q, xd, xdd, xi, direction=direction)
