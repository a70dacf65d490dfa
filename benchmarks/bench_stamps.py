"""``crosscert check`` on uneven recordings: the same simulated crossings every period, with dropped samples,
and with jittered stamps (``--stamp-error``), side by side in one run.

Simulated DexTAR crossings (the benchmark crossing; true geometries: the box centre and seeded draws) at the
speeds given; each written three ways:

- ``even``: every period (the constant-period path, bit for bit as before the clock);
- ``dropped``: two samples left out (steps of two periods at those samples only);
- ``jitter``: the stamps moved by up to ``--delta`` (uniform, seeded), read with ``--stamp-error DELTA``: every
  step its own interval.

Prints the verdict, the online verdict and the wall time of ``check`` for each, interleaved run by run (the
machine's load hits them alike), and the CPU on the first line.  Asserts nothing.

Run: ``python benchmarks/bench_stamps.py [--speeds 1.0,1.2,1.458] [--seeds 0,1] [--delta 2e-5]``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench_window import _cpu
from crosscert.planner.cli import main as cli
from crosscert.planner.simulate import random_geometry, simulate_crossing
from crosscert.planner.sweep import cruise_for
from crosscert.robots import DEXTAR, KinematicModel
from crosscert.robots.dextar import benchmark_crossing
from crosscert.verifier.trajfile import write_trajectory


def _check(path: Path, mode: int, *extra) -> tuple:
    """``check`` in-process: (exit code, verdict, online verdict, wall s)."""
    out = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = cli(["check", str(path), "--initial-mode", str(mode), "--json", "--no-progress", *extra])
    wall = time.perf_counter() - t0
    d = json.loads(out.getvalue()) if out.getvalue() else {}
    return code, d.get("verdict"), d.get("online_verdict"), wall


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--speeds", default="1.0,1.2,1.458")
    p.add_argument("--seeds", default="0,1")
    p.add_argument("--delta", type=float, default=2e-5, help="stamp error bound, s")
    a = p.parse_args()
    kin, b = KinematicModel(DEXTAR), benchmark_crossing()
    print(f"CPU: {_cpu()}; load average {os.getloadavg()[0]:.2f}; stamp error {a.delta:g} s", flush=True)
    totals = {"even": 0.0, "dropped": 0.0, "jitter": 0.0}
    with tempfile.TemporaryDirectory() as tmp:
        for v in (float(s) for s in a.speeds.split(",")):
            for seed in (int(s) for s in a.seeds.split(",")):
                xi = None if seed == 0 else random_geometry(DEXTAR, np.random.default_rng(seed))
                run = simulate_crossing(kin, b.point, b.direction, v, xi_true=xi, t_rest=0.05, working_guess=b.q_point,
                                        seed=seed, cruise=cruise_for(v))
                K, mode = len(run.t), int(run.mode_true[0])
                keep = np.setdiff1d(np.arange(K), [run.k_sing - 30, run.k_sing + 20])
                jitter = run.t + np.random.default_rng(100 + seed).uniform(-a.delta, a.delta, K)
                files = {}
                for name, t, q in (("even", run.t, run.q_meas), ("dropped", run.t[keep], run.q_meas[keep]),
                                   ("jitter", jitter, run.q_meas)):
                    files[name] = Path(tmp) / f"{name}.csv"
                    write_trajectory(files[name], t, q)
                if v == float(a.speeds.split(",")[0]) and seed == int(a.seeds.split(",")[0]):
                    _check(files["even"], mode)  # kernels loaded before the first timing
                    _check(files["jitter"], mode, "--stamp-error", repr(a.delta))
                for name in totals:
                    extra = ("--stamp-error", repr(a.delta)) if name == "jitter" else ()
                    code, verdict, online, wall = _check(files[name], mode, *extra)
                    totals[name] += wall
                    print(f"{v:5.3f} m/s seed {seed}  {name:7s}  exit {code}  verdict {verdict!s:14s} online "
                          f"{online!s:14s} {wall:7.2f} s", flush=True)
    print("total wall: " + ", ".join(f"{k} {t:.1f} s ({t / totals['even']:.2f}x even)" for k, t in totals.items()))
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    sys.exit(main())
