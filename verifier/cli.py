"""``crosscert`` command line: certify a planned crossing, plan one, check a recording, monitor a stream, simulate, sweep.

Exit codes: 0 a verdict was given, 2 bad input or usage (one line on
stderr, no traceback), 3 the data contradict the assumptions (inconsistent).
The DexTAR is the default robot (the only module outside ``robots/`` that
names it).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from pathlib import Path

import numpy as np

from robots.errors import CrosscertError, InputError, TrajectoryFileError
from .step import Backend
from .tracker import TrackerSettings, VelocityModel, Verdict, track, verdict_of
from .trajfile import TrajectoryReader, read_trajectory, write_trajectory

__all__ = ["build_parser", "main"]

DEFAULT_ROBOT = "dextar"
#: Table II speeds of the paper, m/s, and two slower ones.
TABLE2_SPEEDS = (1.458, 1.354, 1.264, 1.185, 1.053, 0.9)
#: What ``check`` and ``monitor`` print on stderr for an inconsistent run.
_INCONSISTENT_HINT = ("a box became empty at step {k}: a_max, the calibration box, eps_q or the initial box is "
                      "violated by the data")


METHODS = ("smoothstep", "time-optimal", "dynamic")
METHOD_HELP = ("time law of the plan: constant speed through the crossing (smoothstep), minimal time along the "
               "straight path (time-optimal, cvxpy), or minimal time with the robot's dynamic model, torque limits "
               "and the dynamic crossing criterion (dynamic, CasADi + IPOPT)")


def _dynamics(robot):
    from robots.dynamics import DEXTAR_DYNAMICS

    if robot.name.lower() != DEFAULT_ROBOT:
        raise InputError(f"robot {robot.name!r} has no dynamic model; use --method smoothstep or time-optimal")
    return DEXTAR_DYNAMICS


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # usage errors: one line, exit 2
        raise _Usage(f"{self.prog}: {message}")


class _Usage(Exception):
    pass


def _floats(text, count, what):
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{what}: expected {count} comma-separated numbers, got {text!r}") from None
    if len(vals) != count:
        raise InputError(f"{what}: expected {count} comma-separated numbers, got {len(vals)}")
    return vals


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``crosscert``."""
    p = _Parser(prog="crosscert", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    c = sub.add_parser("check", help="certify the assembly mode of a recorded joint trajectory")
    c.add_argument("trajectory", help="CSV file: t,q1..qn[,qd1..qdn] (s, rad, rad/s)")
    _tracker_options(c)
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.add_argument("--plot", help="write a PNG figure of the boxes")
    c.add_argument("--no-progress", action="store_true")

    mo = sub.add_parser("monitor", help="certify the assembly mode online, from samples read one line at a time")
    mo.add_argument("trajectory", nargs="?", default="-",
                    help="CSV stream t,q1..qn[,qd1..qdn]: '-' (default) for stdin, a named pipe or a file")
    _tracker_options(mo)
    mo.add_argument("--t-s", type=float, help="sampling period, s (default: fixed by the first two samples)")
    mo.add_argument("--json", action="store_true", help="one JSON object per event, then one summary object")
    mo.add_argument("--spread-hypotheses", action="store_true",
                    help="track the geometry hypotheses of each sample on several threads: lower latency on "
                         "dedicated cores, erratic on busy ones")

    s = sub.add_parser("simulate", help="simulate encoder readings of a crossing (or a bounce)")
    s.add_argument("--robot", default=DEFAULT_ROBOT)
    s.add_argument("--v-sing", type=float, required=True, help="speed at the singularity, m/s")
    s.add_argument("--bounce", action="store_true", help="fail the crossing: stop on the locus and come back")
    s.add_argument("--seed", type=int, default=0, help="seed of the true geometry drawn in the calibration box (0: its centre)")
    s.add_argument("--t-rest", type=float, default=0.3, help="rest before the motion, s")
    s.add_argument("--a-peak", type=float, default=60.0, help="peak acceleration of the ramps, m/s^2")
    s.add_argument("-o", "--output", required=True, help="CSV file to write")

    ce = sub.add_parser("certify", help="minimal certified crossing speed of a task, with its proof and refutation bound")
    _task_options(ce)
    ce.add_argument("--a-max", type=float, help="end-effector acceleration bound, m/s^2 (default: planned peak + 10%%)")
    ce.add_argument("--eps-q", type=float, help="encoder error bound, rad (robot default)")
    ce.add_argument("--tracking-error", type=float, default=0.0, help="extra joint tracking error allowed, rad")
    ce.add_argument("--execution", choices=("cartesian", "joint"), default="cartesian",
                    help="executions the certificate covers: 'cartesian' follow the planned path with any geometry "
                         "in the calibration box (default); 'joint' keep the joints within eps_q + tracking error "
                         "of the plan")
    ce.add_argument("--a-peak", type=float, default=60.0, help="peak acceleration of the planned ramps, m/s^2")
    ce.add_argument("--method", choices=METHODS, default="smoothstep", help=METHOD_HELP)
    ce.add_argument("--v-low", type=float, default=0.6, help="slowest speed tried, m/s")
    ce.add_argument("--v-high", type=float, help="fastest speed tried, m/s (default: the fastest the segment allows)")
    ce.add_argument("--tol", type=float, default=0.01, help="resolution of v_min and of the refutation bound, m/s")
    ce.add_argument("--monte-carlo", type=int, default=50, help="simulated executions at v_min (0 skips)")
    ce.add_argument("--no-refute", action="store_true", help="skip the counterexample search")
    ce.add_argument("--seed", type=int, default=0)
    ce.add_argument("--out", default="crosscert-certify", help="folder for the PNG plot and the JSON report")
    ce.add_argument("--json", action="store_true", help="print the JSON report instead of the table")
    ce.add_argument("--no-progress", action="store_true")

    pl = sub.add_parser("plan", help="plan a crossing at a given speed and write it as a trajectory file")
    _task_options(pl)
    pl.add_argument("--v-sing", type=float, required=True, help="speed at the singularity, m/s")
    pl.add_argument("--a-peak", type=float, default=60.0, help="peak acceleration of the ramps, m/s^2")
    pl.add_argument("--method", choices=METHODS, default="smoothstep", help=METHOD_HELP)
    pl.add_argument("-o", "--output", required=True, help="CSV file to write (t, q1..qn, x1..xn)")

    w = sub.add_parser("sweep", help="the paper's Table II on the simulated benchmark crossing")
    w.add_argument("--robot", default=DEFAULT_ROBOT)
    w.add_argument("--speeds", help="comma-separated speeds at the singularity, m/s")
    w.add_argument("--seed", type=int, default=0, help="seed of the true geometry drawn in the calibration box (0: its centre)")
    w.add_argument("--out", default="crosscert-sweep", help="folder for the PNG figures")
    w.add_argument("--no-progress", action="store_true")
    return p


def _tracker_options(p):
    """The tracker-bound options ``check`` and ``monitor`` share (read back by :func:`_tracker_setup`)."""
    p.add_argument("--robot", default=DEFAULT_ROBOT)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--initial-mode", type=int, choices=(1, -1), help="known assembly mode at the first sample (+1/-1)")
    g.add_argument("--x0", help="initial pose box XLO,XHI,YLO,YHI,... (m); write --x0=-0.01,... when it starts with a minus")
    p.add_argument("--a-max", type=float, help="end-effector acceleration bound, m/s^2 (all components)")
    p.add_argument("--eps-q", type=float, help="encoder error bound, rad")
    p.add_argument("--xd0", type=float, help="initial velocity bound, m/s (all components)")
    p.add_argument("--velocity-model", choices=[m.value for m in VelocityModel], default=VelocityModel.SOUND.value,
                   help="joint-data error model (paper = quantisation only, NOT sound)")
    p.add_argument("--backend", choices=[b.value for b in Backend], default=Backend.COMPILED.value,
                   help="tracker implementation: compiled kernels (default) or the numpy reference (same results)")


def _tracker_setup(a):
    """Robot, interval model, the settings maker ``t_s -> TrackerSettings`` and the ``--x0`` box (or None)."""
    from robots import get_robot

    from .model import IntervalModel

    robot = get_robot(a.robot)
    x0 = None
    if a.x0 is not None:
        v = _floats(a.x0, 2 * robot.n, "--x0")
        x0 = (np.array(v[0::2]), np.array(v[1::2]))

    def settings(t_s):
        return TrackerSettings.for_robot(robot, t_s=t_s, eps_q=a.eps_q, a_max=a.a_max, xd0=a.xd0,
                                         velocity_model=a.velocity_model)

    return robot, IntervalModel(robot), settings, x0


def _task_options(p):
    p.add_argument("--robot", default=DEFAULT_ROBOT)
    p.add_argument("--start", help="start pose at rest, comma-separated, SI (default: 60 mm before the benchmark crossing)")
    p.add_argument("--goal", help="goal pose at rest in the other mode, SI (default: 60 mm after it)")


def _task(a):
    from planner.certify import CrossingTask

    robot, kin, bench = _benchmark(a.robot)
    start = bench.point - 0.06 * bench.direction if a.start is None else np.array(_floats(a.start, robot.n, "--start"))
    goal = bench.point + 0.06 * bench.direction if a.goal is None else np.array(_floats(a.goal, robot.n, "--goal"))
    return robot, kin, CrossingTask(start, goal, bench.q_point)


def _plan(a):
    from planner.certify import PlanningBounds, plan_crossing

    robot, kin, task = _task(a)
    dyn = _dynamics(robot) if a.method == "dynamic" else None
    p = plan_crossing(kin, task, a.v_sing, PlanningBounds(a_peak=a.a_peak, method=a.method, dynamics=dyn))
    write_trajectory(a.output, p.t, p.q, x=p.x)
    print(f"wrote {a.output}: {len(p.t)} samples, crossing at sample {p.k_sing} at {p.v_sing} m/s, "
          f"peak |xdd| {np.abs(p.xdd).max():.1f} m/s^2")
    return 0


def _certify(a):
    from planner.certify import PlanningBounds, certify_crossing

    from .plots import plot_run

    robot, kin, task = _task(a)
    bounds = PlanningBounds(eps_q=a.eps_q, tracking_error=a.tracking_error, a_max=a.a_max, a_peak=a.a_peak,
                            method=a.method, dynamics=_dynamics(robot) if a.method == "dynamic" else None,
                            execution=a.execution)
    out = Path(a.out)
    bar, cb = _progress(None, not a.no_progress, "certify")
    try:
        cert = certify_crossing(robot, task, bounds, v_low=a.v_low, v_high=a.v_high, tol=a.tol,
                                monte_carlo_runs=a.monte_carlo, refute=not a.no_refute, seed=a.seed,
                                progress=cb, kin=kin)
    finally:
        if bar is not None:
            bar.close()
    report = cert.summary()
    out.mkdir(parents=True, exist_ok=True)
    files = []
    if cert.enclosures is not None:
        e, p = cert.enclosures, cert.trajectory
        png = out / f"certificate_{robot.name}_{cert.v_min:.3f}.png"
        plot_run(png, p.t[1] - p.t[0], {"x_lo": e.x_lo, "x_hi": e.x_hi, "xd_lo": e.xd_lo, "xd_hi": e.xd_hi, "mode": e.mode},
                 p.x, p.xd, p.k_sing, title=f"{robot.name}: certified crossing at v_min = {cert.v_min:.3f} m/s")
        files.append(png)
    js = out / "certificate.json"
    tmp = js.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(report, indent=1))
    tmp.replace(js)
    files.append(js)
    if a.json:
        print(json.dumps(report))
        return 0
    print(f"{'v_sing (m/s)':>12} {'m_x (mm)':>10} {'m_xd (m/s)':>11} {'verdict':>15}")
    for r in cert.trials:
        print(f"{r.v_sing:12.4f} {1e3 * r.max_width_pose:10.2f} {r.max_width_velocity:11.3f} {r.verdict.value:>15}")
    vmin = "none (no tried speed certifies)" if cert.v_min is None else f"{cert.v_min:.4f} m/s"
    ref = "not computed" if a.no_refute else ("none found" if cert.refutation_bound is None else f"{cert.refutation_bound:.4f} m/s")
    print(f"minimal certified v_sing: {vmin}")
    if cert.v_min_at_lower_end:
        print(f"note: v_min is the slowest speed tried; lower --v-low (now {a.v_low} m/s) to look for a smaller one")
    if cert.certified_below_v_min:
        print(f"note: certification is not monotone here; also certified below v_min at "
              f"{', '.join(f'{v:.4f}' for v in cert.certified_below_v_min)} m/s")
    print(f"refutation bound (no sound tracker certifies at or below): {ref}")
    if cert.monte_carlo:
        mc = cert.monte_carlo
        print(f"Monte Carlo at v_min: {mc['detected_in_class']}/{mc['in_class']} admissible executions detected "
              f"({mc['detected']}/{mc['runs']} in all), {len(mc['containment_failures'])} containment failures, "
              f"{len(mc['wrong_verdicts'])} wrong verdicts")
    phases = ", ".join(f"{k} {v:.1f}" for k, v in cert.timings_s.items())
    print(f"a_max used: {report['a_max_mps2']} m/s^2; elapsed {cert.elapsed_s:.1f} s ({phases})")
    for f in files:
        print(f"wrote {f}")
    return 0


def _benchmark(name):
    from robots import KinematicModel, benchmark_crossing, get_robot

    robot = get_robot(name)
    if robot.name.lower() != DEFAULT_ROBOT:
        raise InputError(f"robot {name!r} has no simulated benchmark crossing yet; only {DEFAULT_ROBOT} has")
    return robot, KinematicModel(robot), benchmark_crossing()


def _true_geometry(robot, seed):
    if seed == 0:
        return None
    from planner.simulate import random_geometry

    return random_geometry(robot, np.random.default_rng(seed))


def _progress(total, enabled, desc):
    """A tqdm bar on stderr (``total`` None: open-ended) and its per-sample callback."""
    if not enabled:
        return None, None
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="step", file=sys.stderr, leave=False)
    return bar, (lambda k: bar.update(1))


def _check(a):
    robot, model, make_settings, x0 = _tracker_setup(a)
    traj = read_trajectory(a.trajectory, robot.n)
    settings = make_settings(traj.t_s)
    bar, cb = _progress(len(traj.t), not a.no_progress and not a.json, "tracking")
    try:
        res = track(model, traj.q, settings, x0=x0, initial_mode=a.initial_mode, progress=cb, backend=a.backend)
    finally:
        if bar is not None:
            bar.close()
    if a.plot:
        from .plots import plot_run

        plot_run(a.plot, traj.t_s, {"x_lo": res.x_lo, "x_hi": res.x_hi, "xd_lo": res.xd_lo, "xd_hi": res.xd_hi, "mode": res.mode},
                 title=f"{Path(a.trajectory).name}: {res.verdict.value}")
    out = res.summary()
    out["velocity_model"] = str(settings.velocity_model)
    if a.json:
        print(json.dumps(out))
    else:
        print(f"verdict: {out['verdict']}")
        for key in ("initial_mode", "final_mode", "certified_at_step", "inconsistent_at_step", "steps"):
            print(f"{key}: {out[key]}")
        print(f"max width pose (m_x): {1e3 * out['max_width_pose_m']:.3f} mm")
        print(f"max width velocity (m_xd): {out['max_width_velocity_mps']:.4g} m/s")
        print(f"elapsed: {out['elapsed_s']:.2f} s")
        if res.verdict is Verdict.INCONSISTENT:
            print(_INCONSISTENT_HINT.format(k=res.inconsistent_at_step), file=sys.stderr)
    return 3 if res.verdict is Verdict.INCONSISTENT else 0


class _Monitor:
    """What ``crosscert monitor`` has decided so far.

    Samples wait in ``pending`` until the sampling period is known (at the
    second sample, or the first with ``--t-s``); then the compiled
    :class:`~verifier.step.Tracker` starts from ``--x0`` or from the first
    sample's box of ``--initial-mode``, and every later sample is tracked as
    soon as it is fed.

    Parameters
    ----------
    a : argparse.Namespace
    model : verifier.model.IntervalModel
    make_settings : callable
        ``t_s -> TrackerSettings``.
    x0 : (lo, hi) or None
        The ``--x0`` box.
    """

    def __init__(self, a, model, make_settings, x0):
        self.a, self.model, self.make_settings, self.x0 = a, model, make_settings, x0
        self.tracker = None
        self.pending = []  # (line, t, q) read before the tracker could start
        self.samples = 0
        self.latency_ns = []

    def feed(self, line: int, t: float, q, t_s: float | None) -> None:
        """Track the sample read on ``line`` (time ``t`` s, readings ``q`` rad) and print its events."""
        from .step import Tracker
        from .tracker import initial_box_from_mode

        self.samples += 1
        self.pending.append((line, float(t), q))
        if self.tracker is None:
            if t_s is None:
                return
            settings = self.make_settings(t_s)
            x0 = self.x0
            if x0 is None:
                x0 = initial_box_from_mode(self.model, self.pending[0][2], self.a.initial_mode, settings,
                                           backend=self.a.backend)
            self.tracker = Tracker(self.model, settings, x0, backend=self.a.backend,
                                   spread_hypotheses=self.a.spread_hypotheses)
        for line, t, q in self.pending:
            t0 = time.perf_counter_ns()
            r = self.tracker.update(q)
            self.latency_ns.append(time.perf_counter_ns() - t0)
            for e in r.events:
                ev = {"event": e.value, "k": r.k, "t": t, "line": line, "mode": r.mode}
                text = f"sample {r.k} (t = {t:.9g} s): {e}" + (f", mode {r.mode:+d}" if r.mode else "")
                print(json.dumps(ev) if self.a.json else text, flush=True)
        self.pending.clear()

    def summary(self, error: str | None = None) -> dict:
        """The verdict so far (rules of :func:`verifier.tracker.verdict_of`), counts and latencies (us)."""
        st = None if self.tracker is None else self.tracker.state
        bad = -1 if st is None else int(st.bad_at[0])
        init = 0 if st is None else int(st.init_mode[0])
        final = int(st.mode[0]) if st is not None and bad < 0 else 0
        lat = np.array(self.latency_ns, dtype=float) / 1e3
        stat = (lambda f: round(float(f(lat)), 1) if lat.size else None)  # noqa: E731
        return {
            "verdict": verdict_of(init, final, bad >= 0).value,
            "initial_mode": init,
            "final_mode": final,
            "certified_at_step": int(st.streak[0]) if final else None,
            "inconsistent_at_step": bad if bad >= 0 else None,
            "steps": 0 if st is None else st.k,
            "t_s": None if st is None else float(self.tracker.config.settings.t_s),
            "max_width_pose_m": None if st is None else float(st.max_width_pose[0]),
            "max_width_velocity_mps": None if st is None else float(st.max_width_velocity[0]),
            "velocity_model": self.a.velocity_model,
            "latency_us_mean": stat(np.mean),
            "latency_us_p99": stat(lambda v: np.percentile(v, 99)),
            "latency_us_max": stat(np.max),
            "interrupted": error is not None,
            "error": error,
        }

    def finish(self, error: str | None = None) -> int:
        """Print the summary (the last line of output) and return the exit code."""
        out = self.summary(error)
        if self.a.json:
            print(json.dumps(out), flush=True)
        else:
            print(f"verdict: {out['verdict']}" + (" (so far: input interrupted)" if error else ""))
            for key in ("initial_mode", "final_mode", "certified_at_step", "inconsistent_at_step", "steps"):
                print(f"{key}: {out[key]}")
            if out["steps"]:
                print(f"update latency: mean {out['latency_us_mean']} us, p99 {out['latency_us_p99']} us, "
                      f"max {out['latency_us_max']} us")
            sys.stdout.flush()
        if out["inconsistent_at_step"] is not None and error is None:  # else the error is the one line on stderr
            print(_INCONSISTENT_HINT.format(k=out["inconsistent_at_step"]), file=sys.stderr)
        return 3 if out["verdict"] == Verdict.INCONSISTENT.value else 0


def _load_kernels(robot, model, settings, spread_hypotheses):
    """Load the compiled kernels (about 0.4 s from the on-disk cache) on a throw-away tracker, before the
    first sample is read, so that the latencies measured are those of the tracking alone."""
    from .step import Tracker

    box = tuple(np.asarray(v, dtype=np.float64) for v in robot.x_bounds)
    Tracker(model, settings, box, spread_hypotheses=spread_hypotheses).update(np.zeros(robot.n))


def _monitor(a):
    """``crosscert monitor``: track a CSV stream line by line, print events as they happen, then the summary.

    Returns the exit code; on an error (bad line, Ctrl-C) the summary so far is
    printed, marked interrupted, before the error propagates to :func:`main`.
    """
    robot, model, make_settings, x0 = _tracker_setup(a)
    settings = make_settings(robot.t_s if a.t_s is None else a.t_s)
    settings.validated(robot.n)  # bad bounds fail before any input is read
    if a.backend == Backend.COMPILED.value:
        _load_kernels(robot, model, settings, a.spread_hypotheses)
    mon = _Monitor(a, model, make_settings, x0)
    stdin = a.trajectory == "-"
    with contextlib.nullcontext(sys.stdin) if stdin else open(a.trajectory, newline="") as src:
        reader = TrajectoryReader(src, robot.n, "<stdin>" if stdin else a.trajectory, t_s=a.t_s)
        try:
            for line, values in reader:
                t, q = reader.columns(values)[:2]
                mon.feed(line, t, q, reader.t_s)
            if mon.samples < 2:
                raise TrajectoryFileError(f"{reader.name}: at least two samples are needed, got {mon.samples}")
        except (CrosscertError, OSError, KeyboardInterrupt) as exc:
            mon.finish(error=str(exc) or type(exc).__name__)
            raise
    return mon.finish()


def _simulate(a):
    from planner.simulate import simulate_bounce, simulate_crossing

    robot, kin, bench = _benchmark(a.robot)
    fn = simulate_bounce if a.bounce else simulate_crossing
    run = fn(kin, bench.point, bench.direction, a.v_sing, xi_true=_true_geometry(robot, a.seed), t_rest=a.t_rest,
             a_peak=a.a_peak, working_guess=bench.q_point, seed=a.seed)
    write_trajectory(a.output, run.t, run.q_meas)
    kind = "bounce" if a.bounce else "crossing"
    print(f"wrote {a.output}: {run.n_samples} samples of a {kind} at {run.v_sing} m/s (singular sample {run.k_sing})")
    return 0


def _sweep(a):
    from planner.sweep import sweep

    from .plots import plot_run

    robot, kin, bench = _benchmark(a.robot)
    speeds = TABLE2_SPEEDS if a.speeds is None else tuple(_floats(a.speeds, len(a.speeds.split(",")), "--speeds"))
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    models = (VelocityModel.PAPER, VelocityModel.SOUND)
    bar, cb = _progress(None, not a.no_progress, "sweep")
    try:
        rows, figs = sweep(robot, kin, bench, speeds, models, xi_true=_true_geometry(robot, a.seed), seed=a.seed,
                           progress=cb, record_speed=speeds[0])
    finally:
        if bar is not None:
            bar.close()
    print(f"{'v_sing (m/s)':>12} {'model':>8} {'m_x (mm)':>10} {'m_xd (m/s)':>11} {'detected':>9} {'verdict':>15} {'contained':>9}")
    for r in rows:
        det = "yes" if r.verdict is Verdict.MODE_CHANGED else "no"
        print(f"{r.v_sing:12.3f} {r.velocity_model:>8} {1e3 * r.max_width_pose:10.2f} {r.max_width_velocity:11.3f} "
              f"{det:>9} {r.verdict.value:>15} {str(r.contained):>9}")
    for vm in models:
        lowest = [r.v_sing for r in rows if r.velocity_model == str(vm) and r.verdict is Verdict.MODE_CHANGED]
        print(f"lowest certified v_sing ({vm}): {min(lowest):.3f} m/s" if lowest else f"lowest certified v_sing ({vm}): none")
    for name, (run, boxes) in figs.items():
        png = out / f"sweep_{name}_{run.v_sing:.3f}.png"
        plot_run(png, run.t_s, boxes, run.x_true, run.xd_true, run.k_sing, title=f"{robot.name} crossing at {run.v_sing} m/s, {name} model")
        print(f"wrote {png}")
    return 0


def main(argv=None) -> int:
    """Entry point of the ``crosscert`` script; returns the exit code."""
    try:
        a = build_parser().parse_args(argv)
        return {"check": _check, "monitor": _monitor, "simulate": _simulate, "sweep": _sweep, "plan": _plan, "certify": _certify}[a.command](a)
    except _Usage as exc:
        print(str(exc), file=sys.stderr)
        return 2
    except CrosscertError as exc:
        print(f"crosscert: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("crosscert: interrupted", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"crosscert: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
