"""``crosscert`` command line: check a recorded trajectory, simulate one, sweep speeds.

Exit codes: 0 a verdict was given, 2 bad input or usage (one line on
stderr, no traceback), 3 the data contradict the assumptions (inconsistent).
The DexTAR is the default robot (the only module outside ``robots/`` that
names it).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from .errors import CrosscertError, InputError
from .tracker import TrackerSettings, VelocityModel, Verdict, track
from .trajfile import read_trajectory, write_trajectory

__all__ = ["build_parser", "main"]

DEFAULT_ROBOT = "dextar"
#: Table II speeds of the paper, m/s, and two slower ones.
TABLE2_SPEEDS = (1.458, 1.354, 1.264, 1.185, 1.053, 0.9)


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
    c.add_argument("--robot", default=DEFAULT_ROBOT)
    g = c.add_mutually_exclusive_group(required=True)
    g.add_argument("--initial-mode", type=int, choices=(1, -1), help="known assembly mode at the first sample (+1/-1)")
    g.add_argument("--x0", help="initial pose box XLO,XHI,YLO,YHI,... (m); write --x0=-0.01,... when it starts with a minus")
    c.add_argument("--a-max", type=float, help="end-effector acceleration bound, m/s^2 (all components)")
    c.add_argument("--eps-q", type=float, help="encoder error bound, rad")
    c.add_argument("--xd0", type=float, help="initial velocity bound, m/s (all components)")
    c.add_argument("--velocity-model", choices=[m.value for m in VelocityModel], default=VelocityModel.SOUND.value,
                   help="joint-data error model (paper = quantisation only, NOT sound)")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.add_argument("--plot", help="write a PNG figure of the boxes")
    c.add_argument("--no-progress", action="store_true")

    s = sub.add_parser("simulate", help="simulate encoder readings of a crossing (or a bounce)")
    s.add_argument("--robot", default=DEFAULT_ROBOT)
    s.add_argument("--v-sing", type=float, required=True, help="speed at the singularity, m/s")
    s.add_argument("--bounce", action="store_true", help="fail the crossing: stop on the locus and come back")
    s.add_argument("--seed", type=int, default=0, help="seed of the true geometry drawn in the calibration box (0: its centre)")
    s.add_argument("--t-rest", type=float, default=0.3, help="rest before the motion, s")
    s.add_argument("--a-peak", type=float, default=60.0, help="peak acceleration of the ramps, m/s^2")
    s.add_argument("-o", "--output", required=True, help="CSV file to write")

    w = sub.add_parser("sweep", help="the paper's Table II on the simulated benchmark crossing")
    w.add_argument("--robot", default=DEFAULT_ROBOT)
    w.add_argument("--speeds", help="comma-separated speeds at the singularity, m/s")
    w.add_argument("--seed", type=int, default=0, help="seed of the true geometry drawn in the calibration box (0: its centre)")
    w.add_argument("--out", default="crosscert-sweep", help="folder for the PNG figures")
    w.add_argument("--no-progress", action="store_true")
    return p


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
    if not enabled:
        return None, None
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="step", file=sys.stderr, leave=False)
    return bar, (lambda k: bar.update(1))


def _check(a):
    from robots import get_robot

    from .model import IntervalModel

    robot = get_robot(a.robot)
    traj = read_trajectory(a.trajectory, robot.n)
    settings = TrackerSettings.for_robot(robot, t_s=traj.t_s, eps_q=a.eps_q, a_max=a.a_max, xd0=a.xd0,
                                         velocity_model=a.velocity_model)
    model = IntervalModel(robot)
    x0 = None
    if a.x0 is not None:
        v = _floats(a.x0, 2 * robot.n, "--x0")
        x0 = (np.array(v[0::2]), np.array(v[1::2]))
    bar, cb = _progress(len(traj.t), not a.no_progress and not a.json, "tracking")
    try:
        res = track(model, traj.q, settings, x0=x0, initial_mode=a.initial_mode, progress=cb)
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
            print(f"a box became empty at step {res.inconsistent_at_step}: a_max, the calibration box, eps_q or the "
                  "initial box is violated by the data", file=sys.stderr)
    return 3 if res.verdict is Verdict.INCONSISTENT else 0


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
    bar = None
    cb = None
    if not a.no_progress:
        from tqdm import tqdm

        bar = tqdm(desc="sweep", unit="step", file=sys.stderr, leave=False)
        cb = lambda k: bar.update(1)  # noqa: E731
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
        return {"check": _check, "simulate": _simulate, "sweep": _sweep}[a.command](a)
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
