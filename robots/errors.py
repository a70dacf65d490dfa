"""The project's error hierarchy.

Every failure a user can act on raises a subclass of :class:`CrosscertError`
with a message that says what was wrong and what to do; the CLI prints it as
one line on stderr and exits with code 2.
"""

from __future__ import annotations

__all__ = [
    "CrosscertError",
    "InputError",
    "TrajectoryFileError",
    "UnknownRobotError",
    "RobotSourceError",
    "ModelError",
    "SimulationError",
]


class CrosscertError(Exception):
    """Base class of every error crosscert raises on purpose."""


class InputError(CrosscertError, ValueError):
    """An argument or a datum violates what the API documents."""


class TrajectoryFileError(InputError):
    """A trajectory file is missing, malformed or breaks the tracker's assumptions."""


class UnknownRobotError(InputError, KeyError):
    """No robot of that name is registered."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class ModelError(CrosscertError):
    """A robot model cannot be used (unsupported CasADi operation, wrong shapes)."""


class SimulationError(CrosscertError):
    """A simulated motion cannot be produced (unreachable pose, IK failure, limits)."""


class RobotSourceError(InputError):
    """A robot file or an installed entry point cannot be loaded, or does not hold a robot entry."""
