"""Cost and tightness of the proved execution class against the measured one, per plan.

For the benchmark task of each robot with one (DexTAR, 3-RPR), plans at a
few speeds are built once; then, for each plan, the measured class
(``planner.execution.cartesian_class``: corners and 32 random geometries,
x 1.25) and the proved one (``planner.execution_proof.prove_cartesian_class``)
are timed side by side (wall and CPU time of this process, best of
``--repeat``), and their ``e`` and ``d`` printed.  Prints numbers, never
asserts on timing.

    python benchmarks/bench_execution_proof.py [--repeat 3] [--robot dextar]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from crosscert.planner import plan_crossing  # noqa: E402
from crosscert.planner.execution import cartesian_class  # noqa: E402
from crosscert.planner.execution_proof import prove_cartesian_class  # noqa: E402
from crosscert.planner.task import PlanningBounds, benchmark_task  # noqa: E402
from crosscert.robots import KinematicModel, get_entry  # noqa: E402

SPEEDS = {"dextar": (0.99, 1.45, 1.95), "3rpr": (0.5, 1.0)}


def _best(fn, repeat):
    """(result, best wall s, best CPU s) of ``repeat`` calls."""
    walls, cpus, out = [], [], None
    for _ in range(repeat):
        c, t = time.process_time(), time.perf_counter()
        out = fn()
        walls.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    return out, min(walls), min(cpus)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--robot", choices=sorted(SPEEDS), action="append")
    a = ap.parse_args(argv)
    print(f"cpu: {os.cpu_count()} logical cores; load average {os.getloadavg()[0]:.1f}")
    print(f"{'robot':>7} {'v (m/s)':>8} {'K':>4} | {'measured: e':>12} {'d':>10} {'wall s':>7} {'cpu s':>6} | "
          f"{'proved: e':>10} {'d':>10} {'boxes':>5} {'wall s':>7} {'cpu s':>6}")
    for name in a.robot or sorted(SPEEDS):
        entry = get_entry(name)
        robot = entry.robot
        kin = KinematicModel(robot)
        task = benchmark_task(entry)
        for v in SPEEDS[name]:
            plan = plan_crossing(kin, task, v, PlanningBounds())
            prove_cartesian_class(robot, plan.x, plan.q, plan.xi_plan)  # warm: tapes built once per robot
            m, mw, mc = _best(lambda: cartesian_class(kin, plan.x, plan.q, plan.xi_plan, robot.eps_q), a.repeat)
            p, pw, pc = _best(lambda: prove_cartesian_class(robot, plan.x, plan.q, plan.xi_plan), a.repeat)
            print(f"{name:>7} {v:8.3f} {len(plan.x):4d} | {m.drift:12.4e} {m.drift_per_sample:10.3e} {mw:7.3f} "
                  f"{mc:6.3f} | {p.drift:10.4e} {p.step:10.3e} {p.boxes:5d} {pw:7.3f} {pc:6.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
