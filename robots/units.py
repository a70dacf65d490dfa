"""Units of a robot's pose coordinates, and of their rates.

A pose axis is a length (m) or an angle (rad); its velocity and acceleration
bounds are in that unit per s and per s².  :attr:`robots.Robot.pose_units` is
the one place a robot states them; every bound printed, stored or compared per
axis takes its unit from there, so that no computation mixes a length axis
with an angle axis.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["PoseUnit"]


class PoseUnit(StrEnum):
    """The SI unit of one pose coordinate."""

    METRE = "m"
    RADIAN = "rad"

    @property
    def velocity(self) -> str:
        """Unit of this axis' velocity: ``m/s`` or ``rad/s``."""
        return f"{self.value}/s"

    @property
    def acceleration(self) -> str:
        """Unit of this axis' acceleration: ``m/s^2`` or ``rad/s^2``."""
        return f"{self.value}/s^2"
