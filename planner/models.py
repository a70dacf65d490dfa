"""The robot's models a process builds once for the functions any executor may run in it.

The certification's workers (counterexample and bounce searches, Monte Carlo
executions) receive a robot, not its models: models hold CasADi functions and
solvers built on first use, which neither pickle cheaply nor should be built
again for every call.  A worker keeps them here, by robot value (a frozen
dataclass: two variants of one robot differ in their boxes) and thread, in
the planner's one bounded cache, so that a study sweeping many variants
through one worker keeps only the last few.  By thread because CasADi
functions are not to be called from two threads at once: the threads of a
thread-pool executor each get models of their own.
"""

from __future__ import annotations

import threading

from crosscert.robots import KinematicModel
from crosscert.verifier.model import IntervalModel

from .lru import LruCache

__all__ = ["MODELS_KEPT", "kinematic_model", "interval_model"]

#: Models of each kind a process keeps, one per robot and thread (a study's variants beyond these are rebuilt
#: when they come back; building is cheap, the solvers and functions built on first use are what is kept).
MODELS_KEPT = 8

_KINEMATIC = LruCache(MODELS_KEPT)
_INTERVAL = LruCache(MODELS_KEPT)


def kinematic_model(robot) -> KinematicModel:
    """The :class:`~crosscert.robots.KinematicModel` of ``robot`` this thread keeps (built on first use)."""
    return _KINEMATIC.get_or_build((robot, threading.get_ident()), lambda: KinematicModel(robot))


def interval_model(robot) -> IntervalModel:
    """The :class:`~crosscert.verifier.model.IntervalModel` of ``robot`` this thread keeps (built on first use)."""
    return _INTERVAL.get_or_build((robot, threading.get_ident()), lambda: IntervalModel(robot))
