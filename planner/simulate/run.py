"""Simulated runs: the motion, its true joints and what the encoders read.

See :mod:`planner.simulate` for the model of the motion.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from crosscert.robots.assumptions import check_bound
from crosscert.robots import arguments as V
from crosscert.robots.base import Robot
from crosscert.robots.errors import InputError, SimulationError
from crosscert.robots.kinematics import KinematicModel
from crosscert.verifier.trajectory import Trajectory

from ..locus import joints_along, nearest_crossing, scan_line, sign_changes, valid_extent, valid_poses
from ..sampling import align_to_samples
from .measure import Quantisation, quantise
from .timelaw import RAMP_PEAK, TimeLaw, bounce_time_law, crossing_time_law, ramp_length

__all__ = ["SimulatedRun", "simulate_crossing", "simulate_bounce", "simulate_motion", "max_v_sing", "A_PEAK",
           "CRUISE", "REST_END"]

#: Peak acceleration of the simulated speed ramps, m/s^2 (the paper's runs).
A_PEAK = 60.0
#: Half-length of the constant-speed cruise around the crossing, m.
CRUISE = 5e-3
#: Rest after the motion, s.
REST_END = 0.1

#: Largest joint change (rad) between the IK guess interpolated from the scan
#: and the IK at a sample: more means the IK jumped to another branch.
BRANCH_JUMP = 0.2


@dataclass(frozen=True, kw_only=True, eq=False)
class SimulatedRun(Trajectory):
    """A simulated motion sampled at ``t_s``: ground truth and encoder readings.

    A :class:`~verifier.Trajectory` whose fields are the **truth**: ``q``, ``qd``,
    ``qdd`` (rad, rad/s, rad/s^2) and ``x``, ``xd``, ``xdd`` (m, m/s, m/s^2),
    shape ``(N, n)``; ``q_true``, ``x_true``, ... name the same arrays in the
    words of a simulation.  All arrays are read-only.

    Attributes
    ----------
    robot_name : str
    q_meas : ndarray (N, n)
        Encoder readings, rad, ``|q_meas - q_true| <= eps_q``.
    mode_true : ndarray of int (N,)
        Assembly mode from the true geometry: +1/-1, 0 on the locus.
    xi_true : ndarray (m,)
        True geometry.
    k_sing : int
        Sample at the singular instant (crossing, touching, or turning back
        ``short`` before the locus); the time law is shifted so that this
        instant is exactly ``t[k_sing]``.
    t_sing : float
        Singular instant, s.
    x_sing : ndarray (n,)
        Where the path (extended) meets the true singular locus, m; a bounce
        turns back at ``x_sing - short * direction``.
    s_sing : float
        Signed distance (m) from the nominal crossing point to ``x_sing`` along
        ``direction``.
    v_sing : float
        Speed at the crossing (for a bounce: the approach speed), m/s.
    bounce : bool
        True for a bounce (no mode change), False for a crossing.
    short : float
        For a bounce: how far (m) before the true locus it turns back, along
        ``direction`` (0: it touches the locus).  0 for a crossing.
    crossing_point, direction : ndarray (n,)
        Nominal crossing point (m) and unit direction of the path.
    eps_q, a_peak : float
        Encoder error bound (rad), peak acceleration (m/s^2).
    quantisation : Quantisation
    time_law : TimeLaw
        Arc length law, relative to ``crossing_point``.
    """

    robot_name: str
    q_meas: np.ndarray
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
    eps_q: float
    a_peak: float
    quantisation: Quantisation
    time_law: TimeLaw = field(repr=False)
    short: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("q_meas", "xi_true", "x_sing", "crossing_point", "direction"):
            object.__setattr__(self, name, V.frozen_array(getattr(self, name)))
        modes = np.array(self.mode_true, dtype=int)
        modes.setflags(write=False)
        object.__setattr__(self, "mode_true", modes)

    q_true = property(lambda self: self.q, doc="True joints, rad, (N, n): ``q``.")
    qd_true = property(lambda self: self.qd, doc="True joint velocities, rad/s: ``qd``.")
    qdd_true = property(lambda self: self.qdd, doc="True joint accelerations, rad/s^2: ``qdd``.")
    x_true = property(lambda self: self.x, doc="True pose, m: ``x``.")
    xd_true = property(lambda self: self.xd, doc="True velocity, m/s: ``xd``.")
    xdd_true = property(lambda self: self.xdd, doc="True acceleration, m/s^2: ``xdd``.")

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return len(self)

    def recording(self) -> Trajectory:
        """What the encoders recorded: the readings ``q_meas`` at ``t``."""
        return Trajectory(t=self.t, q=self.q_meas, t_s=self.t_s)


def _v_from_distance(dist: float, a_peak: float) -> float:
    return math.sqrt(2.0 * a_peak * dist / RAMP_PEAK) if dist > 0 else 0.0


def _scan_step(robot: Robot) -> float:
    # ~1 mm for a 0.26 m workspace: small enough for Newton continuation.
    return float(np.min(robot.x_hi_array - robot.x_lo_array)) / 256.0


def _prepare(model, crossing_point, direction, v_sing, xi_true, t_s, eps_q, t_rest, t_rest_end,
             a_peak, cruise, working_guess, quantisation, strict_xi):
    if not isinstance(model, KinematicModel):
        raise InputError(f"model must be a KinematicModel, got {type(model).__name__}")
    r = model.robot
    n = model.n
    p = V.vector("crossing_point", crossing_point, n)
    u = V.direction("direction", direction, n)
    v_sing = V.positive("v_sing", v_sing)
    a_peak = V.positive("a_peak", a_peak)
    cruise = V.positive("cruise", cruise)
    t_rest = V.positive("t_rest", t_rest, allow_zero=True)
    t_rest_end = V.positive("t_rest_end", t_rest_end, allow_zero=True)
    t_s = check_bound("t_s", r.t_s if t_s is None else t_s)
    eps_q = check_bound("eps_q", r.eps_q if eps_q is None else eps_q)
    peak = a_peak * np.abs(u)
    if np.any(peak >= r.a_max_array):
        raise InputError(
            f"a_peak = {a_peak} m/s^2 along {u.tolist()} reaches the robot's bound a_max = "
            f"{list(r.a_max)}; choose a_peak below it so the tracker's bound holds"
        )
    xi = r.xi_center if xi_true is None else V.vector("xi_true", xi_true, r.m)
    if strict_xi and not r.xi_in_box(xi):
        raise InputError(
            f"xi_true = {xi.tolist()} lies outside the calibration box of {r.name}; the "
            "certificate only covers geometries inside it (pass strict_xi=False to allow)"
        )
    if working_guess is None:
        raise InputError("working_guess (joints on the working branch, rad) is required")
    qg = V.vector("working_guess", working_guess, n)
    try:
        quantisation = Quantisation(quantisation)
    except ValueError:
        raise InputError(f"quantisation must be one of {[k.value for k in Quantisation]}, got {quantisation!r}") from None
    return p, u, v_sing, a_peak, cruise, t_rest, t_rest_end, t_s, eps_q, xi, qg


def _aligned(law_fn, t_sing_rel: float, t_rest: float, t_s: float):
    """The law with its initial rest grown by less than ``t_s`` so the singular instant is a sample time."""
    at = align_to_samples(t_rest + t_sing_rel, law_fn(t_rest).duration, t_s)
    return law_fn(t_rest + at.shift), at.k_event, at.samples


def _simulate(bounce, model, crossing_point, direction, v_sing, *, xi_true, t_s, eps_q, t_rest,
              t_rest_end, a_peak, cruise, working_guess, seed, quantisation, strict_xi, short=0.0):
    """A simulated crossing (:func:`simulate_crossing`) or, if ``bounce``, bounce (:func:`simulate_bounce`)."""
    p, u, v_sing, a_peak, cruise, t_rest, t_rest_end, t_s, eps_q, xi, qg = _prepare(
        model, crossing_point, direction, v_sing, xi_true, t_s, eps_q, t_rest, t_rest_end,
        a_peak, cruise, working_guess, quantisation, strict_xi)
    short = V.positive("short", short, allow_zero=True)
    name = model.robot.name
    T, D = ramp_length(v_sing, a_peak)
    h = _scan_step(model.robot)
    scan = _scan(model, p, u, xi, qg, bounce=bounce, short=short, cruise=cruise, D=D, h=h)
    too_fast = functools.partial(_too_fast, model, p, u, xi, qg, bounce=bounce, short=short, v_sing=v_sing,
                                 a_peak=a_peak, cruise=cruise, h=h)
    s_true = _check_scan(model, p, u, xi, scan, bounce=bounce, short=short, cruise=cruise, D=D,
                         too_fast=too_fast)
    s_turn = s_true - short  # a bounce turns back here (on the locus when short = 0)
    if bounce:
        law, k_sing, n_samp = _aligned(
            lambda tr: bounce_time_law(v_sing, a_peak, cruise, tr, t_rest_end, s_turn),
            2.0 * T + 2.0 * cruise / v_sing, t_rest, t_s)
    else:
        law, k_sing, n_samp = _aligned(
            lambda tr: crossing_time_law(v_sing, a_peak, cruise, tr, t_rest_end),
            T + (s_true + cruise) / v_sing, t_rest, t_s)
    t = np.arange(n_samp) * t_s
    s, v, a = law.evaluate(t)
    s[k_sing] = s_turn if bounce else s_true  # the singular sample: exactly on the locus, or short of it
    if bounce:
        v[k_sing] = a[k_sing] = 0.0  # the touching instant, exactly
    X, XD, XDD, Q, QD, QDD, modes = _sampled_motion(model, p, u, xi, scan, t, s, v, a, bounce=bounce,
                                                    too_fast=too_fast)
    rng = np.random.default_rng(seed)
    q_meas = quantise(Q, eps_q, quantisation, rng)
    return SimulatedRun(
        robot_name=name, t=t, q_meas=q_meas, q=Q, x=X, xd=XD, xdd=XDD,
        qd=QD, qdd=QDD, mode_true=modes, xi_true=np.array(xi), k_sing=int(k_sing),
        t_sing=float(t[k_sing]), x_sing=p + s_true * u, s_sing=float(s_true), v_sing=v_sing,
        bounce=bounce, crossing_point=p, direction=u, t_s=t_s, eps_q=eps_q, a_peak=a_peak,
        quantisation=quantisation, time_law=law, short=short if bounce else 0.0,
    )


def _scan(model, p, u, xi, qg, *, bounce, short, cruise, D, h):
    """IK continuation along the line ``p + s u`` over exactly the arc lengths (m) the motion needs.

    The grid ends on the path ends: ``[-(D + cruise), D + cruise]`` for a
    crossing (``D`` the ramp length, m); a bounce starts ``2 (D + cruise)``
    before its turning point, ``short`` before the true locus (found first).

    Raises
    ------
    SimulationError
        For a bounce, no valid IK next to the crossing point.
    """
    if bounce:
        near = scan_line(model, p, u, xi, qg, -cruise, cruise, h)
        if near.s.size < 2:
            raise SimulationError(f"{model.robot.name}: no valid IK next to the crossing point {p.tolist()}")
        s_touch, _j = nearest_crossing(model, p, u, xi, near, cruise)
        return scan_line(model, p, u, xi, qg, s_touch - short - 2.0 * (D + cruise), cruise, h)
    return scan_line(model, p, u, xi, qg, -(D + cruise), D + cruise, h)


def _too_fast(model, p, u, xi, qg, reason: str, *, bounce, short, v_sing, a_peak, cruise, h) -> SimulationError:
    """The error of a ``v_sing`` (m/s) whose path needs ``reason``, with the largest feasible ``v_sing``."""
    s_true, e_lo, e_hi = valid_extent(model, p, u, xi, qg, cruise, h)
    if bounce:
        vmax = _v_from_distance((s_true - short - e_lo) / 2.0 - cruise, a_peak)
    else:
        vmax = _v_from_distance(min(-e_lo, e_hi) - cruise, a_peak)
    return SimulationError(
        f"{model.robot.name}: v_sing = {v_sing:.4g} m/s needs {reason}; the valid path around the "
        f"crossing point spans [{e_lo * 1e3:.1f}, {e_hi * 1e3:.1f}] mm, so v_sing <= "
        f"{vmax:.4g} m/s at a_peak = {a_peak:g} m/s^2 and cruise = {cruise * 1e3:g} mm"
    )


def _check_scan(model, p, u, xi, scan, *, bounce, short, cruise, D, too_fast):
    """The arc length (m) of the true crossing; the scan must span the whole path, meeting no other locus.

    Raises
    ------
    SimulationError
        ``too_fast(reason)`` when the path leaves the valid segment or meets
        another Type 2 singularity; no true crossing within the cruise zone.
    """
    if scan.s.size < 2:
        raise too_fast("poses beyond the reachable/valid segment")
    s_true, j = nearest_crossing(model, p, u, xi, scan, cruise)
    s_turn = s_true - short  # a bounce turns back here (on the locus when short = 0)
    s_start = s_turn - 2.0 * (D + cruise) if bounce else -(D + cruise)
    s_end = s_turn if bounce else D + cruise
    if not scan.lo_done and scan.s[0] > s_start:
        raise too_fast(f"a start pose {-s_start * 1e3:.1f} mm before the crossing point, which is "
                       "outside the workspace or unreachable")
    if not bounce and not scan.hi_done:
        raise too_fast(f"an end pose {s_end * 1e3:.1f} mm past the crossing point, which is outside "
                       "the workspace or unreachable")
    ka, kb = sign_changes(scan.det)
    inside = (scan.s[kb] > s_start) & (scan.s[ka] < s_end)
    inside[j] = False  # the locus the path is meant to meet (at s_true, beyond a short bounce's end)
    if inside.any():
        raise too_fast("a path that meets another Type 2 singularity")
    return s_true


def _sampled_motion(model, p, u, xi, scan, t, s, v, a, *, bounce, too_fast):
    """Poses, joints and their rates at the samples of the arc length law ``s, v, a`` (m, m/s, m/s^2).

    Returns
    -------
    X, XD, XDD : ndarray, shape (K, n)
        Pose (m), velocity (m/s), acceleration (m/s^2).
    Q, QD, QDD : ndarray, shape (K, n)
        Joints (rad), their velocities (rad/s) and accelerations (rad/s^2).
    modes : ndarray of int, shape (K,)
        Assembly modes.

    Raises
    ------
    SimulationError
        IK fails or leaves the working branch at a sample (``too_fast``: the
        message gives the largest feasible ``v_sing``); the mode changes other
        than once for a crossing, at all for a bounce.
    """
    name = model.robot.name
    X = p + s[:, None] * u
    XD = v[:, None] * u
    XDD = a[:, None] * u
    Qg = joints_along(scan, s)
    Q, ok = model.ik_batch(X, xi, Qg)
    ok = valid_poses(model, X, Q, ok)
    if not ok.all():
        raise too_fast(f"a valid IK at every sample (fails at t = {t[~ok][0]:.4f} s)")
    if np.max(np.abs(Q - Qg)) > BRANCH_JUMP:
        raise SimulationError(f"{name}: IK left the working branch along the path (step too coarse?)")
    QD = model.joint_velocity(X, Q, xi, XD)
    QDD = model.joint_acceleration(X, Q, xi, XD, QD, XDD)
    modes = model.mode_batch(X, Q, xi)
    nz = modes[modes != 0]
    flips = int(np.count_nonzero(nz[1:] != nz[:-1]))
    if flips != (0 if bounce else 1):
        raise SimulationError(f"{name}: simulated mode changed {flips} times (expected {0 if bounce else 1})")
    return X, XD, XDD, Q, QD, QDD, modes


def simulate_crossing(model: KinematicModel, crossing_point, direction, v_sing: float, *,
                      xi_true=None, t_s: float | None = None, eps_q: float | None = None,
                      t_rest: float = 0.5, t_rest_end: float = REST_END, a_peak: float = A_PEAK,
                      cruise: float = CRUISE, working_guess=None, seed=None,
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
                    t_rest: float = 0.5, t_rest_end: float = REST_END, a_peak: float = A_PEAK,
                    cruise: float = CRUISE, working_guess=None, seed=None,
                    quantisation: str = "floor", strict_xi: bool = True, short: float = 0.0) -> SimulatedRun:
    """Simulate a failed crossing: the end-effector stops on (or ``short`` before) the true locus and comes back.

    Rest, ramp to ``v_sing``, constant speed over ``2 cruise``, smoothstep
    deceleration to rest exactly on the true singular locus (``|a| <= a_peak``),
    or ``short`` metres before it along ``direction``, then the mirror image in
    time back to the start, rest.  The start lies ``2 (D + cruise)`` before the
    turning point, ``D`` the ramp length.  The mode never changes (it is 0 at
    the touching sample ``k_sing`` when ``short = 0``).  Parameters, returns
    and errors as in :func:`simulate_crossing` (``v_sing`` is the approach
    speed), and:

    Parameters
    ----------
    short : float
        Distance (m, >= 0) before the true locus at which the motion turns
        back; 0 (default) touches it.
    """
    return _simulate(True, model, crossing_point, direction, v_sing, xi_true=xi_true, t_s=t_s,
                     eps_q=eps_q, t_rest=t_rest, t_rest_end=t_rest_end, a_peak=a_peak,
                     cruise=cruise, working_guess=working_guess, seed=seed,
                     quantisation=quantisation, strict_xi=strict_xi, short=short)


def max_v_sing(model: KinematicModel, crossing_point, direction, *, xi_true=None,
               a_peak: float = A_PEAK, cruise: float = CRUISE, working_guess=None,
               bounce: bool = False, strict_xi: bool = True, short: float = 0.0) -> float:
    """Largest ``v_sing`` (m/s) whose crossing (or bounce) path stays valid.

    The path must keep valid IK (in ``x_bounds``, joint limits, ``J_q``
    regular) and meet no other Type 2 singularity.  The valid extent is found
    by IK continuation on a grid of step ``h = min(x_bounds side) / 256``,
    its ends refined by bisection (or Brent's method for another singularity)
    and pulled in by ``h / 1000``.  Arguments as in :func:`simulate_crossing`;
    ``short`` (m) as in :func:`simulate_bounce` (used with ``bounce``).
    """
    short = V.positive("short", short, allow_zero=True)
    p, u, _v, a_peak, cruise, _tr, _te, _ts, _eq, xi, qg = _prepare(
        model, crossing_point, direction, 1.0, xi_true, None, None, 0.0, 0.0, a_peak, cruise,
        working_guess, "floor", strict_xi)
    s_true, e_lo, e_hi = valid_extent(model, p, u, xi, qg, cruise, _scan_step(model.robot))
    if bounce:
        return _v_from_distance((s_true - short - e_lo) / 2.0 - cruise, a_peak)
    return _v_from_distance(min(-e_lo, e_hi) - cruise, a_peak)


def simulate_motion(model: KinematicModel, start, goal, v_max: float, *, xi_true=None, t_s: float | None = None,
                    eps_q: float | None = None, t_rest: float = 0.05, t_rest_end: float = 0.05,
                    a_peak: float = 10.0, working_guess=None, seed=None, quantisation: str = "floor",
                    strict_xi: bool = True) -> SimulatedRun:
    """Simulate a regular straight motion from ``start`` to ``goal`` (no singularity is crossed).

    The time law of :func:`simulate_crossing` centred on the segment's
    midpoint: rest, ramp to ``v_max``, constant speed, ramp down, rest.  Pose
    speed ``|x'|`` is in the pose's units per second (m/s for a translation;
    a motion that also turns mixes m and rad).  For robots that ship a
    reference motion instead of a crossing (``simulate``) and for tests.

    ``k_sing``, ``x_sing`` and ``t_sing`` of the result mark the midpoint
    (``s_sing = 0``); ``mode_true`` is constant.  Other parameters as in
    :func:`simulate_crossing`.

    Raises
    ------
    SimulationError
        If ``v_max`` cannot be reached within the segment at ``a_peak``, if IK
        fails, or if the assembly mode changes or vanishes along the motion.
    """
    start = V.vector("start", start, model.n)
    goal = V.vector("goal", goal, model.n)
    L = float(np.linalg.norm(goal - start))
    if not L > 0:
        raise InputError("start and goal coincide")
    u = (goal - start) / L
    mid = 0.5 * (start + goal)
    p, u, v, a_peak, _c, t_rest, t_rest_end, t_s, eps_q, xi, qg = _prepare(
        model, mid, u, v_max, xi_true, t_s, eps_q, t_rest, t_rest_end, a_peak, 1e-9, working_guess,
        quantisation, strict_xi)
    T, D = ramp_length(v, a_peak)
    cruise = 0.5 * L - D
    if cruise <= 0:
        raise SimulationError(f"{model.robot.name}: v = {v:g} needs ramps of {2 * D:.4g} (pose units) at a_peak = "
                              f"{a_peak:g}, longer than the {L:.4g} segment; lower the speed")
    law = crossing_time_law(v, a_peak, cruise, t_rest, t_rest_end)
    n_samp = int(math.floor(law.duration / t_s)) + 1
    t = np.arange(n_samp) * t_s
    s, sd, sdd = law.evaluate(t)
    X = p + s[:, None] * u
    Q = model.ik_path(X, xi, qg)
    ok = valid_poses(model, X, Q, np.ones(len(X), dtype=bool))
    if not ok.all():
        raise SimulationError(f"{model.robot.name}: the motion leaves x_bounds or the joint range at "
                              f"t = {t[~ok][0]:.4f} s")
    XD, XDD = sd[:, None] * u, sdd[:, None] * u
    QD = model.joint_velocity(X, Q, xi, XD)
    QDD = model.joint_acceleration(X, Q, xi, XD, QD, XDD)
    modes = model.mode_batch(X, Q, xi)
    if np.any(modes == 0) or np.any(modes != modes[0]):
        raise SimulationError(f"{model.robot.name}: the motion meets the Type 2 locus; choose another segment")
    k_mid = int(np.argmin(np.abs(s)))
    q_meas = quantise(Q, eps_q, quantisation, np.random.default_rng(seed))
    return SimulatedRun(
        robot_name=model.robot.name, t=t, q_meas=q_meas, q=Q, x=X, xd=XD, xdd=XDD, qd=QD, qdd=QDD,
        mode_true=modes, xi_true=np.array(xi), k_sing=k_mid, t_sing=float(t[k_mid]), x_sing=X[k_mid],
        s_sing=0.0, v_sing=v, bounce=False, crossing_point=p, direction=u, t_s=t_s, eps_q=eps_q,
        a_peak=a_peak, quantisation=quantisation, time_law=law,
    )
