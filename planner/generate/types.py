"""Domain types of crossing generation: limits, objective, result, failures as data."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError, SimulationError

from ..task import PlannedTrajectory

__all__ = [
    "CheckFailed",
    "GeneratedTrajectory",
    "GenerationError",
    "GenerationLimits",
    "LimitExceeded",
    "NotConverged",
    "Objective",
    "Samples",
]

#: Upper end (excluded) of the relative back-off of the limits at the nodes:
#: backing off by half or more would leave no room for the motion.
_MARGIN_MAX = 0.5


class Objective(StrEnum):
    """What the generator minimises."""

    TIME = "time"  # motion time start -> goal, s
    JERK = "jerk"  # integral of |jerk|^2 at a fixed duration, m^2/s^5


# ------------------------------------------------------------------ failures
class GenerationError(SimulationError):
    """No crossing was generated: the solver failed or its solution failed the independent check."""


class NotConverged(GenerationError):
    """IPOPT did not report success.

    Attributes
    ----------
    status : str
        IPOPT's return status (e.g. ``"Infeasible_Problem_Detected"`` when the
        limits do not allow ``v_sing``).
    """

    def __init__(self, status: str) -> None:
        super().__init__(f"trajectory generation did not converge: {status}")
        self.status = status


class CheckFailed(GenerationError):
    """A converged solution failed the independent check on the samples.

    Attributes
    ----------
    check : str
        The requirement that failed (e.g. ``"loop closure"``).
    """

    def __init__(self, check: str, message: str | None = None) -> None:
        super().__init__(message or f"generated trajectory failed the independent check: {check}")
        self.check = check


class LimitExceeded(CheckFailed):
    """A limit met at the NLP nodes is exceeded between them, on the samples.

    Attributes
    ----------
    limit : str
        The worst limit: ``"qd"``, ``"qdd"``, ``"tau"``, ``"xdd"`` or ``"jerk"``.
    ratio : float
        Its largest ``|value| / limit`` over the samples (> 1).
    """

    def __init__(self, limit: str, ratio: float) -> None:
        super().__init__("limits between the nodes",
                         f"generated trajectory failed the independent check: {limit} reaches {ratio:.9g} of its "
                         "limit between the nodes (use more intervals or a larger margin)")
        self.limit = limit
        self.ratio = ratio


# ------------------------------------------------------------------ limits
@dataclass(frozen=True)
class GenerationLimits:
    """Limits of a generated crossing; the torque limits come from the dynamic model.

    Parameters
    ----------
    qd_max : float or array_like (n,)
        Joint speed bound ``|qd_i| <= qd_max_i``, rad/s.
    qdd_max : float or array_like (n,)
        Joint acceleration bound, rad/s^2.
    a_max : float or array_like (n,), optional
        End-effector acceleration bound ``|xdd_i| <= a_max_i``, m/s^2 (the
        tracker's ``[a_max]``: a certified plan needs one).
    jerk_max : float or array_like (n,), optional
        End-effector jerk bound, m/s^3.
    torque : bool
        Impose ``|tau_i| <= tau_max_i`` of the dynamic model.
    margin : float
        Relative back-off of every limit at the NLP nodes (``[0, 0.5)``):
        the limits are checked between the nodes (on the samples) without it.
    """

    qd_max: object
    qdd_max: object
    a_max: object = None
    jerk_max: object = None
    torque: bool = True
    margin: float = 0.02

    def resolved(self, n: int) -> dict:
        """The limits as read-only ``(n,)`` arrays keyed by name (``None`` where unbounded)."""
        m = V.number("margin", self.margin)
        if not (0.0 <= m < _MARGIN_MAX):
            raise InputError(f"margin must be in [0, {_MARGIN_MAX}), got {self.margin}")
        out = {}
        for name, required in (("qd_max", True), ("qdd_max", True), ("a_max", False), ("jerk_max", False)):
            v = getattr(self, name)
            if v is None and required:
                raise InputError(f"{name} is required")
            out[name] = None if v is None else V.vector(name, v, n, broadcast=True, positive=True)
        return out


# ------------------------------------------------------------------ samples and result
@dataclass(frozen=True, eq=False)
class Samples:
    """The NLP solution sampled at ``t_s`` (internal: passed from the NLP to the check).

    Attributes
    ----------
    t : ndarray, shape (K,)
        Sample times, s.
    x, xd, xdd, xddd : ndarray, shape (K, n)
        Pose (m), velocity (m/s), acceleration (m/s^2), jerk (m/s^3).
    k_sing : int
        Sample of the crossing node.
    t_start : float
        Time the motion leaves the start, s.
    node_t : ndarray, shape (N+1,)
        NLP node times on the same clock, s.
    """

    t: np.ndarray
    x: np.ndarray
    xd: np.ndarray
    xdd: np.ndarray
    xddd: np.ndarray
    k_sing: int
    t_start: float
    node_t: np.ndarray


#: Arrays of a GeneratedTrajectory beyond those of a PlannedTrajectory (frozen in ``__post_init__``).
_EXTRA_ARRAYS = ("xddd", "tau", "criterion_direction", "node_t", "node_x", "node_v", "node_a", "node_q", "node_jerk")


@dataclass(frozen=True, kw_only=True, eq=False)
class GeneratedTrajectory(PlannedTrajectory):
    """A generated, independently checked crossing sampled at ``t_s``: a :class:`~planner.task.PlannedTrajectory`.

    The base fields are ``t`` (K,) s; ``q, qd, qdd`` (K, n) joints by IK
    continuation along ``x`` (rad) and their rates (rad/s, rad/s^2);
    ``x, xd, xdd`` (K, n) m, m/s, m/s^2; ``t_s``; ``k_sing`` (the sample with
    ``x[k_sing] == crossing_point``); ``v_sing`` (``|xd[k_sing]|``, m/s);
    ``crossing_point`` (n,) m; ``xi_plan`` (m,).  Every array is read-only.

    Attributes
    ----------
    xddd : ndarray, shape (K, n)
        Jerk, m/s^3 (of the interval starting at or containing the sample).
    tau : ndarray, shape (K, n)
        Actuator torques, N m (eq. (1); eq. (3) at ``k_sing``).
    criterion_direction : ndarray, shape (n,)
        Uncontrolled direction ``t_s`` at the crossing point (unit).
    criterion_residual : float
        ``t_s^T w_x`` at ``k_sing``, N (signed; ``|.| <= criterion_tol``).
    objective : Objective
        ``"time"`` or ``"jerk"``.
    objective_value : float
        Motion time start -> goal (s) or ``integral |jerk|^2 dt`` (m^2/s^5).
    duration : float
        Motion time from leaving the start to reaching the goal, s.
    t_start, t_cross : float
        Times the motion leaves the start and crosses the locus, s.
    modes : tuple of int
        Assembly modes at the first and last sample.
    peak_ratio : dict
        Largest ``|value| / limit`` over the samples for every imposed limit
        (``<= 1 + LIMIT_RTOL``).
    node_t : ndarray, shape (N+1,)
        NLP node times, s (same clock as ``t``).
    node_x, node_v, node_a, node_q : ndarray, shape (N+1, n)
        NLP states at the nodes.
    node_jerk : ndarray, shape (N, n)
        Jerk on each interval, m/s^3.
    solver_stats : dict
        ``status``, ``iterations``, ``solve_time_s`` (IPOPT), ``wall_time_s``
        (whole call, including a minimum-time pre-solve for ``"jerk"``),
        ``presolve_time_s``, ``attempts``, ``margin``, ``n_variables``,
        ``n_constraints``, ``intervals``.
    """

    xddd: np.ndarray
    tau: np.ndarray
    criterion_direction: np.ndarray
    criterion_residual: float
    objective: Objective
    objective_value: float
    duration: float
    t_start: float
    t_cross: float
    modes: tuple
    peak_ratio: dict
    node_t: np.ndarray = field(repr=False)
    node_x: np.ndarray = field(repr=False)
    node_v: np.ndarray = field(repr=False)
    node_a: np.ndarray = field(repr=False)
    node_q: np.ndarray = field(repr=False)
    node_jerk: np.ndarray = field(repr=False)
    solver_stats: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in _EXTRA_ARRAYS:  # frozen only: the independent check has validated them
            object.__setattr__(self, name, V.frozen_array(getattr(self, name)))

    def to_planned_trajectory(self) -> PlannedTrajectory:
        """The trajectory as a plain :class:`~planner.task.PlannedTrajectory` (generation data dropped)."""
        return PlannedTrajectory(t=self.t, q=self.q, qd=self.qd, qdd=self.qdd, x=self.x, xd=self.xd, xdd=self.xdd,
                                 t_s=self.t_s, k_sing=self.k_sing, v_sing=self.v_sing,
                                 crossing_point=self.crossing_point, xi_plan=self.xi_plan)
