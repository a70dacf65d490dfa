"""The current figures of benchmarks/README.md: measured on this machine, written into its "Current figures" block.

Each figure runs one benchmark of this folder, or one ``crosscert`` command, the way its "reproduce" column
says; the block names the machine (CPU, cores, load average), the date and the commit measured.  Nothing is
asserted: a figure is a number printed, never a pass or a fail.

Run (the kernels compiled once first; about 5-10 minutes on 2 cores)::

    python benchmarks/figures.py                      # every figure; rewrites the block of benchmarks/README.md
    python benchmarks/figures.py --only certify,check # some figures, printed only (the block stays whole)
    python benchmarks/figures.py --online-geometries 3

Measure on an otherwise idle machine: the load average at the start and the end is printed in the block.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
README = HERE / "README.md"
BEGIN, END = "<!-- figures:begin -->", "<!-- figures:end -->"
sys.path.insert(0, str(HERE))


def crosscert_cmd() -> list:
    """The ``crosscert`` command of this interpreter (:func:`bench_tracker.crosscert_cmd`)."""
    import bench_tracker  # imported when measuring only: it pins BLAS to one thread for its process

    return bench_tracker.crosscert_cmd()


def machine() -> dict:
    """CPU, cores, versions and commit (:func:`bench_tracker.machine`, one reading for the benchmarks)."""
    import bench_tracker

    return bench_tracker.machine()


def _timed(cmd: list[str]) -> dict:
    """Run ``cmd`` from the repository root: its wall time (s) and standard output."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = p.communicate()
    wall = time.perf_counter() - t0
    if p.returncode not in (0, 3):
        raise RuntimeError(f"{' '.join(cmd)} failed ({p.returncode}): {err.strip().splitlines()[-1:]}")
    return {"wall_s": wall, "stdout": out}


def _children() -> tuple[float, float]:
    """CPU s (user + system) of every finished child so far, and the largest peak resident MiB among them."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime, r.ru_maxrss / 1024.0


def _bench(script: str, *args: str) -> dict:
    """Run ``benchmarks/script`` with ``--json`` and return what it wrote."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.json"
        _timed([sys.executable, str(HERE / script), *args, "--json", str(out)])
        return json.loads(out.read_text())


# --- the figures: each returns rows (figure, value) ------------------------------------------------------------------
def certify(_args) -> list[tuple[str, str]]:
    cc = crosscert_cmd()
    with tempfile.TemporaryDirectory() as tmp:
        _timed(cc + ["certify", "--no-progress", "--monte-carlo", "0", "--out", str(Path(tmp) / "warm")])
        cpu0, _ = _children()
        r = _timed(cc + ["certify", "--no-progress", "--out", str(Path(tmp) / "c")])
        cpu1, peak = _children()
        cert = json.loads((Path(tmp) / "c" / "certificate.json").read_text())
    v, bound = cert["v_min_mps"], cert["refutation_bound_mps"]
    mc = cert["monte_carlo"]
    ratio = f", ratio {v / bound:.3f}" if v and bound else ""
    covered = mc.get("covered_at_run_time")
    return [
        ("`crosscert certify`, warm: wall / CPU / peak memory",
         f"{r['wall_s']:.1f} s / {cpu1 - cpu0:.1f} CPU-s / {peak:.0f} MiB"),
        ("`crosscert certify`: `v_min`, refutation bound", f"{v:.4f} m/s, {bound:.4f} m/s{ratio}"),
        ("`crosscert certify`: Monte Carlo at `v_min` decided by the tracker / covered by the envelope",
         f"{mc['detected_in_class']}/{mc['in_class']} / "
         f"{'not checked' if covered is None else str(covered) + '/' + str(mc['runs'])}; "
         f"{len(mc['containment_failures'])} containment failures, {len(mc['wrong_verdicts'])} wrong verdicts"),
    ]


def check(_args) -> list[tuple[str, str]]:
    cc = crosscert_cmd()
    with tempfile.TemporaryDirectory() as tmp:
        csv = str(Path(tmp) / "crossing.csv")
        _timed(cc + ["simulate", "--v-sing", "1.458", "-o", csv])
        _timed(cc + ["check", csv, "--initial-mode", "1", "--no-progress"])  # kernels loaded from the cache once
        r = _timed(cc + ["check", csv, "--initial-mode", "1", "--json", "--no-progress"])
        _timed(cc + ["sweep", "--no-progress", "--out", str(Path(tmp) / "sweep0")])  # its own kernels, once
        sweep = _timed(cc + ["sweep", "--no-progress", "--out", str(Path(tmp) / "sweep")])
    verdict = json.loads(r["stdout"].strip().splitlines()[-1])["verdict"]
    return [("`crosscert check crossing.csv --initial-mode 1` (1.458 m/s simulated), whole command",
             f"{r['wall_s']:.2f} s ({verdict})"),
            ("`crosscert sweep`, whole command", f"{sweep['wall_s']:.1f} s")]


def tracker(_args) -> list[tuple[str, str]]:
    js = _bench("bench_tracker.py", "--quick", "--backend", "compiled", "--only", "latency", "batch")
    lat = next(r for r in js["latency"]["rows"] if r["t_rest_s"] < 1.0)
    b1000 = next(r for r in js["batch"] if r["B"] == 1000)
    return [("`Tracker.update`, 1.458 m/s crossing: mean / p99 / max",
             f"{lat['mean_us']:.1f} / {lat['p99_us']:.1f} / {lat['max_us']:.0f} µs"),
            ("`track_batch`, B = 1000, scenario-steps per wall s",
             f"{b1000['scenario_steps_per_s'] / 1e3:.0f} k ({b1000['scenario_steps_per_cpu_s'] / 1e3:.0f} k per CPU-s)")]


def window(args) -> list[tuple[str, str]]:
    import numpy as np
    from bench_window import crossing, true_geometries

    from crosscert.robots import DEXTAR
    from crosscert.verifier import IntervalModel, TrackerSettings
    from crosscert.verifier.window import track_window

    im, s = IntervalModel(DEXTAR), TrackerSettings.for_robot(DEXTAR)
    runs = [crossing(1.0, xi).q_meas for xi in true_geometries(args.window_geometries)]
    track_window(im, runs[0], s, initial_mode=1)  # warm
    per = {"undecided": [], "decided": []}
    for q in runs:
        t0 = time.perf_counter()
        w = track_window(im, q, s, initial_mode=1)
        per["undecided" if w.verdict.value == "unknown" else "decided"].append((time.perf_counter() - t0) / len(q))
    ms = {k: f"{1e3 * np.mean(v):.2f} ms ({len(v)} runs)" if v else "no run" for k, v in per.items()}
    return [(f"window (`track_window`), 1.0 m/s crossings, {len(runs)} geometries, per sample: undecided / decided",
             f"{ms['undecided']} / {ms['decided']}")]


def given_plan(_args) -> list[tuple[str, str]]:
    js = _bench("bench_given_plan.py")
    a, p, e = js["arc"], js["plan_095"], js["envelope_us"]
    bound = "none found" if a["bound"] is None else f"{a['bound']:.4f} m/s"
    return [
        ("`certify --plan` of `plan --v-sing 0.95`'s file, warm, no Monte Carlo",
         f"{p['wall_s']:.1f} s; `{p['given']}`, as `certify` at 0.95 m/s (`{p['own']}`)"),
        ("`certify --plan --retime`, the 30° arc given at 1.2 m/s",
         f"{a['wall_s']:.1f} s; certifies from {a['v_min']:.4f} m/s, refutation bound {bound}; re-timed plan "
         f"certified again: `{a['again']}`"),
        ("`monitor --certificate`, per sample inside the envelope: mean / max",
         f"{e['mean']:.1f} / {e['max']:.0f} µs ({e['samples']} samples)"),
    ]


def online(args) -> list[tuple[str, str]]:
    js = _bench("bench_online.py", "--geometries", str(args.online_geometries))
    g = js["geometries"]
    speeds = js["speeds"]
    certified = " / ".join(f"{v['online']} of {v['check']}" for v in speeds.values())
    wrong = sum(v["wrong"] for v in speeds.values())
    u, d = js["update_us"], js.get("delay_ms")
    delay = "no run decided" if d is None else f"median {d['median']:.0f} ms, max {d['max']:.0f} ms"
    return [
        (f"`monitor` (anchored window) vs `check`, {' / '.join(speeds)} m/s, {g} geometries each",
         f"{certified} certified online ({wrong} wrong verdicts)"),
        ("`monitor`: decision delay at 1.1 m/s after the true singular sample", delay),
        ("`monitor`: `update` while a window is open, mean / max (the tracker alone on the same samples)",
         f"{u['open_mean']:.0f} µs / {u['open_max'] / 1e3:.1f} ms ({u['alone_mean']:.0f} µs / "
         f"{u['alone_max'] / 1e3:.1f} ms)"),
    ]


def robots(_args) -> list[tuple[str, str]]:
    rows = _bench("bench_robots.py", "--runs", "1")
    return [(f"`Tracker.update`, {r['robot']} (n = {r['n']}, {r['recording']}): mean / p99",
             f"{r['latency_us_mean']:.0f} / {r['latency_us_p99']:.0f} µs") for r in rows]


#: name -> (measure, how to reproduce it by hand)
FIGURES = {
    "certify": (certify, "`crosscert certify` (after one run that compiles); `benchmarks/bench_certify.py` by phase"),
    "check": (check, "`crosscert simulate --v-sing 1.458 -o crossing.csv`, then `crosscert check`; `crosscert sweep`"),
    "tracker": (tracker, "`python benchmarks/bench_tracker.py --quick --backend compiled --only latency batch`"),
    "window": (window, "`python benchmarks/bench_window.py --speed --parts S1`"),
    "given_plan": (given_plan, "`python benchmarks/bench_given_plan.py`"),
    "online": (online, "`python benchmarks/bench_online.py --geometries N`"),
    "robots": (robots, "`python benchmarks/bench_robots.py --runs 1`"),
}


def render(rows: list[tuple[str, str, str]], info: dict, load: tuple[float, float], wall: float) -> str:
    lines = [f"Measured by `python benchmarks/figures.py` on {info['date']}: {info['cpu']}, {info['cores']} cores; "
             f"commit {info['commit']}; Python {info['python']}, numba {info['numba']}; load average "
             f"{load[0]:.2f} at the start, {load[1]:.2f} at the end; {wall / 60:.0f} min in all.", "",
             "| figure | value | reproduce |", "|---|---|---|"]
    lines += [f"| {f} | {v} | {how} |" for f, v, how in rows]
    return "\n".join(lines)


def write_block(text: str, readme: Path = README) -> None:
    """Replace the block between the markers of ``readme`` (a regular file, its mode kept; the rest untouched)."""
    if readme.is_symlink() or not readme.is_file():
        raise SystemExit(f"{readme}: not a regular file")
    old = readme.read_text()
    if BEGIN not in old or END not in old:
        raise SystemExit(f"{readme}: the markers {BEGIN} and {END} are missing")
    head, rest = old.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    tmp = readme.with_suffix(".md.tmp")
    tmp.write_text(f"{head}{BEGIN}\n{text}\n{END}{tail}")
    os.chmod(tmp, readme.stat().st_mode & 0o7777)
    os.replace(tmp, readme)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", help=f"comma-separated figures, printed only: {','.join(FIGURES)}")
    ap.add_argument("--print", action="store_true", help="print the block; leave benchmarks/README.md alone")
    ap.add_argument("--online-geometries", type=int, default=10, help="geometries per speed online (default 10)")
    ap.add_argument("--window-geometries", type=int, default=20, help="geometries of the window figure (default 20)")
    args = ap.parse_args(argv)
    names = list(FIGURES) if not args.only else args.only.split(",")
    unknown = [n for n in names if n not in FIGURES]
    if unknown:
        ap.error(f"unknown figures {unknown}; choose from {','.join(FIGURES)}")
    t0, load0 = time.perf_counter(), os.getloadavg()[0]
    info = machine()
    rows = []
    for name in names:
        measure, how = FIGURES[name]
        print(f"[{name}] ...", flush=True)
        got = measure(args)
        for f, v in got:
            print(f"  {f}: {v}", flush=True)
        rows += [(f, v, how) for f, v in got]
    text = render(rows, info, (load0, os.getloadavg()[0]), time.perf_counter() - t0)
    if args.print or args.only:
        print(text)
    else:
        write_block(text)
        print(f"written to {README}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
