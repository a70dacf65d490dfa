"""Robot descriptions, their kinematic and dynamic models, and the registry.

The bottom layer of crosscert: it imports neither :mod:`verifier` nor
:mod:`planner`.  The project's error hierarchy (:mod:`robots.errors`), the
one owner of the bounds a certificate assumes (:mod:`robots.assumptions`) and
the argument checks (:mod:`robots.arguments`) live here so every layer above
can use them.  A robot's own helpers (IK, its benchmark crossing) stay in its
module (:mod:`robots.dextar`, :mod:`robots.iri_five_bar`, :mod:`robots.rpr3`,
:mod:`robots.gough_stewart`).
"""

from __future__ import annotations

import logging

from .assumptions import Assumptions
from .base import BenchmarkCrossing, LoopClosure, ReferenceMotion, Robot
from .dextar import DEXTAR
from .dynamics import LumpedDynamics
from .errors import (CrosscertError, InputError, ModelError, RobotSourceError, SimulationError, TrajectoryFileError,
                     UnknownRobotError)
from .gough_stewart import GOUGH_STEWART
from .iri_five_bar import IRI_FIVE_BAR
from .kinematics import KinematicModel
from .mass_model import LumpedMassModel
from .registry import (DEFAULT_ROBOT, ENTRY_POINT_GROUP, ROBOTS, RobotEntry, RobotOrigin, RobotSource, available_robots,
                       get_entry, get_robot, robot_origin)
from .rpr3 import RPR3
from .units import PoseUnit
from .validation import CheckOutcome, CheckResult, ValidationReport, check_definition

__all__ = [
    # the shipped robots and the registry
    "DEXTAR",
    "RPR3",
    "GOUGH_STEWART",
    "IRI_FIVE_BAR",
    "ROBOTS",
    "DEFAULT_ROBOT",
    "RobotEntry",
    "get_robot",
    "get_entry",
    "available_robots",
    "robot_origin",
    "RobotOrigin",
    "RobotSource",
    "ENTRY_POINT_GROUP",
    # describing a robot
    "Robot",
    "LoopClosure",
    "PoseUnit",
    "BenchmarkCrossing",
    "ReferenceMotion",
    "LumpedMassModel",
    # what a certificate assumes about it
    "Assumptions",
    # its models
    "KinematicModel",
    "LumpedDynamics",
    # checking a definition (the interval checks: crosscert.validate)
    "check_definition",
    "ValidationReport",
    "CheckResult",
    "CheckOutcome",
    # errors
    "CrosscertError",
    "InputError",
    "ModelError",
    "SimulationError",
    "RobotSourceError",
    "TrajectoryFileError",
    "UnknownRobotError",
]

logging.getLogger(__name__).addHandler(logging.NullHandler())
