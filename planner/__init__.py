"""Planning side: simulated crossings and operating-range sweeps.

Explicit re-exports (no star imports).
"""

from .simulate import SimulatedRun, max_v_sing, random_geometry, simulate_bounce, simulate_crossing
from .sweep import SweepRow, cruise_for, sweep

__all__ = [
    "SimulatedRun",
    "max_v_sing",
    "random_geometry",
    "simulate_bounce",
    "simulate_crossing",
    "SweepRow",
    "cruise_for",
    "sweep",
]
