"""Sound interval tracking of a parallel robot's pose and velocity.

Explicit re-exports of the public API (no star imports).  The one-sample
function is ``verifier.step.step`` (not re-exported: the name is its module's).
The error classes are :mod:`robots.errors`'s, re-exported for convenience.
"""

import logging

from crosscert.robots.errors import (
    CrosscertError,
    InputError,
    ModelError,
    SimulationError,
    TrajectoryFileError,
    UnknownRobotError,
)
from .model import IntervalModel
from .step import Backend, Event, StepConfig, StepResult, Tracker, TrackerState, advance, configure, init_state
from .tape import Tape
from .files import atomic_write
from .settings import TrackerSettings, VelocityModel, Verdict
from .tracker import (
    BatchResult,
    SampleStream,
    TrackResult,
    initial_box_from_mode,
    track,
    track_batch,
)
from .trajectory import Trajectory
from .trajfile import read_trajectory, write_trajectory
from .validation import validate

__all__ = [
    "CrosscertError",
    "InputError",
    "ModelError",
    "SimulationError",
    "TrajectoryFileError",
    "UnknownRobotError",
    "IntervalModel",
    "Backend",
    "Event",
    "StepConfig",
    "StepResult",
    "Tracker",
    "TrackerState",
    "advance",
    "configure",
    "init_state",
    "Tape",
    "BatchResult",
    "SampleStream",
    "TrackerSettings",
    "TrackResult",
    "VelocityModel",
    "Verdict",
    "initial_box_from_mode",
    "track",
    "track_batch",
    "Trajectory",
    "atomic_write",
    "read_trajectory",
    "write_trajectory",
    "validate",
]

logging.getLogger(__name__).addHandler(logging.NullHandler())
