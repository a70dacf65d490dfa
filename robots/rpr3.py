"""A 3-RPR planar parallel robot: three prismatic-actuated legs between a base and a platform.

Geometry: base points ``A_i = (a_ix, a_iy)`` (world frame, m) and platform
points ``b_i = (b_ix, b_iy)`` (platform frame, m); the pose is
``x = (p_x, p_y, phi)`` (m, m, rad), the platform point ``B_i = p + R(phi) b_i``;
leg ``i`` is a passive revolute joint at ``A_i``, an actuated prismatic joint
of length ``rho_i`` and a passive revolute joint at ``B_i``.  The encoder of leg
``i`` reads ``q_i = rho_i - delta_i``: ``delta_i`` (m) is its calibrated offset.
Loop closure::

    f_i = |p + R(phi) b_i - A_i|^2 - (q_i + delta_i)^2 = 0       (m^2)

Type 2 locus: ``J_x`` has rows ``2 (u_i, cross(r_i, u_i))`` with
``u_i = B_i - A_i`` and ``r_i = B_i - p``, i.e. twice the Plücker coordinates of
the three leg lines, so ``det J_x = 0`` exactly when the three leg lines are
concurrent (or parallel).

Assembly mode (``mode_sign = +1``): moving the reference point of the moments
to ``C12``, the intersection of leg lines 1 and 2, does not change the
determinant and zeroes the first two moments, so
``det J_x = 8 cross(u_1, u_2) cross(u_3, C12 - B_3)``.  The mode is +1 when
"leg 2 turns counter-clockwise from leg 1" and "``C12`` lies left of the directed
leg line ``A_3 -> B_3``" agree (both true or both false), -1 otherwise;
:func:`mode_by_leg_lines` computes it without CasADi and the tests compare.

The benchmark crossing is a pure translation along ``+X`` at constant
``phi = -0.3 rad`` and ``p_y = 0.14 m`` through the locus (near
``p_x = 0.20 m``), so its speed is in m/s like the DexTAR's.  The design,
bounds and calibration intervals are **assumed** (a desk-size 3-RPR; no
published robot): calibration intervals of about 0.2 % of the dimensions,
as the DexTAR's Table I.  SI units: m, rad.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np
from scipy.optimize import brentq

from .base import BenchmarkCrossing, Robot
from .errors import ModelError
from .kinematics import KinematicModel

__all__ = ["RPR3", "rpr3_loop_closure", "rpr3_ik", "mode_by_leg_lines", "singular_x", "rpr3_benchmark_crossing"]

PARAM_NAMES = ("a1x", "a1y", "a2x", "a2y", "a3x", "a3y", "b1x", "b1y", "b2x", "b2y", "b3x", "b3y",
               "delta1", "delta2", "delta3")
_A = ((0.0, 0.0), (0.30, 0.0), (0.12, 0.25))  # base points, m
_B = ((-0.108, -0.045), (0.09, -0.063), (0.018, 0.09))  # platform points in the platform frame, m
# Calibration half-widths, m.  Intervals of the DexTAR's relative size
# (0.15, 0.1, 0.1 mm) certify no crossing of the benchmark (docs/robots.md):
# the shipped robot assumes a calibration ten times finer (CMM or laser tracker).
_BASE_TOL = 1.5e-5  # m, each base coordinate
_PLATFORM_TOL = 1.0e-5  # m, each platform coordinate
_OFFSET_TOL = 1.0e-5  # m, half-width of each leg offset's interval
#: Benchmark: orientation (rad), height (m) and the X range (m) scanned for the crossing.
BENCH_PHI = -0.3
BENCH_Y = 0.14
_BENCH_X_RANGE = (0.15, 0.25)


def rpr3_loop_closure(x, q, xi):
    """The 3-RPR loop closure on CasADi symbols.

    Parameters
    ----------
    x : casadi.SX, shape (3,)
        Pose ``(p_x, p_y, phi)``, m, m, rad.
    q : casadi.SX, shape (3,)
        Encoder readings of the leg lengths, m.
    xi : casadi.SX, shape (15,)
        ``(a1x, a1y, a2x, a2y, a3x, a3y, b1x, b1y, b2x, b2y, b3x, b3y, delta1, delta2, delta3)``, m.

    Returns
    -------
    casadi.SX, shape (3,)
        ``|p + R(phi) b_i - A_i|^2 - (q_i + delta_i)^2``, m^2.
    """
    c, s = ca.cos(x[2]), ca.sin(x[2])
    out = []
    for i in range(3):
        ax, ay, bx, by = xi[2 * i], xi[2 * i + 1], xi[6 + 2 * i], xi[7 + 2 * i]
        ux = x[0] + c * bx - s * by - ax
        uy = x[1] + s * bx + c * by - ay
        out.append(ux**2 + uy**2 - (q[i] + xi[12 + i]) ** 2)
    return ca.vertcat(*out)


def _nominal() -> tuple[float, ...]:
    return (*(v for a in _A for v in a), *(v for b in _B for v in b), 0.0, 0.0, 0.0)


def _half_widths() -> np.ndarray:
    w = np.array([_BASE_TOL] * 6 + [_PLATFORM_TOL] * 6 + [_OFFSET_TOL] * 3)
    # Frame conventions, exact by definition (point intervals): the world
    # frame has its origin at A_1 and its X axis through A_2; the platform
    # frame is placed so that B_1 has its nominal coordinates and B_2 its
    # nominal y coordinate.
    w[[0, 1, 3, 6, 7, 9]] = 0.0
    return w


def _mode_reference(x, q, xi) -> int:
    """``Robot.mode_reference``: the geometric mode at one configuration (a module-level
    function, so that the robot pickles for worker processes)."""
    return int(mode_by_leg_lines(x, xi)[0])


RPR3 = Robot(
    name="3rpr",
    n=3,
    param_names=PARAM_NAMES,
    xi_nominal=_nominal(),
    xi_lo=tuple(np.array(_nominal()) - _half_widths()),
    xi_hi=tuple(np.array(_nominal()) + _half_widths()),
    # prismatic strokes, m (the encoder reads rho_i - delta_i)
    q_lo=(0.03, 0.03, 0.03),
    q_hi=(0.40, 0.40, 0.40),
    # |p - A_i| <= rho_max + |b_i| <= 0.52 m around the base points; phi is
    # 2 pi periodic, so one turn holds every orientation.
    x_bounds=((0.0, 0.0, -0.9), (0.35, 0.30, 0.3)),
    loop_closure=rpr3_loop_closure,
    # 80 m/s^2 as the DexTAR; 200 rad/s^2 gives ~24 m/s^2 at the platform's 0.12 m radius
    # (800 rad/s^2, ~the translational bound there, certifies no crossing: docs/robots.md)
    pose_units=("m", "m", "rad"),  # (p_x, p_y, phi)
    joint_units=("m", "m", "m"),  # prismatic strokes
    a_max=(80.0, 80.0, 200.0),
    eps_q=5e-6,  # m: a 5 um linear encoder count
    t_s=1e-3,
    xd0=(0.1, 0.1, 1.0),  # m/s, m/s, rad/s
    joint_offsets=(12, 13, 14),
    mode_sign=1.0,
    mode_reference=_mode_reference,
    description=(
        "3-RPR planar parallel robot with ASSUMED design data: base points A_i, platform points b_i "
        "(platform frame), leg offsets delta_i. Pose x = (p_x, p_y, phi) in m, m, rad; joints = leg "
        "encoder readings in m (rho_i = q_i + delta_i). Assembly mode +1: sign(cross(u1, u2)) * side of "
        "C12 (leg lines 1 and 2 meet there) w.r.t. the directed leg line A3->B3 is positive."
    ),
)


@functools.lru_cache(maxsize=1)
def _model() -> KinematicModel:
    return KinematicModel(RPR3)


def _xi_or_nominal(xi) -> np.ndarray:
    xi = RPR3.xi_nominal_array if xi is None else np.asarray(xi, dtype=float).reshape(-1)
    if xi.shape != (RPR3.m,):
        raise ModelError(f"3-RPR xi must have {RPR3.m} entries, got shape {xi.shape}")
    return xi


def _legs(x, xi):
    """``(A, B)`` each shape (N, 3, 2), m: base and platform points at poses ``x`` (N, 3)."""
    X = np.atleast_2d(np.asarray(x, dtype=float))
    A = xi[:6].reshape(3, 2)[None]
    b = xi[6:12].reshape(3, 2)
    c, s = np.cos(X[:, 2])[:, None], np.sin(X[:, 2])[:, None]
    B = np.stack([X[:, :1] + c * b[:, 0] - s * b[:, 1], X[:, 1:2] + s * b[:, 0] + c * b[:, 1]], axis=2)
    return np.broadcast_to(A, B.shape), B


def rpr3_ik(x, xi=None) -> np.ndarray:
    """Closed-form inverse kinematics ``q_i = |p + R(phi) b_i - A_i| - delta_i``.

    Parameters
    ----------
    x : array_like, shape (3,) or (N, 3)
        Poses, m, m, rad.
    xi : array_like, shape (15,), optional
        Parameters (default nominal).

    Returns
    -------
    ndarray, shape like ``x``
        Encoder readings, m.
    """
    xi = _xi_or_nominal(xi)
    x = np.asarray(x, dtype=float)
    A, B = _legs(x, xi)
    return (np.linalg.norm(B - A, axis=2) - xi[12:15]).reshape(x.shape)


def mode_by_leg_lines(x, xi=None) -> np.ndarray:
    """Assembly mode from the leg lines, without CasADi: ``sign(cross(u1, u2) cross(u3, C12 - B3))``.

    ``C12`` is the intersection of leg lines 1 and 2; where they are parallel
    the mode is ``sign(cross(u1, u3) cross(u2, C13 - B2))`` (the same
    determinant with legs 2 and 3 swapped, hence the minus sign).

    Parameters
    ----------
    x : array_like, shape (N, 3) or (3,)
        Poses, m, m, rad.
    xi : array_like, shape (15,), optional

    Returns
    -------
    ndarray of int, shape (N,)
    """
    xi = _xi_or_nominal(xi)
    A, B = _legs(x, xi)
    u = B - A

    def cross(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    def meet(i, j):
        # B_i + t u_i on line j: cross(B_i + t u_i - B_j, u_j) = 0
        t = cross(B[:, j] - B[:, i], u[:, j]) / cross(u[:, i], u[:, j])
        return B[:, i] + t[:, None] * u[:, i]

    with np.errstate(divide="ignore", invalid="ignore"):
        m12 = np.sign(cross(u[:, 0], u[:, 1]) * cross(u[:, 2], meet(0, 1) - B[:, 2]))
        m13 = -np.sign(cross(u[:, 0], u[:, 2]) * cross(u[:, 1], meet(0, 2) - B[:, 1]))
    par = np.abs(cross(u[:, 0], u[:, 1])) < 1e-12 * np.linalg.norm(u[:, 0], axis=1) * np.linalg.norm(u[:, 1], axis=1)
    return np.where(par, m13, m12).astype(int)


def _det_on_line(px, xi) -> np.ndarray:
    px = np.atleast_1d(np.asarray(px, dtype=float))
    X = np.stack([px, np.full_like(px, BENCH_Y), np.full_like(px, BENCH_PHI)], axis=1)
    return _model().det_batch(X, rpr3_ik(X, xi), xi)


def singular_x(xi=None, *, samples: int = 201) -> float:
    """``p_x`` (m) where the benchmark line ``p_y = 0.14 m, phi = -0.3 rad`` meets the Type 2 locus.

    Scans ``det J_x`` over ``p_x`` in [0.15, 0.25] m and refines the sign
    change by Brent's method.

    Raises
    ------
    ModelError
        If ``det J_x`` does not change sign exactly once there.
    """
    xi = _xi_or_nominal(xi)
    xs = np.linspace(*_BENCH_X_RANGE, samples)
    det = _det_on_line(xs, xi)
    change = np.nonzero(np.sign(det[:-1]) * np.sign(det[1:]) <= 0)[0]
    if change.size != 1:
        raise ModelError(f"3-RPR: the benchmark line meets the Type 2 locus {change.size} times with xi = {xi.tolist()}")
    k = int(change[0])
    if det[k] == 0.0:
        return float(xs[k])
    return float(brentq(lambda v: float(_det_on_line(v, xi)[0]), xs[k], xs[k + 1], xtol=1e-16, rtol=1e-15,
                        maxiter=200))


def rpr3_benchmark_crossing(xi=None) -> BenchmarkCrossing:
    """The benchmark crossing for ``xi`` (default nominal): along ``+X`` through the locus."""
    xi = _xi_or_nominal(xi)
    point = np.array([singular_x(xi), BENCH_Y, BENCH_PHI])
    return BenchmarkCrossing(point=point, direction=np.array([1.0, 0.0, 0.0]), q_point=rpr3_ik(point, xi),
                             xi=xi.copy())
