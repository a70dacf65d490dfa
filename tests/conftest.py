"""Fixtures shared by the test files.

Everything here is immutable and expensive enough to build once per session
(CasADi functions, interval tapes, IK continuations); the objects come from
:mod:`problems`, so a helper called outside a test gets the very same ones.
A test file may still define a fixture of the same name for itself: pytest
takes the nearer one.
"""

from __future__ import annotations

import pytest

import problems
from crosscert.robots import get_entry


@pytest.fixture(scope="session")
def kin():
    """The DexTAR's float kinematic model (KinematicModel, immutable)."""
    return problems.kinematics()


@pytest.fixture(scope="session")
def imodel():
    """The DexTAR's interval model (IntervalModel: the tapes of the tracker)."""
    return problems.interval_model()


@pytest.fixture(scope="session")
def settings():
    """The tracker's default bounds for the DexTAR (a frozen TrackerSettings)."""
    return problems.default_settings()


@pytest.fixture(scope="session")
def bench():
    """The DexTAR's nominal benchmark crossing (point, direction, joints there)."""
    return get_entry("dextar").benchmark_crossing()


@pytest.fixture(scope="session")
def task():
    """The DexTAR benchmark task: 60 mm either side of the benchmark crossing (a frozen CrossingTask)."""
    return problems.PLANNING["dextar_benchmark"].task()


@pytest.fixture(scope="session")
def simulated_recording(tmp_path_factory, kin, bench):
    """A recording file of a simulated benchmark crossing at 1.3 m/s (readings only), as ``simulate`` writes it."""
    from crosscert.planner.simulate import simulate_crossing
    from crosscert.verifier.trajfile import write_trajectory

    run = simulate_crossing(kin, bench.point, bench.direction, 1.3, working_guess=bench.q_point, t_rest=0.1)
    path = tmp_path_factory.mktemp("recording") / "crossing.csv"
    write_trajectory(path, run.t, run.q_meas)
    return path
