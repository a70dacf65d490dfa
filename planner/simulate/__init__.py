"""Simulated encoder data of a robot crossing, or bouncing on, a Type 2 singularity.

The end-effector follows a straight segment of poses ``x(t) = p + s(t) u``
through a point ``p`` of the *nominal* Type 2 singular locus, ``u`` a unit
direction.  The arc length ``s(t)`` (m, or the pose unit) follows a
:class:`TimeLaw`: rest, a speed ramp up to ``v_sing`` (quintic smoothstep in
speed, so the acceleration is continuous, zero at both ends and peaks at
``a_peak``), constant speed through ``p +- cruise`` (zero acceleration at the
singular instant: the crossing criterion of the paper), a symmetric ramp
down, and rest.  The joints are the IK of the pose with the *true* geometry
``xi_true``, followed by continuation in the working branch of the legs; the
assembly mode changes by itself when the pose passes the true locus.

In a *bounce* the end-effector decelerates to rest exactly on the true locus
and retraces the segment back to its start: the assembly mode never changes.

Encoder readings are quantised (or randomly perturbed) with
``|q_meas - q_true| <= eps_q``.  Velocities and accelerations are exact: from
the time law and eq. (2) and its time derivative (CasADi AD), never finite
differences.  SI units throughout.
"""

from __future__ import annotations

from .measure import Quantisation, quantise, random_geometry
from .run import SimulatedRun, max_v_sing, simulate_bounce, simulate_crossing, simulate_motion
from .timelaw import RAMP_PEAK, TimeLaw, bounce_time_law, crossing_time_law, ramp_length

__all__ = [
    "RAMP_PEAK",
    "TimeLaw",
    "crossing_time_law",
    "bounce_time_law",
    "ramp_length",
    "Quantisation",
    "quantise",
    "random_geometry",
    "SimulatedRun",
    "simulate_crossing",
    "simulate_bounce",
    "simulate_motion",
    "max_v_sing",
]
