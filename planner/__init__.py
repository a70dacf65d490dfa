"""Planning side: planning-time certification, refutation bound, simulated crossings, sweeps.

Explicit re-exports (no star imports).
"""

from .certify import (
    CrossingCertificate,
    CrossingTask,
    PlannedTrajectory,
    PlanningBounds,
    SpeedTrial,
    certify_crossing,
    certify_plan,
    execution_class,
    minimal_v_sing,
    monte_carlo_confirmation,
    plan_crossing,
    speed_ceiling,
)
from .execution import ExecutionClass, cartesian_class, in_class, joint_class
from .generate import GeneratedTrajectory, GenerationLimits, generate_crossing
from .refute import RecordingBounds, RefutationBound, refutation_bound, search_bounce, verify_bounce
from .simulate import SimulatedRun, max_v_sing, random_geometry, simulate_bounce, simulate_crossing
from .sweep import SweepRow, cruise_for, sweep

__all__ = [
    "CrossingCertificate",
    "CrossingTask",
    "PlannedTrajectory",
    "PlanningBounds",
    "SpeedTrial",
    "certify_crossing",
    "certify_plan",
    "execution_class",
    "minimal_v_sing",
    "ExecutionClass",
    "cartesian_class",
    "in_class",
    "joint_class",
    "monte_carlo_confirmation",
    "plan_crossing",
    "speed_ceiling",
    "GeneratedTrajectory",
    "GenerationLimits",
    "generate_crossing",
    "RecordingBounds",
    "RefutationBound",
    "refutation_bound",
    "search_bounce",
    "verify_bounce",
    "SimulatedRun",
    "max_v_sing",
    "random_geometry",
    "simulate_bounce",
    "simulate_crossing",
    "SweepRow",
    "cruise_for",
    "sweep",
]
