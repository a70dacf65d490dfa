"""A lumped-mass model of a parallel robot: point masses, motor inertias, gravity, torque limits (data).

The dynamics derived from it live in :mod:`robots.dynamics`.  Units: SI (kg,
m, kg m^2, m/s^2, N m).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .errors import ModelError
from .arguments import floats

__all__ = ["LumpedMassModel"]


@dataclass(frozen=True, kw_only=True)
class LumpedMassModel:
    """Point masses, motor inertias, gravity and torque limits of a parallel robot (data).

    Parameters
    ----------
    robot_name : str
        Name of the :class:`~robots.base.Robot` whose ``(x, q, xi)`` the
        positions read (checked by :class:`LumpedDynamics`).
    point_names : tuple of str, length P
        Names of the mass points (e.g. ``"B1"``, ``"E"``).
    masses : tuple of float, length P
        Point masses, kg (positive).
    positions : callable
        ``positions(x, q, xi) -> casadi.SX`` of shape ``(d, P)``: column ``j``
        is the position (m) of point ``j`` in ``d``-dimensional space, for
        ``x`` ``(n,)``, ``q`` ``(n,)``, ``xi`` ``(m,)`` CasADi SX symbols.  A
        ``casadi.Function`` of ``(x, q, xi)`` qualifies.  Points fixed to the
        base (a motor axis) contribute nothing and may be left out.
    motor_inertia : tuple of float, length n
        Inertia of each actuated joint's rotating parts reflected to the
        joint (rotor times gear ratio squared, plus any inertia rigidly
        attached to the joint that no point mass represents), kg m^2.
    gravity : tuple of float, length d
        Gravity acceleration in the frame of the positions, m/s^2.  A planar
        robot working in a horizontal plane has no in-plane gravity:
        ``(0, 0)``.
    tau_max : tuple of float, length n
        Actuator torque limits ``|tau_i| <= tau_max_i`` at the joints, N m.
    description : str
        Source of every value (and which are assumptions).
    """

    robot_name: str
    point_names: tuple[str, ...]
    masses: tuple[float, ...]
    positions: Callable = field(repr=False)
    motor_inertia: tuple[float, ...]
    gravity: tuple[float, ...]
    tau_max: tuple[float, ...]
    description: str = ""

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        owner = f"LumpedMassModel({self.robot_name!r})"
        if not isinstance(self.robot_name, str) or not self.robot_name:
            raise ModelError("LumpedMassModel.robot_name must be a non-empty string")
        names = tuple(self.point_names)
        if not names or not all(isinstance(s, str) and s for s in names) or len(set(names)) != len(names):
            raise ModelError(f"{owner}: point_names must be distinct non-empty strings, got {names}")
        set_(self, "point_names", names)
        set_(self, "masses", floats(f"{owner}: masses", self.masses, len(names), positive=True, error=ModelError))
        if not callable(self.positions):
            raise ModelError(f"{owner}: positions must be callable (x, q, xi) -> casadi.SX (d, P)")
        inertia = floats(f"{owner}: motor_inertia", self.motor_inertia, nonneg=True, error=ModelError)
        if not inertia:
            raise ModelError(f"{owner}: motor_inertia needs one entry per actuated joint")
        set_(self, "motor_inertia", inertia)
        set_(self, "tau_max", floats(f"{owner}: tau_max", self.tau_max, len(inertia), positive=True, error=ModelError))
        grav = floats(f"{owner}: gravity", self.gravity, error=ModelError)
        if not grav:
            raise ModelError(f"{owner}: gravity needs one entry per spatial dimension")
        set_(self, "gravity", grav)
        if not isinstance(self.description, str):
            raise ModelError(f"{owner}: description must be a string")

    @property
    def n(self) -> int:
        """Number of actuated joints."""
        return len(self.motor_inertia)

    @property
    def dim(self) -> int:
        """Dimension ``d`` of the space the positions live in."""
        return len(self.gravity)

    @property
    def total_mass(self) -> float:
        """Sum of the point masses, kg."""
        return float(sum(self.masses))

    @property
    def tau_max_array(self) -> np.ndarray:
        """Torque limits, shape ``(n,)``, N m."""
        return np.array(self.tau_max, dtype=float)
