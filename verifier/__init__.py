"""Sound interval tracking of a parallel robot's pose and velocity.

What a user calls, by task (explicit re-exports, no star imports):

* **track a recording** — :class:`TrackerSettings` (its bounds are one
  :class:`~robots.assumptions.Assumptions`), :func:`track` /
  :func:`track_batch` / the online :class:`Tracker`, answering a
  :class:`Verdict`; :class:`Backend` picks the compiled or NumPy kernels;
* **reason over a window** — :func:`track_window` (whole run) and
  :class:`OnlineMonitor` (online: the tracker, and a window from the last
  sample whose mode it knew), :class:`Reasoning`;
* **the interval model** of a robot — :class:`IntervalModel`;
* **recordings** — :class:`Trajectory`, :func:`read_trajectory`,
  :func:`write_trajectory`, and :func:`open_recording` (a CSV, a ROS 2 bag
  or an ``.npz``, sample by sample); :class:`SampleClock` (the samples'
  times of an uneven recording: dropped samples, jittered stamps);
* **check a robot definition** — :func:`validate` (every check, the interval
  ones included).

The one-sample step, its configuration and state (:mod:`verifier.step`), the
packing and kernels (:mod:`verifier.compiled`), tapes (:mod:`verifier.tape`)
and file helpers (:mod:`verifier.files`) stay in their modules; the error
classes are :mod:`robots.errors`'s.
"""

import logging

from .clock import SampleClock
from .model import IntervalModel
from .settings import TrackerSettings, VelocityModel, Verdict
from .step import Backend
from .tracker import BatchResult, SampleStream, Tracker, TrackResult, initial_box_from_mode, track, track_batch
from .trajectory import Trajectory
from .recordings import open_recording
from .trajfile import read_trajectory, write_trajectory
from .validation import validate
from .window import OnlineEvent, OnlineMonitor, OnlineResult, Reasoning, WindowResult, WindowState, track_window

__all__ = [
    # track a recording
    "TrackerSettings",
    "VelocityModel",
    "Verdict",
    "track",
    "track_batch",
    "Tracker",
    "TrackResult",
    "BatchResult",
    "SampleStream",
    "initial_box_from_mode",
    "Backend",
    # reason over a window
    "track_window",
    "OnlineMonitor",
    "OnlineResult",
    "OnlineEvent",
    "WindowState",
    "Reasoning",
    "WindowResult",
    # the interval model
    "IntervalModel",
    # recordings
    "SampleClock",
    "Trajectory",
    "read_trajectory",
    "write_trajectory",
    "open_recording",
    # check a robot definition
    "validate",
]

logging.getLogger(__name__).addHandler(logging.NullHandler())
