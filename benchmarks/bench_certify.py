"""Wall time of `certify_crossing` on the DexTAR benchmark task, phase by phase.

Prints numbers, asserts nothing.  Usage::

    python benchmarks/bench_certify.py [--repeat 2] [--method smoothstep] [--foreground] [--json out.json]

``--foreground`` runs the counterexample searches in the calling process
(``refute_in_background=False``) instead of the background worker.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--method", default="smoothstep", choices=("smoothstep", "time-optimal", "dynamic"))
    p.add_argument("--foreground", action="store_true")
    p.add_argument("--json")
    a = p.parse_args(argv)

    from planner import CrossingTask, PlanningBounds, certify_crossing
    from robots import DEXTAR, DEXTAR_DYNAMICS, KinematicModel, benchmark_crossing
    from verifier.model import IntervalModel

    b = benchmark_crossing()
    task = CrossingTask(b.point - 0.06 * b.direction, b.point + 0.06 * b.direction, b.q_point)
    bounds = PlanningBounds(method=a.method, dynamics=DEXTAR_DYNAMICS if a.method == "dynamic" else None)
    kin, imodel = KinematicModel(DEXTAR), IntervalModel(DEXTAR)
    print(f"machine: {os.cpu_count()} CPUs; method {a.method}; "
          f"refutation {'in the calling process' if a.foreground else 'in the background worker'}")
    runs = []
    for r in range(a.repeat):
        cert = certify_crossing(DEXTAR, task, bounds, kin=kin, imodel=imodel,
                                refute_in_background=not a.foreground)
        row = {"total_s": cert.elapsed_s, **{f"{k}_s": v for k, v in cert.timings_s.items()},
               "v_min": cert.v_min, "refutation_bound": cert.refutation_bound,
               "tracked_speeds": len(cert.trials), "refuted_speeds_searched": len(cert.refutation),
               "mc_detected": None if cert.monte_carlo is None else cert.monte_carlo["detected_in_class"]}
        runs.append(row)
        print(f"run {r + 1}: " + ", ".join(f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}"
                                          for k, v in row.items()))
    if a.repeat > 1:
        print(f"median total {statistics.median(r['total_s'] for r in runs):.2f} s over {a.repeat} runs")
    if a.json:
        Path(a.json).write_text(json.dumps(runs, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
