"""Where a straight line meets the Type 2 locus: the one line scan and crossing finder.

:func:`scan_line` continues the IK along ``p + s u`` on a grid, both ways from
``s = 0``, until a pose is invalid (IK fails, pose outside ``x_bounds``, joints
beyond their limits); :func:`sign_changes` lists the grid intervals where
``det J_x`` changes sign and :func:`locate_crossing` finds the crossing in one
(Brent's method on ``det J_x`` of the IK, to the spacing of doubles).
Plans (:func:`planner.task.crossing_on_segment`) and simulations
(:mod:`planner.simulate`) both find their crossings here.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from crosscert.robots.errors import SimulationError
from crosscert.robots.kinematics import KinematicModel

from .lru import LruCache

__all__ = ["LineScan", "valid_poses", "scan_line", "refine_edge", "sign_changes", "joints_along",
           "locate_crossing", "valid_extent", "nearest_crossing"]

#: Slack, in grid steps, so a limit that is a whole number of steps gets no extra point.
GRID_TOL = 1e-9
#: Bisections of a valid/invalid bracket: 50 halvings of a 1 mm step reach ~1e-18 m.
EDGE_BISECTIONS = 50
#: Margin kept inside a valid extent, in grid steps (micrometres): a path ending there stays valid.
EDGE_MARGIN = 1e-3
#: Brent's tolerances on the arc length of a crossing (m, and relative): the spacing of doubles.
ROOT_XTOL = 1e-15
#: Iteration cap of Brent's method (it converges in far fewer at these tolerances).
ROOT_MAXITER = 200


@dataclass(frozen=True, eq=False)
class LineScan:
    """IK continuation along ``p + s u`` on a grid anchored at ``s = 0``.

    Attributes
    ----------
    s : ndarray, shape (K,)
        Increasing arc lengths, m.
    q : ndarray, shape (K, n)
        Joints there, rad.
    det : ndarray, shape (K,)
        ``det J_x`` there.
    lo_done, hi_done : bool
        The requested lower (upper) end was reached with valid IK.
    lo_fail, hi_fail : float
        First invalid arc length below (above), m; NaN when the end was reached.
    """

    s: np.ndarray
    q: np.ndarray
    det: np.ndarray
    lo_done: bool
    hi_done: bool
    lo_fail: float
    hi_fail: float


def valid_poses(model: KinematicModel, X: np.ndarray, Q: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Mask (N,): IK converged (``ok``), pose within ``x_bounds`` and joints within their limits."""
    r = model.robot
    inside = np.all((X >= r.x_lo_array) & (X <= r.x_hi_array), axis=1)
    in_lim = np.all((Q >= r.q_lo_array) & (Q <= r.q_hi_array), axis=1)
    return ok & inside & in_lim


def scan_line(model, p, u, xi, q_guess, s_lo, s_hi, h) -> LineScan:
    """Continue the IK from ``s = 0`` outwards to ``s_lo < 0`` and ``s_hi > 0``, stopping when invalid.

    A pose is valid when IK converges with ``J_q`` regular, the pose lies in
    ``robot.x_bounds`` and the joints within their limits.  The points on
    the grid ``s = +-h k`` are kept per line (:data:`_SIDES`) and reused by
    a later scan of the same line to any extent: the bounce searches
    simulate one line for many turn-back distances.  Each point depends only
    on the two before it, so a reused scan is the one computed afresh, to
    the last bit.
    """
    Q0, ok0 = model.ik_batch(p[None, :], xi, q_guess[None, :])
    if not valid_poses(model, p[None, :], Q0, ok0)[0]:
        raise SimulationError(
            f"{model.robot.name}: no valid IK at the crossing point {p.tolist()} from "
            f"working_guess {q_guess.tolist()} (unreachable, joint limits, or outside x_bounds)"
        )
    sides = {}
    for sign, lim in ((-1.0, s_lo), (1.0, s_hi)):
        n_steps = int(math.ceil(abs(lim) / h - GRID_TOL))
        sides[sign] = _scan_side(model, p, u, xi, Q0[0], sign, h, n_steps, min(h * n_steps, abs(lim)),
                                 (model, *(np.asarray(a, float).tobytes() for a in (p, u, xi, q_guess)), h, sign))
    s_neg, q_neg, lo_done, lo_fail = sides[-1.0]
    s_pos, q_pos, hi_done, hi_fail = sides[1.0]
    s_all = np.array(s_neg[::-1] + [0.0] + s_pos)
    q_all = np.array(q_neg[::-1] + [Q0[0]] + q_pos).reshape(-1, model.n)
    det = model.det_batch(p + s_all[:, None] * u, q_all, xi)
    return LineScan(s_all, q_all, det, lo_done, hi_done, lo_fail, hi_fail)


#: Continuations of :func:`scan_line` on the grid ``s = sign h k``, by (model, line, guess, h, sign):
#: ``[joints at k = 1, 2, ...], first invalid k or None``; most recently used last.
#: How many continuations :data:`_SIDES` keeps (two per line; a few hundred joint vectors each).
_SIDES_KEPT = 16
_SIDES = LruCache(_SIDES_KEPT)
#: One continuation extended at a time (taken out of the cache, grown, put back).
_SIDES_LOCK = threading.Lock()


def _ik_step(model, p, u, xi, s, q_prev, q_prev2):
    """IK at ``p + s u`` from the linear predictor of the last two joints; None when the pose is invalid."""
    x = p + s * u
    guess = q_prev if q_prev2 is None else 2.0 * q_prev - q_prev2
    Qk, ok = model.ik_batch(x[None, :], xi, guess[None, :])
    return Qk[0] if valid_poses(model, x[None, :], Qk, ok)[0] else None


def _scan_side(model, p, u, xi, q0, sign, h, n_steps, s_end, key):
    """One side of :func:`scan_line`: the points ``sign h k`` for ``k < n_steps`` (kept in :data:`_SIDES`),
    then ``sign s_end``; returns ``(s list, q list, done, first invalid s or NaN)``."""
    with _SIDES_LOCK:
        grid = _SIDES.pop(key, None) or ([], None)
        qs, fail_k = grid
        while len(qs) < n_steps - 1 and fail_k is None:
            k = len(qs) + 1
            q = _ik_step(model, p, u, xi, sign * (h * k), qs[-1] if qs else q0,
                         (qs[-2] if len(qs) >= 2 else q0) if qs else None)
            if q is None:
                fail_k = k
            else:
                qs.append(q)
        _SIDES.put(key, (qs, fail_k))
    if fail_k is not None and fail_k < n_steps:
        return [sign * (h * k) for k in range(1, fail_k)], qs[:fail_k - 1], False, sign * (h * fail_k)
    used = qs[:max(n_steps - 1, 0)]
    s_list = [sign * (h * k) for k in range(1, len(used) + 1)]
    if n_steps < 1:
        return s_list, list(used), True, math.nan
    prev = used[-1] if used else q0
    prev2 = (used[-2] if len(used) >= 2 else q0) if used else None
    q = _ik_step(model, p, u, xi, sign * s_end, prev, prev2)
    if q is None:
        return s_list, list(used), False, sign * s_end
    return s_list + [sign * s_end], list(used) + [q], True, math.nan


def refine_edge(model, p, u, xi, s_ok: float, q_ok: np.ndarray, s_bad: float) -> float:
    """Bisect between a valid arc length and an invalid one; returns the valid end (m)."""
    for _ in range(EDGE_BISECTIONS):
        mid = 0.5 * (s_ok + s_bad)
        if mid in (s_ok, s_bad):
            break
        x = p + mid * u
        Q, ok = model.ik_batch(x[None, :], xi, q_ok[None, :])
        if valid_poses(model, x[None, :], Q, ok)[0]:
            s_ok, q_ok = mid, Q[0]
        else:
            s_bad = mid
    return s_ok


def sign_changes(det: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sign changes of ``det`` as index pairs ``(ka, kb)``, ``ka < kb``.

    ``det[ka]`` and ``det[kb]`` are non-zero with opposite signs and every value
    between them is exactly zero, so a zero sample on the locus counts once.
    """
    nz = np.nonzero(det != 0.0)[0]
    sg = np.sign(det[nz])
    flip = np.nonzero(sg[:-1] != sg[1:])[0]
    return nz[flip], nz[flip + 1]


def joints_along(scan: LineScan, s) -> np.ndarray:
    """Joints interpolated from the scan at arc lengths ``s`` (m): IK guesses, shape (len(s), n)."""
    s = np.atleast_1d(np.asarray(s, dtype=float))
    return np.stack([np.interp(s, scan.s, scan.q[:, j]) for j in range(scan.q.shape[1])], axis=1)


def locate_crossing(model, p, u, xi, scan: LineScan, ka: int, kb: int) -> float:
    """Arc length (m) of the sign change of det J_x between scan points ka and kb (Brent)."""

    def g(s: float) -> float:
        x = p + s * u
        Q, ok = model.ik_batch(x[None, :], xi, joints_along(scan, s))
        if not ok[0]:
            raise SimulationError(f"{model.robot.name}: IK failed near the singular point at s = {s}")
        return float(model.det_batch(x[None, :], Q, xi)[0])

    return float(brentq(g, scan.s[ka], scan.s[kb], xtol=ROOT_XTOL, rtol=ROOT_XTOL, maxiter=ROOT_MAXITER))


def valid_extent(model, p, u, xi, q_guess, cruise, h):
    """Largest valid path around ``p``: returns ``(s_true, e_lo, e_hi)`` (m).

    ``s_true`` is the true crossing nearest ``p``; ``[e_lo, e_hi]`` the largest
    interval around it, on the scan grid, with valid IK and no other sign
    change of det J_x.
    """
    r = model.robot
    span = float(np.linalg.norm(r.x_hi_array - r.x_lo_array))  # no valid pose beyond this
    scan = scan_line(model, p, u, xi, q_guess, -span, span, h)
    s_true, j = nearest_crossing(model, p, u, xi, scan, cruise)
    ka, kb = sign_changes(scan.det)
    if j > 0:  # another singularity before: stop at it
        e_lo = locate_crossing(model, p, u, xi, scan, int(ka[j - 1]), int(kb[j - 1]))
    elif scan.lo_done:
        e_lo = scan.s[0]
    else:
        e_lo = refine_edge(model, p, u, xi, scan.s[0], scan.q[0], scan.lo_fail)
    if j + 1 < ka.size:
        e_hi = locate_crossing(model, p, u, xi, scan, int(ka[j + 1]), int(kb[j + 1]))
    elif scan.hi_done:
        e_hi = scan.s[-1]
    else:
        e_hi = refine_edge(model, p, u, xi, scan.s[-1], scan.q[-1], scan.hi_fail)
    margin = EDGE_MARGIN * h
    return s_true, float(e_lo) + margin, float(e_hi) - margin


def nearest_crossing(model, p, u, xi, scan: LineScan, cruise: float) -> tuple[float, int]:
    """The sign change of det J_x nearest ``s = 0`` (and its pair index); must lie within ``(-cruise, cruise)``."""
    ka, kb = sign_changes(scan.det)
    if ka.size == 0:
        raise SimulationError(
            f"{model.robot.name}: the path through {p.tolist()} along {u.tolist()} does not meet "
            "the Type 2 singular locus of the true geometry; pass a point of the nominal locus"
        )
    mid = 0.5 * (scan.s[ka] + scan.s[kb])
    j = int(np.argmin(np.abs(mid)))
    s_true = locate_crossing(model, p, u, xi, scan, int(ka[j]), int(kb[j]))
    if not abs(s_true) < cruise:
        raise SimulationError(
            f"{model.robot.name}: the true singular point is {s_true * 1e3:.3f} mm from the nominal "
            f"crossing point, outside the constant-speed zone +-{cruise * 1e3:.3f} mm; increase cruise"
        )
    return s_true, j
