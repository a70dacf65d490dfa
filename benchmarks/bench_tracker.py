#!/usr/bin/env python
"""Benchmark of the interval tracker on the DexTAR benchmark crossing, per backend.

Usage::

    python benchmarks/bench_tracker.py --quick                      # reduced sizes (see README)
    python benchmarks/bench_tracker.py                              # full sizes (10^4 x 10^4 streamed: hours)
    python benchmarks/bench_tracker.py --quick --backend compiled   # one backend only
    python benchmarks/bench_tracker.py --quick --only batch memory  # some parts only
    python benchmarks/bench_tracker.py --quick --json out.json

It prints numbers only; nothing here asserts on timing.  ``--backend``
chooses ``compiled`` (numba kernels), ``numpy`` (the reference) or ``both``
(default).  Five parts:

1. ``latency``: one scenario fed to the online ``verifier.tracker.Tracker``
   one reading at a time, ``time.perf_counter_ns`` around each ``update``:
   mean, p50, p99 and max per sample (us), with and without sample 0, the
   real-time factor at 1 kHz (``1 ms / mean``; > 1 keeps up with the
   encoders), on the crossing and on the same crossing after 6 s of rest.
2. ``start`` (compiled only): the first call in a fresh process with an
   empty numba cache (compiles the kernels), with the on-disk cache (loads
   them), and later calls (warm).  Child processes; the empty cache is a
   temporary ``NUMBA_CACHE_DIR``, so the cache in the source tree is untouched.
3. ``batch``: ``track_batch(record=False)`` throughput in scenario-steps per
   wall and per CPU second, on crossings with different random geometries.
   The compiled backend spreads scenarios over numba's threads (2 here).
4. ``memory``: a streamed run (:class:`verifier.tracker.SampleStream`) of
   ``B = 10^4`` scenarios in a child process: ``tracemalloc`` peak, RSS and
   ``ru_maxrss``, time.  Compiled: ``K = 10^4`` in the full mode (the whole
   10^4 x 10^4 run), 300 in the quick mode, ``--stream-k`` otherwise; numpy:
   two short runs and an extrapolation.
5. ``cli``: ``crosscert check`` (whole command) and ``crosscert monitor``
   (piped) on a simulated 6.42 s recording, with each backend (their
   ``--backend`` option).

The crossing is simulated exactly as ``tests/problems.py`` does (the cruise
rule is re-implemented here, the tests are not imported).  BLAS is forced to
one thread (set below, before numpy is imported).
"""

from __future__ import annotations

import time

_T_START = time.perf_counter()  # the start-up children report their import time from here

import os  # noqa: E402

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # before numpy is imported (also inherited by the child processes)

import argparse  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import shlex  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import tracemalloc  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

import numpy as np  # noqa: E402

from crosscert.planner.sweep import cruise_for as sweep_cruise_for  # noqa: E402
from crosscert.verifier.compiled import driver as _driver  # noqa: E402

# batches of many rows run in lanes once that driver is cached (a command's compile child writes it):
# measure the library as it runs then, compiling it here on a first run
_driver.LANES_COMPILE_HERE = True
from crosscert.planner.simulate import random_geometry, simulate_crossing  # noqa: E402
from crosscert.robots import DEXTAR, KinematicModel  # noqa: E402
from crosscert.robots.dextar import benchmark_crossing  # noqa: E402
import crosscert.verifier.tracker as tracker_module  # noqa: E402
from crosscert.verifier.model import IntervalModel  # noqa: E402
from crosscert.verifier.tracker import Tracker  # noqa: E402
from crosscert.verifier.tracker import (  # noqa: E402
    SampleStream,
    TrackerSettings,
    Verdict,
    initial_box_from_mode,
    track,
    track_batch,
    verdict_of,
)

# --- the benchmark crossing, as in tests/problems.py -------------------------
V_SING = 1.458  # m/s, the paper's fastest Table II speed
T_REST = 0.05  # s of rest before the motion
T_REST_LONG = 6.0  # s of rest before the motion in the "6 s rest + crossing" recording
START_DISTANCE = 0.035  # m: the run starts (at least) this far before the locus
A_PEAK = 60.0  # m/s^2, peak acceleration of the ramps (simulate_crossing's default)
REAL_TIME_STEP_MS = 1e3 * DEXTAR.t_s  # 1 ms at 1 kHz
BIG = (10_000, 10_000)  # (B, K) of the streamed run
CLI_SAMPLES = 6420  # samples of the recording given to crosscert check / monitor (6.42 s at 1 kHz)
BACKENDS = ("compiled", "numpy")
PARTS = ("latency", "start", "batch", "memory", "cli")


def cruise_for(v_sing: float, a_peak: float = A_PEAK) -> float:
    """Half-length (m) of the constant-speed zone so the start is START_DISTANCE away."""
    return sweep_cruise_for(v_sing, a_peak, START_DISTANCE)


def settings() -> TrackerSettings:
    # the robot's defaults, including its geometry hypotheses (xi_splits)
    return TrackerSettings.for_robot(DEXTAR)


def simulate(kin: KinematicModel, seed: int, t_rest: float = T_REST):
    """The crossing at V_SING; seed 0 = centre of the calibration box, else a random geometry."""
    bench = benchmark_crossing()
    xi = None if seed == 0 else random_geometry(DEXTAR, np.random.default_rng(seed))
    return simulate_crossing(kin, bench.point, bench.direction, V_SING, xi_true=xi, t_rest=t_rest,
                             working_guess=bench.q_point, seed=seed, quantisation="floor",
                             cruise=cruise_for(V_SING))


def verdict_counts(verdicts) -> dict:
    return dict(sorted(Counter(str(v) for v in verdicts).items()))


def rss_mib() -> float:
    """ru_maxrss of this process, MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def children_cpu_s() -> float:
    """User + system CPU seconds of the finished (waited-for) child processes."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


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


def or_na(value, fmt: str = ".0f") -> str:
    return "n/a" if value is None else format(value, fmt)


def load_now() -> str:
    return "load average " + " / ".join(f"{v:.2f}" for v in os.getloadavg()) + " (1 / 5 / 15 min)"


def kernel_cache_stats() -> dict:
    """numba's on-disk cache hits and misses (= compilations) of the batch drivers in this process: ``run_slot``
    since 2026-12-02 (threads over one driver), ``run_serial`` and ``run_parallel`` in older checkouts."""
    from crosscert.verifier.compiled import step as kernels

    out = {"drivers": {}}
    for name in ("run_slot", "run_serial", "run_parallel"):
        if hasattr(kernels, name):
            st = getattr(kernels, name).stats
            out["drivers"][name] = dict(hits=int(sum(st.cache_hits.values())), misses=int(sum(st.cache_misses.values())))
            out["cache_dir"] = str(st.cache_path)
    return out


def _drivers(k: dict) -> str:
    """``name hits/misses`` of each driver of :func:`kernel_cache_stats`."""
    return ", ".join(f"{name} {v['hits']}/{v['misses']}" for name, v in k["drivers"].items())


def load_kernels(model) -> float:
    """Compile or load the compiled step drivers (serial and parallel) on a throw-away run; seconds."""
    box = tuple(np.asarray(v, dtype=np.float64) for v in DEXTAR.x_bounds)
    q = np.zeros((2, 2, DEXTAR.n))
    t0 = time.perf_counter()
    track_batch(model, q[:1], settings(), box, backend="compiled")  # B = 1: serial driver
    track_batch(model, q, settings(), box, backend="compiled")  # B = 2: parallel driver
    return time.perf_counter() - t0


# --- part 1: latency of Tracker.update, one scenario ----------------------------
def update_latencies(model, run, x0, backend: str) -> dict:
    """Feed ``run`` to a fresh online Tracker one reading at a time; latency of every update (us)."""
    tr = Tracker(model, settings(), x0, backend=backend)
    K = run.n_samples
    readings = np.array(run.q_meas)  # writable, like readings parsed from a stream (see first_update_readonly)
    lat = np.empty(K)
    mode = np.zeros(K, np.int64)
    inside_x = inside_xd = True
    for k in range(K):
        q = readings[k]
        t0 = time.perf_counter_ns()
        r = tr.update(q)
        lat[k] = (time.perf_counter_ns() - t0) / 1e3
        mode[k] = r.mode
        inside_x &= bool(np.all((r.x[0] <= run.x_true[k]) & (run.x_true[k] <= r.x[1])))
        if k > 0:  # the velocity box of sample 0 is the prior xd0
            inside_xd &= bool(np.all((r.xd[0] <= run.xd_true[k]) & (run.xd_true[k] <= r.xd[1])))
    st = tr.state
    final = int(st.mode[0]) if st.bad_at[0] < 0 else 0
    return dict(lat=lat, mode=mode, inside_x=inside_x, inside_xd=inside_xd,
                verdict=str(verdict_of(int(st.init_mode[0]), final, st.bad_at[0] >= 0)),
                certified_at=int(st.streak[0]) if final else -1)


def first_update_readonly(model, run, x0) -> float:
    """Latency (us) of a first compiled update whose reading is a view of a read-only array.

    ``SimulatedRun.q_meas`` is read-only; numba specialises the step driver
    on the array's writeability, so the first such call in a process loads
    (or compiles) a second version of the kernel.  Meaningful only as the
    first read-only call of the process.
    """
    q = run.q_meas[0]
    tr = Tracker(model, settings(), x0, backend="compiled")
    t0 = time.perf_counter_ns()
    tr.update(q)
    return (time.perf_counter_ns() - t0) / 1e3


def latency_stats(lat: np.ndarray, mode: np.ndarray) -> dict:
    """Statistics of latencies ``(runs, K)`` us; after warm-up = samples 1..K-1 of every run."""
    body = lat[:, 1:]
    far, near = mode[1:] != 0, mode[1:] == 0

    def mean(v):
        return float(v.mean()) if v.size else float("nan")

    return dict(
        runs=int(lat.shape[0]), samples=int(lat.shape[1]),
        mean_us=mean(body), p50_us=float(np.percentile(body, 50)), p99_us=float(np.percentile(body, 99)),
        max_us=float(body.max()), sample0_us=float(lat[:, 0].max()), max_incl0_us=float(lat.max()),
        rtf=float(1e3 * REAL_TIME_STEP_MS / mean(body)),
        far_samples=int(far.sum()), far_mean_us=mean(body[:, far]),
        near_samples=int(near.sum()), near_mean_us=mean(body[:, near]),
    )


def bench_latency(model, kin, backends, quick: bool) -> dict:
    rows, readonly = [], None
    say("  Tracker.update on one scenario, time.perf_counter_ns around each call; mean, p50, p99 and 'max' over "
        "samples 1..K-1 (after warm-up: sample 0 excluded), 'max incl. 0' includes sample 0; RTF = 1 ms / mean")
    say(f"  {'recording':<22}{'backend':<10}{'runs':>5}{'K':>6}{'mean us':>10}{'p50 us':>9}{'p99 us':>10}"
        f"{'max us':>10}{'sample 0':>10}{'max incl. 0':>13}{'RTF':>8}{'far us':>9}{'near us':>10}  verdict")
    for label, t_rest in (("crossing", T_REST), (f"{T_REST_LONG:g} s rest + crossing", T_REST_LONG)):
        run = simulate(kin, 0, t_rest)
        t0 = time.perf_counter()
        x0 = initial_box_from_mode(model, run.q_meas[0], int(run.mode_true[0]), settings())
        t_box = time.perf_counter() - t0
        if "compiled" in backends and readonly is None:
            readonly = first_update_readonly(model, run, x0)
            say(f"    (first compiled update of a read-only reading, q_meas[0] of the simulated run: {readonly:.0f} us; numba "
                f"specialises the driver on writeability. Below, readings are writable copies)")
        for backend in backends:
            if backend == "compiled":
                runs = 3 if quick else 5
            else:  # the reference takes ~10-20 ms per sample
                runs = 1 if (quick or t_rest > 1.0) else 3
            outs = [update_latencies(model, run, x0, backend) for _ in range(runs)]
            lat = np.array([o["lat"] for o in outs])
            r = dict(recording=label, backend=backend, t_rest_s=t_rest, k_sing=int(run.k_sing),
                     initial_box_ms=1e3 * t_box, **latency_stats(lat, outs[0]["mode"]),
                     verdict=outs[0]["verdict"], certified_at=outs[0]["certified_at"],
                     true_pose_inside=all(o["inside_x"] for o in outs),
                     true_velocity_inside=all(o["inside_xd"] for o in outs))
            rows.append(r)
            say(f"  {label:<22}{backend:<10}{r['runs']:>5}{r['samples']:>6}{r['mean_us']:>10.1f}{r['p50_us']:>9.1f}"
                f"{r['p99_us']:>10.1f}{r['max_us']:>10.1f}{r['sample0_us']:>10.1f}{r['max_incl0_us']:>13.1f}"
                f"{r['rtf']:>8.2f}{r['far_mean_us']:>9.1f}{r['near_mean_us']:>10.1f}  {r['verdict']} "
                f"(certified at {r['certified_at']}); truth inside: pose {r['true_pose_inside']}, "
                f"velocity {r['true_velocity_inside']}")
        say(f"    ({label}: singular instant at sample {run.k_sing}; initial box {1e3 * t_box:.1f} ms, not included; "
            f"near = {rows[-1]['near_samples']} samples without a certified mode)")
    return dict(rows=rows, first_update_readonly_us=readonly)


# --- part 2: cold start (compiled) ------------------------------------------------
def start_child() -> dict:
    """First calls in this (fresh) process, then warm ones; run with or without a numba cache on disk."""
    t_import = time.perf_counter() - _T_START  # this script's imports: numpy, planner, robots, verifier
    kin = KinematicModel(DEXTAR)
    model = IntervalModel(DEXTAR)
    s = settings()
    run = simulate(kin, 0)
    mode0 = int(run.mode_true[0])

    def timed(fn):
        t0 = time.perf_counter()
        out = fn()
        return time.perf_counter() - t0, out

    t_box, x0 = timed(lambda: initial_box_from_mode(model, run.q_meas[0], mode0, s))
    t_track, res = timed(lambda: track(model, run.q_meas, s, x0=x0, backend="compiled"))
    q2 = np.stack([run.q_meas, run.q_meas])
    t_batch, _ = timed(lambda: track_batch(model, q2, s, x0, backend="compiled"))  # B = 2: parallel driver
    warm_box = [timed(lambda: initial_box_from_mode(model, run.q_meas[0], mode0, s))[0] for _ in range(3)]
    warm_track = [timed(lambda: track(model, run.q_meas, s, x0=x0, backend="compiled"))[0] for _ in range(3)]
    warm_batch = [timed(lambda: track_batch(model, q2, s, x0, backend="compiled"))[0] for _ in range(3)]
    return dict(cache_dir_env=os.environ.get("NUMBA_CACHE_DIR"), samples=int(run.n_samples), import_s=t_import,
                first_initial_box_s=t_box, first_track_s=t_track, first_batch2_s=t_batch,
                warm_initial_box_s=float(np.median(warm_box)),
                warm_track_s=float(np.median(warm_track)), warm_batch2_s=float(np.median(warm_batch)),
                verdict=str(res.verdict), kernels=kernel_cache_stats())


def run_child(args: list, env_extra: dict | None = None, drop_env=()) -> tuple[dict | None, float, float, str]:
    """Run this script with ``args`` in a fresh interpreter; its last stdout line (JSON), wall s, CPU s, stderr."""
    env = {k: v for k, v in os.environ.items() if k not in drop_env}
    env.update(env_extra or {})
    cmd = [sys.executable, str(Path(__file__).resolve())] + [str(a) for a in args]
    c0, t0 = children_cpu_s(), time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall, cpu = time.perf_counter() - t0, children_cpu_s() - c0
    if p.returncode != 0 or not p.stdout.strip():
        return None, wall, cpu, p.stderr
    return json.loads(p.stdout.strip().splitlines()[-1]), wall, cpu, p.stderr


def bench_start() -> dict:
    out = {}
    say("  each row is a fresh process running this script; 'first' = first call in the process, "
        "'warm' = median of 3 later calls")
    say(f"  {'numba cache':<34}{'process s':>10}{'imports s':>10}{'1st box s':>10}{'1st track s':>12}"
        f"{'1st batch B=2 s':>16}{'warm track s':>13}{'warm box s':>11}  kernels (driver cache hits/misses)")
    tmp = tempfile.mkdtemp(prefix="crosscert-numba-cold-")
    try:
        cases = (("empty (cold: compiles)", dict(NUMBA_CACHE_DIR=tmp), ()),
                 ("on disk (first call after install)", None, ("NUMBA_CACHE_DIR",)))
        for label, extra, drop in cases:
            r, wall, cpu, err = run_child(["--start-child"], extra, drop)
            if r is None:
                say(f"  !! start-up child ({label}) failed:\n{err}")
                continue
            r.update(process_wall_s=wall, process_cpu_s=cpu)
            out["cold" if extra else "cached"] = r
            k = r["kernels"]
            say(f"  {label:<34}{wall:>10.1f}{r['import_s']:>10.2f}{r['first_initial_box_s']:>10.2f}"
                f"{r['first_track_s']:>12.2f}{r['first_batch2_s']:>16.2f}{r['warm_track_s']:>13.4f}"
                f"{r['warm_initial_box_s']:>11.4f}  {_drivers(k)}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if "cold" in out and "cached" in out:
        c, d = out["cold"], out["cached"]
        say(f"  first track() of the {c['samples']}-sample crossing: cold {c['first_track_s']:.2f} s, "
            f"cache on disk {d['first_track_s']:.2f} s, warm {d['warm_track_s']:.4f} s "
            f"(+ first parallel batch: cold {c['first_batch2_s']:.2f} s, cache {d['first_batch2_s']:.2f} s)")
        if any(v["misses"] for v in d["kernels"]["drivers"].values()):
            say("  !! the 'on disk' child compiled a driver: the cache in the source tree was stale "
                "(the kernel sources changed since it was written)")
    return out


# --- part 3: batched throughput -----------------------------------------------
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


def bench_batch(model, pool, plan) -> list:
    """``plan``: (backend, B, K) triples."""
    runs, q, lo, hi = pool
    s = settings()
    out = []
    say(f"  {'backend':<10}{'B':>6}{'K':>6}{'distinct':>9}{'wall s':>9}{'CPU s':>8}{'ms/batch step':>15}"
        f"{'scen-steps/s':>14}{'per CPU-s':>11}  verdicts")
    for backend, B, K in plan:
        idx = np.arange(B) % len(runs)  # tile the pool when B exceeds it
        c0, t0 = time.process_time(), time.perf_counter()
        res = track_batch(model, q[idx, :K], s, (lo[idx], hi[idx]), record=False, backend=backend)
        el = time.perf_counter() - t0
        cpu = time.process_time() - c0  # every thread of this process
        counts = verdict_counts(res.verdict)
        bad = np.nonzero(res.inconsistent_at_step >= 0)[0]
        row = dict(backend=backend, B=B, K=K, distinct=int(min(B, len(runs))), wall_s=el, cpu_s=cpu,
                   ms_per_batch_step=1e3 * el / K, scenario_steps_per_s=B * K / el,
                   scenario_steps_per_cpu_s=B * K / cpu, verdicts=counts,
                   inconsistent=[dict(scenario=int(b), seed=int(idx[b]) + 1, step=int(res.inconsistent_at_step[b]),
                                      k_sing=int(runs[idx[b]].k_sing), xi_true=runs[idx[b]].xi_true.tolist())
                                 for b in bad])
        out.append(row)
        say(f"  {backend:<10}{B:>6}{K:>6}{row['distinct']:>9}{el:>9.2f}{cpu:>8.2f}{row['ms_per_batch_step']:>15.2f}"
            f"{row['scenario_steps_per_s']:>14.0f}{row['scenario_steps_per_cpu_s']:>11.0f}  {counts}")
        for r in row["inconsistent"]:
            say(f"    !! INCONSISTENT: scenario {r['scenario']} (seed {r['seed']}) at sample {r['step']} "
                f"(singular instant {r['k_sing']}), xi_true = {r['xi_true']}")
        expected = Verdict.MODE_CHANGED.value if K > max(r.k_sing for r in runs) + 40 else None
        if expected and counts.get(expected, 0) != B:
            say(f"    !! expected every scenario to be {expected} after {K} samples, got {counts}")
    return out


# --- part 4: memory of a streamed run (child process) ---------------------------
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


def steady_rate(stamps: list, first: int):
    """Samples per wall and CPU second after sample ``first``, from ``(k, wall, cpu)`` stamps.

    The compiled backend calls ``progress`` once per sample at the end of each
    block of samples, back to back; a block ends where the next stamp comes
    much later (more than 1 ms and 5 % of the longest gap: a pause of the
    process inside the back-to-back calls is much shorter than a block).  The window
    starts at the end of the first block that reaches sample ``first - 1``;
    None when no block follows it.
    """
    ks = np.array([s[0] for s in stamps])
    ts = np.array([s[1] for s in stamps])
    cs = np.array([s[2] for s in stamps])
    gaps = np.diff(ts)
    if gaps.size == 0:
        return None, None, None
    block_end = np.append(gaps > max(0.05 * gaps.max(), 1e-3), False)  # the last stamp ends the run
    cand = np.nonzero(block_end & (ks >= first - 1))[0]
    if cand.size == 0:
        return None, None, None
    a = int(cand[0])
    n = len(ks) - 1 - a
    return n / (ts[-1] - ts[a]), n / (cs[-1] - cs[a]), int(ks[a]) + 1


def memory_child(B: int, K: int, backend: str) -> dict:
    model = IntervalModel(DEXTAR)
    kin = KinematicModel(DEXTAR)
    s = settings()
    run = simulate(kin, 0)
    k_rest = int(np.argmax(np.any(run.x_true != run.x_true[0], axis=1)))  # samples at rest before the motion
    q_rest = np.array(run.q_true[0])
    # encloses the pose for every q within eps_q of the true joints: contains the true pose
    x0 = initial_box_from_mode(model, q_rest, int(run.mode_true[0]), s)
    # load the kernels (or warm numpy) on a tiny run first: the traced run measures the tracking alone
    track_batch(model, rest_stream(2, 2, q_rest, DEXTAR.eps_q), s, x0, record=False, backend=backend)
    stream = rest_stream(B, K, q_rest, DEXTAR.eps_q)
    base_rss = rss_mib()
    base_hwm = proc_status_mib("VmHWM")
    base_cur = proc_status_mib("VmRSS")
    stamps = []
    tracemalloc.start()
    tracemalloc.reset_peak()
    c0, t0 = time.process_time(), time.perf_counter()

    def tick(k):
        stamps.append((k, time.perf_counter(), time.process_time()))

    res = track_batch(model, stream, s, x0, record=False, progress=tick, backend=backend)
    el = time.perf_counter() - t0
    cpu = time.process_time() - c0
    cur, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    first = 2 * max(s.baselines)  # after the window of the velocity baselines has filled
    thr, thr_cpu, steady_from = steady_rate(stamps, first)
    bad = np.nonzero(res.inconsistent_at_step >= 0)[0]
    return dict(
        backend=backend, B=B, K=K, rest_samples_in_crossing=k_rest, wall_s=el, cpu_s=cpu,
        scenario_steps_per_s=B * K / el, scenario_steps_per_cpu_s=B * K / cpu,
        steady_scenario_steps_per_s=None if thr is None else B * thr,
        steady_scenario_steps_per_cpu_s=None if thr_cpu is None else B * thr_cpu,
        steady_from_step=steady_from,
        tracemalloc_peak_mib=peak / 2**20, tracemalloc_end_mib=cur / 2**20,
        maxrss_before_mib=base_rss, maxrss_after_mib=rss_mib(),
        vmrss_before_mib=base_cur, vmhwm_before_mib=base_hwm, vmhwm_after_mib=proc_status_mib("VmHWM"),
        verdicts=verdict_counts(res.verdict),
        inconsistent=[dict(scenario=int(b), step=int(res.inconsistent_at_step[b])) for b in bad[:20]],
        n_inconsistent=int(bad.size),
        max_width_pose_m=float(res.max_width_pose.max()),
        max_width_velocity_mps=float(res.max_width_velocity.max()),
    )


def bench_memory(B: int, plan) -> list:
    """``plan``: (backend, K) pairs, each run in its own child process."""
    rows = []
    say(f"  streamed rest-pose readings (SampleStream), record=False, B = {B}, each run in its own process; "
        f"steady = after the velocity baselines' window has filled")
    say(f"  {'backend':<10}{'K':>6}{'wall s':>9}{'CPU s':>9}{'tracemalloc peak MiB':>22}{'RSS before MiB':>16}"
        f"{'VmHWM after MiB':>17}{'growth MiB':>12}{'ru_maxrss MiB':>15}{'scen-steps/s':>14}{'steady /s':>11}"
        f"{'steady /CPU-s':>15}  verdicts")
    for backend, K in plan:
        r, wall, cpu, err = run_child(["--memory-child", B, K, backend])
        if r is None:
            say(f"  !! child for {backend}, K={K} failed:\n{err}")
            continue
        rows.append(r)
        growth = r["vmhwm_after_mib"] - r["vmrss_before_mib"]
        say(f"  {backend:<10}{K:>6}{r['wall_s']:>9.1f}{r['cpu_s']:>9.1f}{r['tracemalloc_peak_mib']:>22.1f}"
            f"{r['vmrss_before_mib']:>16.1f}{r['vmhwm_after_mib']:>17.1f}{growth:>12.1f}{r['maxrss_after_mib']:>15.1f}"
            f"{r['scenario_steps_per_s']:>14.0f}{or_na(r['steady_scenario_steps_per_s']):>11}"
            f"{or_na(r['steady_scenario_steps_per_cpu_s']):>15}  {r['verdicts']}")
        say(f"    peak RSS under 1 GiB: {'yes' if r['maxrss_after_mib'] < 1024 else 'NO'} "
            f"(child process: {wall:.1f} s wall, {cpu:.1f} CPU-s in all, model build and warm-up included)")
        if r["n_inconsistent"]:
            say(f"    !! {r['n_inconsistent']} scenario(s) INCONSISTENT at rest, first: {r['inconsistent']}")
    return rows


def extrapolate(rows: list, batch: list) -> dict:
    """From the streamed runs of one backend to BIG = 10^4 scenarios x 10^4 samples."""
    if not rows:
        return {}
    backend, B = rows[0]["backend"], rows[0]["B"]
    a, b = rows[0], rows[-1]
    Bb, Kb = BIG
    scale = Bb / B
    rate = b["steady_scenario_steps_per_s"] or b["scenario_steps_per_s"]
    rate_cpu = b["steady_scenario_steps_per_cpu_s"] or b["scenario_steps_per_cpu_s"]
    crossing = [r for r in batch if r["backend"] == backend]
    big = max(crossing, key=lambda r: r["B"]) if crossing else None
    out = dict(backend=backend, measured_K=[r["K"] for r in rows],
               per_scenario_kib=b["tracemalloc_peak_mib"] * 1024 / B,
               est_traced_mib=b["tracemalloc_peak_mib"] * scale,
               est_rss_mib=(b["vmhwm_after_mib"] - b["vmrss_before_mib"]) * scale + b["vmrss_before_mib"],
               est_time_h_rest=Bb * Kb / rate / 3600, est_cpu_h_rest=Bb * Kb / rate_cpu / 3600,
               est_time_h_crossing=Bb * Kb / big["scenario_steps_per_s"] / 3600 if big else None,
               est_cpu_h_crossing=Bb * Kb / big["scenario_steps_per_cpu_s"] / 3600 if big else None,
               B_crossing=big["B"] if big else None)
    if len(rows) > 1:
        out["peak_ratio"] = b["tracemalloc_peak_mib"] / a["tracemalloc_peak_mib"]
        out["rss_growth_ratio"] = ((b["vmhwm_after_mib"] - b["vmrss_before_mib"])
                                   / max(a["vmhwm_after_mib"] - a["vmrss_before_mib"], 1e-9))
        say(f"  {backend}: tracemalloc peak K={b['K']} / K={a['K']}: {out['peak_ratio']:.3f}; RSS growth "
            f"(VmHWM after - RSS before) K={b['K']} / K={a['K']}: {out['rss_growth_ratio']:.3f}")
    if (B, b["K"]) == BIG:
        say(f"  {backend}: {Bb:.0e} scenarios x {Kb:.0e} samples measured directly (above)")
        return out
    say(f"  {backend}: {Bb:.0e} scenarios x {Kb:.0e} samples, streamed, extrapolated from K = {b['K']}: "
        f"~{out['est_traced_mib']:.0f} MiB traced peak, ~{out['est_rss_mib']:.0f} MiB peak RSS (the state is O(B), "
        f"the readings are streamed); time {out['est_time_h_rest']:.2f} h wall ({out['est_cpu_h_rest']:.2f} CPU-h) "
        f"at the rest throughput ({rate:.0f} scenario-steps/s)")
    if big:
        say(f"  {' ' * len(backend)}  at the crossing throughput of B={big['B']} (part 3, "
            f"{big['scenario_steps_per_s']:.0f} scenario-steps/s): {out['est_time_h_crossing']:.2f} h wall "
            f"({out['est_cpu_h_crossing']:.2f} CPU-h)")
    block = getattr(tracker_module, "_BLOCK", 256)  # samples per kernel call of the compiled backend
    if backend == "compiled" and b["K"] < 2 * block:
        extra = Bb * block * DEXTAR.n * 8 / 2**20
        say(f"  {backend}: runs of K >= {2 * block} hold one more block of {block} readings while the next is stacked: "
            f"expect up to ~{extra:.0f} MiB more than measured at K = {b['K']}")
    return out


# --- part 5: the command line on a 6.42 s recording ---------------------------------
def crosscert_cmd() -> list:
    """The ``crosscert`` script of this interpreter's environment, else ``python -m crosscert``."""
    script = Path(sys.executable).parent / "crosscert"
    return [str(script)] if script.exists() else [sys.executable, "-m", "crosscert"]


def run_command(cmd, shell: bool = False):
    """Run a command from the repository root; (stdout, wall s, CPU s of the finished children)."""
    c0, t0 = children_cpu_s(), time.perf_counter()
    p = subprocess.run(cmd, shell=shell, cwd=ROOT, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, children_cpu_s() - c0
    if p.returncode not in (0, 3):  # 3: inconsistent verdict, still a measurement
        raise RuntimeError(f"{cmd} failed ({p.returncode}):\n{p.stderr}")
    return p.stdout, wall, cpu


def bench_cli(backends, quick: bool) -> dict:
    cc = crosscert_cmd()
    motion = 199  # samples after the rest of a crossing at V_SING (crosscert simulate's defaults)
    t_rest = (CLI_SAMPLES - motion) * DEXTAR.t_s
    tmp = Path(tempfile.mkdtemp(prefix="crosscert-bench-cli-"))
    has_backend = "--backend" in run_command(cc + ["check", "--help"])[0]
    out = {}
    try:
        csv = tmp / "crossing_6s.csv"
        text, wall, _ = run_command(cc + ["simulate", "--v-sing", str(V_SING), "--t-rest", f"{t_rest:.3f}",
                                          "-o", str(csv)])
        samples = sum(1 for _ in csv.open()) - 1
        say(f"  recording: crosscert simulate --v-sing {V_SING} --t-rest {t_rest:.3f} -> {samples} samples "
            f"({samples * DEXTAR.t_s:.2f} s at 1 kHz); {text.strip()}")
        say("  whole commands, each a fresh process with the numba cache on disk (interpreter start, imports, "
            "kernel load, reading the CSV, tracking); wall and CPU: median of the runs")
        for backend in backends:
            if not has_backend and backend != "compiled":
                say(f"  ({backend}: this crosscert has no --backend option; skipped)")
                continue
            opt = ["--backend", backend] if has_backend else []
            repeats = 1 if (quick or backend == "numpy") else 3
            check = [run_command(cc + ["check", str(csv), "--initial-mode", "1", "--json", "--no-progress"] + opt)
                     for _ in range(repeats)]
            walls = [w for _, w, _ in check]
            wall, cpu = float(np.median(walls)), float(np.median([c for _, _, c in check]))
            js = json.loads(check[0][0].strip().splitlines()[-1])
            c = dict(backend=backend, samples=samples, runs=repeats, wall_s=wall, cpu_s=cpu, walls_s=walls,
                     us_per_sample=1e6 * wall / samples, tracking_elapsed_s=js["elapsed_s"],
                     tracking_us_per_sample=1e6 * js["elapsed_s"] / samples, verdict=js["verdict"],
                     certified_at_step=js["certified_at_step"])
            out[f"check_{backend}"] = c
            say(f"  crosscert check {csv.name} --initial-mode 1 --json {' '.join(opt)}: {c['wall_s']:.2f} s wall, "
                f"{c['cpu_s']:.2f} CPU-s ({repeats} run(s)) = {c['us_per_sample']:.0f} us per sample for the whole "
                f"command; track() inside: {c['tracking_elapsed_s']:.2f} s = {c['tracking_us_per_sample']:.0f} us per "
                f"sample (initial box included); verdict {c['verdict']}, certified at {c['certified_at_step']}")
            pipe = (f"cat {shlex.quote(str(csv))} | {' '.join(shlex.quote(x) for x in cc)} monitor --initial-mode 1 "
                    f"--json {' '.join(opt)}")
            mons = [run_command(pipe, shell=True) for _ in range(repeats)]
            summaries = [json.loads(t.strip().splitlines()[-1]) for t, _, _ in mons]
            mid = int(np.argsort([w for _, w, _ in mons])[len(mons) // 2])  # the run of median wall time
            js, (text, wall, cpu) = summaries[mid], mons[mid]
            events = [json.loads(line)["event"] for line in text.strip().splitlines()[:-1]]
            m = dict(backend=backend, samples=samples, runs=repeats, wall_s=wall, cpu_s=cpu,
                     us_per_sample=1e6 * wall / samples, latency_us_mean=js["latency_us_mean"],
                     latency_us_p99=js["latency_us_p99"], latency_us_max=js["latency_us_max"],
                     verdict=js["verdict"], steps=js["steps"], events=events,
                     all_runs=[{k: v[k] for k in ("latency_us_mean", "latency_us_p99", "latency_us_max")}
                               for v in summaries])
            out[f"monitor_{backend}"] = m
            say(f"  cat {csv.name} | crosscert monitor --initial-mode 1 --json {' '.join(opt)}: {m['wall_s']:.2f} s wall, "
                f"{m['cpu_s']:.2f} CPU-s (run of median wall time) = {m['us_per_sample']:.0f} us per sample; update "
                f"latency (its final JSON line): mean {m['latency_us_mean']} us, p99 {m['latency_us_p99']} us, max "
                f"{m['latency_us_max']} us; {m['steps']} steps, verdict {m['verdict']}, events {m['events']}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out


def code_version() -> dict:
    """Git commit of the tree being measured and a hash of the code the benchmark imports."""
    import hashlib

    h = hashlib.sha256()
    for pkg in ("verifier", "verifier/compiled", "planner", "robots"):
        for f in sorted((ROOT / pkg).glob("*.py")):
            h.update(f"{pkg}/{f.name}".encode())
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
    import numba

    return dict(date=datetime.date.today().isoformat(), cpu=cpu, cores=os.cpu_count(),
                python=platform.python_version(), numpy=np.__version__, casadi=casadi.__version__,
                numba=numba.__version__, numba_threads=numba.get_num_threads(), **code_version())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="reduced sizes (see benchmarks/README.md)")
    ap.add_argument("--backend", choices=("compiled", "numpy", "both"), default="both")
    ap.add_argument("--only", nargs="+", choices=PARTS, metavar="PART",
                    help=f"run only these parts ({', '.join(PARTS)})")
    ap.add_argument("--stream-k", type=int, metavar="K",
                    help=f"samples of the compiled streamed run of part 4 (default 300 quick, {BIG[1]} full)")
    ap.add_argument("--json", metavar="PATH", help="also write the numbers as JSON")
    ap.add_argument("--memory-child", nargs=3, metavar=("B", "K", "BACKEND"), help=argparse.SUPPRESS)
    ap.add_argument("--start-child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.memory_child:
        B, K, backend = args.memory_child
        print(json.dumps(memory_child(int(B), int(K), backend)))
        return 0
    if args.start_child:
        print(json.dumps(start_child()))
        return 0

    backends = BACKENDS if args.backend == "both" else (args.backend,)
    parts = args.only or PARTS
    t_all = time.perf_counter()
    load0 = os.getloadavg()
    info = machine()
    say(f"crosscert tracker benchmark ({'quick' if args.quick else 'full'}), {info['date']}; backends: "
        f"{', '.join(backends)}; parts: {', '.join(parts)}")
    say(f"  {info['cpu']}, {info['cores']} cores; Python {info['python']}, numpy {info['numpy']}, "
        f"casadi {info['casadi']}, numba {info['numba']} ({info['numba_threads']} threads); BLAS threads forced to 1")
    say(f"  code: commit {info['commit']}, verifier/planner/robots sha256 {info['code_sha256']}")
    say(f"  DexTAR crossing at v_sing = {V_SING} m/s, t_rest = {T_REST} s, cruise = {cruise_for(V_SING) * 1e3:.2f} mm, "
        f"t_s = {DEXTAR.t_s} s, eps_q = {DEXTAR.eps_q:.3e} rad, a_max = {DEXTAR.a_max}, xd0 = {DEXTAR.xd0}, "
        f"{settings().validated(DEXTAR.n).xi_splits} geometry splits")
    say(f"  {load_now()}")
    t0 = time.perf_counter()
    model = IntervalModel(DEXTAR)
    kin = KinematicModel(DEXTAR)
    say(f"  model build: {time.perf_counter() - t0:.2f} s")
    result = dict(machine=info, quick=args.quick, backends=list(backends), parts=list(parts), loadavg_start=load0[0])
    if "compiled" in backends:
        t_load = load_kernels(model)
        result["kernel_load_s"] = t_load
        result["kernel_cache"] = kernel_cache_stats()
        k = result["kernel_cache"]
        say(f"  compiled kernels ready in this process in {t_load:.2f} s (driver cache hits/misses: "
            f"{_drivers(k)}; cache {k['cache_dir']}); not included below")

    if "latency" in parts:
        say(f"\n[1] latency of Tracker.update, one scenario (nominal geometry), one thread; {load_now()}")
        result["latency"] = bench_latency(model, kin, backends, args.quick)

    if "start" in parts and "compiled" in backends:
        say(f"\n[2] start-up of the compiled backend: cold (empty numba cache), cache on disk, warm; {load_now()}")
        result["start"] = bench_start()

    batch = []
    if "batch" in parts:
        say(f"\n[3] track_batch throughput (record=False), random true geometries; {load_now()}")
        pool = build_pool(model, kin, 100 if args.quick else 1000)
        K = pool[1].shape[1]
        plan = [(b, B, K) for b in backends for B in ((1, 100, 1000) if b == "compiled" else (1, 100))]
        batch = bench_batch(model, pool, plan)
        result["batch"] = batch

    if "memory" in parts:
        k_compiled = args.stream_k or (300 if args.quick else BIG[1])
        k_numpy = (20, 80) if args.quick else (50, 200)
        plan = [(b, K) for b in backends for K in ((k_compiled,) if b == "compiled" else k_numpy)]
        say(f"\n[4] memory of a streamed batched run, B = {BIG[0]}, "
            + ", ".join(f"{b} K = {' and '.join(str(k) for b2, k in plan if b2 == b)}" for b in backends)
            + f"; {load_now()}")
        mem = bench_memory(BIG[0], plan)
        result["memory"] = mem
        result["extrapolation"] = [extrapolate([r for r in mem if r["backend"] == b], batch) for b in backends]

    if "cli" in parts:
        say(f"\n[5] crosscert check and crosscert monitor on a {CLI_SAMPLES * DEXTAR.t_s:.2f} s recording; {load_now()}")
        result["cli"] = bench_cli(backends, args.quick)

    total = time.perf_counter() - t_all
    after = code_version()
    if after["code_sha256"] != info["code_sha256"]:
        say(f"\n!! the measured code changed during the run (now commit {after['commit']}, "
            f"sha256 {after['code_sha256']}): child processes may have run different code")
    say(f"\ntotal wall time: {total:.0f} s; load average at start {load0[0]:.2f}, at end {os.getloadavg()[0]:.2f} "
        f"(on {os.cpu_count()} cores: a load above ~1 means other processes competed; compare wall and CPU times)")
    result.update(total_s=total, loadavg_end=os.getloadavg()[0], code_after=after)
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
