"""The registry of shipped robots: the only place commands and studies find a robot by name.

A :class:`RobotEntry` bundles what the layers above need besides the robot's
kinematics: an optional lumped dynamic model (the ``dynamic`` time law) and an
optional benchmark crossing (the default task of ``plan``, ``certify``,
``simulate`` and ``sweep``).  Nothing outside ``robots/`` names a robot.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from .base import BenchmarkCrossing, ReferenceMotion, Robot
from .gough_stewart import GOUGH_STEWART, gs_reference_motion
from .dextar import DEXTAR, DEXTAR_DYNAMICS, benchmark_crossing
from .mass_model import LumpedMassModel
from .rpr3 import RPR3, rpr3_benchmark_crossing
from .errors import InputError, UnknownRobotError

__all__ = ["RobotEntry", "ROBOTS", "DEFAULT_ROBOT", "available_robots", "get_entry", "get_robot"]


@dataclass(frozen=True, eq=False)
class RobotEntry:
    """A registered robot and what it ships with.

    Attributes
    ----------
    robot : Robot
        Parameters and loop closure.
    dynamics : LumpedMassModel or None
        Lumped dynamic model, when the robot has one.
    benchmark : callable ``xi -> BenchmarkCrossing`` or None
        Its reference crossing for a geometry (``None``: nominal).
    motion : callable ``xi -> ReferenceMotion`` or None
        A regular reference motion for ``simulate`` (robots without a
        benchmark crossing).
    """

    robot: Robot
    dynamics: LumpedMassModel | None = None
    benchmark: Callable[..., BenchmarkCrossing] | None = None
    motion: Callable[..., ReferenceMotion] | None = None

    @property
    def name(self) -> str:
        """Registry name (lower case)."""
        return self.robot.name.lower()

    def require_dynamics(self) -> LumpedMassModel:
        """The dynamic model, or InputError naming what to use instead."""
        if self.dynamics is None:
            raise InputError(f"robot {self.robot.name!r} has no dynamic model; use method smoothstep or time-optimal")
        return self.dynamics

    def benchmark_crossing(self, xi=None) -> BenchmarkCrossing:
        """The benchmark crossing for geometry ``xi`` (nominal when None), or InputError if there is none."""
        if self.benchmark is None:
            raise InputError(f"robot {self.robot.name!r} ships no crossing benchmark, so crossing planning "
                             "(plan, certify, sweep, study) is not available for it; check, monitor and simulate are")
        return self.benchmark(xi)

    def reference_motion(self, xi=None) -> ReferenceMotion:
        """The reference motion for geometry ``xi`` (nominal when None), or InputError if there is none."""
        if self.motion is None:
            raise InputError(f"robot {self.robot.name!r} has no reference motion")
        return self.motion(xi)


#: Registered robots by lower-case name.
ROBOTS: dict[str, RobotEntry] = {
    e.name: e
    for e in (
        RobotEntry(DEXTAR, DEXTAR_DYNAMICS, benchmark_crossing),
        RobotEntry(RPR3, None, rpr3_benchmark_crossing),
        RobotEntry(GOUGH_STEWART, None, None, gs_reference_motion),
    )
}

#: The robot commands use when ``--robot`` is not given.
DEFAULT_ROBOT = "dextar"


def available_robots() -> list[str]:
    """Sorted names of the registered robots."""
    return sorted(ROBOTS)


def get_entry(name: str) -> RobotEntry:
    """The registry entry called ``name`` (case and surrounding blanks ignored).

    Raises
    ------
    UnknownRobotError
        If no robot has that name; the message lists the known names.
    """
    key = name.strip().lower() if isinstance(name, str) else name
    try:
        return ROBOTS[key]
    except (KeyError, TypeError):
        raise UnknownRobotError(
            f"unknown robot {name!r}; known robots: {', '.join(available_robots())}"
        ) from None


def get_robot(name: str) -> Robot:
    """The registered :class:`Robot` called ``name`` (see :func:`get_entry`)."""
    return get_entry(name).robot
