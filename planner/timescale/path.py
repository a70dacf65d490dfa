"""The straight crossing path sampled on a uniform grid, and its crossing node.

:func:`sample_path` gives the poses and the exact joint path derivatives at
the nodes; :func:`node_index`, :func:`crossing_direction` and
:func:`criterion_coeffs` locate the crossing and write the crossing criterion
as ``cx a + cxx b = 0`` for both solvers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError, SimulationError
from crosscert.robots.kinematics import KinematicModel

__all__ = ["PathSamples", "sample_path", "sample_curve"]

#: A continuation step whose joints differ from the first-order prediction
#: ``q_k + q'_k ds`` by more than this (rad) is a jump to another leg branch.
BRANCH_JUMP = 0.1
#: Fewest grid intervals: the crossing criterion needs an interval on each side of a node.
MIN_INTERVALS = 2
#: ``s_star`` counts as a node when within this fraction of ``ds`` of it
#: (rounding of ``k L / N``, far below any meaningful offset).
NODE_RTOL = 1e-6
#: ``c . x'`` below this fraction of ``|x'|`` means the criterion direction is
#: normal to the path (the criterion would not involve the path acceleration).
NORMAL_RTOL = 1e-9


@dataclass(frozen=True, eq=False)
class PathSamples:
    """A straight pose path and its joint path sampled on a uniform grid.

    ``N + 1`` nodes, ``n`` pose/joint coordinates; subscript ``_s`` denotes a
    derivative with respect to the path parameter ``s`` (m).  Arrays are
    read-only.

    Attributes
    ----------
    s : ndarray, shape (N + 1,)
        Grid ``s_i = i L / N``, m.
    x, x_s, x_ss : ndarray, shape (N + 1, n)
        Poses ``p0 + s u`` (m), ``x' = u`` (1), ``x'' = 0`` (1/m).
    q, q_s, q_ss : ndarray, shape (N + 1, n)
        Joints (rad), ``q'`` (rad/m), ``q''`` (rad/m^2) from the kinematics.
    p0, u : ndarray, shape (n,)
        Start pose (m) and unit direction.
    length : float
        ``L``, m.
    xi : ndarray, shape (m,)
        Geometry used for the IK (the planner's view, usually nominal), SI.
    kin : KinematicModel
        The model (used by :func:`~planner.timescale.resample` for exact IK
        between nodes and by the default crossing criterion).
    """

    s: np.ndarray
    x: np.ndarray
    x_s: np.ndarray
    x_ss: np.ndarray
    q: np.ndarray
    q_s: np.ndarray
    q_ss: np.ndarray
    p0: np.ndarray
    u: np.ndarray
    length: float
    xi: np.ndarray
    kin: KinematicModel = field(repr=False)
    #: ``curve(s) -> (x, x', x'')`` of a curved path (None: the straight ``p0 + s u``); :func:`sample_curve`.
    curve: object = field(default=None, repr=False)

    def poses(self, s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``x(s)``, ``x'(s)``, ``x''(s)`` at the path parameters ``s`` (K,): three (K, n) arrays."""
        s = np.asarray(s, float)
        if self.curve is not None:
            return self.curve(s)
        n = self.u.size
        return self.p0 + s[:, None] * self.u, np.tile(self.u, (s.size, 1)), np.zeros((s.size, n))

    def __post_init__(self) -> None:
        for name in ("s", "x", "x_s", "x_ss", "q", "q_s", "q_ss", "p0", "u", "xi"):
            getattr(self, name).setflags(write=False)

    @property
    def n_intervals(self) -> int:
        """Number of grid intervals ``N``."""
        return int(self.s.shape[0]) - 1

    @property
    def ds(self) -> float:
        """Grid step ``L / N``, m."""
        return self.length / self.n_intervals


def sample_path(kin: KinematicModel, p0, u, L: float, N: int, working_guess, xi=None) -> PathSamples:
    """Sample the straight path ``x(s) = p0 + s u``, ``s in [0, L]``, and its IK.

    The joints follow the working branch of the legs by continuation: Newton
    from ``working_guess`` at ``p0``, then from the first-order prediction
    ``q_k + q'_k ds`` at each next node.  ``q'`` and ``q''`` are exact (eq. (2)
    and its derivative with ``x' = u``, ``x'' = 0``).

    Parameters
    ----------
    kin : KinematicModel
    p0 : array_like, shape (n,)
        Start pose, m.
    u : array_like, shape (n,)
        Direction (normalised here, so ``s`` is the arc length in m).
    L : float
        Path length, m (> 0).
    N : int
        Number of grid intervals (>= 2); step ``ds = L / N``.  To impose the
        crossing at ``s*`` choose ``N`` so that ``s*`` is a node.
    working_guess : array_like, shape (n,)
        Joints on the working branch near ``p0``, rad.
    xi : array_like, shape (m,), optional
        Geometry, SI; default the robot's nominal parameters.

    Returns
    -------
    PathSamples
        ``N + 1`` nodes.

    Raises
    ------
    InputError
        Malformed arguments.
    SimulationError
        IK fails (unreachable pose, ``J_q`` singular), a pose leaves
        ``robot.x_bounds``, joints leave their limits, or the continuation
        jumps to another branch; the message gives the arc length.
    """
    if not isinstance(kin, KinematicModel):
        raise InputError(f"kin must be a KinematicModel, got {type(kin).__name__}")
    n, r = kin.n, kin.robot
    p0 = V.vector("p0", p0, n)
    u = V.direction("u", u, n)
    L = V.positive("L", L)
    if isinstance(N, bool) or not isinstance(N, (int, np.integer)) or N < MIN_INTERVALS:
        raise InputError(f"N must be an integer >= {MIN_INTERVALS}, got {N!r}")
    N = int(N)
    qg = V.vector("working_guess", working_guess, n)
    xi = r.xi_nominal_array if xi is None else V.vector("xi", xi, r.m)

    s = L * np.arange(N + 1) / N
    s[-1] = L
    ds = L / N
    X = p0 + s[:, None] * u
    XS = np.tile(u, (N + 1, 1))
    Q = np.empty((N + 1, n))
    QS = np.empty((N + 1, n))
    guess = qg
    for k in range(N + 1):
        Qk, ok = kin.ik_batch(X[k:k + 1], xi, guess[None, :])
        if not ok[0]:
            raise SimulationError(
                f"{r.name}: IK failed at s = {s[k] * 1e3:.4f} mm (x = {X[k].tolist()}): pose "
                "unreachable or J_q singular; shorten the path")
        if k > 0 and np.max(np.abs(Qk[0] - guess)) > BRANCH_JUMP:
            raise SimulationError(
                f"{r.name}: IK continuation jumped to another branch at s = {s[k] * 1e3:.4f} mm; "
                "refine the grid (larger N)")
        Q[k] = Qk[0]
        QS[k] = kin.joint_velocity(X[k:k + 1], Q[k:k + 1], xi, XS[k:k + 1])[0]
        guess = Q[k] + ds * QS[k]  # tangent predictor keeps Newton on the branch
    _within_bounds(r, s, X, Q)
    XSS = np.zeros_like(X)  # straight path
    QSS = kin.joint_acceleration(X, Q, xi, XS, QS, XSS)
    return PathSamples(s=s, x=X, x_s=XS, x_ss=XSS, q=Q, q_s=QS, q_ss=QSS, p0=p0, u=u,
                       length=L, xi=np.array(xi, dtype=float), kin=kin)


def _within_bounds(r, s, X, Q) -> None:
    """SimulationError at the first node whose pose leaves ``x_bounds`` or whose joints leave their limits."""
    inside = np.all((X >= r.x_lo_array) & (X <= r.x_hi_array), axis=1)
    in_lim = np.all((Q >= r.q_lo_array) & (Q <= r.q_hi_array), axis=1)
    bad = np.nonzero(~(inside & in_lim))[0]
    if bad.size:
        k = int(bad[0])
        what = "outside x_bounds" if not inside[k] else "beyond the joint limits"
        raise SimulationError(f"{r.name}: the path is {what} at s = {s[k] * 1e3:.4f} mm; shorten it")


def sample_curve(kin: KinematicModel, curve, L: float, N: int, joints_at, xi=None) -> PathSamples:
    """Sample a curved path ``x(s)``, ``s in [0, L]``, on a uniform grid of ``N`` intervals, and its IK.

    ``curve(s) -> (x, x', x'')`` gives the poses and their derivatives in ``s`` at the nodes (any smooth
    parametrisation; ``s`` need not be the arc length); ``joints_at(s)`` Newton guesses of the joints on the
    working branch.  ``q'`` and ``q''`` are exact given ``x'`` and ``x''`` (eq. (2) and its derivative), as in
    :func:`sample_path`.

    Raises
    ------
    SimulationError
        IK fails, or a pose or joint leaves the robot's bounds (the message gives ``s``).
    """
    r = kin.robot
    L = V.positive("L", L)
    if isinstance(N, bool) or not isinstance(N, (int, np.integer)) or N < MIN_INTERVALS:
        raise InputError(f"N must be an integer >= {MIN_INTERVALS}, got {N!r}")
    N = int(N)
    xi = r.xi_nominal_array if xi is None else V.vector("xi", xi, r.m)
    s = L * np.arange(N + 1) / N
    s[-1] = L
    X, XS, XSS = (np.array(a, float) for a in curve(s))
    Q, ok = kin.ik_batch(X, xi, joints_at(s))
    if not ok.all():
        k = int(np.nonzero(~ok)[0][0])
        raise SimulationError(f"{r.name}: IK failed at s = {s[k] * 1e3:.4f} mm (x = {X[k].tolist()})")
    _within_bounds(r, s, X, Q)
    QS = kin.joint_velocity(X, Q, xi, XS)
    QSS = kin.joint_acceleration(X, Q, xi, XS, QS, XSS)
    u = XS[0] / np.linalg.norm(XS[0])
    return PathSamples(s=s, x=X, x_s=XS, x_ss=XSS, q=Q, q_s=QS, q_ss=QSS, p0=X[0].copy(), u=u, length=L,
                       xi=np.array(xi, dtype=float), kin=kin, curve=curve)


def node_index(samples: PathSamples, s_star, *, exact: bool) -> int:
    """Index of the node nearest ``s_star`` (m); with ``exact``, InputError unless it is a node."""
    s_star = V.number("s_star", s_star)
    ds = samples.ds
    k = round(s_star / ds)
    if not 0 <= k <= samples.n_intervals:
        raise InputError(f"s_star = {s_star} m lies outside the path [0, {samples.length}] m")
    if exact and abs(samples.s[k] - s_star) > NODE_RTOL * ds:
        raise InputError(
            f"s_star = {s_star} m is not a grid node (nearest {samples.s[k]} m, step {ds} m); "
            "choose L and N so that s_star = k L / N")
    return k


def crossing_direction(samples: PathSamples, k: int, direction) -> np.ndarray:
    """Unit criterion direction at node ``k``: ``direction``, or the kernel of ``J_x`` (uncontrolled motion)."""
    n = samples.x.shape[1]
    if direction is not None:
        c = V.vector("criterion_direction", direction, n)
        if not np.any(c):
            raise InputError("criterion_direction must be non-zero")
        return c / np.linalg.norm(c)
    jx = samples.kin.jac_x_batch(samples.x[k:k + 1], samples.q[k:k + 1], samples.xi)[0]
    return np.linalg.svd(jx)[2][-1]  # right singular vector of the smallest singular value


def criterion_coeffs(samples: PathSamples, k: int, c: np.ndarray) -> tuple[float, float]:
    """``(c . x', c . x'')`` at node ``k``: the criterion reads ``cx a + cxx b = 0``."""
    cx = float(c @ samples.x_s[k])
    cxx = float(c @ samples.x_ss[k])
    if abs(cx) <= NORMAL_RTOL * np.linalg.norm(samples.x_s[k]):
        raise InputError(
            "the criterion direction is normal to the path at s_star: c.xddot = 0 does not "
            "involve the path acceleration there (the path does not cross along it)")
    return cx, cxx
