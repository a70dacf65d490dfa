"""The online monitor (``crosscert monitor``, ``verifier.window.OnlineMonitor``) against ``check``.

Prints the table of the online-certification targets (docs/tracker.md, "Online: the anchored window"):

1. simulated DexTAR crossings at 1.0 / 1.1 / 1.2 m/s (``--geometries`` true geometries each, the centre and
   seeded draws in the calibration box, 0.5 s at rest after): the verdict of the monitor (the window in its
   worker process, the readings fed at the robot's rate, 1 kHz) against ``check``'s (the same monitor inline, then
   the window over the whole recording), runs where they differ, and wrong verdicts (must be 0);
2. the decision delay at 1.1 m/s: the sample at which the change is known online minus the true singular
   instant, ms (median, max);
3. ``update`` latency while a window is open (mean, max, µs) and over the whole run;
4. the width of the pose box 0.2 s after the decision against a run at rest at the same pose that never
   crossed (ratio, worst case; the truth inside);
5. there-and-back at 1.1 m/s: the changes reported online (two expected) and the final verdict;
6. bounces turning back 15 mm before the locus at 1.0 m/s: never ``mode-changed``; ``mode-unchanged``
   online wherever ``check`` says so.

Run: ``python benchmarks/bench_online.py [--geometries N] [--speeds 1.0,1.1,1.2]`` (about 2 minutes per
geometry and speed on 2 cores, most of it the real-time feeding).  The CPU is named on the first line.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from bench_window import _cpu  # noqa: E402  (one reading of the CPU's name for the benchmarks)
from crosscert.planner.simulate import random_geometry, simulate_bounce, simulate_crossing  # noqa: E402
from crosscert.planner.sweep import cruise_for  # noqa: E402
from crosscert.robots import DEXTAR, KinematicModel  # noqa: E402
from crosscert.robots.dextar import benchmark_crossing  # noqa: E402
from crosscert.verifier.model import IntervalModel  # noqa: E402
from crosscert.verifier.settings import TrackerSettings, Verdict  # noqa: E402
from crosscert.verifier.step import Event  # noqa: E402
from crosscert.verifier.tracker import Tracker, initial_box_from_mode  # noqa: E402
from crosscert.verifier.window import OnlineMonitor, WindowState, track_window  # noqa: E402

REST_AFTER = 0.5  # s at rest after the motion


def _geometry(seed: int):
    return None if seed == 0 else random_geometry(DEXTAR, np.random.default_rng(seed), corners=seed % 2 == 0)


def _crossing(kin, v, seed):
    b = benchmark_crossing()
    return simulate_crossing(kin, b.point, b.direction, v, xi_true=_geometry(seed), t_rest=0.05,
                             t_rest_end=REST_AFTER, working_guess=b.q_point, seed=seed, cruise=cruise_for(v))


def _bounce(kin, v, seed, before):
    """A bounce turning back ``before`` m ahead of the nominal locus."""
    b = benchmark_crossing()
    d = np.asarray(b.direction, float) / np.linalg.norm(b.direction)
    return simulate_bounce(kin, np.asarray(b.point) - before * d, d, v, xi_true=_geometry(seed), t_rest=0.05,
                           t_rest_end=REST_AFTER, working_guess=b.q_point, seed=seed, cruise=cruise_for(v))


def online(model, s, q, mode0, paced=True, window=True):
    """The monitor with its worker (``window`` False: the tracker alone, today's ``monitor`` before the
    anchored window), readings fed every ``t_s``, then settled: (monitor, results, events, latencies in ns,
    window-open flags)."""
    mon = OnlineMonitor(model, s, initial_box_from_mode(model, q[0], mode0, s), window=window)
    res, events, lat, open_ = [], [], [], []
    t0 = time.perf_counter()
    for k, qk in enumerate(q):
        if paced:  # sleeping (which releases the GIL), as a controller waiting for its next sample would
            wait = t0 + k * s.t_s - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
        a = time.perf_counter_ns()
        r = mon.update(qk)
        lat.append(time.perf_counter_ns() - a)
        open_.append(r.window is WindowState.OPEN)
        res.append(r)
        events += r.events
    events += mon.settle()
    mon.close()
    return mon, res, events, np.array(lat), np.array(open_)


def check(model, s, q, mode0):
    """``check``'s verdict: the inline monitor, then the window over the whole recording when it is open."""
    x0 = initial_box_from_mode(model, q[0], mode0, s)
    with OnlineMonitor(model, s, x0, worker=False) as mon:
        for qk in q:
            mon.update(qk)
        v = mon.verdict()
    if v is Verdict.UNKNOWN:
        v = track_window(model, q, s, x0=x0).verdict
    return v


def _contains(box, x):
    return bool(np.all(box[0] <= x) and np.all(x <= box[1]))


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--geometries", type=int, default=20)
    p.add_argument("--speeds", default="1.0,1.1,1.2")
    p.add_argument("--json", help="also write the figures to this file (benchmarks/figures.py reads it)")
    a = p.parse_args()
    out = {"geometries": a.geometries, "speeds": {}}
    speeds = [float(v) for v in a.speeds.split(",")]
    kin, model = KinematicModel(DEXTAR), IntervalModel(DEXTAR)
    s = TrackerSettings.for_robot(DEXTAR)
    print(f"CPU: {_cpu()}; {a.geometries} geometries per speed; the monitor fed at 1 kHz", flush=True)
    warm = _crossing(kin, 1.1, 1)
    online(model, s, warm.q_meas, int(warm.mode_true[0]), paced=False)  # kernels loaded, caches warm
    delays, lat_open, lat_all, lat_before, ratios, outside = [], [], [], [], [], 0
    print("[1] v (m/s) | check certifies | online: tracker alone (before) | online: anchored window (after) "
          "| check certifies, online not | wrong verdicts")
    for v in speeds:
        n_check = n_online = n_before = differ = wrong = 0
        for g in range(a.geometries):
            run = _crossing(kin, v, g)
            m0 = int(run.mode_true[0])
            vc = check(model, s, run.q_meas, m0)
            before, _, _, lat_b, _ = online(model, s, run.q_meas, m0, window=False)
            n_before += before.verdict() is Verdict.MODE_CHANGED
            mon, res, events, lat, open_ = online(model, s, run.q_meas, m0)
            lat_before.append(lat_b[open_])
            vo = mon.verdict()
            n_check += vc is Verdict.MODE_CHANGED
            n_online += vo is Verdict.MODE_CHANGED
            differ += vc is Verdict.MODE_CHANGED and vo is not Verdict.MODE_CHANGED
            wrong += Verdict.MODE_UNCHANGED in (vc, vo)
            lat_all.append(lat)
            lat_open.append(lat[open_])
            changed = [e for e in events if e.event is Event.MODE_CHANGED]
            if v == 1.1 and changed:
                delays.append((changed[0].known_at - run.k_sing) * s.t_s * 1e3)
            outside += sum(not _contains(r.x, run.x_true[k]) for k, r in enumerate(res))
            if changed and changed[0].known_at + 200 < len(res):
                k = changed[0].known_at + 200
                still = Tracker(model, s, initial_box_from_mode(model, run.q_meas[k], int(run.mode_true[-1]), s))
                for _ in range(201):
                    r0 = still.update(run.q_meas[k])
                ratios.append(float(np.max((res[k].x[1] - res[k].x[0]) / (r0.x[1] - r0.x[0]))))
        out["speeds"][f"{v:.1f}"] = {"check": n_check, "before": n_before, "online": n_online, "differ": differ,
                                      "wrong": wrong}
        print(f"    {v:.1f}     | {n_check:2d}/{a.geometries} | {n_before:2d}/{a.geometries} | {n_online:2d}/{a.geometries} "
              f"| {differ} | {wrong}", flush=True)
    if delays:
        out["delay_ms"] = {"median": statistics.median(delays), "max": max(delays), "runs": len(delays)}
        print(f"[2] decision delay at 1.1 m/s: median {statistics.median(delays):.0f} ms, max {max(delays):.0f} ms "
              f"({len(delays)} runs decided online)")
    lo, la, lb = (np.concatenate(v) / 1e3 for v in (lat_open, lat_all, lat_before))
    out["update_us"] = {"open_mean": float(lo.mean()), "open_max": float(lo.max()), "samples": int(lo.size),
                        "alone_mean": float(lb.mean()), "alone_max": float(lb.max()), "all_mean": float(la.mean()),
                        "all_max": float(la.max())}
    print(f"[3] update latency while a window is open: mean {lo.mean():.1f} us, max {lo.max():.0f} us "
          f"({lo.size} samples); the tracker alone (before) on the same samples: mean {lb.mean():.1f} us, max "
          f"{lb.max():.0f} us (ratio of means {lo.mean() / lb.mean():.2f}); whole runs: mean {la.mean():.1f} us, "
          f"max {la.max():.0f} us")
    out["outside"] = outside
    if ratios:
        out["box_ratio"] = {"median": statistics.median(ratios), "worst": max(ratios)}
        print(f"[4] pose box 0.2 s after the decision / never crossed: median {statistics.median(ratios):.2f}, "
              f"worst {max(ratios):.2f}; samples with the truth outside a box: {outside}")
    back = _crossing(kin, 1.1, 3)
    q = np.concatenate([back.q_meas, back.q_meas[-2::-1]])
    mon, res, events, _, _ = online(model, s, q, int(back.mode_true[0]))
    changes = [(e.k, e.mode) for e in events if e.event is Event.MODE_CHANGED]
    out["there_and_back"] = {"changes": [int(k) for k, _ in changes], "verdict": mon.verdict().value}
    print(f"[5] there-and-back at 1.1 m/s: changes reported online {changes}; final verdict {mon.verdict().value} "
          "(expected mode-unchanged)")
    n_changed = n_check_unchanged = n_online_unchanged = 0
    for g in range(a.geometries):
        run = _bounce(kin, 1.0, g, 0.015)
        m0 = int(run.mode_true[0])
        vc = check(model, s, run.q_meas, m0)
        vo = online(model, s, run.q_meas, m0)[0].verdict()
        n_changed += Verdict.MODE_CHANGED in (vc, vo)
        n_check_unchanged += vc is Verdict.MODE_UNCHANGED
        n_online_unchanged += vo is Verdict.MODE_UNCHANGED and vc is Verdict.MODE_UNCHANGED
    out["bounces"] = {"changed": n_changed, "check_unchanged": n_check_unchanged,
                      "online_unchanged": n_online_unchanged}
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    print(f"[6] bounces 15 mm before the locus at 1.0 m/s: mode-changed {n_changed} (must be 0); check "
          f"mode-unchanged {n_check_unchanged}/{a.geometries}, online too on {n_online_unchanged} of them")


if __name__ == "__main__":
    main()
