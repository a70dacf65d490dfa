"""Interval view of a robot: the tapes the tracker evaluates, derived from f.

Everything here is computed from the robot's single CasADi definition of the
loop-closure equations ``f(x, q, xi) = 0`` (shape ``(n,)``):

* ``J_x = df/dx`` and ``J_q = df/dq`` (``(n, n)``), by CasADi's AD;
* the velocity constraint ``g = J_x xd + J_q qd = 0`` (eq. 2 of the paper);
* its time derivative ``J_x xdd + J_q qdd + h(x, q, xi, xd, qd) = 0`` where
  ``h = dg/d(x, q) . (xd, qd)``, used to bound joint accelerations;
* the assembly-mode indicator ``mode_sign * det J_x`` (its sign is the mode).

The robot object only has to provide ``n``, ``xi_nominal`` (for ``m``),
``loop_closure`` and ``mode_sign``; nothing here names a particular robot.
"""

from __future__ import annotations

from functools import cached_property

import casadi as ca
import numpy as np

from crosscert.robots.errors import ModelError
from .tape import Tape

__all__ = ["IntervalModel"]


class IntervalModel:
    """Tapes for the interval evaluation of one robot's kinematics.

    Parameters
    ----------
    robot : object
        Has ``n`` (DOF), ``xi_nominal`` (length ``m``), ``loop_closure``
        (``f(x, q, xi) -> SX (n,)``) and ``mode_sign``.
    """

    def __init__(self, robot):
        self.robot = robot
        n = int(robot.n)
        m = len(robot.xi_nominal)
        self.n, self.m = n, m
        x = ca.SX.sym("x", n)
        q = ca.SX.sym("q", n)
        xi = ca.SX.sym("xi", m)
        xd = ca.SX.sym("xd", n)
        qd = ca.SX.sym("qd", n)
        xdd = ca.SX.sym("xdd", n)
        f = ca.vec(robot.loop_closure(x, q, xi))
        if f.shape != (n, 1):
            raise ModelError(f"{robot.name}: loop_closure must return {n} equations, got shape {f.shape}")
        jx = ca.jacobian(f, x)
        jq = ca.jacobian(f, q)
        g = ca.mtimes(jx, xd) + ca.mtimes(jq, qd)
        h = ca.jtimes(g, ca.vertcat(x, q), ca.vertcat(xd, qd))
        det = float(getattr(robot, "mode_sign", 1.0)) * ca.det(jx)
        self.sx = dict(x=x, q=q, xi=xi, xd=xd, qd=qd, xdd=xdd, f=f, jx=jx, jq=jq, g=g, h=h, det=det)
        fun = ca.Function
        self.tape_f = Tape(fun("f", [x, q, xi], [f]))
        self.tape_jx = Tape(fun("jx", [x, q, xi], [jx]))
        self.tape_jq = Tape(fun("jq", [x, q, xi], [jq]))
        # J_x and J_q qd in one pass (shared subexpressions); J_q qd as one
        # expression is tighter than the product of two enclosures
        self.tape_vel = Tape(fun("vel", [x, q, xi, qd], [jx, ca.mtimes(jq, qd)]))
        self.tape_jx_xd = Tape(fun("jx_xd", [x, q, xi, xd], [ca.mtimes(jx, xd)]))
        self.tape_accel_rhs = Tape(fun("accel_rhs", [x, q, xi, xd, qd, xdd], [ca.mtimes(jx, xdd) + h]))
        self.tape_det = Tape(fun("det", [x, q, xi], [det]))

    @cached_property
    def tape_jac(self) -> Tape:
        """``df/d(x, q, xi)`` ``(n, 2n + m)`` in one tape (the columns of ``J_x``, ``J_q``, then ``J_xi``): the
        mean-value form of the loop closure over a whole box (:mod:`verifier.one_motion`)."""
        s = self.sx
        z = ca.vertcat(s["x"], s["q"], s["xi"])
        return Tape(ca.Function("jall", [s["x"], s["q"], s["xi"]], [ca.jacobian(s["f"], z)]))

    @cached_property
    def tape_hess(self) -> Tape:
        """The Hessians of the equations of ``f`` in ``(x, q, xi)``, stacked: ``(n (2n + m), 2n + m)`` (rows
        ``i (2n + m) .. (i + 1)(2n + m)`` are equation ``i``'s): the second-order Taylor form of the loop closure
        over a box (:mod:`verifier.one_motion`)."""
        s = self.sx
        z = ca.vertcat(s["x"], s["q"], s["xi"])
        H = ca.vertcat(*[ca.hessian(s["f"][i], z)[0] for i in range(self.n)])
        return Tape(ca.Function("hessians", [s["x"], s["q"], s["xi"]], [H]))

    @cached_property
    def program(self):
        """Every tape packed as flat arrays for the compiled kernels
        (:func:`verifier.compiled.straight.pack`), built once per model."""
        from .compiled.straight import pack

        return pack(self)

    @cached_property
    def numeric(self) -> dict[str, ca.Function]:
        """Float CasADi functions of the same expressions (for tests and simulation)."""
        s = self.sx
        return {
            "f": ca.Function("f", [s["x"], s["q"], s["xi"]], [s["f"]]),
            "jx": ca.Function("jx", [s["x"], s["q"], s["xi"]], [s["jx"]]),
            "jq": ca.Function("jq", [s["x"], s["q"], s["xi"]], [s["jq"]]),
            "det": ca.Function("det", [s["x"], s["q"], s["xi"]], [s["det"]]),
            "h": ca.Function("h", [s["x"], s["q"], s["xi"], s["xd"], s["qd"]], [s["h"]]),
        }

    def xi_box(self, widen: float = 1.0):
        """The calibration box ``[xi]`` as ``(lo, hi)`` arrays of shape ``(m,)``.

        ``widen`` scales the half-widths around the nominal value (1 = as given).
        """
        r = self.robot
        nom = np.asarray(r.xi_nominal, dtype=np.float64)
        lo = np.asarray(r.xi_lo, dtype=np.float64)
        hi = np.asarray(r.xi_hi, dtype=np.float64)
        if widen != 1.0:
            lo = nom - widen * (nom - lo)
            hi = nom + widen * (hi - nom)
        return lo, hi
