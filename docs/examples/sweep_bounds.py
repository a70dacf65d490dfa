"""Sweep the planning bounds of the DexTAR benchmark crossing: v_min versus a_max and [xi] width.

An example of the optimisation scripts users write around
:func:`planner.certify_crossing`: every case is one (acceleration bound,
calibration width) pair, certified independently, so the cases run in
parallel through :func:`run_cases`, a three-line executor abstraction.

For each case the script computes the minimal certified crossing speed
``v_min`` of the benchmark task (start and goal 60 mm either side of the
nominal singular point along the benchmark direction) with

* ``PlanningBounds(a_max=(a, a))`` — the tracker's acceleration hypothesis;
  the plan's ramp peak ``a_peak`` is lowered to ``a`` when ``a`` is below the
  default 60 m/s^2 (``certify_crossing`` refuses an ``a_max`` below the
  planned peak: "bounds contradict the plan");
* the DexTAR robot whose calibration half-widths are scaled by ``w`` around
  the centre of ``[xi]`` (the centre, hence the plan, is the same for every
  width);

and ``certify_crossing(robot, task, bounds, refute=False,
monte_carlo_runs=0, tol=...)``.  Output: a table on stdout (Markdown), a PNG
of ``v_min`` against ``a_max`` per width and a JSON file of every case, in
``--out``.

Run from the repository root::

    python docs/examples/sweep_bounds.py            # 4 a_max x 3 widths, tol 0.02 m/s
    python docs/examples/sweep_bounds.py --quick    # 2 x 2, tol 0.05 m/s (the test)
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

if importlib.util.find_spec("crosscert") is None:
    sys.exit("sweep_bounds.py: install crosscert first (pip install . in the checkout)")


from crosscert.planner import PlanningBounds, benchmark_task, certify_crossing
from crosscert.planner.study import scaled_box
from crosscert.robots import get_entry

ENTRY = get_entry("dextar")
DEXTAR = ENTRY.robot

#: Default peak acceleration of the planned speed ramps (PlanningBounds.a_peak), m/s^2.
A_PEAK = PlanningBounds().a_peak

FULL_A_MAX = (50.0, 65.0, 80.0, 100.0)
FULL_WIDTHS = (0.5, 1.0, 2.0)
QUICK_A_MAX = (65.0, 100.0)
QUICK_WIDTHS = (1.0, 2.0)


# ------------------------------------------------------------------ executor
def run_cases(fn, cases, executor=None):
    """``[fn(c) for c in cases]``, evaluated in parallel, results in the order of ``cases``.

    Parameters
    ----------
    fn : callable
        A module-level (picklable) function of one case.
    cases : iterable
        The cases; each must be picklable.
    executor : object, optional
        Anything with the :class:`concurrent.futures.Executor` interface.
        Only ``executor.submit(fn, case)`` and the returned futures'
        ``.result()`` are used, so a Dask distributed ``Client`` (whose
        ``submit`` returns futures with ``.result()`` as well) can replace the
        default without changing this function: ``run_cases(fn, cases,
        executor=dask.distributed.Client(...))``.  (``map`` is not used: an
        Executor's ``map`` yields results, a Dask ``Client.map`` returns
        futures.)  The caller owns a given executor and shuts it down.
        Default: a ``ProcessPoolExecutor(max_workers=os.cpu_count())``
        created and shut down here.

    Returns
    -------
    list
        ``fn(case)`` for each case.  The first exception raised by a case is
        re-raised here (let ``fn`` catch what should not stop the sweep).
    """
    cases = list(cases)
    if executor is None:
        with ProcessPoolExecutor(max_workers=os.cpu_count()) as pool:
            return run_cases(fn, cases, pool)
    futures = [executor.submit(fn, c) for c in cases]
    return [f.result() for f in futures]


# ------------------------------------------------------------------ one case
def scaled_robot(width: float, robot=DEXTAR):
    """``robot`` with every half-width of ``[xi]`` scaled by ``width`` around the box centre."""
    if not width > 0:
        raise ValueError(f"width scale must be positive, got {width}")
    return scaled_box(robot, width, width)


def run_case(case: dict) -> dict:
    """Certify one ``{"a_max", "width", "tol"}`` case; returns a JSON-ready dict (never raises)."""
    a, width, tol = float(case["a_max"]), float(case["width"]), float(case["tol"])
    a_peak = min(A_PEAK, a)
    out = {"a_max": a, "width": width, "tol": tol, "a_peak": a_peak, "v_min": None, "verdict": None,
           "trials": 0, "certified_below_v_min": [], "elapsed_s": None, "error": None}
    t0 = time.perf_counter()
    try:
        robot = scaled_robot(width)
        bounds = PlanningBounds(a_max=(a, a), a_peak=a_peak)
        cert = certify_crossing(robot, benchmark_task(ENTRY), bounds, refute=False, monte_carlo_runs=0, tol=tol)
        out["v_min"] = cert.v_min
        out["verdict"] = cert.verdict.value
        out["trials"] = len(cert.trials)
        # certification need not be monotone in the speed: report certified speeds below v_min
        if cert.v_min is not None:
            out["certified_below_v_min"] = [t.v_sing for t in cert.trials
                                            if t.v_sing < cert.v_min and t.verdict.value == "mode-changed"]
    except Exception as exc:  # one bad case must not lose the others
        out["error"] = f"{type(exc).__name__}: {exc}"
    out["elapsed_s"] = time.perf_counter() - t0
    return out


# ------------------------------------------------------------------ report
def _fmt_v(r):
    if r["error"]:
        return "error"
    return "none" if r["v_min"] is None else f"{r['v_min']:.3f}"


def table(results, a_values, widths) -> str:
    """Markdown table: one row per a_max, one v_min column (m/s) per width scale."""
    by = {(r["a_max"], r["width"]): r for r in results}
    head = "| a_max (m/s^2) | a_peak (m/s^2) | " + " | ".join(f"v_min, [xi] x{w:g} (m/s)" for w in widths) + " |"
    rule = "|---|---|" + "---|" * len(widths)
    rows = [head, rule]
    for a in a_values:
        cells = [_fmt_v(by[(a, w)]) for w in widths]
        rows.append(f"| {a:g} | {min(A_PEAK, a):g} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def plot(results, a_values, widths, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by = {(r["a_max"], r["width"]): r for r in results}
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for w in widths:
        pts = [(a, by[(a, w)]["v_min"]) for a in a_values if by[(a, w)]["v_min"] is not None]
        if pts:
            xs, ys = zip(*pts)
            ax.plot(xs, ys, "o-", label=f"[xi] half-widths x{w:g}")
    failed = [f"x{w:g} at {a:g}" for w in widths for a in a_values if by[(a, w)]["v_min"] is None]
    if failed:
        ax.text(0.02, 0.02, "not certified: " + ", ".join(failed), transform=ax.transAxes, fontsize=8, color="C3")
    ax.axvline(A_PEAK, color="0.7", lw=0.8, ls="--", label=f"a_peak = min({A_PEAK:g}, a_max)")
    ax.set_xlabel("a_max along the crossing direction (m/s$^2$)")
    ax.set_ylabel("minimal certified v_sing (m/s)")
    ax.set_title("DexTAR benchmark crossing: v_min vs a_max")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="2 a_max x 2 widths, tol 0.05 m/s (for tests)")
    p.add_argument("--out", default="sweep-bounds", help="output folder (PNG, JSON); default ./sweep-bounds")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default os.cpu_count())")
    args = p.parse_args(argv)
    if args.workers is not None and args.workers < 1:
        p.error("--workers must be >= 1")

    a_values, widths, tol = (QUICK_A_MAX, QUICK_WIDTHS, 0.05) if args.quick else (FULL_A_MAX, FULL_WIDTHS, 0.02)
    cases = [{"a_max": a, "width": w, "tol": tol} for a in a_values for w in widths]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    workers = args.workers or os.cpu_count()
    print(f"{len(cases)} cases on {workers} worker(s), tol {tol} m/s", flush=True)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        results = run_cases(run_case, cases, pool)
    wall = time.perf_counter() - t0

    for r in results:
        extra = f"  ERROR {r['error']}" if r["error"] else ""
        if r["certified_below_v_min"]:
            extra += f"  (also certified below v_min at {r['certified_below_v_min']})"
        print(f"a_max {r['a_max']:6g}  width x{r['width']:<4g} v_min {_fmt_v(r):>6}  "
              f"{r['trials']:3d} trials  {r['elapsed_s']:6.1f} s{extra}")
    print()
    print(table(results, a_values, widths))
    print(f"\nwall time {wall:.1f} s")

    png = out / "sweep_bounds.png"
    plot(results, a_values, widths, png)
    (out / "sweep_bounds.json").write_text(json.dumps({"cases": results, "wall_s": wall, "workers": workers}, indent=2))
    print(f"wrote {png} and {out / 'sweep_bounds.json'}")
    return 1 if any(r["error"] for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
