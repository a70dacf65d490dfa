"""Wall and CPU time of `certify_crossing` (what `crosscert certify` runs) on the DexTAR task, phase by phase.

Prints numbers, asserts nothing.  Usage::

    python benchmarks/bench_certify.py [--repeat 2] [--method smoothstep] [--foreground] [--no-cold] [--json out.json]
    python benchmarks/bench_certify.py --moved

Each measurement runs in a fresh child process (this script with ``--child``):

* **cache on disk**: ``--repeat`` runs (default 2) in one process with the
  numba cache of the source tree: run 1 is the first call after an install
  (kernels loaded from disk), run 2 and later are warm (report these);
* **cold cache** (skip with ``--no-cold``): one run with ``NUMBA_CACHE_DIR``
  set to an empty temporary directory, so every kernel is compiled (the
  cache in the source tree is left alone).

``--foreground`` runs the counterexample searches in the calling process
(``refute_in_background=False``) instead of the background worker.  CPU time
is that of the certifying process (all its threads) plus that of the worker
process, which is waited for when the certificate is returned.

``--moved`` instead times the call an optimisation script repeats
(``certify_crossing(..., refute=False, monte_carlo_runs=0, bounce=False)``) in
one process: the task, the same task again, then the task moved 2, 4 and 6 mm
along y; once from scratch each time and once with ``v_guess`` = the previous
call's ``v_min`` (issue 19's target: a new task in <= 2 s).

``--profile`` instead profiles one warm run with every search in the calling
process (``refute_in_background=False``, so the worker's share is seen too)
and prints the inclusive time (``--cpu``: CPU time, steadier on a loaded
machine) of each part of the work (:data:`PARTS`):
plans, execution classes, forward tracking, window passes, the CasADi
kinematics, NLP building, IPOPT, the counterexample checks, the simulations.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PHASES = ("setup", "search", "certificate", "monte_carlo", "refutation", "bounce")
#: Parts of the work in the ``--profile`` table: (label, module path suffix, function name).  Times are
#: inclusive (a part may contain another: window passes contain forward passes of the kernel).
PARTS = (
    ("speed search (search_v_min)", "planner/certify/plan.py", "search_v_min"),
    ("  plans (plan_crossing)", "planner/plan.py", "plan_crossing"),
    ("  execution classes (cartesian_class)", "planner/execution.py", "cartesian_class"),
    ("  forward tracker runs (track)", "verifier/tracker.py", "track"),
    ("  window passes (track_window)", "verifier/window/offline.py", "track_window"),
    ("Monte Carlo (monte_carlo_runs)", "planner/montecarlo.py", "monte_carlo_runs"),
    ("  batched forward tracking (track_batch)", "verifier/tracker.py", "track_batch"),
    ("refutation bound (refute_speed)", "planner/certify/crossing.py", "refute_speed"),
    ("bounce verdicts, tracker side (bounce_verdicts)", "planner/bounce.py", "bounce_verdicts"),
    ("bounce floor, crossing searches (bounce_floor)", "planner/bounce.py", "bounce_floor"),
    ("  bounce simulations (simulate_bounce)", "planner/simulate/run.py", "simulate_bounce"),
    ("counterexample NLPs (search_counterexample)", "planner/refute/nlp.py", "search_counterexample"),
    ("  FK initial guesses (fk_branch_guess)", "planner/refute/nlp.py", "fk_branch_guess"),
    ("  NLP building (_counterexample_solver)", "planner/refute/nlp.py", "_counterexample_solver"),
    ("  IPOPT iterations (ParametricSolver.solve)", "planner/ipopt.py", "solve"),
    ("  solver builds (ParametricSolver.__init__)", "planner/ipopt.py", "__init__"),
    ("  trusted checks (verify_counterexample)", "planner/refute/verify.py", "verify_counterexample"),
    ("every window pass (verifier.window.passes.run_pass)", "verifier/window/passes.py", "run_pass"),
    ("every compiled kernel call (compiled/step.py run)", "verifier/compiled/step.py", "run"),
    ("CasADi numeric kinematics (KinematicModel._call)", "robots/kinematics.py", "_call"),
)


def children_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def child(repeat: int, method: str, foreground: bool) -> list:
    """``repeat`` runs of certify_crossing in this process; one dict per run."""
    from crosscert.planner import PlanningBounds, benchmark_task, certify_crossing
    from crosscert.robots import DEFAULT_ROBOT, KinematicModel, get_entry
    from crosscert.verifier.model import IntervalModel

    entry = get_entry(DEFAULT_ROBOT)
    DEXTAR = entry.robot
    task = benchmark_task(entry)
    bounds = PlanningBounds(method=method, dynamics=entry.dynamics if method == "dynamic" else None)
    kin, imodel = KinematicModel(DEXTAR), IntervalModel(DEXTAR)
    runs = []
    for _ in range(repeat):
        c0, w0, t0 = time.process_time(), children_cpu_s(), time.perf_counter()
        cert = certify_crossing(DEXTAR, task, bounds, kin=kin, imodel=imodel, refute_in_background=not foreground)
        wall = time.perf_counter() - t0
        cpu, worker = time.process_time() - c0, children_cpu_s() - w0
        runs.append({"wall_s": wall, "elapsed_s": cert.elapsed_s, "cpu_s": cpu + worker, "cpu_main_s": cpu,
                     "cpu_worker_s": worker, **{f"{k}_s": cert.timings_s.get(k) for k in PHASES},
                     "v_min": cert.v_min, "refutation_bound": cert.refutation_bound,
                     "tracked_speeds": len(cert.trials), "refuted_speeds_searched": len(cert.refutation),
                     "mc_detected": None if cert.monte_carlo is None else cert.monte_carlo.detected_in_class})
    return runs


def profile(method: str, cpu: bool = False, save: str | None = None) -> None:
    """One warm ``certify_crossing`` under cProfile, every search in this process; prints the :data:`PARTS` table.

    ``cpu``: time the parts by this process's CPU time (all threads) instead of the wall clock, which a
    loaded machine inflates; ``save``: also write the raw statistics there (``pstats`` format).
    """
    import cProfile
    import pstats

    from crosscert.planner import PlanningBounds, benchmark_task, certify_crossing
    from crosscert.planner.certify.plan import certify_speed
    from crosscert.robots import DEFAULT_ROBOT, KinematicModel, get_entry
    from crosscert.verifier.model import IntervalModel

    entry = get_entry(DEFAULT_ROBOT)
    robot, task = entry.robot, benchmark_task(entry)
    bounds = PlanningBounds(method=method, dynamics=entry.dynamics if method == "dynamic" else None)
    kin, imodel = KinematicModel(robot), IntervalModel(robot)
    certify_speed(kin, imodel, task, bounds, 1.0)  # loads the kernels (not profiled)
    clock = time.process_time if cpu else time.perf_counter
    prof = cProfile.Profile(clock)
    t0 = clock()
    prof.enable()
    cert = certify_crossing(robot, task, bounds, kin=kin, imodel=imodel, refute_in_background=False)
    prof.disable()
    wall = clock() - t0
    if save:
        prof.dump_stats(save)
    stats = pstats.Stats(prof).stats
    load = " / ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"one warm certify_crossing under cProfile, every search in this process: {wall:.1f} "
          f"{'CPU-s' if cpu else 's'} (v_min {cert.v_min}, refutation bound {cert.refutation_bound}; load average "
          f"{load} at the end); inclusive {'CPU ' if cpu else ''}times:")
    print(f"{'part':<52}{'calls':>7}{'s':>9}{'share':>8}")
    for label, path, name in PARTS:
        calls = tot = 0.0
        for (file, _line, fn), (_cc, nc, _tt, ct, _callers) in stats.items():
            if fn == name and file.replace("\\", "/").endswith(path):
                calls, tot = calls + nc, tot + ct
        print(f"{label:<52}{int(calls):>7}{tot:>9.2f}{tot / wall:>8.0%}")


def moved(guess: bool) -> list:
    """The repeated call of an optimisation script, in this process: one dict per call (see ``--moved``)."""
    from dataclasses import replace

    import numpy as np

    from crosscert.planner import PlanningBounds, benchmark_task, certify_crossing
    from crosscert.robots import DEFAULT_ROBOT, KinematicModel, get_entry
    from crosscert.verifier.model import IntervalModel

    entry = get_entry(DEFAULT_ROBOT)
    robot, task = entry.robot, benchmark_task(entry)
    kin, imodel = KinematicModel(robot), IntervalModel(robot)
    calls, previous = [], None
    for mm in (0, 0, 2, 4, 6):
        shift = np.array([0.0, 1e-3 * mm])
        t = replace(task, start=task.start + shift, goal=task.goal + shift)
        c0, t0 = time.process_time(), time.perf_counter()
        cert = certify_crossing(robot, t, PlanningBounds(), kin=kin, imodel=imodel, refute=False, monte_carlo_runs=0,
                                bounce=False, v_guess=previous if guess else None)
        calls.append({"moved_mm": mm, "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
                      "v_min": cert.v_min, "questions": len(cert.trials)})
        previous = cert.v_min
    return calls


def measure(args: argparse.Namespace, repeat: int, cache_dir: str | None) -> list | None:
    """Run the child process; ``cache_dir`` None = the numba cache of the source tree."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", "--repeat", str(repeat), "--method", args.method]
    cmd += ["--foreground"] if args.foreground else []
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        print(f"!! child failed:\n{p.stderr}", flush=True)
        return None
    return json.loads(p.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=2, help="runs in the process with the cache on disk (default 2)")
    p.add_argument("--method", default="smoothstep", choices=("smoothstep", "time-optimal", "dynamic"))
    p.add_argument("--foreground", action="store_true")
    p.add_argument("--no-cold", action="store_true", help="skip the run with an empty numba cache")
    p.add_argument("--json")
    p.add_argument("--profile", action="store_true", help="profile one warm run by part of the work instead")
    p.add_argument("--cpu", action="store_true", help="with --profile: CPU time instead of wall time")
    p.add_argument("--save", help="with --profile: write the raw cProfile statistics to this file")
    p.add_argument("--moved", action="store_true", help="time the repeated call of an optimisation script instead")
    p.add_argument("--guess", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.moved and a.child:
        print(json.dumps(moved(a.guess)))
        return 0
    if a.moved:
        return _print_moved()
    if a.profile:
        profile(a.method, a.cpu, a.save)
        return 0
    if a.child:
        print(json.dumps(child(a.repeat, a.method, a.foreground)))
        return 0

    load = " / ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"machine: {os.cpu_count()} CPUs; load average {load} (1 / 5 / 15 min); method {a.method}; "
          f"refutation {'in the calling process' if a.foreground else 'in the background worker'}", flush=True)
    rows = []
    for i, r in enumerate(measure(a, a.repeat, None) or []):
        rows.append({"case": "cache on disk, run 1 (first call)" if i == 0 else f"warm, run {i + 1}", **r})
    if not a.no_cold:
        tmp = tempfile.mkdtemp(prefix="crosscert-numba-cold-")
        try:
            rows += [{"case": "cold (empty numba cache)", **r} for r in measure(a, 1, tmp) or []]
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    print(f"{'case':<36}" + "".join(f"{k + ' s':>15}" for k in PHASES)
          + f"{'total wall s':>14}{'CPU s':>8}{'(main':>8}{'+ worker)':>10}{'v_min':>8}{'refuted':>9}{'MC':>5}")
    for r in rows:
        phases = "".join(f"{r[k + '_s']:>15.2f}" if r[k + "_s"] is not None else f"{'-':>15}" for k in PHASES)
        ref = "-" if r["refutation_bound"] is None else f"{r['refutation_bound']:.3f}"
        vmin = "-" if r["v_min"] is None else f"{r['v_min']:.3f}"
        print(f"{r['case']:<36}{phases}{r['elapsed_s']:>14.2f}{r['cpu_s']:>8.1f}{r['cpu_main_s']:>8.1f}"
              f"{r['cpu_worker_s']:>10.1f}{vmin:>8}{ref:>9}{str(r['mc_detected']):>5}")
    print(f"(total wall = certify_crossing's elapsed_s; {rows[0]['tracked_speeds'] if rows else '?'} tracked speeds, "
          f"{rows[0]['refuted_speeds_searched'] if rows else '?'} speeds searched for counterexamples; "
          f"load average at the end {' / '.join(f'{v:.2f}' for v in os.getloadavg())})")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    return 0


def _print_moved() -> int:
    """``--moved``: both variants, each in a fresh child process, one after the other."""
    print(f"machine: {os.cpu_count()} CPUs; load average {' / '.join(f'{v:.2f}' for v in os.getloadavg())}",
          flush=True)
    print(f"{'call':<34}{'wall s':>8}{'CPU s':>8}{'questions':>11}{'v_min':>10}")
    for guess in (False, True):
        cmd = [sys.executable, str(Path(__file__).resolve()), "--child", "--moved"] + (["--guess"] if guess else [])
        out = subprocess.run(cmd, capture_output=True, text=True)
        if out.returncode != 0:
            print(f"!! child failed:\n{out.stderr}", flush=True)
            return 1
        for i, c in enumerate(json.loads(out.stdout.strip().splitlines()[-1])):
            what = ("first call" if i == 0 else "same task" if i == 1 else f"task moved {c['moved_mm']} mm")
            what += " (v_guess)" if guess and i > 0 else ""
            print(f"{what:<34}{c['wall_s']:>8.2f}{c['cpu_s']:>8.2f}{c['questions']:>11}{c['v_min']:>10.4f}")
    print(f"load average at the end {' / '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
