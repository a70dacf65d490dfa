#!/usr/bin/env python
"""Benchmark of the interval tracker on the DexTAR benchmark crossing.

Usage::

    python benchmarks/bench_tracker.py            # full run (about 10-15 min on 2 cores)
    python benchmarks/bench_tracker.py --quick    # reduced sizes (about 3 min)
    python benchmarks/bench_tracker.py --quick --json out.json

It prints numbers only; nothing here asserts on timing.  Three parts:

1. ``track`` on one scenario, single thread: wall time per sample (ms),
   split into samples where the tracker certified the assembly mode ("far"
   from the singularity) and samples where it did not ("near"), and the
   real-time factor at 1 kHz (``1 ms / time per sample``; > 1 means faster
   than real time).
2. ``track_batch(record=False)`` throughput, in scenario-samples per second,
   for ``B`` in (1, 10, 100, 1000) copies of the crossing simulated with
   different random true geometries.
3. Memory of a streamed batched run (:class:`verifier.tracker.SampleStream`,
   readings generated on the fly) for ``B = 10^4`` scenarios and two run
   lengths ``K``: ``tracemalloc`` peak and ``ru_maxrss``, each run in its own
   child process so that the two high-water marks are independent; then the
   extrapolation to ``10^4`` scenarios x ``10^4`` samples.

The crossing is simulated exactly as ``tests/problems.py`` does (the cruise
rule is re-implemented here, the tests are not imported).  BLAS is forced to
one thread (set below, before numpy is imported).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # before numpy is imported (also inherited by the child processes)

import argparse  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from planner.sweep import cruise_for as sweep_cruise_for  # noqa: E402
from planner.simulate import random_geometry, simulate_crossing  # noqa: E402
from robots import DEXTAR, KinematicModel, benchmark_crossing  # noqa: E402
from verifier.model import IntervalModel  # noqa: E402
from verifier.tracker import (  # noqa: E402
    SampleStream,
    TrackerSettings,
    Verdict,
    initial_box_from_mode,
    track,
    track_batch,
)

# --- the benchmark crossing, as in tests/problems.py -------------------------
V_SING = 1.458  # m/s, the paper's fastest Table II speed
T_REST = 0.05  # s of rest before the motion
START_DISTANCE = 0.035  # m: the run starts (at least) this far before the locus
A_PEAK = 60.0  # m/s^2, peak acceleration of the ramps (simulate_crossing's default)
REAL_TIME_STEP_MS = 1e3 * DEXTAR.t_s  # 1 ms at 1 kHz
BIG = (10_000, 10_000)  # (B, K) of the extrapolated run


def cruise_for(v_sing: float, a_peak: float = A_PEAK) -> float:
    """Half-length (m) of the constant-speed zone so the start is START_DISTANCE away."""
    return sweep_cruise_for(v_sing, a_peak, START_DISTANCE)


def settings() -> TrackerSettings:
    # the robot's defaults, including its geometry hypotheses (xi_splits)
    return TrackerSettings.for_robot(DEXTAR)


def simulate(kin: KinematicModel, seed: int):
    """The crossing at V_SING; seed 0 = centre of the calibration box, else a random geometry."""
    bench = benchmark_crossing()
    xi = None if seed == 0 else random_geometry(DEXTAR, np.random.default_rng(seed))
    return simulate_crossing(kin, bench.point, bench.direction, V_SING, xi_true=xi, t_rest=T_REST,
                             working_guess=bench.q_point, seed=seed, quantisation="floor",
                             cruise=cruise_for(V_SING))


def verdict_counts(verdicts) -> dict:
    return dict(sorted(Counter(str(v) for v in verdicts).items()))


def rss_mib() -> float:
    """ru_maxrss of this process, MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def proc_status_mib(field: str) -> float:
    """``VmHWM`` (peak) or ``VmRSS`` (current) of this process from /proc, MiB (nan elsewhere).

    Unlike ``ru_maxrss``, which Linux carries over from the parent across
    fork/exec (so a child started by a big parent starts at the parent's
    peak), ``VmHWM`` belongs to the process's own address space.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return float("nan")


def say(msg: str = "") -> None:
    print(msg, flush=True)


# --- part 1: single-scenario track --------------------------------------------
def bench_single(model, kin, repeats: int) -> dict:
    s = settings()
    run = simulate(kin, 0)
    mode0 = int(run.mode_true[0])
    t0 = time.perf_counter()
    x0 = initial_box_from_mode(model, run.q_meas[0], mode0, s)
    t_init = time.perf_counter() - t0
    per_rep, cpu_rep = [], []
    res = None
    for _ in range(repeats):
        stamps, cpu = [], []

        def tick(k):
            stamps.append(time.perf_counter())
            cpu.append(time.process_time())

        c0, t0 = time.process_time(), time.perf_counter()
        res = track(model, run.q_meas, s, x0=x0, progress=tick)
        per_rep.append(np.diff(np.concatenate([[t0], stamps])) * 1e3)
        cpu_rep.append(np.diff(np.concatenate([[c0], cpu])) * 1e3)
    dt = np.median(np.array(per_rep), axis=0)  # wall ms per sample, median over repeats
    dc = np.median(np.array(cpu_rep), axis=0)  # process CPU ms per sample
    far = res.mode != 0
    near = ~far
    inside_x = bool(np.all((res.x_lo <= run.x_true) & (run.x_true <= res.x_hi)))
    inside_xd = bool(np.all((res.xd_lo[1:] <= run.xd_true[1:]) & (run.xd_true[1:] <= res.xd_hi[1:])))

    def stats(mask):
        v = dt[mask]
        if v.size == 0:
            return dict(steps=0, mean_ms=float("nan"), median_ms=float("nan"), max_ms=float("nan"),
                        rtf=float("nan"), cpu_mean_ms=float("nan"), rtf_cpu=float("nan"))
        return dict(steps=int(v.size), mean_ms=float(v.mean()), median_ms=float(np.median(v)),
                    max_ms=float(v.max()), rtf=float(REAL_TIME_STEP_MS / v.mean()),
                    cpu_mean_ms=float(dc[mask].mean()), rtf_cpu=float(REAL_TIME_STEP_MS / dc[mask].mean()))

    out = dict(
        samples=int(run.n_samples), k_sing=int(run.k_sing), repeats=repeats,
        initial_box_ms=1e3 * t_init,
        overall=stats(np.ones_like(far)), far=stats(far), near=stats(near),
        near_steps=[int(k) for k in np.nonzero(near)[0]],
        verdict=str(res.verdict), certified_at_step=int(res.certified_at_step),
        inconsistent_at_step=int(res.inconsistent_at_step),
        true_pose_inside=inside_x, true_velocity_inside=inside_xd,
        track_total_s=float(dt.sum() / 1e3),
    )
    say(f"  crossing: {out['samples']} samples at 1 kHz, true singular instant at sample {out['k_sing']}; "
        f"median of {repeats} run(s); initial box (initial_box_from_mode): {t_init * 1e3:.1f} ms, not included below")
    say(f"  verdict {out['verdict']}, certified at sample {out['certified_at_step']}, "
        f"inconsistent at {out['inconsistent_at_step']}; true pose inside boxes: {inside_x}, "
        f"true velocity inside: {inside_xd}")
    say(f"  {'samples':<26}{'count':>6}{'mean ms':>10}{'median ms':>11}{'max ms':>9}{'real-time factor':>18}"
        f"{'CPU ms (mean)':>15}{'RTF (CPU)':>11}")
    for key, label in (("overall", "overall"), ("far", "far (mode certified)"), ("near", "near (mode not certified)")):
        r = out[key]
        say(f"  {label:<26}{r['steps']:>6}{r['mean_ms']:>10.2f}{r['median_ms']:>11.2f}{r['max_ms']:>9.1f}{r['rtf']:>18.4f}"
            f"{r['cpu_mean_ms']:>15.2f}{r['rtf_cpu']:>11.4f}")
    if out["near_steps"]:
        ns = out["near_steps"]
        say(f"  near samples: {ns[0]}..{ns[-1]} ({len(ns)} samples)")
    return out


# --- part 2: batched throughput -----------------------------------------------
def build_pool(model, kin, size: int):
    """``size`` crossings with random true geometries (seeds 1..size) and their initial boxes."""
    s = settings()
    runs, lo, hi = [], [], []
    t0 = time.perf_counter()
    for seed in range(1, size + 1):
        r = simulate(kin, seed)
        b = initial_box_from_mode(model, r.q_meas[0], int(r.mode_true[0]), s)
        runs.append(r)
        lo.append(b[0])
        hi.append(b[1])
    K = max(r.n_samples for r in runs)
    # pad with the last reading (the robot is at rest at the end), as the tests do
    q = np.stack([np.vstack([r.q_meas, np.repeat(r.q_meas[-1:], K - r.n_samples, axis=0)]) for r in runs])
    say(f"  pool: {size} random geometries simulated with their initial boxes in {time.perf_counter() - t0:.1f} s; "
        f"{min(r.n_samples for r in runs)}-{K} samples (padded to {K}), singular instant at samples "
        f"{min(r.k_sing for r in runs)}-{max(r.k_sing for r in runs)}")
    return runs, q, np.array(lo), np.array(hi)


def bench_batch(model, pool, sizes_steps) -> list:
    runs, q, lo, hi = pool
    s = settings()
    out = []
    say(f"  {'B':>6}{'K':>6}{'distinct':>9}{'wall s':>9}{'CPU s':>8}{'ms/batch step':>15}{'scen-steps/s':>14}{'per CPU-s':>11}  verdicts")
    for B, K in sizes_steps:
        idx = np.arange(B) % len(runs)  # tile the pool when B exceeds it
        c0, t0 = time.process_time(), time.perf_counter()
        res = track_batch(model, q[idx, :K], s, (lo[idx], hi[idx]), record=False)
        el = time.perf_counter() - t0
        cpu = time.process_time() - c0
        counts = verdict_counts(res.verdict)
        bad = np.nonzero(res.inconsistent_at_step >= 0)[0]
        row = dict(B=B, K=K, distinct=int(min(B, len(runs))), wall_s=el, cpu_s=cpu, ms_per_batch_step=1e3 * el / K,
                   scenario_steps_per_s=B * K / el, scenario_steps_per_cpu_s=B * K / cpu, verdicts=counts,
                   inconsistent=[dict(scenario=int(b), seed=int(idx[b]) + 1, step=int(res.inconsistent_at_step[b]),
                                      k_sing=int(runs[idx[b]].k_sing), xi_true=runs[idx[b]].xi_true.tolist())
                                 for b in bad])
        out.append(row)
        say(f"  {B:>6}{K:>6}{row['distinct']:>9}{el:>9.2f}{cpu:>8.2f}{row['ms_per_batch_step']:>15.2f}"
            f"{row['scenario_steps_per_s']:>14.0f}{row['scenario_steps_per_cpu_s']:>11.0f}  {counts}")
        for r in row["inconsistent"]:
            say(f"    !! INCONSISTENT: scenario {r['scenario']} (seed {r['seed']}) at sample {r['step']} "
                f"(singular instant {r['k_sing']}), xi_true = {r['xi_true']}")
        expected = Verdict.MODE_CHANGED.value if K > max(r.k_sing for r in runs) + 40 else None
        if expected and counts.get(expected, 0) != B:
            say(f"    !! expected every scenario to be {expected} after {K} samples, got {counts}")
    return out


# --- part 3: memory of a streamed run (child process) ---------------------------
def rest_stream(B: int, K: int, q_rest: np.ndarray, eps: float, seed: int = 7) -> SampleStream:
    """Readings of the crossing's rest pose, generated on the fly, scenario-dependent.

    Even scenarios: an encoder grid shifted by a scenario-dependent offset
    ``c_b in [0, eps)``, floor quantisation (constant reading).  Odd scenarios:
    uniform dither ``|e| < eps`` drawn per sample from a generator seeded by
    ``(seed, k)``.  Every reading is within ``eps`` of the true joints.
    """
    b = np.arange(B)
    shift = (eps * ((b * 0.6180339887498949) % 1.0))[:, None]  # (B, 1)
    grid = eps * np.floor((q_rest[None, :] + shift) / eps) - shift  # in (q - eps, q]
    odd = (b % 2 == 1)[:, None]

    def sample(k: int) -> np.ndarray:
        u = np.random.default_rng((seed, k)).uniform(-1.0, 1.0, size=(B, q_rest.size))
        return np.where(odd, q_rest[None, :] + eps * (1.0 - 1e-9) * u, grid)

    return SampleStream(B, K, sample)


def memory_child(B: int, K: int) -> dict:
    model = IntervalModel(DEXTAR)
    kin = KinematicModel(DEXTAR)
    s = settings()
    run = simulate(kin, 0)
    k_rest = int(np.argmax(np.any(run.x_true != run.x_true[0], axis=1)))  # samples at rest before the motion
    q_rest = np.array(run.q_true[0])
    # encloses the pose for every q within eps_q of the true joints: contains the true pose
    x0 = initial_box_from_mode(model, q_rest, int(run.mode_true[0]), s)
    stream = rest_stream(B, K, q_rest, DEXTAR.eps_q)
    base_rss = rss_mib()
    base_hwm = proc_status_mib("VmHWM")
    base_cur = proc_status_mib("VmRSS")
    stamps = []
    tracemalloc.start()
    tracemalloc.reset_peak()
    c0, t0 = time.process_time(), time.perf_counter()
    cpus = []

    def tick(k):
        stamps.append(time.perf_counter())
        cpus.append(time.process_time())

    res = track_batch(model, stream, s, x0, record=False, progress=tick)
    el = time.perf_counter() - t0
    cpu = time.process_time() - c0
    cur, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    dt = np.diff(np.concatenate([[t0], stamps]))
    depth = max(s.baselines)
    dcpu = np.diff(np.concatenate([[c0], cpus]))
    first = 2 * depth if K > 2 * depth + 5 else K // 2  # after the baseline window has filled
    steady, steady_cpu = dt[first:], dcpu[first:]
    bad = np.nonzero(res.inconsistent_at_step >= 0)[0]
    return dict(
        B=B, K=K, rest_samples_in_crossing=k_rest, wall_s=el, cpu_s=cpu,
        scenario_steps_per_s=B * K / el,
        steady_ms_per_batch_step=1e3 * float(np.mean(steady)),
        steady_scenario_steps_per_s=B / float(np.mean(steady)),
        steady_scenario_steps_per_cpu_s=B / float(np.mean(steady_cpu)),
        steady_from_step=int(first),
        tracemalloc_peak_mib=peak / 2**20, tracemalloc_end_mib=cur / 2**20,
        maxrss_before_mib=base_rss, maxrss_after_mib=rss_mib(),
        vmrss_before_mib=base_cur, vmhwm_before_mib=base_hwm, vmhwm_after_mib=proc_status_mib("VmHWM"),
        verdicts=verdict_counts(res.verdict),
        inconsistent=[dict(scenario=int(b), step=int(res.inconsistent_at_step[b])) for b in bad[:20]],
        n_inconsistent=int(bad.size),
        max_width_pose_m=float(res.max_width_pose.max()),
        max_width_velocity_mps=float(res.max_width_velocity.max()),
    )


def bench_memory(B: int, Ks) -> dict:
    rows = []
    say(f"  streamed rest-pose readings (SampleStream), record=False, B = {B}, each K in its own process")
    say(f"  {'K':>5}{'wall s':>9}{'CPU s':>8}{'tracemalloc peak MiB':>22}{'RSS before MiB':>16}{'VmHWM after MiB':>17}"
        f"{'growth MiB':>12}{'ru_maxrss MiB':>15}{'steady scen-steps/s':>21}{'per CPU-s':>11}  verdicts")
    for K in Ks:
        cmd = [sys.executable, str(Path(__file__).resolve()), "--memory-child", str(B), str(K)]
        p = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
        if p.returncode != 0:
            say(f"  !! child for K={K} failed:\n{p.stderr}")
            continue
        r = json.loads(p.stdout.strip().splitlines()[-1])
        rows.append(r)
        growth = r["vmhwm_after_mib"] - r["vmrss_before_mib"]
        say(f"  {K:>5}{r['wall_s']:>9.1f}{r['cpu_s']:>8.1f}{r['tracemalloc_peak_mib']:>22.1f}{r['vmrss_before_mib']:>16.1f}"
            f"{r['vmhwm_after_mib']:>17.1f}{growth:>12.1f}{r['maxrss_after_mib']:>15.1f}{r['steady_scenario_steps_per_s']:>21.0f}"
            f"{r['steady_scenario_steps_per_cpu_s']:>11.0f}  {r['verdicts']}")
        if r["n_inconsistent"]:
            say(f"    !! {r['n_inconsistent']} scenario(s) INCONSISTENT at rest, first: {r['inconsistent']}")
    return dict(B=B, runs=rows)


def extrapolate(mem: dict, batch: list) -> dict:
    rows = mem["runs"]
    if len(rows) < 2:
        return {}
    a, b = rows[0], rows[-1]
    Bb, Kb = BIG
    scale = Bb / mem["B"]
    per_scen_kib = b["tracemalloc_peak_mib"] * 1024 / mem["B"]
    est_traced = b["tracemalloc_peak_mib"] * scale
    est_rss = (b["vmhwm_after_mib"] - b["vmrss_before_mib"]) * scale + b["vmrss_before_mib"]
    array_in = Bb * Kb * DEXTAR.n * 8 / 2**30
    recorded = Bb * Kb * (5 * DEXTAR.n * 8 + 1) / 2**30
    thr_rest = b["steady_scenario_steps_per_s"]
    thr_rest_cpu = b["steady_scenario_steps_per_cpu_s"]
    big_rows = [r for r in batch if r["B"] == max(x["B"] for x in batch)]
    thr_cross = big_rows[0]["scenario_steps_per_s"] if big_rows else float("nan")
    thr_cross_cpu = big_rows[0]["scenario_steps_per_cpu_s"] if big_rows else float("nan")
    out = dict(
        peak_ratio=b["tracemalloc_peak_mib"] / a["tracemalloc_peak_mib"],
        rss_growth_ratio=(b["vmhwm_after_mib"] - b["vmrss_before_mib"]) / max(a["vmhwm_after_mib"] - a["vmrss_before_mib"], 1e-9),
        per_scenario_kib=per_scen_kib, est_traced_mib=est_traced, est_rss_mib=est_rss,
        array_input_gib=array_in, record_gib=recorded,
        est_time_h_rest=Bb * Kb / thr_rest / 3600, est_time_h_crossing=Bb * Kb / thr_cross / 3600,
        est_cpu_h_rest=Bb * Kb / thr_rest_cpu / 3600, est_cpu_h_crossing=Bb * Kb / thr_cross_cpu / 3600,
        thr_rest=thr_rest, thr_cross=thr_cross, thr_rest_cpu=thr_rest_cpu, thr_cross_cpu=thr_cross_cpu, B_cross=big_rows[0]["B"] if big_rows else None,
    )
    say(f"  tracemalloc peak K={b['K']} / K={a['K']}: {out['peak_ratio']:.3f}   "
        f"RSS growth (VmHWM after - RSS before) K={b['K']} / K={a['K']}: {out['rss_growth_ratio']:.3f}")
    say(f"  per scenario: {per_scen_kib:.1f} KiB traced at the peak (O(B), independent of K)")
    say(f"  {Bb:.0e} scenarios x {Kb:.0e} samples, streamed: ~{est_traced:.0f} MiB traced peak, "
        f"~{est_rss:.0f} MiB peak RSS of the process (same as for K={b['K']} at B={Bb})")
    say(f"    (for contrast: the readings as a (B, K, n) array would take {array_in:.2f} GiB, "
        f"record=True another {recorded:.1f} GiB)")
    say(f"  estimated time, one process: {out['est_time_h_rest']:.1f} h wall ({out['est_cpu_h_rest']:.1f} CPU-h) at the "
        f"steady throughput of the rest run (B={mem['B']}: {thr_rest:.0f} scenario-steps/s wall, "
        f"{thr_rest_cpu:.0f} per CPU-s)")
    say(f"                               {out['est_time_h_crossing']:.1f} h wall ({out['est_cpu_h_crossing']:.1f} CPU-h) at the "
        f"crossing throughput of B={out['B_cross']} ({thr_cross:.0f} scenario-steps/s wall, {thr_cross_cpu:.0f} per CPU-s)")
    return out


def code_version() -> dict:
    """Git commit of the tree being measured and a hash of the code the benchmark imports."""
    import hashlib

    h = hashlib.sha256()
    for pkg in ("verifier", "planner", "robots"):
        for f in sorted((ROOT / pkg).glob("*.py")):
            h.update(f.name.encode())
            h.update(f.read_bytes())
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "verifier", "planner", "robots"], cwd=ROOT,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit, dirty = "unknown", ""
    return dict(commit=commit + (" (+ uncommitted changes)" if dirty else ""), code_sha256=h.hexdigest()[:12])


def machine() -> dict:
    cpu = platform.processor()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import casadi

    return dict(date=datetime.date.today().isoformat(), cpu=cpu, cores=os.cpu_count(),
                python=platform.python_version(), numpy=np.__version__, casadi=casadi.__version__,
                **code_version())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="reduced sizes, about 3 minutes")
    ap.add_argument("--json", metavar="PATH", help="also write the numbers as JSON")
    ap.add_argument("--memory-child", nargs=2, type=int, metavar=("B", "K"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.memory_child:
        print(json.dumps(memory_child(*args.memory_child)))
        return 0

    t_all = time.perf_counter()
    load0 = os.getloadavg()
    info = machine()
    say(f"crosscert tracker benchmark ({'quick' if args.quick else 'full'}), {info['date']}")
    say(f"  {info['cpu']}, {info['cores']} cores; Python {info['python']}, numpy {info['numpy']}, "
        f"casadi {info['casadi']}; BLAS threads forced to 1")
    say(f"  code: commit {info['commit']}, verifier/planner/robots sha256 {info['code_sha256']}")
    say(f"  DexTAR crossing at v_sing = {V_SING} m/s, t_rest = {T_REST} s, cruise = {cruise_for(V_SING) * 1e3:.2f} mm, "
        f"t_s = {DEXTAR.t_s} s, eps_q = {DEXTAR.eps_q:.3e} rad, a_max = {DEXTAR.a_max}, xd0 = {DEXTAR.xd0}")
    t0 = time.perf_counter()
    model = IntervalModel(DEXTAR)
    kin = KinematicModel(DEXTAR)
    say(f"  model build: {time.perf_counter() - t0:.2f} s")

    say("\n[1] track, one scenario (nominal geometry), single thread")
    single = bench_single(model, kin, repeats=1 if args.quick else 3)

    say("\n[2] track_batch throughput (record=False), random true geometries")
    pool = build_pool(model, kin, 100 if args.quick else 1000)
    K_full = pool[1].shape[1]
    plan = [(1, K_full), (10, K_full), (100, K_full), (1000, 150 if args.quick else K_full)]
    batch = bench_batch(model, pool, plan)

    Ks = (20, 80) if args.quick else (50, 200)
    say(f"\n[3] memory of a streamed batched run, B = 10000, K = {Ks[0]} vs {Ks[1]}")
    mem = bench_memory(10_000, Ks)
    ext = extrapolate(mem, batch)

    total = time.perf_counter() - t_all
    after = code_version()
    if after["code_sha256"] != info["code_sha256"]:
        say(f"\n!! the measured code changed during the run (now commit {after['commit']}, "
            f"sha256 {after['code_sha256']}): child processes of part 3 may have run different code")
    say(f"\ntotal wall time: {total:.0f} s; load average at start {load0[0]:.2f}, at end {os.getloadavg()[0]:.2f} "
        f"(on {os.cpu_count()} cores: a load above ~1 means other processes competed; compare wall and CPU times)")
    if args.json:
        Path(args.json).write_text(json.dumps(dict(machine=info, quick=args.quick, single=single, batch=batch,
                                                   memory=mem, extrapolation=ext, total_s=total,
                                                   loadavg_start=load0[0], loadavg_end=os.getloadavg()[0]), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
