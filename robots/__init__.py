"""Robot descriptions, their kinematic and dynamic models, and the registry.

The bottom layer of crosscert: it imports neither :mod:`verifier` nor
:mod:`planner`.  The project's error hierarchy (:mod:`robots.errors`) and its
argument checks (:mod:`robots.arguments`) live here so every layer above can
use them.
"""

from __future__ import annotations

import logging

from .base import BenchmarkCrossing, LoopClosure, Robot
from .units import PoseUnit
from .dextar import DEXTAR, DEXTAR_DYNAMICS, benchmark_crossing, elbows_out_ik, singular_y
from .dynamics import LumpedDynamics
from .mass_model import LumpedMassModel
from .errors import CrosscertError, InputError, ModelError, SimulationError, TrajectoryFileError, UnknownRobotError
from .kinematics import KinematicModel
from .rpr3 import RPR3
from .gough_stewart import GOUGH_STEWART
from .base import ReferenceMotion
from .validation import CheckOutcome, CheckResult, ValidationReport, validate
from .registry import DEFAULT_ROBOT, ROBOTS, RobotEntry, available_robots, get_entry, get_robot

__all__ = [
    "Robot",
    "PoseUnit",
    "LoopClosure",
    "KinematicModel",
    "LumpedMassModel",
    "LumpedDynamics",
    "BenchmarkCrossing",
    "RobotEntry",
    "ROBOTS",
    "DEFAULT_ROBOT",
    "get_entry",
    "get_robot",
    "available_robots",
    "DEXTAR",
    "RPR3",
    "GOUGH_STEWART",
    "ReferenceMotion",
    "validate",
    "ValidationReport",
    "CheckResult",
    "CheckOutcome",
    "DEXTAR_DYNAMICS",
    "benchmark_crossing",
    "elbows_out_ik",
    "singular_y",
    "CrosscertError",
    "InputError",
    "ModelError",
    "SimulationError",
    "TrajectoryFileError",
    "UnknownRobotError",
]

logging.getLogger(__name__).addHandler(logging.NullHandler())
