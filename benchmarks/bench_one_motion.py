"""The one-motion refutation (verifier.one_motion) side by side: window reasoning with and without it.

For each speed of ``--speeds`` (default 1.0,0.95), the simulated benchmark crossings of bench_window.py's
table 1 (20 true geometries: the centre and 19 seeded, every other at a corner of [ξ]) run through
``track_window`` twice in the same process, with ``one_motion=0`` (the window before) and with its default,
alternating per run so the load hits both alike.  Prints, per speed and variant: runs certified
``mode-changed`` of 20, wrong verdicts (``mode-unchanged``/``inconsistent``), runs whose returned tubes miss
the true pose or velocity (after sample 0), the mean window time per sample (ms) over all runs and over the
runs undecided before; and the CPU, the load average before and after.

Run: ``python benchmarks/bench_one_motion.py [--speeds 1.0,0.95] [--geometries 20]`` (about 5 minutes per
speed on 2 shared cores).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_window import _cpu, _crossing, _true_geometries  # noqa: E402
from problems import default_settings, interval_model  # noqa: E402
from crosscert.verifier.tracker import initial_box_from_mode  # noqa: E402
from crosscert.verifier.window import track_window  # noqa: E402


def _contains(w, r) -> bool:
    with np.errstate(invalid="ignore"):
        px = np.all((w.x_lo <= r.x_true) & (r.x_true <= w.x_hi))
        pv = np.all((w.xd_lo[1:] <= r.xd_true[1:]) & (r.xd_true[1:] <= w.xd_hi[1:]))
    return bool(px and pv)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--speeds", default="1.0,0.95")
    p.add_argument("--geometries", type=int, default=20)
    a = p.parse_args(argv)
    im, s = interval_model(), default_settings()
    geoms = _true_geometries(a.geometries)
    print(f"CPU: {_cpu()}, {os.cpu_count()} cores; load average {os.getloadavg()}", flush=True)
    r0 = _crossing(1.2, None)  # warm-up (kernels, tapes)
    track_window(im, r0.q_meas, s, initial_mode=1)
    for v in (float(x) for x in a.speeds.split(",")):
        rows = {0: [], 1: []}
        for i, xi in enumerate(geoms):
            r = _crossing(v, xi)
            x0 = initial_box_from_mode(im, r.q_meas[0], 1, s)
            order = (0, 1) if i % 2 == 0 else (1, 0)
            for variant in order:
                t0 = time.perf_counter()
                w = track_window(im, r.q_meas, s, x0=x0, **({"one_motion": 0} if variant == 0 else {}))
                dt = time.perf_counter() - t0
                rows[variant].append((w.verdict.value, _contains(w, r), dt / len(r.q_meas)))
            print(f"  v {v:.2f} geometry {i:2d}: before {rows[0][-1][0]:>14s} {1e3 * rows[0][-1][2]:6.2f} ms/sample, "
                  f"after {rows[1][-1][0]:>14s} {1e3 * rows[1][-1][2]:6.2f} ms/sample", flush=True)
        undecided = [i for i, row in enumerate(rows[0]) if row[0] == "unknown"]
        for variant, label in ((0, "before (one_motion=0)"), (1, "after (default)")):
            res = rows[variant]
            cert = sum(x[0] == "mode-changed" for x in res)
            wrong = sum(x[0] in ("mode-unchanged", "inconsistent") for x in res)
            miss = sum(not x[1] for x in res)
            ms = 1e3 * np.mean([x[2] for x in res])
            ms_u = 1e3 * np.mean([res[i][2] for i in undecided]) if undecided else float("nan")
            print(f"v {v:.2f} {label:22s}: certified {cert:2d} / {len(res)}, wrong {wrong}, truth outside tubes {miss}, "
                  f"{ms:6.2f} ms/sample (runs undecided before: {ms_u:6.2f})", flush=True)
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
