"""Simulated encoder data of a robot crossing, or bouncing on, a Type 2 singularity.

The end-effector follows a straight segment of poses ``x(t) = p + s(t) u``
through a point ``p`` of the *nominal* Type 2 singular locus, ``u`` a unit
direction.  The arc length ``s(t)`` (m, or the pose unit) follows a
:class:`TimeLaw`: rest, a speed ramp up to ``v_sing`` (quintic smoothstep in
speed, so the acceleration is continuous, zero at both ends and peaks at
``a_peak``), constant speed through ``p +- cruise`` (zero acceleration at the
singular instant: the crossing criterion of the paper), a symmetric ramp
down, and rest.  The joints are the IK of the pose with the *true* geometry
``xi_true``, followed by continuation in the working branch of the legs; the
assembly mode changes by itself when the pose passes the true locus.

In a *bounce* the end-effector decelerates to rest exactly on the true locus
and retraces the segment back to its start: the assembly mode never changes.

Encoder readings are quantised (or randomly perturbed) with
``|q_meas - q_true| <= eps_q``.  Velocities and accelerations are exact: from
the time law and eq. (2) and its time derivative (CasADi AD), never finite
differences.  SI units throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from robots.base import Robot
from robots.kinematics import KinematicModel
from robots.errors import InputError, SimulationError

__all__ = [
    "RAMP_PEAK",
    "TimeLaw",
    "crossing_time_law",
    "bounce_time_law",
    "ramp_length",
    "SimulatedRun",
    "simulate_crossing",
    "simulate_bounce",
    "max_v_sing",
    "random_geometry",
]

#: Peak of the smoothstep derivative ``30 u^2 (1 - u)^2`` (at ``u = 1/2``):
#: a ramp of speed change ``dv`` over ``T`` peaks at ``|a| = RAMP_PEAK dv / T``.
RAMP_PEAK = 1.875
_QUANTISATIONS = ("floor", "round", "uniform")


def ramp_length(v: float, a_peak: float) -> tuple[float, float]:
    """Duration (s) and distance (m) of a rest-to-``v`` smoothstep ramp peaking at ``a_peak``.

    ``T = 1.875 v / a_peak`` and ``D = v T / 2 = 1.875 v^2 / (2 a_peak)``.
    """
    T = RAMP_PEAK * v / a_peak
    return T, 0.5 * v * T


# ------------------------------------------------------------------ time law
@dataclass(frozen=True)
class TimeLaw:
    """Piecewise arc length ``s(t)`` made of constant-speed and smoothstep-ramp segments.

    Attributes
    ----------
    segments : tuple of (t0, T, s0, v0, v1)
        Start time (s), duration (s), start arc length (m), start and end
        speeds (m/s).  Speed ramps from ``v0`` to ``v1`` as
        ``v0 + (v1 - v0) S(u)``, ``S(u) = 10u^3 - 15u^4 + 6u^5``,
        ``u = (t - t0) / T``; ``v0 == v1`` is a constant-speed segment.
    duration : float
        End time, s (the law holds the last position afterwards).
    """

    segments: tuple[tuple[float, float, float, float, float], ...]
    duration: float

    @staticmethod
    def build(s_start: float, pieces) -> "TimeLaw":
        """Chain ``pieces`` ``(T, v0, v1)`` from rest-state ``s_start`` at ``t = 0``."""
        segs = []
        t0, s0 = 0.0, float(s_start)
        for T, v0, v1 in pieces:
            if T <= 0.0:
                continue
            segs.append((t0, float(T), s0, float(v0), float(v1)))
            s0 = s0 + T * (v0 + v1) / 2.0  # both segment kinds average their end speeds
            t0 += T
        return TimeLaw(tuple(segs), t0)

    @property
    def s_start(self) -> float:
        """Arc length at ``t = 0``, m."""
        return self.segments[0][2]

    @property
    def s_end(self) -> float:
        """Arc length at the end, m."""
        t0, T, s0, v0, v1 = self.segments[-1]
        return s0 + T * (v0 + v1) / 2.0

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Arc length (m), speed (m/s) and acceleration (m/s^2) at times ``t`` (s), each shape of ``t``."""
        t = np.asarray(t, dtype=float)
        starts = np.array([seg[0] for seg in self.segments])
        # Each time belongs to the last segment starting strictly before it
        # (t = 0 to the first); u is clipped so times outside [0, duration]
        # hold the end states.
        idx = np.clip(np.searchsorted(starts, t, side="left") - 1, 0, len(starts) - 1)
        seg = np.array(self.segments)[idx]
        t0, T, s0, v0, v1 = (seg[..., j] for j in range(5))
        u = np.clip((t - t0) / T, 0.0, 1.0)
        dv = v1 - v0
        step = u**3 * (10.0 + u * (-15.0 + 6.0 * u))
        dstep = 30.0 * u**2 * (1.0 - u) ** 2
        istep = u**4 * (2.5 + u * (-3.0 + u))  # integral of step over [0, u]
        s = s0 + T * (v0 * u + dv * istep)
        v = v0 + dv * step
        a = np.where((t >= 0.0) & (t <= self.duration), dv / T * dstep, 0.0)
        return s, v, a


def crossing_time_law(v_sing: float, a_peak: float, cruise: float, t_rest: float,
                      t_rest_end: float) -> TimeLaw:
    """Rest, ramp to ``v_sing``, constant speed over ``s in [-cruise, cruise]``, ramp to rest, rest.

    ``s = 0`` is the nominal crossing point.  Units: m, s, m/s, m/s^2.
    """
    T, D = ramp_length(v_sing, a_peak)
    pieces = [
        (t_rest, 0.0, 0.0),
        (T, 0.0, v_sing),
        (2.0 * cruise / v_sing, v_sing, v_sing),
        (T, v_sing, 0.0),
        (t_rest_end, 0.0, 0.0),
    ]
    return TimeLaw.build(-(cruise + D), pieces)


def bounce_time_law(v_sing: float, a_peak: float, cruise: float, t_rest: float,
                    t_rest_end: float, s_touch: float) -> TimeLaw:
    """Approach at ``v_sing`` (constant over ``2 cruise``), stop at ``s_touch``, retrace to the start.

    The motion after the touching instant mirrors the approach in time, so the
    end-effector comes back to its start, at rest.  Units: m, s.
    """
    T, D = ramp_length(v_sing, a_peak)
    tc = 2.0 * cruise / v_sing
    pieces = [
        (t_rest, 0.0, 0.0),
        (T, 0.0, v_sing),
        (tc, v_sing, v_sing),
        (T, v_sing, 0.0),
        (T, 0.0, -v_sing),
        (tc, -v_sing, -v_sing),
        (T, -v_sing, 0.0),
        (t_rest_end, 0.0, 0.0),
    ]
    return TimeLaw.build(s_touch - 2.0 * (D + cruise), pieces)


# -------------------------------------------------------------- line scans
@dataclass(frozen=True)
class _Scan:
    """IK continuation along ``p + s u`` on a grid anchored at ``s = 0``."""

    s: np.ndarray        # (K,) increasing arc lengths
    q: np.ndarray        # (K, n) joints
    det: np.ndarray      # (K,) det J_x
    lo_done: bool        # the requested lower end was reached with valid IK
    hi_done: bool
    lo_fail: float       # first invalid arc length below (nan if lo_done)
    hi_fail: float


def _valid_poses(model: KinematicModel, X: np.ndarray, Q: np.ndarray, ok: np.ndarray) -> np.ndarray:
    r = model.robot
    inside = np.all((X >= r.x_lo_array) & (X <= r.x_hi_array), axis=1)
    in_lim = np.all((Q >= r.q_lo_array) & (Q <= r.q_hi_array), axis=1)
    return ok & inside & in_lim


def _scan_line(model, p, u, xi, q_guess, s_lo, s_hi, h) -> _Scan:
    """Continue the IK from ``s = 0`` outwards to ``s_lo < 0`` and ``s_hi > 0``, stopping when invalid.

    A pose is valid when IK converges with ``J_q`` regular, the pose lies in
    ``robot.x_bounds`` and the joints within their limits.
    """
    Q0, ok0 = model.ik_batch(p[None, :], xi, q_guess[None, :])
    if not _valid_poses(model, p[None, :], Q0, ok0)[0]:
        raise SimulationError(
            f"{model.robot.name}: no valid IK at the crossing point {p.tolist()} from "
            f"working_guess {q_guess.tolist()} (unreachable, joint limits, or outside x_bounds)"
        )
    sides = {}
    for sign, lim in ((-1.0, s_lo), (1.0, s_hi)):
        n_steps = int(math.ceil(abs(lim) / h - 1e-9))
        grid = sign * np.minimum(h * np.arange(1, n_steps + 1), abs(lim))
        s_list, q_list = [], []
        q_prev = Q0[0]
        q_prev2 = None
        done = True
        fail = math.nan
        for s in grid:
            x = p + s * u
            guess = q_prev if q_prev2 is None else 2.0 * q_prev - q_prev2  # linear predictor
            Qk, ok = model.ik_batch(x[None, :], xi, guess[None, :])
            if not _valid_poses(model, x[None, :], Qk, ok)[0]:
                done = False
                fail = s
                break
            s_list.append(s)
            q_list.append(Qk[0])
            q_prev2, q_prev = q_prev, Qk[0]
        sides[sign] = (s_list, q_list, done, fail)
    s_neg, q_neg, lo_done, lo_fail = sides[-1.0]
    s_pos, q_pos, hi_done, hi_fail = sides[1.0]
    s_all = np.array(s_neg[::-1] + [0.0] + s_pos)
    q_all = np.array(q_neg[::-1] + [Q0[0]] + q_pos).reshape(-1, model.n)
    det = model.det_batch(p + s_all[:, None] * u, q_all, xi)
    return _Scan(s_all, q_all, det, lo_done, hi_done, lo_fail, hi_fail)


def _refine_edge(model, p, u, xi, s_ok: float, q_ok: np.ndarray, s_bad: float) -> float:
    """Bisect between a valid arc length and an invalid one; returns the valid end (m)."""
    for _ in range(50):
        mid = 0.5 * (s_ok + s_bad)
        if mid in (s_ok, s_bad):
            break
        x = p + mid * u
        Q, ok = model.ik_batch(x[None, :], xi, q_ok[None, :])
        if _valid_poses(model, x[None, :], Q, ok)[0]:
            s_ok, q_ok = mid, Q[0]
        else:
            s_bad = mid
    return s_ok


def _sign_changes(det: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sign changes of ``det`` as index pairs ``(ka, kb)``, ``ka < kb``.

    ``det[ka]`` and ``det[kb]`` are non-zero with opposite signs and every value
    between them is exactly zero, so a zero sample on the locus counts once.
    """
    nz = np.nonzero(det != 0.0)[0]
    sg = np.sign(det[nz])
    flip = np.nonzero(sg[:-1] != sg[1:])[0]
    return nz[flip], nz[flip + 1]


def _q_interp(scan: _Scan, s) -> np.ndarray:
    s = np.atleast_1d(np.asarray(s, dtype=float))
    return np.stack([np.interp(s, scan.s, scan.q[:, j]) for j in range(scan.q.shape[1])], axis=1)


def _locate_singularity(model, p, u, xi, scan: _Scan, ka: int, kb: int) -> float:
    """Arc length (m) of the sign change of det J_x between scan points ka and kb (Brent)."""

    def g(s: float) -> float:
        x = p + s * u
        Q, ok = model.ik_batch(x[None, :], xi, _q_interp(scan, s))
        if not ok[0]:
            raise SimulationError(f"{model.robot.name}: IK failed near the singular point at s = {s}")
        return float(model.det_batch(x[None, :], Q, xi)[0])

    return float(brentq(g, scan.s[ka], scan.s[kb], xtol=1e-15, rtol=1e-15, maxiter=200))


def _extent(model, p, u, xi, q_guess, cruise, h):
    """Largest valid path around ``p``: returns ``(s_true, e_lo, e_hi)`` (m).

    ``s_true`` is the true crossing nearest ``p``; ``[e_lo, e_hi]`` the largest
    interval around it, on the scan grid, with valid IK and no other sign
    change of det J_x.
    """
    r = model.robot
    span = float(np.linalg.norm(r.x_hi_array - r.x_lo_array))  # no valid pose beyond this
    scan = _scan_line(model, p, u, xi, q_guess, -span, span, h)
    s_true, j = _true_crossing(model, p, u, xi, scan, cruise)
    ka, kb = _sign_changes(scan.det)
    if j > 0:  # another singularity before: stop at it
        e_lo = _locate_singularity(model, p, u, xi, scan, int(ka[j - 1]), int(kb[j - 1]))
    elif scan.lo_done:
        e_lo = scan.s[0]
    else:
        e_lo = _refine_edge(model, p, u, xi, scan.s[0], scan.q[0], scan.lo_fail)
    if j + 1 < ka.size:
        e_hi = _locate_singularity(model, p, u, xi, scan, int(ka[j + 1]), int(kb[j + 1]))
    elif scan.hi_done:
        e_hi = scan.s[-1]
    else:
        e_hi = _refine_edge(model, p, u, xi, scan.s[-1], scan.q[-1], scan.hi_fail)
    # Keep a micrometre-scale margin so a path ending at the edge stays valid.
    margin = 1e-3 * h
    return s_true, float(e_lo) + margin, float(e_hi) - margin


def _true_crossing(model, p, u, xi, scan: _Scan, cruise: float) -> tuple[float, int]:
    """The sign change of det J_x nearest ``s = 0`` (and its pair index); must lie within ``(-cruise, cruise)``."""
    ka, kb = _sign_changes(scan.det)
    if ka.size == 0:
        raise SimulationError(
            f"{model.robot.name}: the path through {p.tolist()} along {u.tolist()} does not meet "
            "the Type 2 singular locus of the true geometry; pass a point of the nominal locus"
        )
    mid = 0.5 * (scan.s[ka] + scan.s[kb])
    j = int(np.argmin(np.abs(mid)))
    s_true = _locate_singularity(model, p, u, xi, scan, int(ka[j]), int(kb[j]))
    if not abs(s_true) < cruise:
        raise SimulationError(
            f"{model.robot.name}: the true singular point is {s_true * 1e3:.3f} mm from the nominal "
            f"crossing point, outside the constant-speed zone +-{cruise * 1e3:.3f} mm; increase cruise"
        )
    return s_true, j


def _v_from_distance(dist: float, a_peak: float) -> float:
    return math.sqrt(2.0 * a_peak * dist / RAMP_PEAK) if dist > 0 else 0.0


def _scan_step(robot: Robot) -> float:
    # ~1 mm for a 0.26 m workspace: small enough for Newton continuation.
    return float(np.min(robot.x_hi_array - robot.x_lo_array)) / 256.0


# ------------------------------------------------------------------ checks
def _vec(name: str, v, n: int) -> np.ndarray:
    """A finite float vector of length ``n`` (a copy), or InputError naming ``name``."""
    try:
        a = np.array(v, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a numeric vector of length {n}") from exc
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise InputError(f"{name} must be a finite vector of length {n}, got {v!r}")
    return a


def _pos(name: str, v, *, allow_zero: bool = False) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a number, got {v!r}") from exc
    if not math.isfinite(f) or f < 0 or (f == 0 and not allow_zero):
        raise InputError(f"{name} must be {'>= 0' if allow_zero else '> 0'} and finite, got {v!r}")
    return f


def random_geometry(robot: Robot, rng=None, *, corners: bool = False) -> np.ndarray:
    """A random true geometry in the calibration box.

    Parameters
    ----------
    robot : Robot
    rng : numpy.random.Generator or int or None
        Generator, or a seed for ``numpy.random.default_rng``.
    corners : bool
        Draw a random corner of ``[xi_lo, xi_hi]`` instead of a uniform point.

    Returns
    -------
    ndarray, shape (m,)
        Parameters, SI.
    """
    rng = np.random.default_rng(rng)
    lo, hi = robot.xi_lo_array, robot.xi_hi_array
    if corners:
        return np.where(rng.integers(0, 2, size=robot.m) == 1, hi, lo)
    return np.clip(lo + (hi - lo) * rng.random(robot.m), lo, hi)


# ------------------------------------------------------------------ result
@dataclass(frozen=True)
class SimulatedRun:
    """A simulated motion sampled at ``t_s``: ground truth and encoder readings.

    All arrays are read-only.  ``N`` samples, ``n`` joints/pose coordinates.

    Attributes
    ----------
    robot_name : str
    t : ndarray (N,)
        Sample times ``k t_s``, s.
    q_meas : ndarray (N, n)
        Encoder readings, rad, ``|q_meas - q_true| <= eps_q``.
    q_true, qd_true, qdd_true : ndarray (N, n)
        Joints (rad), joint velocities (rad/s), accelerations (rad/s^2).
    x_true, xd_true, xdd_true : ndarray (N, n)
        Pose (m), velocity (m/s), acceleration (m/s^2).
    mode_true : ndarray of int (N,)
        Assembly mode from the true geometry: +1/-1, 0 on the locus.
    xi_true : ndarray (m,)
        True geometry.
    k_sing : int
        Sample at the singular instant (crossing or touching); the time law is
        shifted so that this instant is exactly ``t[k_sing]``.
    t_sing : float
        Singular instant, s.
    x_sing : ndarray (n,)
        Where the path meets the true singular locus, m.
    s_sing : float
        Signed distance (m) from the nominal crossing point to ``x_sing`` along
        ``direction``.
    v_sing : float
        Speed at the crossing (for a bounce: the approach speed), m/s.
    bounce : bool
        True for a bounce (no mode change), False for a crossing.
    crossing_point, direction : ndarray (n,)
        Nominal crossing point (m) and unit direction of the path.
    t_s, eps_q, a_peak : float
        Sampling period (s), encoder error bound (rad), peak acceleration (m/s^2).
    quantisation : str
        ``"floor"``, ``"round"`` or ``"uniform"``.
    time_law : TimeLaw
        Arc length law, relative to ``crossing_point``.
    """

    robot_name: str
    t: np.ndarray
    q_meas: np.ndarray
    q_true: np.ndarray
    x_true: np.ndarray
    xd_true: np.ndarray
    xdd_true: np.ndarray
    qd_true: np.ndarray
    qdd_true: np.ndarray
    mode_true: np.ndarray
    xi_true: np.ndarray
    k_sing: int
    t_sing: float
    x_sing: np.ndarray
    s_sing: float
    v_sing: float
    bounce: bool
    crossing_point: np.ndarray
    direction: np.ndarray
    t_s: float
    eps_q: float
    a_peak: float
    quantisation: str
    time_law: TimeLaw = field(repr=False)

    def __post_init__(self) -> None:
        for name in ("t", "q_meas", "q_true", "x_true", "xd_true", "xdd_true", "qd_true",
                     "qdd_true", "mode_true", "xi_true", "x_sing", "crossing_point", "direction"):
            getattr(self, name).setflags(write=False)

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return int(self.t.shape[0])


# -------------------------------------------------------------- simulation
def _prepare(model, crossing_point, direction, v_sing, xi_true, t_s, eps_q, t_rest, t_rest_end,
             a_peak, cruise, working_guess, quantisation, strict_xi):
    if not isinstance(model, KinematicModel):
        raise InputError(f"model must be a KinematicModel, got {type(model).__name__}")
    r = model.robot
    n = model.n
    p = _vec("crossing_point", crossing_point, n)
    d = _vec("direction", direction, n)
    nd = float(np.linalg.norm(d))
    if nd == 0.0:
        raise InputError("direction must be non-zero")
    u = d / nd
    v_sing = _pos("v_sing", v_sing)
    a_peak = _pos("a_peak", a_peak)
    cruise = _pos("cruise", cruise)
    t_rest = _pos("t_rest", t_rest, allow_zero=True)
    t_rest_end = _pos("t_rest_end", t_rest_end, allow_zero=True)
    t_s = _pos("t_s", r.t_s if t_s is None else t_s)
    eps_q = _pos("eps_q", r.eps_q if eps_q is None else eps_q)
    peak = a_peak * np.abs(u)
    if np.any(peak >= r.a_max_array):
        raise InputError(
            f"a_peak = {a_peak} m/s^2 along {u.tolist()} reaches the robot's bound a_max = "
            f"{list(r.a_max)}; choose a_peak below it so the tracker's bound holds"
        )
    xi = r.xi_center if xi_true is None else _vec("xi_true", xi_true, r.m)
    if strict_xi and not r.xi_in_box(xi):
        raise InputError(
            f"xi_true = {xi.tolist()} lies outside the calibration box of {r.name}; the "
            "certificate only covers geometries inside it (pass strict_xi=False to allow)"
        )
    if working_guess is None:
        raise InputError("working_guess (joints on the working branch, rad) is required")
    qg = _vec("working_guess", working_guess, n)
    if quantisation not in _QUANTISATIONS:
        raise InputError(f"quantisation must be one of {_QUANTISATIONS}, got {quantisation!r}")
    return p, u, v_sing, a_peak, cruise, t_rest, t_rest_end, t_s, eps_q, xi, qg


def _aligned(law_fn, t_sing_rel: float, t_rest: float, t_s: float):
    """Shift the initial rest by less than ``t_s`` so the singular instant is a sample time."""
    k = math.ceil((t_rest + t_sing_rel) / t_s - 1e-9)
    extra = max(0.0, k * t_s - (t_rest + t_sing_rel))
    return law_fn(t_rest + extra), k


def _measure(q_true: np.ndarray, eps_q: float, quantisation: str, rng) -> np.ndarray:
    if quantisation == "floor":
        return eps_q * np.floor(q_true / eps_q)
    if quantisation == "round":
        return eps_q * np.round(q_true / eps_q)
    # Shrink by 1e-9 so rounding of q_true + e cannot push |e| past eps_q.
    return q_true + eps_q * (1.0 - 1e-9) * rng.uniform(-1.0, 1.0, size=q_true.shape)


def _simulate(bounce, model, crossing_point, direction, v_sing, *, xi_true, t_s, eps_q, t_rest,
              t_rest_end, a_peak, cruise, working_guess, seed, quantisation, strict_xi):
    p, u, v_sing, a_peak, cruise, t_rest, t_rest_end, t_s, eps_q, xi, qg = _prepare(
        model, crossing_point, direction, v_sing, xi_true, t_s, eps_q, t_rest, t_rest_end,
        a_peak, cruise, working_guess, quantisation, strict_xi)
    name = model.robot.name
    T, D = ramp_length(v_sing, a_peak)
    h = _scan_step(model.robot)
    # Scan exactly the arc lengths the motion needs (grid ends on the path ends);
    # a bounce starts 2 (D + cruise) before the true locus, found first.
    if bounce:
        near = _scan_line(model, p, u, xi, qg, -cruise, cruise, h)
        if near.s.size < 2:
            raise SimulationError(f"{name}: no valid IK next to the crossing point {p.tolist()}")
        s_touch, _j = _true_crossing(model, p, u, xi, near, cruise)
        scan = _scan_line(model, p, u, xi, qg, s_touch - 2.0 * (D + cruise), cruise, h)
    else:
        scan = _scan_line(model, p, u, xi, qg, -(D + cruise), D + cruise, h)

    def too_fast(reason: str):
        s_true, e_lo, e_hi = _extent(model, p, u, xi, qg, cruise, h)
        if bounce:
            vmax = _v_from_distance((s_true - e_lo) / 2.0 - cruise, a_peak)
        else:
            vmax = _v_from_distance(min(-e_lo, e_hi) - cruise, a_peak)
        return SimulationError(
            f"{name}: v_sing = {v_sing:.4g} m/s needs {reason}; the valid path around the "
            f"crossing point spans [{e_lo * 1e3:.1f}, {e_hi * 1e3:.1f}] mm, so v_sing <= "
            f"{vmax:.4g} m/s at a_peak = {a_peak:g} m/s^2 and cruise = {cruise * 1e3:g} mm"
        )

    if scan.s.size < 2:
        raise too_fast("poses beyond the reachable/valid segment")
    s_true, j = _true_crossing(model, p, u, xi, scan, cruise)
    s_start = s_true - 2.0 * (D + cruise) if bounce else -(D + cruise)
    s_end = s_true if bounce else D + cruise
    if not scan.lo_done and scan.s[0] > s_start:
        raise too_fast(f"a start pose {-s_start * 1e3:.1f} mm before the crossing point, which is "
                       "outside the workspace or unreachable")
    if not bounce and not scan.hi_done:
        raise too_fast(f"an end pose {s_end * 1e3:.1f} mm past the crossing point, which is outside "
                       "the workspace or unreachable")
    ka, kb = _sign_changes(scan.det)
    inside = (scan.s[kb] > s_start) & (scan.s[ka] < s_end)
    inside[j] = False
    if inside.any():
        raise too_fast("a path that meets another Type 2 singularity")

    if bounce:
        law, k_sing = _aligned(
            lambda tr: bounce_time_law(v_sing, a_peak, cruise, tr, t_rest_end, s_true),
            2.0 * T + 2.0 * cruise / v_sing, t_rest, t_s)
    else:
        law, k_sing = _aligned(
            lambda tr: crossing_time_law(v_sing, a_peak, cruise, tr, t_rest_end),
            T + (s_true + cruise) / v_sing, t_rest, t_s)
    n_samp = int(math.floor(law.duration / t_s + 1e-9)) + 1
    t = np.arange(n_samp) * t_s
    s, v, a = law.evaluate(t)
    s[k_sing] = s_true  # the singular sample lies exactly on the true locus
    if bounce:
        v[k_sing] = a[k_sing] = 0.0  # the touching instant, exactly
    X = p + s[:, None] * u
    XD = v[:, None] * u
    XDD = a[:, None] * u
    Qg = _q_interp(scan, s)
    Q, ok = model.ik_batch(X, xi, Qg)
    ok = _valid_poses(model, X, Q, ok)
    if not ok.all():
        raise too_fast(f"a valid IK at every sample (fails at t = {t[~ok][0]:.4f} s)")
    if np.max(np.abs(Q - Qg)) > 0.2:
        raise SimulationError(f"{name}: IK left the working branch along the path (step too coarse?)")
    QD = model.joint_velocity(X, Q, xi, XD)
    QDD = model.joint_acceleration(X, Q, xi, XD, QD, XDD)
    modes = model.mode_batch(X, Q, xi)
    nz = modes[modes != 0]
    flips = int(np.count_nonzero(nz[1:] != nz[:-1]))
    if flips != (0 if bounce else 1):
        raise SimulationError(f"{name}: simulated mode changed {flips} times (expected {0 if bounce else 1})")
    rng = np.random.default_rng(seed)
    q_meas = _measure(Q, eps_q, quantisation, rng)
    return SimulatedRun(
        robot_name=name, t=t, q_meas=q_meas, q_true=Q, x_true=X, xd_true=XD, xdd_true=XDD,
        qd_true=QD, qdd_true=QDD, mode_true=modes, xi_true=np.array(xi), k_sing=int(k_sing),
        t_sing=float(t[k_sing]), x_sing=p + s_true * u, s_sing=float(s_true), v_sing=v_sing,
        bounce=bounce, crossing_point=p, direction=u, t_s=t_s, eps_q=eps_q, a_peak=a_peak,
        quantisation=quantisation, time_law=law,
    )


def simulate_crossing(model: KinematicModel, crossing_point, direction, v_sing: float, *,
                      xi_true=None, t_s: float | None = None, eps_q: float | None = None,
                      t_rest: float = 0.5, t_rest_end: float = 0.1, a_peak: float = 60.0,
                      cruise: float = 5e-3, working_guess=None, seed=None,
                      quantisation: str = "floor", strict_xi: bool = True) -> SimulatedRun:
    """Simulate a straight crossing of the Type 2 locus: the assembly mode changes once.

    Rest, smoothstep ramp to ``v_sing``, constant speed over ``crossing_point +-
    cruise`` (zero acceleration at the true crossing), ramp down, rest.

    Parameters
    ----------
    model : KinematicModel
    crossing_point : array_like, shape (n,)
        A point of the *nominal* Type 2 singular locus, SI.
    direction : array_like, shape (n,)
        Direction of motion through it (normalised here).
    v_sing : float
        Speed at the singular point (bounce: approach speed), m/s.
    xi_true : array_like, shape (m,), optional
        True geometry, inside the calibration box unless ``strict_xi=False``;
        default the box centre.
    t_s, eps_q : float, optional
        Sampling period (s) and encoder error bound (rad); robot defaults.
    t_rest, t_rest_end : float
        Rest before (default 0.5 s, lets a tracker settle) and after (0.1 s).
    a_peak : float
        Peak acceleration of the ramps, m/s^2; must stay below ``robot.a_max``.
    cruise : float
        Half-length of the constant-speed zone around the crossing point, m.
    working_guess : array_like, shape (n,)
        Joints on the working branch of the legs (e.g. near the start), rad:
        Newton's start for the IK at the crossing point, then continuation.
    seed : int or numpy.random.Generator, optional
        Seeds ``numpy.random.default_rng`` (used by ``"uniform"``).
    quantisation : {"floor", "round", "uniform"}
        ``eps_q * floor(q / eps_q)``, ``eps_q * round(q / eps_q)``, or
        ``q + U[-eps_q, eps_q]``.
    strict_xi : bool
        Reject ``xi_true`` outside the calibration box.

    Returns
    -------
    SimulatedRun

    Raises
    ------
    InputError
        Malformed arguments, ``a_peak`` not below ``a_max``, ``xi_true`` outside the box.
    SimulationError
        Start/end pose outside the workspace or unreachable, IK failure, or the
        path meeting another singularity (the message gives the largest
        feasible ``v_sing``); true singular point outside the cruise zone.
    """
    return _simulate(False, model, crossing_point, direction, v_sing, xi_true=xi_true, t_s=t_s,
                     eps_q=eps_q, t_rest=t_rest, t_rest_end=t_rest_end, a_peak=a_peak,
                     cruise=cruise, working_guess=working_guess, seed=seed,
                     quantisation=quantisation, strict_xi=strict_xi)


def simulate_bounce(model: KinematicModel, crossing_point, direction, v_sing: float, *,
                    xi_true=None, t_s: float | None = None, eps_q: float | None = None,
                    t_rest: float = 0.5, t_rest_end: float = 0.1, a_peak: float = 60.0,
                    cruise: float = 5e-3, working_guess=None, seed=None,
                    quantisation: str = "floor", strict_xi: bool = True) -> SimulatedRun:
    """Simulate a failed crossing: the end-effector stops on the true locus and comes back.

    Rest, ramp to ``v_sing``, constant speed over ``2 cruise``, smoothstep
    deceleration to rest exactly on the true singular locus (``|a| <= a_peak``),
    then the mirror image in time back to the start, rest.  The start lies
    ``2 (D + cruise)`` before the true locus, ``D`` the ramp length.  The mode
    never changes (it is 0 at the touching sample ``k_sing``).  Parameters,
    returns and errors as in :func:`simulate_crossing` (``v_sing`` is the
    approach speed).
    """
    return _simulate(True, model, crossing_point, direction, v_sing, xi_true=xi_true, t_s=t_s,
                     eps_q=eps_q, t_rest=t_rest, t_rest_end=t_rest_end, a_peak=a_peak,
                     cruise=cruise, working_guess=working_guess, seed=seed,
                     quantisation=quantisation, strict_xi=strict_xi)


def max_v_sing(model: KinematicModel, crossing_point, direction, *, xi_true=None,
               a_peak: float = 60.0, cruise: float = 5e-3, working_guess=None,
               bounce: bool = False, strict_xi: bool = True) -> float:
    """Largest ``v_sing`` (m/s) whose crossing (or bounce) path stays valid.

    The path must keep valid IK (in ``x_bounds``, joint limits, ``J_q``
    regular) and meet no other Type 2 singularity.  The valid extent is found
    by IK continuation on a grid of step ``h = min(x_bounds side) / 256``,
    its ends refined by bisection (or Brent's method for another singularity)
    and pulled in by ``h / 1000``.  Arguments as in :func:`simulate_crossing`.
    """
    p, u, _v, a_peak, cruise, _tr, _te, _ts, _eq, xi, qg = _prepare(
        model, crossing_point, direction, 1.0, xi_true, None, None, 0.0, 0.0, a_peak, cruise,
        working_guess, "floor", strict_xi)
    s_true, e_lo, e_hi = _extent(model, p, u, xi, qg, cruise, _scan_step(model.robot))
    if bounce:
        return _v_from_distance((s_true - e_lo) / 2.0 - cruise, a_peak)
    return _v_from_distance(min(-e_lo, e_hi) - cruise, a_peak)
