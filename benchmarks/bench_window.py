"""Window reasoning (verifier.window): detection power and cost per sample, against the forward tracker.

Prints three tables (docs/tracker.md, "Window reasoning"):

1. simulated benchmark crossings at 0.9-1.3 m/s, 20 true geometries each (the
   centre and 19 seeded ones, every other at a corner of the box): runs
   certified by the forward tracker and by the window passes, wrong verdicts,
   time per run and per sample;
2. bounces at 1.2 m/s turning back 0-20 mm before the locus (3 geometries);
3. the fixed-lag online variant (``crosscert monitor --lag``): latency per
   sample and how many samples it certifies late.

Run: ``python benchmarks/bench_window.py`` (about 10 minutes on 2 cores).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from problems import default_settings, interval_model, kinematics, simulate  # noqa: E402
from crosscert.planner.simulate import random_geometry, simulate_bounce, simulate_crossing  # noqa: E402
from crosscert.planner.sweep import cruise_for  # noqa: E402
from crosscert.robots import DEXTAR  # noqa: E402
from crosscert.robots.dextar import benchmark_crossing  # noqa: E402
from crosscert.verifier.tracker import initial_box_from_mode, track  # noqa: E402
from crosscert.verifier.window import FixedLagWindow, track_window  # noqa: E402


def _run(fn, v, xi, **kw):
    kin, im, s, bench = kinematics(), interval_model(), default_settings(), benchmark_crossing()
    r = fn(kin, bench.point, bench.direction, v, xi_true=xi, t_rest=0.05, working_guess=bench.q_point, seed=1,
           cruise=kw.pop("cruise", cruise_for(v)), **kw)
    x0 = initial_box_from_mode(im, r.q_meas[0], 1, s)
    t0 = time.perf_counter()
    f = track(im, r.q_meas, s, x0=x0)
    tf = time.perf_counter() - t0
    t0 = time.perf_counter()
    w = track_window(im, r.q_meas, s, x0=x0)
    return f.verdict.value, w.verdict.value, len(r.q_meas), tf, time.perf_counter() - t0


def main() -> None:
    geoms = [None] + [random_geometry(DEXTAR, np.random.default_rng(i), corners=(i % 2 == 0)) for i in range(1, 20)]
    print("[1] crossings: v_sing, certified forward / window of 20, wrong, window s per run, us per sample fwd / win")
    for v in (0.9, 0.95, 1.0, 1.05, 1.1, 1.2, 1.3):
        res = [_run(simulate_crossing, v, xi) for xi in geoms]
        nw = sum(r[1] == "mode-changed" for r in res)
        nf = sum(r[0] == "mode-changed" for r in res)
        bad = sum(r[1] in ("mode-unchanged", "inconsistent") for r in res)
        print(f"{v:5.2f}  {nf:2d} / {nw:2d}  wrong {bad}  {np.mean([r[4] for r in res]):6.2f} s  "
              f"{1e6 * np.mean([r[3] / r[2] for r in res]):7.0f} / {1e6 * np.mean([r[4] / r[2] for r in res]):7.0f}",
              flush=True)
    print("[2] bounces at 1.2 m/s: turn-back distance (m), (forward, window, window s) per geometry")
    for short in (0.0, 0.005, 0.010, 0.015, 0.020):
        res = [_run(simulate_bounce, 1.2, xi, short=short, cruise=max(5e-3, cruise_for(1.2) - short / 2))
               for xi in geoms[:3]]
        print(short, [(r[0], r[1], f"{r[4]:.1f}") for r in res], flush=True)
    print("[3] fixed lag: run, lag, latency mean / max, lagged samples certified, of them not by the tracker")
    im, s = interval_model(), default_settings()
    for v, bounce in ((1.1, False), (1.2, True)):
        run = simulate(v, bounce, 0)
        x0 = initial_box_from_mode(im, run.q_meas[0], 1, s)
        for lag in (20, 50):
            fl = FixedLagWindow(im, s, x0, lag=lag)
            t, res, fwd = [], [], []
            for q in run.q_meas:
                t0 = time.perf_counter()
                res.append(fl.update(q))
                t.append(time.perf_counter() - t0)
                fwd.append(int(fl.tracker.state.mode[0]))
            lagged = [r for r in res if r.lagged >= 0]
            late = sum(r.lagged_mode != 0 and fwd[r.lagged] == 0 for r in lagged)
            print(f"{'bounce' if bounce else 'crossing'} {v} m/s  lag {lag}  {1e3 * np.mean(t):.1f} / "
                  f"{1e3 * np.max(t):.1f} ms  {np.mean([r.lagged_mode != 0 for r in lagged]):.3f}  {late}", flush=True)


if __name__ == "__main__":
    main()
