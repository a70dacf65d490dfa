"""A Gough–Stewart 6-6 platform: six prismatic-actuated legs between a base and a platform.

Geometry: base points ``A_i`` (world frame, m) and platform points ``b_i``
(platform frame, m), ``i = 1..6``: 36 parameters.  Pose
``x = (p_x, p_y, p_z, yaw, pitch, roll)`` (m, rad), platform orientation
``R = Rz(yaw) Ry(pitch) Rx(roll)`` (ZYX Euler angles about the home
orientation ``R = I``), ``B_i = p + R b_i``; leg ``i`` reads its length
``q_i = |B_i - A_i|`` (m).  Loop closure::

    f_i = |p + R b_i - A_i|^2 - q_i^2 = 0        (m^2)

Why Euler angles: the loop closure then uses only ``+ - *``, ``sin`` and
``cos``, which the interval evaluator encloses tightly; a rotation vector
would need ``sqrt`` and a division by the rotation angle, whose enclosure
blows up around the home orientation (angle 0), exactly where the platform
works.  The ZYX angles are a chart valid for ``|pitch| < pi/2`` (at
``pitch = +-pi/2`` yaw and roll rotate about the same axis and ``det J_x``
vanishes for a reason that is not a singularity of the robot);
``x_bounds`` keeps ``|pitch| <= 0.35 rad``, far from it.  Angular bounds
(``a_max``, ``xd0``) are on the Euler-angle rates (rad/s^2, rad/s).

Assembly mode: ``J_x = 2 P diag(I, E)`` with ``P`` the six leg lines'
Plücker coordinates (rows ``(u_i, (R b_i) x u_i)``, ``u_i = B_i - A_i``)
and ``E = [z, Rz y, Rz Ry x]`` the Euler-rate map, ``det E = -cos(pitch) < 0``
in the chart; hence ``mode_sign = -1`` and the mode is ``sign(det P)``.  The
geometric reference (:func:`mode_by_plucker`) computes it from the leg lines
without CasADi.  The home pose is mode -1.

Type 2 locus: turning the platform about the vertical by ``yaw = +-pi/2``
(pitch = roll = 0) is singular at every position ``p`` (the classic
singularity of the semi-regular design); along the yaw turn about HOME
``det P = -3.73e-3 cos(yaw)`` m^3 to four digits, so the mode goes from -1 to
+1 at ``yaw = pi/2`` with a simple sign change (``d det P / d yaw = 3.73e-3``
m^3/rad there, zero along the translations).
docs/examples/gough_stewart_crossing.py plans a 6-DOF crossing through it.

Workspace (``x_bounds``): +-0.15 m about HOME, ``p_z`` in [0.6, 1.0] m, pitch
and roll +-0.35 rad, yaw in [-1.3, 2.3] rad: the upper end takes a yaw turn
from home through the locus at +pi/2 and 0.73 rad beyond it; the locus at
-pi/2 stays outside.  Each mode has one forward-kinematics solution there
for the joints checked: the interval branch and prune of the first sample
(over the whole box, readings +-``eps_q``) on poses across it, with this
calibration box where it isolates the solutions (yaw up to about 1 rad) and
with a box ten times narrower up to yaw 2.3 rad; multi-start Newton at the
nominal geometry on 45 poses.  The joints of a pose beyond the locus (mode
+1) also reach a mode -1 pose higher up and turned less (``yaw = 2.1``,
``p_z = 0.8`` and ``yaw = 1.04``, ``p_z = 0.96``): one solution per mode,
not one in all.

The design is the usual semi-regular hexagon pair (base radius 0.5 m,
platform radius 0.3 m, joints in pairs 20 deg either side of their axis),
**assumed**, with calibration intervals of about 0.1 % of the radii.  This
robot ships a reference motion for ``simulate`` and no crossing benchmark
(``plan``, ``sweep`` and ``certify`` without ``--plan`` refuse it); a planned
crossing is certified with ``certify --plan`` (docs/examples/gough_stewart_crossing.py
writes one).  SI units: m, rad.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from .base import ReferenceMotion, Robot
from .errors import ModelError

__all__ = ["GOUGH_STEWART", "gough_stewart_loop_closure", "gs_ik", "mode_by_plucker", "gs_reference_motion",
           "HOME"]

_RB, _RP = 0.5, 0.3  # base and platform radii, m
_HALF_B, _HALF_P = math.radians(20.0), math.radians(20.0)  # half-angles of the joint pairs


def _hexagon(radius: float, half: float, offset: float) -> list[tuple[float, float, float]]:
    pts = []
    for k in range(3):
        axis = offset + 2.0 * math.pi * k / 3.0
        for s in (-1.0, 1.0):
            a = axis + s * half
            pts.append((radius * math.cos(a), radius * math.sin(a), 0.0))
    return pts


# base pairs around 0, 120, 240 deg; platform pairs around 60, 180, 300 deg,
# each platform joint rotated to pair with the nearest base joints
_BASE = _hexagon(_RB, _HALF_B, 0.0)
_PLAT = _hexagon(_RP, _HALF_P, math.pi / 3.0)
_PLAT = _PLAT[-1:] + _PLAT[:-1]  # leg i joins A_i to the nearest platform joint of the neighbouring pair
PARAM_NAMES = tuple(f"a{i + 1}{c}" for i in range(6) for c in "xyz") + tuple(
    f"b{i + 1}{c}" for i in range(6) for c in "xyz")
#: Home pose: platform 0.8 m above the base, no rotation.
HOME = np.array([0.0, 0.0, 0.8, 0.0, 0.0, 0.0])
_TOL_B, _TOL_P = 2.5e-4, 1.5e-4  # m, half-widths of the base and platform coordinates (~0.05 % of the radii)


def _rotation(yaw, pitch, roll, lib):
    cy, sy, cp, sp, cr, sr = lib.cos(yaw), lib.sin(yaw), lib.cos(pitch), lib.sin(pitch), lib.cos(roll), lib.sin(roll)
    return ((cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
            (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
            (-sp, cp * sr, cp * cr))


def gough_stewart_loop_closure(x, q, xi):
    """The Gough–Stewart loop closure on CasADi symbols.

    Parameters
    ----------
    x : casadi.SX, shape (6,)
        ``(p_x, p_y, p_z, yaw, pitch, roll)``, m and rad.
    q : casadi.SX, shape (6,)
        Leg lengths, m.
    xi : casadi.SX, shape (36,)
        ``(a1x, a1y, a1z, ..., a6z, b1x, ..., b6z)``, m.

    Returns
    -------
    casadi.SX, shape (6,)
        ``|p + R b_i - A_i|^2 - q_i^2``, m^2.
    """
    R = _rotation(x[3], x[4], x[5], ca)
    out = []
    for i in range(6):
        a = [xi[3 * i + c] for c in range(3)]
        b = [xi[18 + 3 * i + c] for c in range(3)]
        u = [x[r] + R[r][0] * b[0] + R[r][1] * b[1] + R[r][2] * b[2] - a[r] for r in range(3)]
        out.append(u[0] ** 2 + u[1] ** 2 + u[2] ** 2 - q[i] ** 2)
    return ca.vertcat(*out)


def _nominal() -> np.ndarray:
    return np.array([v for p in _BASE for v in p] + [v for p in _PLAT for v in p])


def _half_widths() -> np.ndarray:
    w = np.array([_TOL_B] * 18 + [_TOL_P] * 18)
    # frame conventions (exact): world origin at A_1, A_2 in the plane y = a1y... fixed by point
    # intervals on a1 (x, y, z), a2 (y, z), a3 (z); likewise for the platform frame on b1, b2, b3
    w[[0, 1, 2, 4, 5, 8, 18, 19, 20, 22, 23, 26]] = 0.0
    return w


def _xi_or_nominal(xi) -> np.ndarray:
    xi = _nominal() if xi is None else np.asarray(xi, dtype=float).reshape(-1)
    if xi.shape != (36,):
        raise ModelError(f"Gough-Stewart xi must have 36 entries, got shape {xi.shape}")
    return xi


def _legs(x, xi):
    """``u = B - A``, shape (N, 6, 3), and ``r = R b``, shape (N, 6, 3), m."""
    X = np.atleast_2d(np.asarray(x, dtype=float))
    R = np.array(_rotation(X[:, 3], X[:, 4], X[:, 5], np)).transpose(2, 0, 1)  # (N, 3, 3)
    A = xi[:18].reshape(6, 3)
    b = xi[18:].reshape(6, 3)
    r = np.einsum("nij,kj->nki", R, b)
    return X[:, None, :3] + r - A[None], r


def gs_ik(x, xi=None) -> np.ndarray:
    """Closed-form inverse kinematics ``q_i = |p + R b_i - A_i|``: poses (N, 6) or (6,) -> leg lengths, m."""
    xi = _xi_or_nominal(xi)
    x = np.asarray(x, dtype=float)
    u, _r = _legs(x, xi)
    return np.linalg.norm(u, axis=2).reshape(x.shape)


def mode_by_plucker(x, xi=None) -> np.ndarray:
    """Assembly mode ``sign(det [u_i, r_i x u_i])`` of the six leg lines (no CasADi), (N,) ints.

    Equal to ``-sign(det J_x)``: ``J_x`` is this Plücker matrix times 2 and the
    Euler-rate map, whose determinant ``-cos(pitch)`` is negative in the chart.
    """
    xi = _xi_or_nominal(xi)
    u, r = _legs(x, xi)
    return np.sign(np.linalg.det(np.concatenate([u, np.cross(r, u)], axis=2))).astype(int)


def _mode_reference(x, q, xi) -> int:
    """``Robot.mode_reference``: the geometric mode at one configuration (a module-level
    function, so that the robot pickles for worker processes)."""
    return int(mode_by_plucker(x, xi)[0])


GOUGH_STEWART = Robot(
    name="gough-stewart",
    n=6,
    param_names=PARAM_NAMES,
    xi_nominal=tuple(_nominal()),
    xi_lo=tuple(_nominal() - _half_widths()),
    xi_hi=tuple(_nominal() + _half_widths()),
    q_lo=(0.55,) * 6,
    q_hi=(1.25,) * 6,
    # the tracked workspace around HOME: +-0.15 m, pitch and roll +-0.35 rad
    # (|pitch| < pi/2 keeps the Euler chart valid), yaw from -1.3 rad (short of
    # the locus at -pi/2) to 2.3 rad (through the locus at +pi/2, for a planned
    # crossing); one FK solution per mode there (module docstring)
    x_bounds=((-0.15, -0.15, 0.6, -1.3, -0.35, -0.35), (0.15, 0.15, 1.0, 2.3, 0.35, 0.35)),
    loop_closure=gough_stewart_loop_closure,
    # 40 m/s^2 (a fast hexapod); 120 rad/s^2 gives ~40 m/s^2 at the platform's 0.3 m radius
    pose_units=("m", "m", "m", "rad", "rad", "rad"),  # (p_x, p_y, p_z, yaw, pitch, roll)
    joint_units=("m",) * 6,  # prismatic legs
    a_max=(40.0, 40.0, 40.0, 120.0, 120.0, 120.0),
    eps_q=5e-6,  # m: a 5 um linear encoder count on each leg
    t_s=1e-3,
    xd0=(0.05, 0.05, 0.05, 0.15, 0.15, 0.15),  # m/s and rad/s
    mode_sign=-1.0,  # det of the Euler-rate map is -cos(pitch): mode +1 = Plücker determinant > 0 (home: -1)
    mode_reference=_mode_reference,
    description=(
        "Gough-Stewart 6-6 platform with ASSUMED design data (base radius 0.5 m, platform radius 0.3 m). "
        "Pose x = (p_x, p_y, p_z, yaw, pitch, roll) in m and rad (R = Rz Ry Rx, |pitch| < pi/2); joints = leg "
        "lengths in m; xi = 18 base and 18 platform coordinates. Assembly mode = sign of the leg lines' Plücker determinant (-1 at home)."
    ),
)


def gs_reference_motion(xi=None) -> ReferenceMotion:
    """The reference motion of ``simulate``: 0.12 m along X with a 0.2 rad yaw turn, through HOME.

    It starts at ``HOME - half`` and ends at ``HOME + half`` (regular all the
    way); the tests add random motions around HOME.
    """
    xi = _xi_or_nominal(xi)
    delta = np.array([0.12, 0.0, 0.0, 0.2, 0.0, 0.0])
    start = HOME - 0.5 * delta
    return ReferenceMotion(start=start, goal=HOME + 0.5 * delta, q_start=gs_ik(start, xi), xi=xi.copy())
