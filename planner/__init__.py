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

Explicit re-exports, grouped by what a user does (no star imports); the
lower-level pieces (execution classes, acceleration bounds, the NLP
generator, counterexample searches) are imported from their modules.
"""

import logging

from .assumption_cost import AtRobotAMax, ComparisonOutcome, certify_at_robot_a_max
from .certify.certificate import CrossingCertificate
from .certify.crossing import certify_crossing
from .certify.plan import CertifiedRun, SpeedSearch, certify_plan, certify_speed, minimal_v_sing, search_v_min
from .execution import ExecutionClass
from .execution_proof import execution_class
from .montecarlo import MonteCarloResult, monte_carlo_confirmation
from .plan import plan_crossing, speed_ceiling
from .refute import CrossingFloor, RecordingBounds, RefutationBound, crossing_floor, refutation_bound
from .simulate import SimulatedRun, max_v_sing, random_geometry, simulate_bounce, simulate_crossing
from .sweep import SweepRow, sweep
from .task import CrossingTask, ExecutionKind, Method, PlannedTrajectory, PlanningBounds, benchmark_task

__all__ = [
    # the task and its bounds
    "CrossingTask",
    "benchmark_task",
    "PlanningBounds",
    "Method",
    "ExecutionKind",
    # plan and certify a crossing (the main job)
    "certify_crossing",
    "CrossingCertificate",
    "certify_at_robot_a_max",
    "AtRobotAMax",
    "ComparisonOutcome",
    # its parts: a plan, one speed, the speed search, the executions covered
    "plan_crossing",
    "PlannedTrajectory",
    "speed_ceiling",
    "certify_plan",
    "certify_speed",
    "CertifiedRun",
    "search_v_min",
    "minimal_v_sing",
    "SpeedSearch",
    "execution_class",
    "ExecutionClass",
    "monte_carlo_confirmation",
    "MonteCarloResult",
    # what no sound tracker can do: the refutation bound and the crossing floor
    "refutation_bound",
    "RefutationBound",
    "crossing_floor",
    "CrossingFloor",
    "RecordingBounds",
    # simulated recordings and the paper's sweep (design studies: planner.study.run_study)
    "simulate_crossing",
    "simulate_bounce",
    "SimulatedRun",
    "max_v_sing",
    "random_geometry",
    "sweep",
    "SweepRow",
]

logging.getLogger(__name__).addHandler(logging.NullHandler())
