"""The gap for ``mode-unchanged``: bounces of a task that turn back short of the locus.

The refutation bound and ``v_min`` bracket, in speed, where a crossing's
mode change can be certified.  This module brackets, in distance, where a
*failed* crossing can be certified ``mode-unchanged``: bounces along the
task's path at one approach speed that decelerate to rest ``d`` metres
before the true locus and come back (``planner.simulate.simulate_bounce``,
centre geometry, readings quantised by ``floor``).

* ``certified_from`` — the smallest tried ``d`` from which every tried
  bounce is certified ``mode-unchanged`` by the run-time tracker with window
  reasoning (robot's calibration box, ``eps_q`` and ``a_max``);
* ``floor`` — the crossing floor (:func:`planner.refute.crossing_floor`): the
  largest ``d`` at which a verified motion that *did* change mode explains
  the same readings; no sound method certifies ``mode-unchanged`` there.

SI units: m, m/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robots import KinematicModel
from verifier.model import IntervalModel
from verifier.tracker import TrackerSettings, Verdict, initial_box_from_mode
from verifier.window import track_window

from . import refute
from .simulate import simulate_bounce
from .sweep import cruise_for
from .generate.crossing import crossing_point_and_joints
from .task import CrossingTask, PlanningBounds

__all__ = ["BounceGap", "bounce_gap", "BOUNCE_DISTANCES", "BOUNCE_FLOOR_TOL"]

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

    def summary(self) -> dict:
        """JSON-ready summary (SI units)."""
        return {
            "speed_mps": self.speed,
            "tracker": [{"turn_back_m": d, "verdict": v.value} for d, v in zip(self.distances, self.verdicts)],
            "certified_from_m": self.certified_from,
            "crossing_floor_m": self.floor,
            "gap_m": None if self.certified_from is None or self.floor is None else self.certified_from - self.floor,
            "crossing_searches": [
                {"turn_back_m": r.parameter, "counterexample": bool(r.verified), "outcome": r.outcome.value,
                 "solver_status": r.status}
                for r in self.floor_rows
            ],
        }


def bounce_gap(robot, task: CrossingTask, bounds: PlanningBounds, speed: float, *, starts=None,
               distances=BOUNCE_DISTANCES, tol: float = BOUNCE_FLOOR_TOL, kin=None, imodel=None,
               exhaustive: bool = False) -> BounceGap:
    """Certified and refuted turn-back distances of the task's bounces at ``speed`` (module docstring).

    Module-level so that any executor can run it in another process.

    The tracker is asked by bisection over ``distances``: the farthest first
    (not certified: no ``certified_from``), then the middle of the bracket
    between the nearest certified and the farthest uncertified distance
    (the nearest distance is presumed uncertified until the bracket reaches
    it).  The crossing searches then run on every third distance below
    ``certified_from`` and bisect up to it: a bounce certified
    ``mode-unchanged`` has no crossing explanation, so the floor lies below.
    Both results keep their meaning when the family is not monotone in the
    distance: every tried distance from ``certified_from`` on is certified,
    and the floor is a verified counterexample.

    Parameters
    ----------
    robot : robots.Robot
    task : CrossingTask
    bounds : PlanningBounds
        ``t_s``, ``eps_q`` and ``a_peak`` (of the bounces' ramps) are used.
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
    imodel = IntervalModel(robot) if imodel is None else imodel
    b = bounds.resolved(robot)
    xi = robot.xi_center
    point, q_point, m0 = crossing_point_and_joints(kin, task, xi)
    u = (task.goal - task.start) / np.linalg.norm(task.goal - task.start)
    distances = tuple(sorted({float(d) for d in distances}))

    recordings: dict = {}

    def recording(d):  # the tracker and the crossing search read the same bounce: simulate it once
        if d not in recordings:
            recordings[d] = _bounce_readings(d)
        return recordings[d]

    def _bounce_readings(d):
        run = simulate_bounce(kin, point, u, speed, xi_true=xi, t_s=b.t_s, eps_q=b.eps_q, t_rest=0.02,
                              a_peak=b.a_peak, cruise=max(5e-3, cruise_for(speed, b.a_peak) - d / 2),
                              working_guess=q_point, seed=0, short=d)
        return run.q_meas, b.t_s

    s = TrackerSettings.for_robot(robot, t_s=b.t_s, eps_q=b.eps_q)
    verdicts: dict[float, Verdict] = {}

    def unchanged(i: int) -> bool:
        d = distances[i]
        if d not in verdicts:
            q, _ = recording(d)
            x0 = initial_box_from_mode(imodel, q[0], m0, s)
            verdicts[d] = track_window(imodel, q, s, x0=x0, max_geometries=BOUNCE_WINDOW_GEOMETRIES).verdict
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
    scan = distances[::3]
    if certified_from is not None and not exhaustive:
        scan = tuple(d for d in scan if d < certified_from) or distances[:1]
    floor = refute.crossing_floor(kin, recording, scan, tol=tol, m0=m0, xi_starts=starts,
                                  bounds={"eps_q": b.eps_q}, max_cpu_time=BOUNCE_CPU_TIME,
                                  upper=None if exhaustive else certified_from)
    tried = tuple(sorted(verdicts))
    return BounceGap(float(speed), tried, tuple(verdicts[d] for d in tried), certified_from, floor.floor,
                     tuple(floor.rows))
