#!/usr/bin/env python
"""Per-sample cost of the interval tracker for every registered robot (n = 2, 3, 6).

Usage::

    python benchmarks/bench_robots.py            # every robot, compiled backend
    python benchmarks/bench_robots.py --runs 5   # more repetitions of the latency run
    python benchmarks/bench_robots.py --json out.json

It prints numbers only; nothing asserts on timing.  For each robot of the
registry, one recording is simulated with the centre of the calibration box:

* a robot with a benchmark crossing: that crossing at ``--v-sing`` (1.458 m/s
  by default), starting 35 mm before the locus;
* a robot with a reference motion instead: that motion at ``--v-motion``
  (0.25 pose units per second).

Two measurements, compiled backend, BLAS on one thread:

1. ``latency``: the online :class:`verifier.tracker.Tracker` fed one reading at
   a time, ``perf_counter_ns`` around each ``update``; mean, p50, p99, max
   over samples 1..K-1 (us), over ``--runs`` runs (kernels loaded first);
2. ``batch``: ``track_batch`` of ``--batch`` copies of the recording with
   different reading errors, in us per scenario-step (wall time, numba's
   threads).

The initial box (``initial_box_from_mode``) is timed separately (``init``).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

import numpy as np  # noqa: E402

from crosscert.planner.simulate import simulate_crossing, simulate_motion  # noqa: E402
from crosscert.planner.sweep import cruise_for  # noqa: E402
from crosscert.robots import KinematicModel, available_robots, get_entry  # noqa: E402
from crosscert.verifier.model import IntervalModel  # noqa: E402
from crosscert.verifier.tracker import Tracker  # noqa: E402
from crosscert.verifier.tracker import TrackerSettings, initial_box_from_mode, track_batch  # noqa: E402


def recording(entry, v_sing: float, v_motion: float):
    """The simulated run of a robot: its benchmark crossing, else its reference motion."""
    kin = KinematicModel(entry.robot)
    if entry.benchmark is not None:
        b = entry.benchmark_crossing()
        return simulate_crossing(kin, b.point, b.direction, v_sing, t_rest=0.05, working_guess=b.q_point,
                                 cruise=cruise_for(v_sing, 60.0, 0.035)), "crossing"
    m = entry.reference_motion()
    return simulate_motion(kin, m.start, m.goal, v_motion, working_guess=m.q_start, t_rest=0.05), "motion"


def measure(name: str, runs: int, batch: int, v_sing: float, v_motion: float) -> dict:
    entry = get_entry(name)
    robot = entry.robot
    run, kind = recording(entry, v_sing, v_motion)
    im = IntervalModel(robot)
    s = TrackerSettings.for_robot(robot)
    q = np.array(run.q_meas)
    t0 = time.perf_counter()
    x0 = initial_box_from_mode(im, q[0], int(run.mode_true[0]), s)
    init_ms = 1e3 * (time.perf_counter() - t0)
    Tracker(im, s, x0).update(q[0].copy())  # load the kernels
    lat = []
    for _ in range(runs):
        tr = Tracker(im, s, x0)
        for k in range(len(q)):
            qk = q[k].copy()
            t1 = time.perf_counter_ns()
            tr.update(qk)
            if k:
                lat.append(time.perf_counter_ns() - t1)
    lat = np.array(lat) / 1e3
    rng = np.random.default_rng(0)
    qb = np.stack([run.q + robot.eps_q * (1 - 1e-9) * rng.uniform(-1, 1, run.q.shape) for _ in range(batch)])
    boxes = [initial_box_from_mode(im, qb[b, 0], int(run.mode_true[0]), s) for b in range(batch)]
    xb = (np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes]))
    track_batch(im, qb[:1, :10], s, (xb[0][:1], xb[1][:1]))  # warm
    t2 = time.perf_counter()
    res = track_batch(im, qb, s, xb)
    wall = time.perf_counter() - t2
    return {
        "robot": name, "n": robot.n, "m": robot.m, "hypotheses": int(np.prod(s.xi_splits)) if s.xi_splits else 1,
        "recording": kind, "samples": len(q), "init_ms": round(init_ms, 1),
        "latency_us_mean": round(float(lat.mean()), 1), "latency_us_p50": round(float(np.median(lat)), 1),
        "latency_us_p99": round(float(np.quantile(lat, 0.99)), 1), "latency_us_max": round(float(lat.max()), 1),
        "batch_us_per_scenario_step": round(1e6 * wall / (batch * len(q)), 1),
        "batch_verdicts": sorted({str(v) for v in res.verdict}),
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--batch", type=int, default=16)
    p.add_argument("--v-sing", type=float, default=1.458)
    p.add_argument("--v-motion", type=float, default=0.25)
    p.add_argument("--json")
    a = p.parse_args(argv)
    rows = [measure(name, a.runs, a.batch, a.v_sing, a.v_motion) for name in available_robots()]
    head = (f"{'robot':>14} {'n':>2} {'m':>3} {'hyp':>3} {'rec':>8} {'K':>5} {'init ms':>8} {'mean us':>8} "
            f"{'p50 us':>7} {'p99 us':>7} {'max us':>8} {'batch us':>9}")
    print(head)
    for r in rows:
        print(f"{r['robot']:>14} {r['n']:>2} {r['m']:>3} {r['hypotheses']:>3} {r['recording']:>8} {r['samples']:>5} "
              f"{r['init_ms']:>8} {r['latency_us_mean']:>8} {r['latency_us_p50']:>7} {r['latency_us_p99']:>7} "
              f"{r['latency_us_max']:>8} {r['batch_us_per_scenario_step']:>9}")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
