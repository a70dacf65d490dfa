"""Window reasoning (verifier.window): detection power and cost per sample, against the forward tracker.

Prints two tables (docs/tracker.md, "Window reasoning"; the online monitor's: benchmarks/bench_online.py):

1. simulated benchmark crossings at 0.9-1.3 m/s, 20 true geometries each (the
   centre and 19 seeded ones, every other at a corner of the box): runs
   certified by the forward tracker and by the window passes, wrong verdicts,
   time per run and per sample;
2. bounces at 1.2 m/s turning back 0-20 mm before the locus (3 geometries);

Run: ``python benchmarks/bench_window.py`` (about 10 minutes on 2 cores).

``--speed`` prints the cost figures of issue 17 instead (a few minutes):

S1. window reasoning per sample on the 1.0 m/s crossings of the 20 true
    geometries, split by outcome (undecided, decided by the window, decided by
    the forward pass), after a warm-up run;
S1b. (since 2026-12-02) the same runs asked only ``mode-changed``
    (``track_window(goal=...)``, what ``certify`` asks), verdicts compared;
S2. where one undecided run spends its time: the kernel passes
    (``advance``), the forward-kinematics enumeration of the final boxes
    (``pose_solutions``) and the rest (tube bookkeeping in Python);

``--explain`` (since 2026-12-03, issues 17 and 20): S1 and S2 pass
``planner.refute.RefutingExplainer`` to ``track_window`` (what ``crosscert check``
does): a recording whose two final modes are explained by verified motions
stops early, ``unknown`` with reason ``undecidable``; each run also prints
the explainer's questions, answers and IPOPT wall time, and S2 the
explainer's share of the undecided run.

``--parts S1`` or ``--parts S2`` runs one part (``--geometries N``: fewer geometries in S1).

``--bounce-floor`` (``--speeds V``, default 1.0; ``--geometries N``) asks, for the bounce of each
true geometry turning back ``d`` before the locus at ``V`` m/s, where its crossing floor is (the largest
``d`` a verified crossing explains, ``planner.refute.crossing_floor`` bisected to 0.5 mm between 2 and
20 mm) and whether the window (``track_window`` defaults) certifies ``mode-unchanged`` 0.5 and 1 mm above
it: issue 20's goal is every geometry within 1 mm.  Up to a minute per geometry.

``--ceiling`` (``--speeds 1.0,0.95``, ``--starts N``, ``--geometries N``) asks, for each crossing of
table 1, whether *any* sound method could certify it: besides the window's
verdict it searches a bounce (a motion that stays in the initial mode, within
``a_max``, the reading error and ``[ξ]``, that explains the same readings;
``planner.refute.search_bounce`` from the box centre and ``N`` seeded starting
geometries, every candidate checked by ``verify_bounce``).  A run with a
verified bounce cannot be certified ``mode-changed`` by any sound method; a
run certified *and* with a verified bounce would be a soundness bug (counted
as a conflict; must be 0).  About 2 s per search.  The speed part uses only names that exist since 2026-12-01, so the same
script measures an older checkout (run it with that checkout's interpreter).
"""

from __future__ import annotations

import inspect
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from problems import default_settings, interval_model, kinematics  # noqa: E402
from crosscert.planner.simulate import random_geometry, simulate_bounce, simulate_crossing  # noqa: E402
from crosscert.planner.sweep import cruise_for  # noqa: E402
from crosscert.verifier.compiled import driver as _driver  # noqa: E402

# batches of many rows run in lanes once that driver is cached (a command's compile child writes it):
# measure the library as it runs then, compiling it here on a first run
_driver.LANES_COMPILE_HERE = True
from crosscert.robots import DEXTAR  # noqa: E402
from crosscert.robots.dextar import benchmark_crossing  # noqa: E402
from crosscert.verifier.tracker import initial_box_from_mode, track  # noqa: E402
from crosscert.verifier.window import track_window  # noqa: E402


def true_geometries(n: int) -> list:
    """The true geometries of the tables: the centre of [xi] (None) and ``n - 1`` seeded ones, every other at a
    corner of the box."""
    return [None] + [random_geometry(DEXTAR, np.random.default_rng(i), corners=(i % 2 == 0)) for i in range(1, n)]


def crossing(v, xi):
    """The simulated straight crossing of the tables at ``v`` m/s with true geometry ``xi``."""
    kin, bench = kinematics(), benchmark_crossing()
    return simulate_crossing(kin, bench.point, bench.direction, v, xi_true=xi, t_rest=0.05,
                             working_guess=bench.q_point, seed=1, cruise=cruise_for(v))


def _run(fn, v, xi, **kw):
    kin, im, s, bench = kinematics(), interval_model(), default_settings(), benchmark_crossing()
    r = fn(kin, bench.point, bench.direction, v, xi_true=xi, t_rest=0.05, working_guess=bench.q_point, seed=1,
           cruise=kw.pop("cruise", cruise_for(v)), **kw)
    x0 = initial_box_from_mode(im, r.q_meas[0], 1, s)
    t0 = time.perf_counter()
    f = track(im, r.q_meas, s, x0=x0)
    tf = time.perf_counter() - t0
    t0 = time.perf_counter()
    w = track_window(im, r.q_meas, s, x0=x0)
    return f.verdict.value, w.verdict.value, len(r.q_meas), tf, time.perf_counter() - t0


def main() -> None:
    geoms = true_geometries(20)
    print("[1] crossings: v_sing, certified forward / window of 20, wrong, window s per run, us per sample fwd / win")
    for v in (0.9, 0.95, 1.0, 1.05, 1.1, 1.2, 1.3):
        res = [_run(simulate_crossing, v, xi) for xi in geoms]
        nw = sum(r[1] == "mode-changed" for r in res)
        nf = sum(r[0] == "mode-changed" for r in res)
        bad = sum(r[1] in ("mode-unchanged", "inconsistent") for r in res)
        print(f"{v:5.2f}  {nf:2d} / {nw:2d}  wrong {bad}  {np.mean([r[4] for r in res]):6.2f} s  "
              f"{1e6 * np.mean([r[3] / r[2] for r in res]):7.0f} / {1e6 * np.mean([r[4] / r[2] for r in res]):7.0f}",
              flush=True)
    print("[2] bounces at 1.2 m/s: turn-back distance (m), (forward, window, window s) per geometry")
    for short in (0.0, 0.005, 0.010, 0.015, 0.020):
        res = [_run(simulate_bounce, 1.2, xi, short=short, cruise=max(5e-3, cruise_for(1.2) - short / 2))
               for xi in geoms[:3]]
        print(short, [(r[0], r[1], f"{r[4]:.1f}") for r in res], flush=True)


def ceiling(speeds, starts: int, geometries: int = 20) -> None:
    """Certified runs against the runs no sound method can certify (module docstring, ``--ceiling``)."""
    from crosscert.planner.refute import RecordingBounds, search_bounce

    kin, im, s = kinematics(), interval_model(), default_settings()
    geoms = true_geometries(geometries)
    # starting geometries of the non-convex search, seeded apart from the true ones
    seeds = [None] + [random_geometry(DEXTAR, np.random.default_rng(100 + i), corners=(i % 2 == 0))
                      for i in range(starts)]
    print(f"CPU: {_cpu()}; {_load('at start: ')}", flush=True)
    print("[C] crossings: C certified mode-changed by the window, B a verified bounce explains the readings "
          "(no sound method can certify), . neither, ! both (a soundness bug)", flush=True)
    for v in speeds:
        marks = []
        for xi in geoms:
            r = crossing(v, xi)
            w = track_window(im, r.q_meas, s, initial_mode=1)
            rb = RecordingBounds(q_meas=r.q_meas, m0=1, assumptions=s.assumptions)
            bounce = any(search_bounce(kin, rb, xi_start=x0).verified for x0 in seeds)
            certified = w.verdict.value == "mode-changed"
            marks.append("!" if certified and bounce else "C" if certified else "B" if bounce else ".")
        line = "".join(marks)
        print(f"{v:5.2f}  {line}  certified {line.count('C')} / {len(line)}, provably uncertifiable {line.count('B')}, "
              f"open {line.count('.')}, conflicts {line.count('!')}", flush=True)
    print(f"  {_load('')}", flush=True)


def bounce_floor(v: float, geometries: int = 20, step: float = 5e-4) -> None:
    """Per geometry: the crossing floor of its bounces at ``v`` and the window's verdicts just above it
    (module docstring, ``--bounce-floor``)."""
    from crosscert.planner.refute import crossing_floor

    kin, im, s, bench = kinematics(), interval_model(), default_settings(), benchmark_crossing()
    starts = [None] + [random_geometry(DEXTAR, np.random.default_rng(100 + i), corners=(i % 2 == 0))
                       for i in range(2)]

    def bounce(xi, d):
        return simulate_bounce(kin, bench.point, bench.direction, v, xi_true=xi, t_rest=0.05,
                               working_guess=bench.q_point, seed=1, cruise=max(5e-3, cruise_for(v) - d / 2), short=d)

    print(f"CPU: {_cpu()}; {_load('at start: ')}", flush=True)
    print(f"[F] bounces at {v} m/s: crossing floor (largest turn-back distance a verified crossing explains, "
          f"bisected to {1e3 * step:.1f} mm), window verdicts (track_window defaults) at floor + "
          f"{1e3 * step:.1f} and + {2e3 * step:.1f} mm", flush=True)
    met = 0
    for i, xi in enumerate(true_geometries(geometries)):
        t0 = time.perf_counter()
        fl = crossing_floor(kin, lambda d, xi=xi: (bounce(xi, d).q_meas, 1e-3), [0.002, 0.02], tol=step,
                            xi_starts=starts)
        if fl.floor is None:
            print(f"  {i:2d}  no verified crossing at 2 mm: widen the range", flush=True)
            continue
        marks = ""
        for d in (fl.floor + step, fl.floor + 2 * step):
            r = bounce(xi, d)
            x0 = initial_box_from_mode(im, r.q_meas[0], 1, s)
            w = track_window(im, r.q_meas, s, x0=x0).verdict.value
            marks += {"mode-unchanged": "U", "mode-changed": "!", "inconsistent": "X"}.get(w, ".")
        met += "U" in marks
        print(f"  {i:2d}  floor {1e3 * fl.floor:5.2f} mm  +{1e3 * step:.1f} / +{2e3 * step:.1f} mm: {marks}  "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
    print(f"  certified within {2e3 * step:.1f} mm of the floor: {met} / {geometries}; {_load('')}", flush=True)


def _load(note: str) -> str:
    la = os.getloadavg()
    return f"{note}load average {la[0]:.2f} / {la[1]:.2f} / {la[2]:.2f} on {os.cpu_count()} cores"


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown CPU"


class _Clock:
    """Wall time spent inside some functions called by the window's modules (patched in their namespaces)."""

    def __init__(self, modules, names):
        self.total = {}
        self.saved = {(m, n): getattr(m, n) for m in modules for n in names if hasattr(m, n)}

    def __enter__(self):
        for (module, name), fn in self.saved.items():
            def timed(*a, _fn=fn, _name=name, **kw):
                t0 = time.perf_counter()
                try:
                    return _fn(*a, **kw)
                finally:
                    self.total[_name] = self.total.get(_name, 0.0) + time.perf_counter() - t0
            setattr(module, name, timed)
        return self

    def __exit__(self, *exc):
        for (module, name), fn in self.saved.items():
            setattr(module, name, fn)


def _digest(w) -> str:
    """A short hash of everything a window result reports but its time: verdicts, each hypothesis' summary and
    surviving sub-boxes, the hull tubes, bit for bit (the same digest before and after a speed change)."""
    import hashlib

    h = hashlib.sha256(repr([w.verdict.value, w.forward_verdict.value, w.initial_mode,
                             [(x.final_mode, x.status.value, x.refutation.value, x.passes, x.geometries_alive,
                               x.complete) for x in w.hypotheses]]).encode())
    arrays = [w.x_lo, w.x_hi, w.xd_lo, w.xd_hi]
    for x in w.hypotheses:
        arrays += [a for a in (x.x_lo, x.x_hi, x.xd_lo, x.xd_hi, x.xi_lo, x.xi_hi) if a is not None]
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()[:12]


def _explainer(explain: bool):
    """A fresh ``RefutingExplainer`` with ``--explain`` (imported only then: older checkouts have none)."""
    if not explain:
        return None
    from crosscert.planner.refute import RefutingExplainer

    return RefutingExplainer()


def _warm_explainer(im, s, q) -> None:
    """Ask a fresh explainer about both final modes of the recording ``q``: builds the NLPs of both kinds with
    the explainer's own IPOPT options (its solvers are cached per process by size, kind and options; a
    search with other options, as ``search_bounce``'s defaults, builds other ones), so that S1 and S2 time
    the questions, not the one-off builds (about 0.25 s each)."""
    from crosscert.verifier.window import ExplainRequest

    xi = im.xi_box()
    lo, hi = (np.asarray(b, dtype=np.float64) for b in im.robot.x_bounds)
    K = q.shape[0]
    ex = _explainer(True)
    for final in (1, -1):
        ex(ExplainRequest(im, q, s, xi, None, 1, final, xi[0][None], xi[1][None], np.tile(lo, (K, 1)),
                          np.tile(hi, (K, 1))))


def _asked(ex) -> str:
    """The explainer's answers of one run: final mode, search, outcome, IPOPT and wall s."""
    if ex is None:
        return ""
    return "  explainer " + (", ".join(f"{a.final_mode:+d} {a.kind.value if a.kind else '-'} {a.outcome.value} "
                                       f"ipopt {a.solve_s:.2f} s wall {a.wall_s:.2f} s" for a in ex.log) or "not asked")


def speed(geometries: int, parts: str = "S1,S2", explain: bool = False) -> None:
    import crosscert.verifier.window as W

    print(f"CPU: {_cpu()}; {_load('at start: ')}", flush=True)
    im, s = interval_model(), default_settings()
    runs = [crossing(1.0, xi).q_meas for xi in true_geometries(geometries)]
    kw = {}
    if explain:  # warm-up of the searches too: the explainer's NLPs of both kinds built once per process
        _warm_explainer(im, s, runs[0])
    track_window(im, runs[0], s, initial_mode=1)  # warm-up: kernels loaded, caches filled
    print(f"[S1] window reasoning, 1.0 m/s crossings, {len(runs)} true geometries (ms per sample)"
          f"{', with the explainer' if explain else ''}", flush=True)
    rows = []
    for i, q in enumerate(runs):
        ex = _explainer(explain)
        if explain:  # only then: older checkouts' track_window has no such argument
            kw["explainer"] = ex
        t0, c0 = time.perf_counter(), time.process_time()
        w = track_window(im, q, s, initial_mode=1, **kw)
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        kind = ("forward" if w.forward_verdict.value != "unknown" else
                "undecided" if w.verdict.value == "unknown" else "window")
        rows.append((kind, dt / len(q), dt, len(q), w, dc / len(q), ex))
        print(f"  geometry {i:2d}: {len(q)} samples  {w.verdict.value:15s} {kind:9s} {dt:7.3f} s  "
              f"{1e3 * dt / len(q):7.3f} ms/sample  (CPU {1e3 * dc / len(q):7.3f})  "
              f"passes {[h.passes for h in w.hypotheses]}  alive {[h.geometries_alive for h in w.hypotheses]}  "
              f"digest {_digest(w)}{_asked(ex)}", flush=True)
    for kind in ("undecided", "window", "forward"):
        sel = [r for r in rows if r[0] == kind]
        if sel:
            per = np.array([r[1] for r in sel])
            print(f"  {kind:9s} ({len(sel):2d} runs): mean {1e3 * per.mean():.3f} ms/sample, min {1e3 * per.min():.3f}, "
                  f"max {1e3 * per.max():.3f}; mean {np.mean([r[2] for r in sel]):.3f} s per run; "
                  f"CPU {1e3 * np.mean([r[5] for r in sel]):.3f} ms/sample", flush=True)
            if explain:
                asks = [a for r in sel for a in r[6].log]
                print(f"  {'':9s} explainer: {len(asks)} questions, IPOPT {sum(a.solve_s for a in asks):.2f} s, "
                      f"wall {sum(a.wall_s for a in asks):.2f} s in all", flush=True)
    per = np.array([r[1] for r in rows])
    print(f"  all       ({len(rows):2d} runs): mean {1e3 * per.mean():.3f} ms/sample", flush=True)
    print(f"  verdicts: {[r[4].verdict.value for r in rows]}")
    print(f"  {_load('')}", flush=True)
    if "goal" in inspect.signature(track_window).parameters:  # since 2026-12-02: what certify asks
        print("[S1b] the same runs asked only `mode-changed` (track_window(goal=...), as certify's search, "
              "certificate run and Monte Carlo ask)", flush=True)
        per = {}
        for i, q in enumerate(runs):
            t0, c0 = time.perf_counter(), time.process_time()
            w = track_window(im, q, s, initial_mode=1, goal="mode-changed")
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            same = w.verdict is rows[i][4].verdict
            per.setdefault(rows[i][0], []).append((dt / len(q), dc / len(q)))
            print(f"  geometry {i:2d}: {w.verdict.value:15s} {'same' if same else 'DIFFERS'}  {dt:7.3f} s  "
                  f"{1e3 * dt / len(q):7.3f} ms/sample  (CPU {1e3 * dc / len(q):7.3f})  digest {_digest(w)}",
                  flush=True)
        for kind, v in per.items():
            print(f"  {kind:9s} ({len(v):2d} runs): mean {1e3 * np.mean([a for a, _ in v]):.3f} ms/sample, "
                  f"CPU {1e3 * np.mean([c for _, c in v]):.3f}", flush=True)
        print(f"  {_load('')}", flush=True)
    und = [i for i, r in enumerate(rows) if r[0] == "undecided"] or [0]
    q = runs[und[0]]
    print(f"[S2] where an undecided run spends its time (geometry {und[0]}, {len(q)} samples)", flush=True)
    ex = _explainer(explain)
    # the modules that call them: verifier.window's passes and hypotheses (one module in older checkouts)
    modules = [getattr(W, m) for m in ("passes", "hypotheses") if hasattr(W, m)] or [W]
    with _Clock(modules, ("advance", "pose_solutions", "contract_tubes", "one_motion_rows")) as clock:
        t0 = time.perf_counter()
        track_window(im, q, s, initial_mode=1, **({"explainer": ex} if explain else {}))
        total = time.perf_counter() - t0
    if ex is not None:
        clock.total["explainer"] = sum(a.wall_s for a in ex.log)
    rest = total - sum(clock.total.values())
    for name, v in sorted(clock.total.items(), key=lambda kv: -kv[1]):
        print(f"  {name:15s} {v:7.3f} s  {100 * v / total:5.1f} %", flush=True)
    print(f"  {'the rest':15s} {rest:7.3f} s  {100 * rest / total:5.1f} %   (total {total:.3f} s)", flush=True)


if __name__ == "__main__":
    if "--bounce-floor" in sys.argv:
        bounce_floor(float(sys.argv[sys.argv.index("--speeds") + 1].split(",")[0]) if "--speeds" in sys.argv else 1.0,
                     int(sys.argv[sys.argv.index("--geometries") + 1]) if "--geometries" in sys.argv else 20)
    elif "--ceiling" in sys.argv:
        ceiling([float(v) for v in (sys.argv[sys.argv.index("--speeds") + 1] if "--speeds" in sys.argv
                                    else "1.0,0.95").split(",")],
                int(sys.argv[sys.argv.index("--starts") + 1]) if "--starts" in sys.argv else 4,
                int(sys.argv[sys.argv.index("--geometries") + 1]) if "--geometries" in sys.argv else 20)
    elif "--speed" in sys.argv:
        speed(int(sys.argv[sys.argv.index("--geometries") + 1]) if "--geometries" in sys.argv else 20,
              sys.argv[sys.argv.index("--parts") + 1] if "--parts" in sys.argv else "S1,S2",
              "--explain" in sys.argv)
    else:
        main()
