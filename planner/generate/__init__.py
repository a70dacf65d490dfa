"""Trajectory generation through a Type 2 singularity with the dynamic crossing criterion (CasADi + IPOPT).

:func:`generate_crossing` computes a rest-to-rest motion of the end-effector
from ``task.start`` (one assembly mode) to ``task.goal`` (the other) that
passes a given point of the Type 2 locus at a prescribed speed ``v_sing``,
satisfies there the crossing criterion of Briot and Arakelian (Section III-B
of the paper, ref. [11] there; :mod:`robots.dynamics`, eq. (2)), and respects
joint speed, joint acceleration and actuator torque limits, minimising either
the motion time or the integral of the squared jerk (:class:`Objective`).

IPOPT must report success, and the sampled solution must then pass an
independent check (joints by IK continuation, rates, torques and criterion
recomputed with numpy); an unconverged or unverified solution is never
returned.  Failures are data: :class:`NotConverged` carries IPOPT's
``status``, :class:`LimitExceeded` the ``limit`` and its ``ratio``.

Modules: :mod:`.types` (limits, objective, result, errors), :mod:`.nlp` (the
transcription and its solve), :mod:`.check` (the independent check),
:mod:`.crossing` (the entry point).  SI units throughout (m, rad, s, N, N m).
``planner`` never names a robot: the robot and its dynamic data come from
:mod:`robots`.
"""

from .check import CRITERION_TOL, LIMIT_RTOL
from .crossing import GenerationOptions, generate_crossing
from .types import (
    CheckFailed,
    GeneratedTrajectory,
    GenerationError,
    GenerationLimits,
    LimitExceeded,
    NotConverged,
    Objective,
)

__all__ = [
    "CRITERION_TOL",
    "LIMIT_RTOL",
    "CheckFailed",
    "GeneratedTrajectory",
    "GenerationError",
    "GenerationLimits",
    "GenerationOptions",
    "LimitExceeded",
    "NotConverged",
    "Objective",
    "generate_crossing",
]
