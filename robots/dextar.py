"""The DexTAR five-bar planar parallel robot of the paper (Section III.A, eq. (7), Table I).

Geometry (Fig. 2 of the paper): motors at ``A1 = (-d/2, 0)`` and
``A2 = (d/2, 0)``; the proximal link of leg ``i`` (length ``l_i1``) ends at
``B_i = A_i + l_i1 (cos q_i1, sin q_i1)`` with ``q_i1 = q_i + delta_i``; the
distal links (lengths ``l_i2``) meet at the end-effector ``E = x = (x, y)``.
Eq. (7) is ``f_i = |E - B_i|^2 - l_i2^2 = 0``.

Assembly mode: +1 when ``E`` lies strictly to the left of the directed line
``B1 -> B2`` (``cross(B2 - B1, E - B1) > 0``), -1 when strictly right.  With
``J_x`` rows ``2 (E - B_i)^T``, ``det J_x = 4 cross(E - B1, E - B2)
= 4 cross(B2 - B1, E - B1)``, hence ``mode_sign = +1``.

The benchmark of Section IV crosses the Type 2 locus going down the ``Y``
axis in the "elbows out" working mode (``B1`` left of ``A1``, ``B2`` right
of ``A2``); :func:`singular_y` and :func:`benchmark_crossing` compute it.
SI units: m, rad.
"""

from __future__ import annotations

import functools
import math

import casadi as ca
import numpy as np
from scipy.optimize import brentq

from .errors import ModelError

from .base import BenchmarkCrossing, Robot
from .kinematics import KinematicModel
from .mass_model import LumpedMassModel

__all__ = [
    "DEXTAR",
    "dextar_loop_closure",
    "elbows_out_ik",
    "distal_joints",
    "mode_by_cross_product",
    "singular_y",
    "axis_singular_y",
    "BenchmarkCrossing",
    "benchmark_crossing",
    "dextar_mass_points",
    "DEXTAR_DYNAMICS",
]

PARAM_NAMES = ("l11", "l21", "l12", "l22", "d", "delta1", "delta2")


def dextar_loop_closure(x, q, xi):
    """Eq. (7) on CasADi symbols.

    Parameters
    ----------
    x : casadi.SX, shape (2,)
        End-effector position ``E``, m.
    q : casadi.SX, shape (2,)
        Motor angles, rad.
    xi : casadi.SX, shape (7,)
        ``(l11, l21, l12, l22, d, delta1, delta2)``, m and rad.

    Returns
    -------
    casadi.SX, shape (2,)
        ``|E - B_i|^2 - l_i2^2``, m^2.
    """
    l11, l21, l12, l22, d, delta1, delta2 = (xi[i] for i in range(7))
    q11 = q[0] + delta1
    q21 = q[1] + delta2
    f1 = (x[0] + d / 2 - l11 * ca.cos(q11)) ** 2 + (x[1] - l11 * ca.sin(q11)) ** 2 - l12**2
    f2 = (x[0] - d / 2 - l21 * ca.cos(q21)) ** 2 + (x[1] - l21 * ca.sin(q21)) ** 2 - l22**2
    return ca.vertcat(f1, f2)


def _mode_reference(x, q, xi) -> int:
    """``Robot.mode_reference``: the geometric mode at one configuration (a module-level
    function, so that the robot pickles for worker processes)."""
    return int(mode_by_cross_product(x, q, xi)[0])


_MM = 1e-3
DEXTAR = Robot(
    name="dextar",
    n=2,
    param_names=PARAM_NAMES,
    # Table I, mm -> m.  The design value l11 = 90 mm lies 5 um above its
    # calibrated interval; it is kept as published (only [xi] is certified).
    xi_nominal=(90 * _MM, 90 * _MM, 90 * _MM, 90 * _MM, 118 * _MM, 0.0, 0.0),
    xi_lo=(89.832 * _MM, 89.929 * _MM, 89.899 * _MM, 89.877 * _MM, 117.843 * _MM, -0.004, -0.004),
    xi_hi=(89.995 * _MM, 90.115 * _MM, 90.050 * _MM, 90.084 * _MM, 118.107 * _MM, 0.004, 0.004),
    # The paper gives no joint limits: one full turn each, centred on the
    # upward vertical, holds both working modes of each leg.
    q_lo=(-0.5 * math.pi, -0.5 * math.pi),
    q_hi=(1.5 * math.pi, 1.5 * math.pi),
    # |E - A_i| <= l_i1 + l_i2 <= 0.18020 m with |A1 A2| >= 0.11784 m gives
    # |x| <= 0.1213 m and |y| <= 0.1703 m; rounded outwards.
    x_bounds=((-0.13, -0.18), (0.13, 0.18)),
    loop_closure=dextar_loop_closure,
    pose_units=("m", "m"),  # E = (x, y)
    a_max=(80.0, 80.0),
    eps_q=math.pi / 34000,
    t_s=1e-3,
    # Initial velocity box after homing, Section III.A: [-0.1, 0.1]^2 m/s.
    xd0=(0.1, 0.1),
    # Halving the two angular offsets (4 geometry hypotheses) lowers the
    # slowest certified crossing of the benchmark from 1.354 to 1.264 m/s;
    # finer or other splits did not certify 1.185 m/s (docs/tracker.md).
    xi_splits=(1, 1, 1, 1, 1, 2, 2),
    # eq. (7) reads q_i only through q_i + delta_i
    joint_offsets=(5, 6),
    mode_sign=1.0,
    mode_reference=_mode_reference,
    description=(
        "DexTAR five-bar planar parallel robot (Mecademic), model of eq. (7) and "
        "calibrated parameter intervals of Table I of the paper. Pose x = E = (x, y) "
        "in m, joints (q1, q2) in rad, xi = (l11, l21, l12, l22, d, delta1, delta2). "
        "Assembly mode +1: E left of the directed line B1->B2."
    ),
)


@functools.lru_cache(maxsize=1)
def _model() -> KinematicModel:
    return KinematicModel(DEXTAR)


def _xi_or_nominal(xi) -> np.ndarray:
    xi = DEXTAR.xi_nominal_array if xi is None else np.asarray(xi, dtype=float).reshape(-1)
    if xi.shape != (7,):
        raise ModelError(f"DexTAR xi must have 7 entries, got shape {xi.shape}")
    return xi


def elbows_out_ik(x, xi=None) -> np.ndarray:
    """Closed-form IK in the "elbows out" working mode (``B1`` left of ``A1 E``, ``B2`` right of ``A2 E``).

    Parameters
    ----------
    x : array_like, shape (2,) or (N, 2)
        End-effector positions, m.
    xi : array_like, shape (7,), optional
        Parameters (default nominal).

    Returns
    -------
    ndarray, shape like ``x``
        Motor angles, rad, wrapped into ``[-pi/2, 3pi/2)``; NaN where unreachable.
    """
    xi = _xi_or_nominal(xi)
    x = np.asarray(x, dtype=float)
    E = np.atleast_2d(x)
    l11, l21, l12, l22, d, delta1, delta2 = xi
    out = np.empty_like(E)
    for col, (ax, l1, l2, delta, side) in enumerate(
        ((-d / 2, l11, l12, delta1, 1.0), (d / 2, l21, l22, delta2, -1.0))
    ):
        vx, vy = E[:, 0] - ax, E[:, 1]
        r = np.hypot(vx, vy)
        with np.errstate(invalid="ignore", divide="ignore"):
            cos_a = (l1**2 + r**2 - l2**2) / (2 * l1 * r)
            alpha = np.arccos(np.where(np.abs(cos_a) <= 1.0, cos_a, np.nan))
        q = np.arctan2(vy, vx) + side * alpha - delta
        out[:, col] = np.mod(q + 0.5 * np.pi, 2 * np.pi) - 0.5 * np.pi
    return out.reshape(x.shape)


def distal_joints(q, xi=None) -> tuple[np.ndarray, np.ndarray]:
    """Positions of ``B1`` and ``B2``, each shape (N, 2), m, for joints ``q`` (rad), shape (N, 2) or (2,)."""
    xi = _xi_or_nominal(xi)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    l11, l21, _l12, _l22, d, delta1, delta2 = xi
    b1 = np.stack([-d / 2 + l11 * np.cos(q[:, 0] + delta1), l11 * np.sin(q[:, 0] + delta1)], axis=1)
    b2 = np.stack([d / 2 + l21 * np.cos(q[:, 1] + delta2), l21 * np.sin(q[:, 1] + delta2)], axis=1)
    return b1, b2


def mode_by_cross_product(x, q, xi=None) -> np.ndarray:
    """Geometric assembly mode ``sign(cross(B2 - B1, E - B1))`` (independent of CasADi).

    Parameters
    ----------
    x, q : array_like, shape (N, 2) or (2,)
        End-effector positions (m) and motor angles (rad).
    xi : array_like, shape (7,), optional

    Returns
    -------
    ndarray of int, shape (N,)
    """
    E = np.atleast_2d(np.asarray(x, dtype=float))
    b1, b2 = distal_joints(q, xi)
    u, v = b2 - b1, E - b1
    return np.sign(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]).astype(int)


def _det_on_axis(kin: KinematicModel, y, xi) -> np.ndarray:
    y = np.atleast_1d(np.asarray(y, dtype=float))
    E = np.stack([np.zeros_like(y), y], axis=1)
    return kin.det_batch(E, elbows_out_ik(E, xi), xi)


def axis_singular_y(kin: KinematicModel, xi, y_range: tuple[float, float], samples: int) -> float:
    """Height ``y_s`` (m) where the line ``x = 0`` meets the Type 2 locus of a five-bar with this module's
    loop closure (``kin``: its kinematic model), elbows out, for the geometry ``xi`` ``(7,)``.

    Solves ``det J_x(E(y), IK(E(y)), xi) = 0`` with ``E(y) = (0, y)`` and the
    elbows-out IK, by a scan of ``y_range`` (m) downwards at ``samples`` points and Brent's method on the
    first sign change met (the one a benchmark going down crosses).

    Raises
    ------
    ModelError
        If ``det J_x`` does not change sign on the scanned range.
    """
    ys = np.linspace(y_range[1], y_range[0], samples)
    det = _det_on_axis(kin, ys, xi)
    sgn = np.sign(det)
    change = np.nonzero(np.isfinite(det[:-1]) & np.isfinite(det[1:]) & (sgn[:-1] * sgn[1:] <= 0))[0]
    if change.size == 0:
        raise ModelError(f"{kin.robot.name}: no Type 2 singularity on x = 0 for y in {y_range} with "
                         f"xi = {np.asarray(xi).tolist()}")
    k = change[0]
    if det[k] == 0.0:
        return float(ys[k])
    return float(brentq(lambda y: float(_det_on_axis(kin, y, xi)[0]), ys[k + 1], ys[k], xtol=1e-16, rtol=1e-15,
                        maxiter=200))


def singular_y(xi=None, *, y_range: tuple[float, float] = (0.02, 0.16), samples: int = 281) -> float:
    """Height ``y_s`` (m) where the line ``x = 0`` meets the DexTAR's Type 2 locus, elbows out
    (:func:`axis_singular_y`).

    Parameters
    ----------
    xi : array_like, shape (7,), optional
        True geometry (default nominal).
    y_range : (float, float)
        Search interval, m.
    samples : int
        Scan points.
    """
    return axis_singular_y(_model(), _xi_or_nominal(xi), y_range, samples)


def benchmark_crossing(xi=None) -> BenchmarkCrossing:
    """The benchmark crossing geometry for ``xi`` (default: nominal, the planner's view)."""
    xi = _xi_or_nominal(xi)
    y_s = singular_y(xi)
    point = np.array([0.0, y_s])
    return BenchmarkCrossing(
        point=point,
        direction=np.array([0.0, -1.0]),
        q_point=elbows_out_ik(point, xi),
        xi=xi.copy(),
    )


# ---------------------------------------------------------------------- dynamics
def dextar_mass_points(x, q, xi):
    """Mass points of the DexTAR on CasADi symbols ``x``, ``q``, ``xi`` (as for :func:`dextar_loop_closure`).

    Returns
    -------
    casadi.SX, shape (2, 5)
        Columns ``P1, B1, P2, B2, E``: mid-points of the proximal links, the
        elbows ``B_i = A_i + l_i1 (cos q_i1, sin q_i1)`` and the end-effector, m.
    """
    l11, l21, _l12, _l22, d, delta1, delta2 = (xi[i] for i in range(7))
    u1 = ca.vertcat(ca.cos(q[0] + delta1), ca.sin(q[0] + delta1))
    u2 = ca.vertcat(ca.cos(q[1] + delta2), ca.sin(q[1] + delta2))
    a1 = ca.vertcat(-d / 2, 0)
    a2 = ca.vertcat(d / 2, 0)
    e = ca.vertcat(x[0], x[1])
    return ca.horzcat(a1 + 0.5 * l11 * u1, a1 + l11 * u1, a2 + 0.5 * l21 * u2, a2 + l21 * u2, e)


# Assumed DexTAR data: the paper and Mecademic publish no inertial data.
_M_PROX = 0.10  # kg, each proximal link (90 mm aluminium arm with its clamp), a uniform rod
_M_DIST = 0.08  # kg, each distal link (90 mm tube with its two bearings)
_M_TOOL = 0.05  # kg, end-effector shaft and tool
_J_ROTOR = 5e-5  # kg m^2, rotor of a ~100 W servo motor
_GEAR = 10.0  # reduction ratio; 3000 rpm at the motor gives ~31 rad/s at the joint
#: The DexTAR's lumped-mass model.  **Every value is an assumption**: the
#: paper (and Mecademic's public data) give no masses, inertias, gear ratios
#: or torque limits.  Replace this instance when the real data are known.
DEXTAR_DYNAMICS = LumpedMassModel(
    robot_name="dextar",
    point_names=("P1", "B1", "P2", "B2", "E"),
    # A uniform rod of mass m rotating about A_i is *exactly* equivalent (mass,
    # centre of mass, inertia) to m/6 at A_i, 2m/3 at its midpoint P_i and m/6
    # at B_i; the m/6 at the fixed motor axis A_i does nothing and is left out.
    # The distal links are lumped half at each end (B_i and E): the usual
    # assumption of the crossing literature (Briot & Arakelian; Pagis) under
    # which the criterion is "end-effector acceleration normal to the
    # uncontrolled direction"; it keeps mass and centre of mass and
    # overestimates each distal link's central inertia by m l^2 / 6.
    masses=(
        2 * _M_PROX / 3,
        _M_PROX / 6 + _M_DIST / 2,
        2 * _M_PROX / 3,
        _M_PROX / 6 + _M_DIST / 2,
        _M_TOOL + _M_DIST,  # tool + half of each distal link
    ),
    positions=dextar_mass_points,
    # rotor 5e-5 kg m^2 behind a 10:1 reduction: 5e-3 kg m^2 at the joint
    motor_inertia=(_J_ROTOR * _GEAR**2, _J_ROTOR * _GEAR**2),
    # The paper does not say whether the DexTAR's plane is horizontal; the
    # five-bar is assumed to work in a horizontal plane (table-top pick and
    # place), where gravity has no in-plane component.  Use (0, -9.81) for a
    # vertical plane with Y up.
    gravity=(0.0, 0.0),
    # peak torque of such a motor (~0.3 N m) times the 10:1 reduction
    tau_max=(3.0, 3.0),
    description=(
        "DexTAR lumped-mass model with ASSUMED parameters (none are published): proximal links "
        "90 mm, 0.10 kg uniform rods (2/3 at mid-link, 1/6 at the elbow); distal links 0.08 kg lumped "
        "half at each end; tool 0.05 kg at E; rotor 5e-5 kg m^2 behind a 10:1 gear (5e-3 kg m^2 at "
        "the joint); tau_max 3 N m per joint; horizontal plane (no in-plane gravity)."
    ),
)
