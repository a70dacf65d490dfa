"""``update`` latency of the online monitor, readings fed at 1 kHz by sleeping, side by side in one run.

On simulated DexTAR crossings at 1.1 m/s (the benchmark crossing; true geometries: the box centre and seeded
draws, every other at a corner; 0.5 s at rest after), each run fed four ways, interleaved run by run:

- ``tracker``: :meth:`Tracker.update` alone;
- ``alone``: :meth:`OnlineMonitor.update` without a window (``window=False``);
- ``process``: the monitor with its window in a worker process (the default);
- ``thread``: the monitor with its window on a thread (``worker="thread"``);
- ``tracker-stamped``, ``process-stamped``: ``tracker`` and ``process`` with every reading's stamp
  (``update(q, t)`` on a :class:`~verifier.clock.SampleClock`, as ``crosscert monitor`` feeds them): the
  clock's cost on the update path (steps of one period, so the same boxes).

Prints mean, median, 99th percentile and max (µs) over every sample and over the samples at which the
``process`` run had a window open (the same samples for the four), and the sample at which each windowed
run reported the change.  The CPU and the load average are on the first and last lines: on shared cores
the figures move from run to run, their ratios less.

Run: ``python benchmarks/bench_online_latency.py [--seeds 1,2,3] [--rounds 4]`` (about 20 s per round and
seed).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from bench_window import _cpu  # noqa: E402
from crosscert.planner.simulate import random_geometry, simulate_crossing  # noqa: E402
from crosscert.planner.sweep import cruise_for  # noqa: E402
from crosscert.robots import DEXTAR, KinematicModel  # noqa: E402
from crosscert.robots.dextar import benchmark_crossing  # noqa: E402
from crosscert.verifier.clock import SampleClock  # noqa: E402
from crosscert.verifier.model import IntervalModel  # noqa: E402
from crosscert.verifier.settings import TrackerSettings  # noqa: E402
from crosscert.verifier.step import Event  # noqa: E402
from crosscert.verifier.tracker import Tracker, initial_box_from_mode  # noqa: E402
from crosscert.verifier.window import OnlineMonitor, WindowState  # noqa: E402

KINDS = ("tracker", "alone", "process", "thread", "tracker-stamped", "process-stamped")


def _crossing(kin, seed):
    b = benchmark_crossing()
    xi = None if seed == 0 else random_geometry(DEXTAR, np.random.default_rng(seed), corners=seed % 2 == 0)
    return simulate_crossing(kin, b.point, b.direction, 1.1, xi_true=xi, t_rest=0.05, t_rest_end=0.5,
                             working_guess=b.q_point, seed=seed, cruise=cruise_for(1.1))


def _paced(update, q, t_s, stamped=False):
    """``update`` on every reading at its time (sleeping until then; with ``stamped``, given its stamp
    ``k t_s``): latencies (µs) and results."""
    lat, out = np.empty(len(q)), []
    t0 = time.perf_counter()
    for k, qk in enumerate(q):
        wait = t0 + k * t_s - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        a = time.perf_counter_ns()
        out.append(update(qk, k * t_s) if stamped else update(qk))
        lat[k] = (time.perf_counter_ns() - a) / 1e3
    return lat, out


def _feed(kind, model, s, q, x0):
    """One run fed ``kind``'s way: latencies, window-open flags (None without a window), change sample."""
    stamped = kind.endswith("-stamped")
    clock = SampleClock(s.t_s) if stamped else None
    if kind.startswith("tracker"):
        return _paced(Tracker(model, s, x0, clock=clock).update, q, s.t_s, stamped)[0], None, None
    worker = {"alone": True, "process": "process", "thread": "thread"}[kind.removesuffix("-stamped")]
    mon = OnlineMonitor(model, s, x0, worker=worker, window=kind != "alone", clock=clock)
    lat, res = _paced(mon.update, q, s.t_s, stamped)
    mon.close()
    changed = [e.k for r in res for e in r.events if e.event is Event.MODE_CHANGED]
    return lat, np.array([r.window is WindowState.OPEN for r in res]), (changed[0] if changed else None)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--seeds", default="1,2,3")
    p.add_argument("--rounds", type=int, default=4)
    a = p.parse_args()
    kin, model = KinematicModel(DEXTAR), IntervalModel(DEXTAR)
    s = TrackerSettings.for_robot(DEXTAR)
    runs = [_crossing(kin, int(g)) for g in a.seeds.split(",")]
    x0s = [initial_box_from_mode(model, r.q_meas[0], int(r.mode_true[0]), s) for r in runs]
    print(f"CPU: {_cpu()}; load average {os.getloadavg()[0]:.2f}; 1.1 m/s, fed at 1 kHz", flush=True)
    _feed("tracker", model, s, runs[0].q_meas[:50], x0s[0])  # kernels loaded
    lat = {k: [] for k in KINDS}
    opened, changes = [], {"process": [], "thread": [], "process-stamped": []}
    for rnd in range(a.rounds):
        for r, x0 in zip(runs, x0s):
            got = {k: _feed(k, model, s, r.q_meas, x0) for k in (KINDS if rnd % 2 == 0 else KINDS[::-1])}
            opened.append(got["process"][1])
            for k in KINDS:
                lat[k].append(got[k][0])
            for k in changes:
                changes[k].append(got[k][2])
    mask = np.concatenate(opened)
    for k in KINDS:
        v = np.concatenate(lat[k])
        for name, w in (("all", v), ("open", v[mask])):
            print(f"{k:8s} {name:4s}: n {w.size:5d}  mean {w.mean():6.1f}  median {np.median(w):6.1f}  "
                  f"p99 {np.percentile(w, 99):7.1f}  max {w.max():7.0f} us")
    for k, v in changes.items():
        print(f"sample of the change reported, window on a {k}: {v}")
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
