"""What a crossing plan is asked to do and under which bounds: the planner's domain types.

* :class:`CrossingTask` — go from a start at rest in one assembly mode to a
  goal at rest in the other;
* :class:`PlanningBounds` — encoder error, acceleration, sampling and time-law
  choices of the certification, as given; :class:`ResolvedBounds` — the same
  resolved against the robot once (one :class:`~robots.assumptions.Assumptions`),
  and for one plan (:meth:`ResolvedBounds.for_plan`);
* :class:`PlannedTrajectory` — a planned crossing: a :class:`~verifier.Trajectory`
  with its crossing sample;
* :func:`crossing_on_segment` — where the straight segment of a task meets
  the Type 2 locus (the one crossing finder of the planner);
* :func:`benchmark_task` — the task of a registered robot's benchmark crossing.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from enum import Enum, StrEnum

import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.assumptions import Assumptions, check_bound
from crosscert.robots.errors import InputError, SimulationError
from crosscert.robots.registry import RobotEntry
from crosscert.verifier.one_motion import ONE_MOTION_SAMPLES
from crosscert.verifier.settings import TrackerSettings
from crosscert.verifier.trajectory import Trajectory
from crosscert.verifier.window import Reasoning

from .acceleration import AccelerationAssumption, acceleration_assumption
from .execution import ExecutionKind
from .locus import LineScan, locate_crossing, sign_changes

__all__ = [
    "Method",
    "parse_option",
    "ExecutionKind",
    "CrossingTask",
    "PlanningBounds",
    "ResolvedBounds",
    "resolved",
    "PlannedTrajectory",
    "SegmentCrossing",
    "crossing_on_segment",
    "benchmark_task",
    "BENCHMARK_HALF_LENGTH",
]

log = logging.getLogger(__name__)

#: Start and goal of a benchmark task lie this far either side of the crossing
#: point, m: room for the speed ramps up to ~2 m/s at 60 m/s^2.
BENCHMARK_HALF_LENGTH = 0.06

#: IK continuation step along the segment, m: small enough for Newton to stay
#: on the working branch at the scale of a desktop robot (links of ~0.1 m).
_SEGMENT_STEP = 5e-4



class Method(StrEnum):
    """Time law of a plan (see :func:`planner.plan.plan_crossing`)."""

    SMOOTHSTEP = "smoothstep"
    TIME_OPTIMAL = "time-optimal"
    DYNAMIC = "dynamic"


def parse_option(kind: type[Enum], name: str, value):
    """``kind(value)``, or InputError listing the choices (``name`` is the option's name)."""
    try:
        return kind(value)
    except ValueError:
        choices = ", ".join(repr(m.value) for m in kind)
        raise InputError(f"unknown {name} {value!r}; use one of {choices}") from None


@dataclass(frozen=True, eq=False)
class CrossingTask:
    """Go from ``start`` (at rest, one assembly mode) to ``goal`` (at rest, the other).

    Parameters
    ----------
    start, goal : array (n,)
        Poses, SI (stored read-only).
    working_guess : array (n,)
        Joints (rad) on the working branch near ``start``.
    """

    start: np.ndarray
    goal: np.ndarray
    working_guess: np.ndarray

    def __post_init__(self):
        for name in ("start", "goal", "working_guess"):
            object.__setattr__(self, name, V.vector(f"task {name}", getattr(self, name)))
        if self.start.shape != self.goal.shape:
            raise InputError("task start and goal must have the same dimension")
        if np.linalg.norm(self.goal - self.start) == 0.0:
            raise InputError("task start and goal coincide")


def benchmark_task(entry: RobotEntry, xi=None, *, half_length: float = BENCHMARK_HALF_LENGTH) -> CrossingTask:
    """The robot's benchmark crossing as a task: start and goal ``half_length`` (m) either side of it.

    Raises
    ------
    InputError
        If the robot ships no benchmark crossing.
    """
    b = entry.benchmark_crossing(xi)
    return CrossingTask(b.point - half_length * b.direction, b.point + half_length * b.direction, b.q_point)


@dataclass(frozen=True)
class PlanningBounds:
    """Bounds of the planning-time certification as the caller gives them (SI), checked once at construction.

    ``eps_q``, ``t_s``, ``a_max`` and ``xd0`` obey the rules of
    :class:`~robots.assumptions.Assumptions`; ``None`` takes the robot's value
    when :meth:`resolve` resolves the bounds against a robot, once per
    certification (:class:`ResolvedBounds`, what the planner reads).

    Parameters
    ----------
    eps_q : float, optional
        Encoder error bound, rad (robot default).
    tracking_error : float
        Allowed deviation of the readings from the planned joints, rad.
    a_max : float or array (n,), optional
        End-effector acceleration bound per pose axis, in that axis' unit per
        s^2 (m/s^2 or rad/s^2, ``robot.pose_units``); one number stands for
        every axis only when all axes share a unit.  ``None``: derived for
        each plan from the robot, axis by axis (:meth:`ResolvedBounds.for_plan`):
        its physical ``a_max``, or its declared tracking margin around the plan.
    a_margin : float, optional
        Asked-for tracking margin, relative: an axis the plan accelerates is
        bounded by its planned peak times ``1 + a_margin`` (an assumption about
        the controller, stated as such in the certificate).  ``None``
        (default): no margin around the plan.
    a_peak : float
        Peak acceleration of the planned speed ramps, m/s^2.
    t_s : float, optional
        Sampling period, s (robot default).
    t_rest : float
        Rest before and after the motion, s (20 samples at 1 kHz: the
        velocity box contracts from ``xd0`` long before the motion starts;
        longer rests only add tracked samples).
    xi_splits : tuple, optional
        Geometry hypotheses of the tracker (robot default).
    method : Method or str
        Time law of the plans (see :func:`planner.plan.plan_crossing`).
    dynamics : robots.dynamics.LumpedMassModel, optional
        Dynamic model for ``Method.DYNAMIC`` (torque limits, criterion).
    qd_max, qdd_max : float, optional
        Joint speed (rad/s) and acceleration (rad/s^2) limits of the
        ``time-optimal`` and ``dynamic`` plans (30 and 3000 by default for
        ``dynamic``; none for ``time-optimal``).
    execution : ExecutionKind or str
        Class of admissible executions the certificate covers
        (:mod:`planner.execution`): ``cartesian`` (default; the end-effector
        follows the planned path, any geometry in ``[xi]``) or ``joint``
        (joints within ``eps_q + tracking_error`` of the planned joints).
    reasoning : Reasoning or str
        How certifying runs and the Monte Carlo confirmation reach a verdict
        (:class:`verifier.window.Reasoning`): ``window`` (default; forward
        tracker, then window passes over the whole run when it is undecided)
        or ``forward`` (the tracker alone).
    one_motion : int
        Samples of the one-motion step in those windows
        (``verifier.window.track_window(one_motion=...)``; default
        :data:`verifier.one_motion.ONE_MOTION_SAMPLES`, 40, as in ``track_window``;
        0: not tried).  It lowers the benchmark task's v_min by a few percent
        at about twice certify's time (docs/tracker.md, "One motion, one
        geometry"); an optimisation loop that values time over the last few
        percent of speed passes 0.
    xd0 : float or array (n,), optional
        Initial speed bound per pose axis, its unit per s: the executions start
        with ``|x'(0)| <= xd0`` (robot default: near rest).  A given plan that
        does not start at rest states its initial speed here.
    """

    eps_q: float | None = None
    tracking_error: float = 0.0
    a_max: tuple | None = None
    a_margin: float | None = None
    a_peak: float = 60.0
    t_s: float | None = None
    t_rest: float = 0.02
    xi_splits: tuple | None = None
    method: Method = Method.SMOOTHSTEP
    dynamics: object = field(default=None, repr=False)
    qd_max: float | None = None
    qdd_max: float | None = None
    execution: ExecutionKind = ExecutionKind.CARTESIAN
    reasoning: Reasoning = Reasoning.WINDOW
    one_motion: int = ONE_MOTION_SAMPLES
    xd0: tuple | None = None
    def __post_init__(self) -> None:
        set_ = object.__setattr__  # frozen: normalise once; the bounds by the assumptions' rules
        if self.eps_q is not None:
            set_(self, "eps_q", float(check_bound("eps_q", self.eps_q, 1)[0]))
        if self.t_s is not None:
            set_(self, "t_s", check_bound("t_s", self.t_s, 1))
        if self.a_max is not None:
            set_(self, "a_max", tuple(float(v) for v in check_bound("a_max", self.a_max, max(np.size(self.a_max), 1))))
        if self.xd0 is not None:
            set_(self, "xd0", tuple(float(v) for v in check_bound("xd0", self.xd0, max(np.size(self.xd0), 1))))
        set_(self, "a_peak", V.positive("a_peak", self.a_peak))
        set_(self, "tracking_error", V.positive("tracking_error", self.tracking_error, allow_zero=True))
        if self.a_margin is not None:
            if self.a_max is not None:
                raise InputError("a_margin and a_max both set the acceleration bound: give one")
            set_(self, "a_margin", V.positive("a_margin", self.a_margin, allow_zero=True))
        set_(self, "t_rest", V.positive("t_rest", self.t_rest, allow_zero=True))
        if self.xi_splits is not None:
            set_(self, "xi_splits", tuple(self.xi_splits))
        set_(self, "method", parse_option(Method, "planning method", self.method))
        set_(self, "execution", parse_option(ExecutionKind, "execution class", self.execution))
        set_(self, "reasoning", parse_option(Reasoning, "reasoning", self.reasoning))
        set_(self, "one_motion", V.count("one_motion", self.one_motion))
        if self.method is Method.DYNAMIC and self.dynamics is None:
            raise InputError("method 'dynamic' needs a dynamic model (PlanningBounds.dynamics)")

    def resolve(self, robot) -> ResolvedBounds:
        """These bounds for ``robot``, once: :class:`ResolvedBounds` holding one
        :class:`~robots.assumptions.Assumptions`.

        The robot's defaults fill what was not given (``eps_q``, ``t_s``, ``xd0``, ``xi_splits``, and
        ``a_max``: its physical bound until :meth:`ResolvedBounds.for_plan` derives a plan's); ``a_max`` and
        ``xd0`` become one bound per pose axis in the robot's units.

        Raises
        ------
        InputError
            One number for ``a_max`` or ``xd0`` on a robot whose pose axes mix m and rad, or a count of
            bounds that is not the robot's number of axes.
        """
        a_max = None if self.a_max is None else _per_axis_a_max(self.a_max, robot)
        xd0 = None if self.xd0 is None else _per_axis(self.xd0, robot, "xd0", robot.velocity_units, robot.xd0)
        assumptions = Assumptions.for_robot(robot, t_s=self.t_s, eps_q=self.eps_q, a_max=a_max, xd0=xd0)
        splits = self.xi_splits if self.xi_splits is not None else getattr(robot, "xi_splits", None)
        return ResolvedBounds(self, robot, assumptions, splits)


def _per_axis_a_max(value: tuple, robot) -> tuple[float, ...]:
    """A given ``a_max`` (checked positive): one bound per pose axis (one number only when every axis has the
    same unit)."""
    return _per_axis(value, robot, "a_max", robot.acceleration_units, robot.a_max, " (its physical a_max)")


def _per_axis(value: tuple, robot, name: str, units, example, why: str = "") -> tuple[float, ...]:
    """A given per-axis bound ``name`` in ``units``: one entry per pose axis (one number only when every axis
    has the same unit; ``example``: the robot's own values, for the message)."""
    if len(value) == 1:
        if robot.mixed_units:
            raise InputError(
                f"{name} = {list(value)} is one number, but robot {robot.name}'s pose axes are in "
                f"({', '.join(units)}): give one bound per axis, e.g. {name} = "
                f"({', '.join(f'{v:g}' for v in example)}){why}")
        return value * robot.n
    if len(value) != robot.n:
        raise InputError(f"{name} needs {robot.n} entries, got {len(value)} (one bound per pose axis of robot "
                         f"{robot.name}, in {', '.join(units)})")
    return value


#: The options of :class:`PlanningBounds` that no robot default fills: :class:`ResolvedBounds` reads them
#: through by name from the caller's bounds.
_OPTIONS = ("tracking_error", "a_margin", "a_peak", "t_rest", "method", "dynamics", "qd_max", "qdd_max",
            "execution", "reasoning", "one_motion")


@dataclass(frozen=True, eq=False)
class ResolvedBounds:
    """:class:`PlanningBounds` resolved against one robot: built once (:meth:`PlanningBounds.resolve`), then
    read by every step of a certification, never bound again.

    The bounds are one :class:`~robots.assumptions.Assumptions` (``t_s``, ``eps_q``, ``a_max``, ``xd0``,
    the calibration box, the units); the options of the caller's bounds (``tracking_error``, ``a_margin``,
    ``a_peak``, ``t_rest``, ``method``, ``dynamics``, ``qd_max``, ``qdd_max``, ``execution``,
    ``reasoning``, ``one_motion``) read through by name.

    The acceleration bound resolves in two steps.  For the robot: the given ``a_max``, else the robot's
    physical ``a_max`` (the cap of any bound derived from a plan).  For one plan, an explicit step:
    :meth:`for_plan` gives new bounds whose ``assumptions.a_max`` is what a certificate of that plan assumes
    (:func:`planner.acceleration.acceleration_assumption`), with units and sources in ``acceleration``.

    Attributes
    ----------
    given : PlanningBounds
        What the caller asked for (``None``: the robot's default).
    robot : robots.Robot
    assumptions : robots.assumptions.Assumptions
        The bounds in force; ``eps_q`` one number for every joint.
    xi_splits : tuple of int or None
        Geometry hypotheses of the tracker (given, else the robot's).
    acceleration : planner.acceleration.AccelerationAssumption or None
        The acceleration bound of :attr:`plan`, per axis with unit and source (``None``: not for a plan yet).
    plan : PlannedTrajectory or None
        The plan :meth:`for_plan` derived ``a_max`` for.
    """

    given: PlanningBounds
    robot: object = field(repr=False)
    assumptions: Assumptions = field(repr=False)
    xi_splits: tuple | None = None
    acceleration: AccelerationAssumption | None = None
    plan: object = field(default=None, repr=False)

    @property
    def eps_q(self) -> float:
        """Reading error of every joint, in its unit (rad or m)."""
        return float(self.assumptions.eps_q[0])

    @property
    def t_s(self) -> float:
        """Sampling period, s."""
        return self.assumptions.t_s

    @property
    def a_max_given(self) -> tuple[float, ...] | None:
        """The caller's acceleration bound, one per pose axis in its unit per s^2 (``None``: not given)."""
        return None if self.given.a_max is None else tuple(float(v) for v in self.assumptions.a_max)

    def for_plan(self, plan) -> ResolvedBounds:
        """These bounds for one plan: ``assumptions.a_max`` the bound a certificate of ``plan`` assumes per
        axis, and ``acceleration`` that bound with its units and sources.

        The plan-dependent step of the resolution (the given ``a_max`` checked against the plan's peak, or
        the robot's bound, or a margin around the peak: :func:`planner.acceleration.acceleration_assumption`).
        Bounds already for ``plan`` are returned as they are.

        Raises
        ------
        InputError
            The plan's peak acceleration exceeds the given or the robot's ``a_max`` on some axis.
        """
        if self.plan is plan:
            return self
        acc = acceleration_assumption(plan, self, self.robot)
        return replace(self, assumptions=self.assumptions.with_(a_max=acc.values), acceleration=acc, plan=plan)

    def tracker_settings(self) -> TrackerSettings:
        """The run-time tracker under these bounds: :attr:`assumptions` as they are (``t_s``, ``eps_q``,
        ``a_max``, ``xd0``, the robot's calibration box) and :attr:`xi_splits`.

        Every run of a certification that tracks an execution's own readings (the Monte Carlo executions,
        the bounces) takes its settings here, so that it assumes what the certificate states: a stated
        initial speed ``xd0`` included, and, for bounds :meth:`for_plan`, that plan's ``a_max``.
        """
        return TrackerSettings(assumptions=self.assumptions, xi_splits=self.xi_splits)


def _option(name: str) -> property:
    return property(lambda self: getattr(self.given, name), doc=f"``{name}`` of the caller's bounds.")


for _name in _OPTIONS:  # after @dataclass: the options read the caller's bounds
    setattr(ResolvedBounds, _name, _option(_name))
del _name


def resolved(bounds, robot) -> ResolvedBounds:
    """The bounds a public step of the planner reads: ``bounds`` as they are when resolved for ``robot``;
    a :class:`PlanningBounds` (``None``: the defaults) resolved now.

    A certification resolves its bounds once and passes the result down, so this resolves only what a caller
    of a single step hands in.

    Raises
    ------
    InputError
        ``bounds`` resolved for another robot.
    """
    if isinstance(bounds, ResolvedBounds):
        if bounds.robot is not robot and bounds.robot != robot:
            other = robot.name if robot.name != bounds.robot.name else f"another definition of {robot.name}"
            raise InputError(f"these bounds are resolved for robot {bounds.robot.name}, not for {other}: "
                             f"resolve the PlanningBounds for this robot (PlanningBounds.resolve)")
        return bounds
    return (bounds or PlanningBounds()).resolve(robot)


@dataclass(frozen=True, kw_only=True, eq=False)
class PlannedTrajectory(Trajectory):
    """A planned crossing sampled at ``t_s``: a :class:`~verifier.Trajectory` with every field set.

    Attributes
    ----------
    t : (K,) s; q, qd, qdd : (K, n) rad, rad/s, rad/s^2; x, xd, xdd : (K, n) SI.
    k_sing : int
        Sample of the nominal crossing.
    v_sing : float
        Speed there, m/s.
    crossing_point : ndarray, shape (n,)
        Where the plan meets the nominal locus, m.
    xi_plan : ndarray, shape (m,)
        Planning geometry.
    """

    k_sing: int
    v_sing: float
    crossing_point: np.ndarray
    xi_plan: np.ndarray

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("qd", "qdd", "x", "xd", "xdd"):
            if getattr(self, name) is None:
                raise InputError(f"a planned trajectory needs {name}")
        object.__setattr__(self, "k_sing", int(self.k_sing))
        object.__setattr__(self, "v_sing", float(self.v_sing))
        object.__setattr__(self, "crossing_point", V.vector("crossing_point", self.crossing_point, self.n))
        object.__setattr__(self, "xi_plan", V.vector("xi_plan", self.xi_plan))


@dataclass(frozen=True, eq=False)
class SegmentCrossing:
    """Where the straight segment start -> goal meets the Type 2 locus.

    Attributes
    ----------
    s_star : float
        Arc length of the crossing point from the start, m.
    u : ndarray, shape (n,)
        Unit direction start -> goal.
    length : float
        Segment length, m.
    m0 : int
        Assembly mode at the start (+1 or -1); the goal is in ``-m0``.
    s_grid, q_grid : ndarray, shapes (N,) and (N, n)
        Arc lengths (m) of the scan and the joints (rad) there, on the working
        branch: :meth:`joints_at` interpolates them as Newton guesses.
    """

    s_star: float
    u: np.ndarray
    length: float
    m0: int
    s_grid: np.ndarray = field(default=None, repr=False)
    q_grid: np.ndarray = field(default=None, repr=False)

    def joints_at(self, s) -> np.ndarray:
        """Joints (K, n) interpolated from the scan at arc lengths ``s`` (K,) m: guesses on the working branch."""
        s = np.asarray(s, dtype=float)
        return np.stack([np.interp(s, self.s_grid, self.q_grid[:, j]) for j in range(self.q_grid.shape[1])], axis=1)


def crossing_on_segment(kin, task: CrossingTask, xi) -> SegmentCrossing:
    """Where ``task``'s straight segment meets the Type 2 locus for geometry ``xi``.

    IK continuation on a grid of ``_SEGMENT_STEP``, then the crossing in the
    grid interval where ``det J_x`` changes sign (:func:`planner.locus.locate_crossing`).

    Raises
    ------
    InputError
        If the start or goal is unreachable or on the locus, if both lie in the
        same assembly mode, or if the segment crosses the locus more than once.
    """
    xi = np.asarray(xi, dtype=float)
    key = (kin.robot, task.start.tobytes(), task.goal.tobytes(), np.asarray(task.working_guess, float).tobytes(),
           xi.tobytes())
    hit = _CROSSINGS.get(key)
    if hit is None:
        hit = _CROSSINGS[key] = _crossing_on_segment(kin, task, xi)
        while len(_CROSSINGS) > _CROSSING_CACHE_SIZE:
            del _CROSSINGS[next(iter(_CROSSINGS))]
    return hit


#: :func:`crossing_on_segment` results of this process, by (robot, task, geometry): plans of one task
#: at many speeds, the execution class and the searches all ask for the same crossing.
_CROSSINGS: dict = {}
_CROSSING_CACHE_SIZE = 64


def _crossing_on_segment(kin, task: CrossingTask, xi) -> SegmentCrossing:
    L = float(np.linalg.norm(task.goal - task.start))
    u = (task.goal - task.start) / L
    N = max(8, int(np.ceil(L / _SEGMENT_STEP)))
    s = np.linspace(0.0, L, N + 1)
    X = task.start[None] + s[:, None] * u[None]
    try:
        Q = kin.ik_path(X, xi, task.working_guess)
    except SimulationError as exc:
        raise InputError(f"the straight path from start to goal is not reachable in the working mode: {exc}") from None
    modes = kin.mode_batch(X, Q, xi)
    m0, m1 = modes[0], modes[-1]
    if m0 == 0 or m1 == 0:
        raise InputError("start or goal lies on the Type 2 locus; move it off the locus")
    if m0 == m1:
        raise InputError(f"goal is in the same assembly mode ({m0:+d}) as the start: there is nothing to cross")
    if np.count_nonzero(modes[:-1] * modes[1:] < 0) > 1:
        raise InputError("the straight path crosses the Type 2 locus more than once; choose another start/goal")
    scan = LineScan(s, Q, kin.det_batch(X, Q, xi), True, True, math.nan, math.nan)
    ka, kb = sign_changes(scan.det)
    s_star = locate_crossing(kin, task.start, u, xi, scan, int(ka[0]), int(kb[0]))
    for a in (u, s, Q):
        a.setflags(write=False)
    return SegmentCrossing(s_star, u, L, int(m0), s, Q)
