"""Planning side: plans of a crossing, their certification, refutation bound, simulations, sweeps.

Layout, along the method:

* :mod:`planner.task` — what is asked (task, bounds, options) and where the
  segment meets the locus; :mod:`planner.locus` — the line scans behind it;
* :mod:`planner.plan` — the three time laws, built on :mod:`planner.timescale`
  (time-optimal) and :mod:`planner.generate` (dynamic);
* :mod:`planner.acceleration` — the per-axis acceleration bounds a certificate
  assumes, with units and sources;
* :mod:`planner.certify.plan` — certification of plans and the speed search;
* :mod:`planner.montecarlo` — simulated executions tracked at run time;
* :mod:`planner.refute` — verified counterexamples (the refutation bound, the crossing floor);
* :mod:`planner.certify.crossing` — all of it, on an executor; :mod:`planner.assumption_cost`
  — the same under the robot's physical ``a_max``;
* :mod:`planner.simulate`, :mod:`planner.sweep` — simulated runs and the
  paper's speed sweep; :mod:`planner.cli` — the ``crosscert`` command.

Explicit re-exports (no star imports).
"""

import logging

from .acceleration import AccelerationAssumption, AccelerationSource, AxisAcceleration, acceleration_assumption
from .assumption_cost import AtRobotAMax, ComparisonOutcome, certify_at_robot_a_max
from .certify.plan import CertifiedRun, SpeedSearch, SpeedTrial, certify_plan, certify_speed, execution_class, minimal_v_sing, search_v_min
from .execution import ExecutionClass, cartesian_class, in_class, joint_class
from .generate import GeneratedTrajectory, GenerationLimits, generate_crossing
from .montecarlo import MonteCarloResult, monte_carlo_confirmation
from .certify.crossing import CrossingCertificate, certify_crossing
from .plan import plan_crossing, speed_ceiling
from .refute import (
    CrossingFloor,
    RecordingBounds,
    RefutationBound,
    crossing_floor,
    refutation_bound,
    search_bounce,
    search_crossing,
    verify_bounce,
    verify_crossing,
)
from .simulate import Quantisation, SimulatedRun, max_v_sing, quantise, random_geometry, simulate_bounce, simulate_crossing
from .sweep import SweepRow, cruise_for, sweep
from .task import CrossingTask, ExecutionKind, Method, PlannedTrajectory, PlanningBounds, benchmark_task

__all__ = [
    "CrossingTask",
    "PlanningBounds",
    "PlannedTrajectory",
    "Method",
    "ExecutionKind",
    "benchmark_task",
    "plan_crossing",
    "speed_ceiling",
    "SpeedTrial",
    "certify_plan",
    "execution_class",
    "minimal_v_sing",
    "search_v_min",
    "certify_speed",
    "SpeedSearch",
    "CertifiedRun",
    "MonteCarloResult",
    "monte_carlo_confirmation",
    "CrossingCertificate",
    "certify_crossing",
    "AccelerationAssumption",
    "AccelerationSource",
    "AxisAcceleration",
    "acceleration_assumption",
    "AtRobotAMax",
    "ComparisonOutcome",
    "certify_at_robot_a_max",
    "ExecutionClass",
    "cartesian_class",
    "in_class",
    "joint_class",
    "GeneratedTrajectory",
    "GenerationLimits",
    "generate_crossing",
    "RecordingBounds",
    "RefutationBound",
    "refutation_bound",
    "search_bounce",
    "verify_bounce",
    "CrossingFloor",
    "crossing_floor",
    "search_crossing",
    "verify_crossing",
    "Quantisation",
    "quantise",
    "SimulatedRun",
    "max_v_sing",
    "random_geometry",
    "simulate_bounce",
    "simulate_crossing",
    "SweepRow",
    "cruise_for",
    "sweep",
]

logging.getLogger(__name__).addHandler(logging.NullHandler())
