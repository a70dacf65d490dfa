"""The figures of a user's own plan: ``certify --plan``, ``--retime``, and the envelope check at run time.

Prints, on the DexTAR benchmark task (robot a_max on both axes, the default):

1. ``certify --plan`` on the plan ``crosscert plan --v-sing 0.95`` writes, beside ``certify``'s own verdict
   for 0.95 m/s (the same plan certified by the task's speed search);
2. a curved path (the 30-degree arc of tests/problems.py, ``ARC``) given at 1.2 m/s: ``--retime``'s minimal
   speed and refutation bound on that path, and the re-timed plan it writes certified again;
3. the wall time of ``certify --plan`` (warm, one process) without and with the re-timing;
4. the envelope check per sample (``EnvelopeMonitor.update``) on a recording of the certified plan;
5. the Monte Carlo executions of the certificate (the path followed with random geometries): how many the
   envelope check can confirm at run time, how many the tracker alone decides.

Run: ``python benchmarks/bench_given_plan.py`` (about 2-4 min on 2 cores; the kernels compiled once first).
"""

from __future__ import annotations

import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import problems  # noqa: E402  (the named reference problems: the arc)
from bench_window import _cpu as cpu_name  # noqa: E402  (one reading of the CPU's name for the benchmarks)
from crosscert.planner import PlanningBounds, benchmark_task  # noqa: E402
from crosscert.planner.certify.envelope import CertifiedEnvelope, EnvelopeMonitor, EnvelopeState  # noqa: E402
from crosscert.planner.certify.plan import certify_speed  # noqa: E402
from crosscert.planner.certify.trajectory import certify_path, certify_trajectory  # noqa: E402
from crosscert.planner.cli import main  # noqa: E402
from crosscert.planner.path import plan_along_path  # noqa: E402
from crosscert.planner.plan import plan_crossing  # noqa: E402
from crosscert.planner.simulate import quantise, random_geometry  # noqa: E402
from crosscert.robots import DEXTAR, KinematicModel, get_entry  # noqa: E402
from crosscert.verifier.model import IntervalModel  # noqa: E402
from crosscert.verifier.trajfile import write_trajectory  # noqa: E402


def main_bench() -> dict:
    """Print the figures; return them (benchmarks/figures.py)."""
    out = {}
    print(f"CPU: {cpu_name()}; Python {platform.python_version()}")
    kin, imodel = KinematicModel(DEXTAR), IntervalModel(DEXTAR)
    task = benchmark_task(get_entry("dextar"))
    b = PlanningBounds().resolve(DEXTAR)
    tmp = Path(tempfile.mkdtemp(prefix="bench_given_plan_"))
    certify_speed(kin, imodel, task, b, 1.3)  # kernels loaded (compiled once after install)

    p095 = tmp / "p095.csv"
    assert main(["plan", "--v-sing", "0.95", "-o", str(p095)]) == 0
    own = certify_speed(kin, imodel, task, b, 0.95).verdict
    t0 = time.perf_counter()
    given = certify_trajectory(DEXTAR, p095, monte_carlo_runs=0, refute_plan=False, kin=kin, imodel=imodel)
    t_plan = time.perf_counter() - t0
    out["plan_095"] = {"given": given.verdict.value, "own": own.value, "wall_s": t_plan}
    print(f"1. certify --plan (plan --v-sing 0.95): {given.verdict.value}; certify's verdict at 0.95 m/s: "
          f"{own.value}; {'same' if given.verdict is own else 'DIFFERENT'}")

    arc = problems.arc_task()
    v_given = problems.ARC["not_certified"]
    arc_plan = plan_along_path(kin, arc, v_given, b)
    arc_file = tmp / "arc.csv"
    write_trajectory(arc_file, arc_plan.t, arc_plan.q, x=arc_plan.x)
    t0 = time.perf_counter()
    arc_given = certify_trajectory(DEXTAR, arc_file, monte_carlo_runs=0, kin=kin, imodel=imodel)
    retimed = certify_path(DEXTAR, arc_given.trajectory, arc_given.bounds, source="arc", monte_carlo_runs=0,
                           kin=kin, imodel=imodel)
    t_retime = time.perf_counter() - t0
    again_file = tmp / "retimed.csv"
    r = retimed.trajectory
    write_trajectory(again_file, r.t, r.q, x=r.x)
    again = certify_trajectory(DEXTAR, again_file, monte_carlo_runs=0, kin=kin, imodel=imodel)
    bound = "none" if retimed.refutation_bound is None else f"{retimed.refutation_bound:.4f} m/s"
    out["arc"] = {"v_given": v_given, "given": arc_given.verdict.value, "v_min": retimed.v_min,
                  "bound": retimed.refutation_bound, "again": again.verdict.value, "wall_s": t_retime}
    print(f"2. arc given at {v_given} m/s: {arc_given.verdict.value}; re-timed: certifies from "
          f"{retimed.v_min:.4f} m/s, refutation bound {bound} ({retimed.refutation_search}); the re-timed plan "
          f"certified again: {again.verdict.value}")
    print(f"3. certify --plan, warm: {t_plan:.1f} s without re-timing (0.95 m/s plan, no Monte Carlo); "
          f"{t_retime:.1f} s for the arc with --retime (its plan, refutation and the path's speed search)")

    cert_dir = tmp / "cert"
    p11 = tmp / "p11.csv"
    plan = plan_crossing(kin, task, 1.1, b)
    write_trajectory(p11, plan.t, plan.q, x=plan.x)
    assert main(["certify", "--plan", str(p11), "--monte-carlo", "0", "--no-progress", "--out", str(cert_dir)]) == 0
    env = CertifiedEnvelope.load(cert_dir / "certificate.json", DEXTAR, DEXTAR.eps_q, p11)
    times = []
    for _ in range(20):
        m = EnvelopeMonitor(env)
        for q in plan.q:
            t0 = time.perf_counter_ns()
            m.update(q)
            times.append(time.perf_counter_ns() - t0)
    ns = np.array(times[len(plan.q):])  # the first pass warms numpy up
    out["envelope_us"] = {"mean": float(ns.mean() / 1e3), "max": float(ns.max() / 1e3), "samples": int(ns.size)}
    print(f"4. envelope check per sample, inside the envelope: mean {ns.mean() / 1e3:.1f} us, max "
          f"{ns.max() / 1e3:.1f} us ({len(ns)} samples); state at the end: {m.status.state.value}")

    inside = 0
    runs = 50
    for i in range(runs):
        rng = np.random.default_rng([0, i])
        xi = random_geometry(DEXTAR, rng, corners=(i % 5 == 4))
        q_true, _ok = kin.ik_batch(plan.x, xi, plan.q)
        m = EnvelopeMonitor(env)
        for q in quantise(q_true, DEXTAR.eps_q, "floor", rng):
            s = m.update(q)
        inside += s.state is EnvelopeState.CERTIFIED
    out["envelope_mc"] = {"inside": inside, "runs": runs, "radius_mrad": 1e3 * float(np.max(env.radius))}
    print(f"5. Monte Carlo executions (the planned path, random geometries): {inside}/{runs} confirmed by the "
          f"envelope at run time (half-width {1e3 * float(np.max(env.radius)):.2f} mrad); the others fall back "
          "to the tracker")
    return out


if __name__ == "__main__":
    import argparse
    import json

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", help="also write the figures to this file (benchmarks/figures.py reads it)")
    args = ap.parse_args()
    figures = main_bench()
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1))
