"""The acceleration assumption of a certificate: one bound per pose axis, with its unit and its source.

Every certificate assumes ``|x''_i(t)| <= a_max_i`` for the executed motion,
per pose axis ``i``, in that axis' unit per s^2 (m/s^2 for a length, rad/s^2
for an angle: :attr:`robots.Robot.pose_units`).  Each axis' bound comes from
one :class:`AccelerationSource`, decided on that axis alone, so that no bound
of one axis is ever computed from another axis:

* ``robot a_max`` (the default): the robot's physical bound ``a_max``, the
  only number that holds whatever the controller does (the source paper's
  assumption);
* ``given``: the caller's bound (``PlanningBounds.a_max``);
* ``plan peak + margin``: asked for explicitly (``PlanningBounds.a_margin``):
  an axis the plan accelerates gets its planned peak enlarged by that
  relative margin, an assumption about the controller's tracking error;
* ``plan peak + robot tracking margin``: the robot declares how far its
  controller lets the executed acceleration deviate from the plan
  (``Robot.tracking_a_margin``): the planned peak plus that margin.

No bound derived from the plan exceeds the robot's ``a_max`` (the physical
bound holds too); a given bound is taken as given, a larger one only makes
the certificate assume more (weaker, still sound).  A plan that asks more than
``a_max`` of some axis is refused: no execution of it exists under the
robot's bound.  See docs/planning.md, "The acceleration
assumption".
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from crosscert.robots.errors import InputError

__all__ = ["AccelerationSource", "AxisAcceleration", "AccelerationAssumption", "acceleration_assumption",
           "robot_a_max_assumption", "PLAN_AT_REST"]

#: An axis whose planned peak ``|x''_i|`` is at most this fraction of the robot's
#: ``a_max_i`` (same axis, same unit) is one the plan does not accelerate:
#: rounding in a plan along a coordinate direction, not a motion.
PLAN_AT_REST = 1e-9


class AccelerationSource(StrEnum):
    """Where one axis' acceleration bound comes from."""

    PLAN_PEAK = "plan peak + margin"
    TRACKING_MARGIN = "plan peak + robot tracking margin"
    ROBOT_A_MAX = "robot a_max"
    GIVEN = "given"


@dataclass(frozen=True)
class AxisAcceleration:
    """One pose axis' bound on ``|x''_i|``: ``value`` in ``unit`` (``"m/s^2"`` or ``"rad/s^2"``), and its source."""

    value: float
    unit: str
    source: AccelerationSource

    def summary(self) -> dict:
        """JSON-ready ``{"value", "unit", "source"}``."""
        return {"value": self.value, "unit": self.unit, "source": self.source.value}

    def __str__(self) -> str:
        return f"{self.value:.4g} {self.unit} ({self.source.value})"


@dataclass(frozen=True)
class AccelerationAssumption:
    """The per-axis acceleration bounds a certificate assumes (one :class:`AxisAcceleration` per pose axis)."""

    axes: tuple[AxisAcceleration, ...]

    @property
    def values(self) -> tuple[float, ...]:
        """The bounds, per axis, each in its own unit (for the tracker, which reads them axis by axis)."""
        return tuple(a.value for a in self.axes)

    @property
    def sources(self) -> tuple[AccelerationSource, ...]:
        """The source of each axis' bound."""
        return tuple(a.source for a in self.axes)

    def summary(self) -> list[dict]:
        """JSON-ready list, one ``{"value", "unit", "source"}`` per pose axis."""
        return [a.summary() for a in self.axes]

    def describe(self) -> str:
        """One line: each axis' bound with its unit and source."""
        return "; ".join(f"axis {i + 1}: {a}" for i, a in enumerate(self.axes))

    def same_values(self, other: AccelerationAssumption) -> bool:
        """Whether both assume the same bound on every axis (units checked axis by axis)."""
        if len(self.axes) != len(other.axes):
            return False
        for a, o in zip(self.axes, other.axes):
            if a.unit != o.unit:
                raise InputError(f"acceleration bounds in {a.unit} and {o.unit} compared on one axis")
        return all(a.value == o.value for a, o in zip(self.axes, other.axes))

    @staticmethod
    def widest(assumptions) -> AccelerationAssumption:
        """Per axis, the largest bound of ``assumptions`` (e.g. the plans of one batch) with its source."""
        assumptions = list(assumptions)
        if not assumptions:
            raise InputError("no acceleration assumption to combine")
        out = []
        for i in range(len(assumptions[0].axes)):
            column = [a.axes[i] for a in assumptions]
            if len({c.unit for c in column}) != 1:
                raise InputError(f"axis {i + 1}: acceleration bounds in different units {sorted({c.unit for c in column})}")
            out.append(max(column, key=lambda c: c.value))
        return AccelerationAssumption(tuple(out))


def robot_a_max_assumption(robot) -> AccelerationAssumption:
    """The robot's physical ``a_max`` on every axis (source ``robot a_max``)."""
    return AccelerationAssumption(tuple(AxisAcceleration(float(v), u, AccelerationSource.ROBOT_A_MAX)
                                        for v, u in zip(robot.a_max, robot.acceleration_units)))


def acceleration_assumption(plan, b, robot) -> AccelerationAssumption:
    """The acceleration bounds a certificate of ``plan`` assumes, per axis, under ``b``.

    The plan-dependent step of the bounds' resolution: :meth:`planner.task.ResolvedBounds.for_plan` calls it.

    Parameters
    ----------
    plan : PlannedTrajectory
        Its ``xdd`` (K, n) gives the planned peak of each axis, in that axis' unit per s^2.
    b : planner.task.ResolvedBounds
        Its ``a_max_given`` (per axis; ``None``: not given) and ``a_margin`` (relative; ``None``: no margin
        asked for).
    robot : robots.Robot
        Its ``pose_units``, ``tracking_a_margin`` and ``a_max``.

    Returns
    -------
    AccelerationAssumption
        Axis ``i`` depends only on axis ``i`` of the plan and of the robot:
        ``given`` when ``b.a_max_given`` is set; else, with ``b.a_margin`` set and
        the axis accelerated by the plan (peak above :data:`PLAN_AT_REST` of
        ``a_max_i``), its peak times ``1 + a_margin``; else, when the robot
        declares a tracking margin, the peak plus that margin; else the
        robot's ``a_max_i``.  Never above ``a_max_i``.

    Raises
    ------
    InputError
        ``b.a_max_given`` or the robot's ``a_max`` below the plan's peak on some
        axis (the message names the axis, both values and the unit).
    """
    peak = np.max(np.abs(np.asarray(plan.xdd, float)), axis=0)
    units = robot.acceleration_units
    if peak.shape != (robot.n,):
        raise InputError(f"the plan has {peak.size} pose axes, robot {robot.name} has {robot.n}")
    _check_peak(peak, robot.a_max, units, "the robot's a_max", "no execution of this plan exists under it; "
                "slow the plan down or lower its peak acceleration")
    given = b.a_max_given
    if given is not None:
        _check_peak(peak, given, units, "a_max", "raise a_max on that axis or lower a_peak")
        return AccelerationAssumption(tuple(AxisAcceleration(float(given[i]), units[i], AccelerationSource.GIVEN)
                                            for i in range(robot.n)))
    margin = robot.tracking_a_margin
    axes = []
    for i in range(robot.n):
        a_max = float(robot.a_max[i])
        if b.a_margin is not None and peak[i] > PLAN_AT_REST * a_max:
            axes.append(AxisAcceleration(min(float(peak[i] * (1.0 + b.a_margin)), a_max), units[i],
                                         AccelerationSource.PLAN_PEAK))
        elif margin is not None:
            axes.append(AxisAcceleration(min(float(peak[i] + margin[i]), a_max), units[i],
                                         AccelerationSource.TRACKING_MARGIN))
        else:
            axes.append(AxisAcceleration(a_max, units[i], AccelerationSource.ROBOT_A_MAX))
    return AccelerationAssumption(tuple(axes))


def _check_peak(peak, bound, units, name: str, advice: str) -> None:
    """InputError naming every axis whose planned peak exceeds ``bound`` (``name`` says whose bound)."""
    low = [i for i in range(len(peak)) if bound[i] < peak[i]]
    if low:
        raise InputError("bounds contradict the plan: " + "; ".join(
            f"axis {i + 1}: {name} = {bound[i]:g} {units[i]} is below the planned peak {peak[i]:.6g} {units[i]}"
            for i in low) + f"; {advice}")
