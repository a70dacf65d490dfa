"""Robot descriptions and their kinematic models.

``ROBOTS`` maps a registry name to its :class:`Robot`; :func:`get_robot`
looks one up by name and :func:`available_robots` lists the names.
"""

from __future__ import annotations

from verifier.errors import UnknownRobotError

from .base import LoopClosure, Robot
from .dextar import DEXTAR, BenchmarkCrossing, benchmark_crossing, elbows_out_ik, singular_y
from .dynamics import DEXTAR_DYNAMICS, LumpedDynamics, LumpedMassModel
from .kinematics import KinematicModel

__all__ = [
    "Robot",
    "LoopClosure",
    "KinematicModel",
    "LumpedMassModel",
    "LumpedDynamics",
    "DEXTAR_DYNAMICS",
    "DEXTAR",
    "BenchmarkCrossing",
    "benchmark_crossing",
    "elbows_out_ik",
    "singular_y",
    "ROBOTS",
    "get_robot",
    "available_robots",
]

#: Registry of the robots the CLI knows, by name.
ROBOTS: dict[str, Robot] = {"dextar": DEXTAR}


def available_robots() -> list[str]:
    """Sorted names of the registered robots."""
    return sorted(ROBOTS)


def get_robot(name: str) -> Robot:
    """The registered robot called ``name`` (case and surrounding blanks ignored).

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
