"""The gap for ``mode-unchanged``: bounces of a task that turn back short of the locus.

The refutation bound and ``v_min`` bracket, in speed, where a crossing's
mode change can be certified.  This module brackets, in distance, where a
*failed* crossing can be certified ``mode-unchanged``: bounces along the
task's path at one approach speed that decelerate to rest ``d`` metres
before the true locus and come back (``planner.simulate.simulate_bounce``,
centre geometry, readings quantised by ``floor``).

* ``certified_from`` — the smallest tried ``d`` from which every tried
  bounce is certified ``mode-unchanged`` by the run-time tracker with window
  reasoning under the certification's bounds (robot's calibration box,
  ``eps_q``, ``xd0`` and ``a_max``: the certificate's, when the bounds are
  for its plan);
* ``floor`` — the crossing floor (:func:`planner.refute.crossing_floor`): the
  largest ``d`` at which a verified motion that *did* change mode explains
  the same readings; no sound method certifies ``mode-unchanged`` there.

SI units: m, m/s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from crosscert.robots import KinematicModel
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.settings import Verdict
from crosscert.verifier.tracker import initial_box_from_mode
from crosscert.verifier.window import track_window

from . import refute
from .simulate import simulate_bounce
from .sweep import cruise_for
from .generate.crossing import crossing_point_and_joints
from .task import CrossingTask, PlanningBounds, ResolvedBounds, resolved

__all__ = ["BounceGap", "BounceVerdicts", "bounce_gap", "bounce_verdicts", "bounce_floor", "gap_of", "BOUNCE_DISTANCES",
           "BOUNCE_FLOOR_TOL"]

#: Turn-back distances tried, m: every 2 mm from 0 to 30 mm.
BOUNCE_DISTANCES = tuple(round(0.002 * i, 6) for i in range(16))
#: Resolution of the crossing floor's bisection, m.
BOUNCE_FLOOR_TOL = 5e-4
#: Geometry sub-boxes per hypothesis of the window passes on each bounce.
BOUNCE_WINDOW_GEOMETRIES = 8
#: IPOPT CPU cap per crossing-counterexample attempt, s (as for the refutation bound).
BOUNCE_CPU_TIME = 2.0


@dataclass(frozen=True, eq=False)
class BounceGap:
    """Where the bounces of a task can and cannot be certified ``mode-unchanged``.

    Attributes
    ----------
    speed : float
        Approach speed of the bounces, m/s.
    distances : tuple of float
        Turn-back distances tried by the tracker, m (increasing).
    verdicts : tuple of Verdict
        The tracker's verdict (window reasoning) at each distance.
    certified_from : float or None
        Smallest tried distance (m) from which every tried bounce is
        certified ``mode-unchanged``; ``None`` if the farthest is not.
    floor : float or None
        Crossing floor, m (``None``: no verified crossing at any distance).
    floor_rows : tuple of planner.refute.RecordingRefutation
        The crossing searches, one per distance tried.
    """

    speed: float
    distances: tuple
    verdicts: tuple
    certified_from: float | None
    floor: float | None
    floor_rows: tuple

    @property
    def floor_search(self) -> refute.SearchCompleteness:
        """What ``floor`` rests on: a verified crossing, crossing searches that found none, or none that ended."""
        return refute.completeness(self.floor_rows)

    def summary(self) -> dict:
        """JSON-ready summary (SI units)."""
        return {
            "speed_mps": self.speed,
            "tracker": [{"turn_back_m": d, "verdict": v.value} for d, v in zip(self.distances, self.verdicts)],
            "certified_from_m": self.certified_from,
            "crossing_floor_m": self.floor,
            "crossing_floor_search": self.floor_search.value,
            "gap_m": None if self.certified_from is None or self.floor is None else self.certified_from - self.floor,
            "crossing_searches": [
                {"turn_back_m": r.parameter, "counterexample": bool(r.verified), "outcome": r.outcome.value,
                 "solver_status": r.status}
                for r in self.floor_rows
            ],
        }


@dataclass(frozen=True, eq=False)
class BounceVerdicts:
    """The tracker's side of :func:`bounce_gap`: verdicts on the bounces tried, and ``certified_from``.

    Attributes
    ----------
    speed : float
        Approach speed, m/s.
    distances : tuple of float
        Turn-back distances tried, m (increasing).
    verdicts : tuple of Verdict
        The tracker's verdict (window reasoning) at each.
    certified_from : float or None
        Smallest tried distance (m) from which every tried bounce is certified ``mode-unchanged``.
    readings : dict
        ``{distance: q_meas (K, n)}`` of the bounces tried, rad (the crossing searches read the same ones).
    """

    speed: float
    distances: tuple
    verdicts: tuple
    certified_from: float | None
    readings: dict = field(repr=False)


class _Bounces:
    """The task's bounces at one approach speed: readings by turn-back distance, simulated once each."""

    def __init__(self, robot, task: CrossingTask, bounds: PlanningBounds | ResolvedBounds, speed: float, kin=None,
                 readings=None):
        self.kin = KinematicModel(robot) if kin is None else kin
        self.b = resolved(bounds, robot)
        self.speed = float(speed)
        xi = robot.xi_center
        self.point, self.q_point, self.m0 = crossing_point_and_joints(self.kin, task, xi)
        self.u = (task.goal - task.start) / np.linalg.norm(task.goal - task.start)
        self.readings = dict(readings or {})

    def recording(self, d):
        """``(q_meas, t_s)`` of the bounce turning back ``d`` m before the true locus (centre geometry)."""
        if d not in self.readings:
            b = self.b
            run = simulate_bounce(self.kin, self.point, self.u, self.speed, xi_true=self.kin.robot.xi_center,
                                  t_s=b.t_s, eps_q=b.eps_q, t_rest=0.02, a_peak=b.a_peak,
                                  cruise=max(5e-3, cruise_for(self.speed, b.a_peak) - d / 2),
                                  working_guess=self.q_point, seed=0, short=d)
            self.readings[d] = run.q_meas
        return self.readings[d], self.b.t_s


def bounce_verdicts(robot, task: CrossingTask, bounds: PlanningBounds | ResolvedBounds, speed: float, *,
                    distances=BOUNCE_DISTANCES, kin=None, imodel=None, exhaustive: bool = False,
                    parallel: bool = True) -> BounceVerdicts:
    """The tracker's verdicts on the task's bounces at ``speed``, by bisection over ``distances`` (m).

    The farthest first (not certified: no ``certified_from``), then the
    middle of the bracket between the nearest certified and the farthest
    uncertified distance (the nearest is presumed uncertified until the
    bracket reaches it).  ``exhaustive`` tracks every distance.  Every tried
    distance from ``certified_from`` on is certified, monotone family or not.
    ``parallel``: window passes over the thread slots (the same verdicts).
    """
    fam = _Bounces(robot, task, bounds, speed, kin)
    imodel = IntervalModel(robot) if imodel is None else imodel
    distances = tuple(sorted({float(d) for d in distances}))
    s = fam.b.tracker_settings()
    verdicts: dict[float, Verdict] = {}

    def unchanged(i: int) -> bool:
        d = distances[i]
        if d not in verdicts:
            q, _ = fam.recording(d)
            x0 = initial_box_from_mode(imodel, q[0], fam.m0, s)
            verdicts[d] = track_window(imodel, q, s, x0=x0, max_geometries=BOUNCE_WINDOW_GEOMETRIES,
                                       parallel=parallel, goal=Verdict.MODE_UNCHANGED,
                                       one_motion=fam.b.one_motion).verdict
        return verdicts[d] is Verdict.MODE_UNCHANGED

    if exhaustive:
        for i in range(len(distances)):
            unchanged(i)
    elif unchanged(len(distances) - 1):
        lo, hi = 0, len(distances) - 1  # lo presumed uncertified until tried
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if unchanged(mid):
                hi = mid
            else:
                lo = mid
        if lo == 0:
            unchanged(0)
    certified_from = None
    for d in sorted(verdicts, reverse=True):
        if verdicts[d] is not Verdict.MODE_UNCHANGED:
            break
        certified_from = d
    tried = tuple(sorted(verdicts))
    return BounceVerdicts(fam.speed, tried, tuple(verdicts[d] for d in tried), certified_from, dict(fam.readings))


def bounce_floor(robot, task: CrossingTask, bounds: PlanningBounds | ResolvedBounds, tracked: BounceVerdicts, *,
                 starts=None, distances=BOUNCE_DISTANCES, tol: float = BOUNCE_FLOOR_TOL, kin=None,
                 exhaustive: bool = False):
    """The crossing floor of the bounces of ``tracked`` (:func:`planner.refute.crossing_floor`).

    Module-level so that any executor can run it in another process.  The
    searches run on every third distance below ``tracked.certified_from``
    and bisect up to it (a bounce certified ``mode-unchanged`` has no
    crossing explanation, so the floor lies below); ``exhaustive`` searches
    every third distance and bisects between them only.  Returns a
    :class:`planner.refute.CrossingFloor`.
    """
    fam = _Bounces(robot, task, bounds, tracked.speed, kin, readings=tracked.readings)
    distances = tuple(sorted({float(d) for d in distances}))
    certified_from = tracked.certified_from
    scan = distances[::3]
    if certified_from is not None and not exhaustive:
        scan = tuple(d for d in scan if d < certified_from) or distances[:1]
    return refute.crossing_floor(fam.kin, fam.recording, scan, tol=tol, m0=fam.m0, xi_starts=starts,
                                 bounds=_floor_bounds(fam.b), max_cpu_time=BOUNCE_CPU_TIME,
                                 upper=None if exhaustive else certified_from)


def _floor_bounds(b: ResolvedBounds) -> dict:
    """The crossing searches' bounds (:func:`planner.refute.crossing_floor`): the readings within ``eps_q``
    (the bounces are simulated without tracking error), the ``a_max`` and ``xd0`` the tracker's side assumes."""
    a = b.assumptions
    return {"eps_q": b.eps_q, "a_max": np.array(a.a_max, float), "v0_max": np.array(a.xd0, float)}


def bounce_gap(robot, task: CrossingTask, bounds: PlanningBounds | ResolvedBounds, speed: float, *,
               starts=None, distances=BOUNCE_DISTANCES, tol: float = BOUNCE_FLOOR_TOL, kin=None, imodel=None,
               exhaustive: bool = False) -> BounceGap:
    """Certified and refuted turn-back distances of the task's bounces at ``speed`` (module docstring).

    :func:`bounce_verdicts` (the tracker's side, by bisection over
    ``distances``) then :func:`bounce_floor` (the crossing searches, below
    ``certified_from``).  Both results keep their meaning when the family is
    not monotone in the distance: every tried distance from
    ``certified_from`` on is certified, and the floor is a verified
    counterexample.

    Parameters
    ----------
    robot : robots.Robot
    task : CrossingTask
    bounds : ResolvedBounds or PlanningBounds
        ``t_s``, ``eps_q`` and ``a_peak`` (of the bounces' ramps) are used, and ``a_max`` and ``xd0`` are
        assumed by the tracker and the crossing searches (resolved for ``robot``, or for a certificate's plan
        with the ``a_max`` it assumes: :meth:`~planner.task.ResolvedBounds.for_plan`; or resolved here:
        :func:`planner.task.resolved`).
    speed : float
        Approach speed, m/s.
    starts : sequence of array_like (m,), optional
        Starting geometries of the crossing searches (default: the box centre).
    distances : sequence of float
        Turn-back distances, m.
    tol : float
        Resolution of the crossing floor, m.
    exhaustive : bool
        Track every distance and search crossings on every third one (no
        bisection of the tracker's side; for tests and studies of the whole family).
    """
    kin = KinematicModel(robot) if kin is None else kin
    tracked = bounce_verdicts(robot, task, bounds, speed, distances=distances, kin=kin, imodel=imodel,
                              exhaustive=exhaustive)
    floor = bounce_floor(robot, task, bounds, tracked, starts=starts, distances=distances, tol=tol, kin=kin,
                         exhaustive=exhaustive)
    return gap_of(tracked, floor)


def gap_of(tracked: BounceVerdicts, floor) -> BounceGap:
    """The :class:`BounceGap` of the tracker's side and the crossing searches."""
    return BounceGap(tracked.speed, tracked.distances, tracked.verdicts, tracked.certified_from, floor.floor,
                     tuple(floor.rows))
