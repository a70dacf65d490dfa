"""Prototype (issue 20): how many surviving rows of the wrong hypothesis the one-motion LP refutes.

Runs track_window, keeps the final rows of each hypothesis (per-row tubes), then refute_row on each.
Usage: python benchmarks/proto_one_motion.py [--size 120] [--novel] [--cases bench,certify,floor]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import crosscert.verifier.window as W  # noqa: E402
import crosscert.verifier.window.offline as O  # noqa: E402
from crosscert.verifier.one_motion import refute_row  # noqa: E402

CAPTURED = []
_real_decide = O.decide


def _capture(hyps, passes, *a, **kw):
    out = _real_decide(hyps, passes, *a, **kw)
    CAPTURED.append((hyps, passes.q))
    return out


O.decide = _capture  # where track_window looks it up


def rows_report(label, hyps, q, xi_true, size, velocity):
    for h in hyps:
        if h.refuted:
            print(f"  {label} hyp m={h.m:+d}: refuted", flush=True)
            continue
        s, model = h.finals.s, h.finals.model
        t0 = time.perf_counter()
        ref, holds_truth = [], []
        for r in range(len(h.xlo)):
            ref.append(refute_row(model, s, q, (h.xlo[r], h.xhi[r]), h.tx[r], h.txd[r], size=size, velocity=velocity))
            holds_truth.append(xi_true is not None and bool(np.all(h.xlo[r] <= xi_true) & np.all(xi_true <= h.xhi[r])))
        dt = time.perf_counter() - t0
        bad = sum(a and b for a, b in zip(ref, holds_truth))
        print(f"  {label} hyp m={h.m:+d} (m0={h.m0:+d}): rows {len(ref)}, refuted {sum(ref)}, "
              f"refuted rows holding the true xi {bad}, {1e3 * dt / max(len(ref), 1):.0f} ms/row", flush=True)


def bench(v, size, velocity, which):
    from bench_window import _true_geometries, _crossing
    from problems import default_settings, interval_model
    from crosscert.verifier.tracker import initial_box_from_mode
    im, s = interval_model(), default_settings()
    geoms = _true_geometries(20)
    for g in which:
        r = _crossing(v, geoms[g])
        x0 = initial_box_from_mode(im, r.q_meas[0], 1, s)
        CAPTURED.clear()
        w = W.track_window(im, r.q_meas, s, x0=x0)
        print(f"v={v} geometry {g}: {w.verdict.value}", flush=True)
        if CAPTURED:
            hyps, q = CAPTURED[-1]
            rows_report(f"g{g}", hyps, q, r.xi_true, size, velocity)


def certify(v, size, velocity):
    from problems import interval_model
    from crosscert.planner.certify.plan import certify_speed
    from crosscert.planner.task import PlanningBounds, benchmark_task
    from crosscert.robots import DEXTAR, KinematicModel, get_entry
    CAPTURED.clear()
    run = certify_speed(KinematicModel(DEXTAR), interval_model(), benchmark_task(get_entry("dextar")),
                        PlanningBounds(), v)
    print(f"certify plan v={v}: forward {run.forward.verdict.value}, window "
          f"{run.window.verdict.value if run.window else None}", flush=True)
    if CAPTURED:
        hyps, q = CAPTURED[-1]
        rows_report(f"plan{v}", hyps, q, None, size, velocity)


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--size", type=int, default=120)
    p.add_argument("--novel", action="store_true", help="no velocity unknowns")
    p.add_argument("--cases", default="bench,certify,floor")
    p.add_argument("--geoms", default="")
    p.add_argument("--v", type=float, default=1.0)
    a = p.parse_args()
    cases = a.cases.split(",")
    if "bench" in cases:
        which = [int(g) for g in a.geoms.split(",")] if a.geoms else list(range(20))
        bench(a.v, a.size, not a.novel, which)
    if "certify" in cases:
        for v in (0.9557, 0.945):
            certify(v, a.size, not a.novel)
    if "floor" in cases:
        certify(0.8438, a.size, not a.novel)
