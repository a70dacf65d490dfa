"""The argument parser of ``crosscert``: every command, option, default and unit in one place."""

from __future__ import annotations

import argparse
import importlib.metadata as md

import numpy as np

from crosscert.robots.errors import CrosscertError
from crosscert.robots.registry import DEFAULT_ROBOT, available_robots, get_entry, robot_key
from crosscert.verifier.step import Backend
from crosscert.verifier.settings import VelocityModel
from crosscert.verifier.trajfile import parse_number
from crosscert.verifier.one_motion import ONE_MOTION_SAMPLES
from crosscert.verifier.recordings import DEFAULT_TOPIC, Stamp
from crosscert.verifier.window import ONLINE_HORIZON, Reasoning

from ..execution import ExecutionKind
from ..simulate.run import A_PEAK as SIM_A_PEAK
from ..task import Method, PlanningBounds
from ..certify.crossing import V_LOW

#: Peak acceleration of planned ramps: the PlanningBounds default, m/s^2.
PLAN_A_PEAK = PlanningBounds.a_peak

__all__ = ["build_parser", "robot_of", "UsageError", "TABLE2_SPEEDS", "number", "numbers",
           "count"]

#: Table II speeds of the paper, m/s, and two slower ones.
TABLE2_SPEEDS = (1.458, 1.354, 1.264, 1.185, 1.053, 0.9)

METHOD_HELP = ("time law of the plan: constant speed through the crossing (smoothstep), minimal time along the "
               "straight path (time-optimal, cvxpy), or minimal time with the robot's dynamic model, torque limits "
               "and the dynamic crossing criterion (dynamic, CasADi + IPOPT)")


def number(text: str) -> float:
    """argparse ``type=``: a finite decimal number (see :func:`verifier.trajfile.parse_number`)."""
    try:
        return parse_number(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a decimal number") from None


def numbers(text: str) -> tuple[float, ...]:
    """argparse ``type=``: one or more comma-separated finite decimal numbers."""
    return tuple(number(t) for t in text.split(","))


def count(text: str) -> int:
    """argparse ``type=``: a non-negative integer in ASCII digits."""
    t = text.strip()
    if not (t.isascii() and t.isdigit()):
        raise argparse.ArgumentTypeError(f"{text!r} is not a non-negative whole number")
    return int(t)


class UsageError(Exception):
    """A usage error argparse found: printed as one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # usage errors: one line, exit 2
        raise UsageError(f"{self.prog}: {message}")


class _Formatter(argparse.ArgumentDefaultsHelpFormatter):
    """Defaults in ``--help``, except where there is none to show."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False or action.default is argparse.SUPPRESS \
                or "%(default)" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


def _version() -> str:
    try:
        return md.version("crosscert")
    except md.PackageNotFoundError:  # running from a source tree that was never installed
        return "unknown (not installed)"


#: Units of the per-axis acceleration and velocity bounds of a pose (positions in m, angles in rad).


def robot_of(argv) -> str:
    """The robot ``argv`` names with ``--robot`` (one that loads), else the default: its values show in ``--help``.
    A name that does not load is reported after parsing, as one line."""
    argv = list(argv)
    for i, arg in enumerate(argv):
        name = arg.split("=", 1)[1] if arg.startswith("--robot=") else (
            argv[i + 1] if arg == "--robot" and i + 1 < len(argv) else None)
        if name is not None:
            try:
                return robot_key(name)
            except CrosscertError:
                continue
    return DEFAULT_ROBOT


def _values(v) -> str:
    """A robot default as ``help`` shows it: one number, or one per axis in brackets."""
    vals = [float(x) for x in np.atleast_1d(v)]
    return f"{vals[0]:g}" if len(set(vals)) == 1 else "(" + ", ".join(f"{x:g}" for x in vals) + ")"


def _robot_default(robot: str, attr: str) -> str:
    """``help`` text of a default the robot supplies: its value and unit for ``robot`` (from its assumptions)."""
    a = get_entry(robot).robot.assumptions
    value = a.t_s if attr == "t_s" else getattr(a, attr)
    if np.ndim(value) and np.all(value == value[0]):
        value = value[0]
    return f"default of {robot}: {_values(value)} {a.unit(attr)}; see crosscert robots"


def _unit(robot: str, attr: str) -> str:
    """Unit of assumption ``attr`` for ``robot``, for ``help`` (one per coordinate when they differ)."""
    return get_entry(robot).robot.assumptions.unit(attr)


def _robot_option(p):
    p.add_argument("--robot", default=DEFAULT_ROBOT,
                   help=f"robot: one of {', '.join(available_robots())}, or a file of yours, path/to/robot.py:NAME "
                        "(NAME a RobotEntry it defines; docs/your-robot.md)")


def _tracker_options(p, robot):
    """The tracker-bound options ``check`` and ``monitor`` share (defaults shown for ``robot``)."""
    _robot_option(p)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--initial-mode", type=int, choices=(1, -1), help="known assembly mode at the first sample (+1/-1)")
    g.add_argument("--x0", help="initial pose box XLO,XHI,YLO,YHI,... (m); write --x0=-0.01,... when it starts with a minus")
    p.add_argument("--a-max", type=number,
                   help="end-effector acceleration bound, m/s^2, every pose axis (robots whose axes are all lengths; "
                        + _robot_default(robot, "a_max") + ")")
    p.add_argument("--eps-q", type=number, help=f"encoder error bound, {_unit(robot, 'eps_q')} (" + _robot_default(robot, "eps_q") + ")")
    p.add_argument("--xd0", type=number, help="initial velocity bound, m/s, every pose axis (robots whose axes are all "
                                              "lengths; " + _robot_default(robot, "xd0") + ")")
    p.add_argument("--t-s", type=number, help="sampling period, s: every step of the time column (in s) is a whole "
                                              "number of it, or within --stamp-error (default: inferred from the time "
                                              "column, the first step fixing it; "
                                              + _robot_default(robot, "t_s") + ")")
    p.add_argument("--stamp-error", type=number, default=0.0, metavar="S",
                   help="bound on each time stamp's error, s: 0 for a fixed-period controller (every step a whole "
                        "number of periods: a dropped sample is a step of two); more for jittered stamps, each "
                        "sample's true time within it of its stamp (docs/soundness.md, 'Time stamps')")
    p.add_argument("--velocity-model", choices=[m.value for m in VelocityModel], default=VelocityModel.SOUND.value,
                   help="joint-data error model (paper = quantisation only, NOT sound)")
    p.add_argument("--backend", choices=[b.value for b in Backend], default=Backend.COMPILED.value,
                   help="tracker implementation: compiled kernels or the numpy reference (same results)")
    p.add_argument("--horizon", type=count, default=ONLINE_HORIZON,
                   help="longest anchored window, samples: a window from the last sample whose mode was known that "
                        "reaches it undecided gives up (mode unknown until the tracker certifies one again)")
    p.add_argument("--certificate", metavar="JSON",
                   help="a certificate.json of crosscert certify: while the readings stay in its certified envelope "
                        "around the plan, its verdict holds for this execution from the sample its run decided")
    p.add_argument("--certified-plan", metavar="FILE",
                   help="with --certificate: the certified plan file (default: the one it names, beside it)")
    b = p.add_argument_group("ROS 2 bags (.mcap, .db3, or a bag's folder; pip install 'crosscert[bags]')")
    b.add_argument("--topic", help=f"topic of the sensor_msgs/msg/JointState messages (default: {DEFAULT_TOPIC})")
    b.add_argument("--joints", metavar="NAME,NAME",
                   help="the messages' names of the joints q1..qn, in order (required for a bag: the robots declare "
                        "no joint names; the error lists the names the messages carry)")
    b.add_argument("--stamp", choices=[s.value for s in Stamp],
                   help="a sample's time: the message's header stamp (the publisher's) or the bag's log time (when the "
                        f"recorder received it) (default: {Stamp.HEADER.value})")


def _task_options(p):
    _robot_option(p)
    p.add_argument("--start", help="start pose at rest, comma-separated, SI (default: 60 mm before the benchmark crossing)")
    p.add_argument("--goal", help="goal pose at rest in the other mode, SI (default: 60 mm after it)")


def build_parser(robot: str = DEFAULT_ROBOT) -> argparse.ArgumentParser:
    """The argument parser of ``crosscert``; ``--help`` shows the defaults of ``robot`` (a registered name)."""
    p = _Parser(prog="crosscert", formatter_class=_Formatter,
                description="Certify whether a parallel robot's motion through a Type 2 singularity changes its "
                            "assembly mode, from joint encoders alone, with interval analysis. Exit codes: 0 a "
                            "verdict, 2 bad input or usage, 3 the data contradict the assumptions (inconsistent), "
                            "130 interrupted. Robots (--robot of every command): "
                            f"{', '.join(available_robots())}; 'crosscert robots' lists them with their defaults.")
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    def command(name, help_):
        return sub.add_parser(name, help=help_, description=help_, formatter_class=_Formatter)

    c = command("check", "certify the assembly mode of a recorded joint trajectory")
    c.add_argument("trajectory", help="CSV file t,q1..qn[,qd1..qdn] (s, rad, rad/s), a ROS 2 bag (.mcap, .db3, a "
                                      "bag's folder) or an .npz of arrays t (K,) and q (K, n)")
    _tracker_options(c, robot)
    c.add_argument("--reasoning", choices=[r.value for r in Reasoning], default=Reasoning.WINDOW.value,
                   help="'window': when the forward tracker leaves the verdict open, contract the whole recording "
                        "forward and backward under each final-mode hypothesis; 'forward': the tracker alone")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.add_argument("--plot", help="write a PNG figure of the boxes")
    c.add_argument("--no-progress", action="store_true", help="no progress bar")

    mo = command("monitor", "certify the assembly mode online, from samples read one line at a time")
    mo.add_argument("trajectory", nargs="?", default="-",
                    help="CSV stream t,q1..qn[,qd1..qdn]: '-' for stdin, a named pipe or a file; or a ROS 2 bag "
                         "(.mcap, .db3, a bag's folder) or an .npz, read message by message")
    _tracker_options(mo, robot)
    mo.add_argument("--json", action="store_true", help="one JSON object per event, then one summary object")
    mo.add_argument("--reasoning", choices=[r.value for r in Reasoning], default=Reasoning.WINDOW.value,
                    help="'window': when the tracker loses the mode, reason over the readings from the last sample "
                         "whose mode it knew, on a thread of its own, and track the decided mode's boxes from its "
                         "decision on; 'forward': the tracker alone")
    mo.add_argument("--spread-hypotheses", action="store_true",
                    help="track the geometry hypotheses of each sample on several threads: lower latency on "
                         "dedicated cores, erratic on busy ones")

    s = command("simulate", "simulate encoder readings of the benchmark crossing (or a bounce)")
    _robot_option(s)
    s.add_argument("--v-sing", type=number, required=True, help="speed at the singularity, m/s")
    s.add_argument("--bounce", action="store_true", help="fail the crossing: stop on the locus and come back")
    s.add_argument("--seed", type=count, default=0,
                   help="seed of the true geometry drawn in the calibration box (0: its centre)")
    s.add_argument("--t-rest", type=number, default=0.3, help="rest before the motion, s")
    s.add_argument("--a-peak", type=number, default=SIM_A_PEAK, help="peak acceleration of the ramps, m/s^2")
    s.add_argument("--start-distance", type=number, metavar="D",
                   help="start at least D m before the crossing point along the path (a bounce: D before its turning "
                        "point), by lengthening the constant-speed zone; a start too close to the locus for the "
                        "calibration box cannot be told apart from the other mode (default: the ramp plus 5 mm)")
    s.add_argument("-o", "--output", required=True, help="CSV file to write")

    ce = command("certify", "minimal certified crossing speed of a task, with its proof and refutation bound; "
                            "or the verdict of your own planned trajectory (--plan)")
    _task_options(ce)
    ce.add_argument("--plan", metavar="FILE",
                    help="certify this planned trajectory instead of planning the task: CSV t,q1..qn[,x1..xn] at a "
                         "constant step, starting at rest (docs/file-formats.md, 'Planned trajectory')")
    ce.add_argument("--retime", action="store_true",
                    help="with --plan: keep the plan's path and re-time it: the slowest speed at the singularity at "
                         "which this path certifies (written as a plan to --out) and the refutation bound on it")
    ce.add_argument("--initial-mode", type=int, choices=(1, -1),
                    help="with --plan of joints only: the assembly mode at its first sample (+1/-1)")
    ce.add_argument("--xd0", type=numbers, metavar="V[,V...]",
                    help="with --plan: the initial speed bound per pose axis, each in its unit per s (default: the "
                         "robot's, a start at rest)")
    ce.add_argument("--a-max", type=numbers, metavar="A[,A...]",
                    help="end-effector acceleration bound per pose axis, each in its axis' unit (m/s^2 or rad/s^2), "
                         "comma-separated; one number for every axis when they share a unit (default: the robot's "
                         "physical a_max on every axis, or its declared tracking margin around the plan; "
                         "docs/planning.md)")
    ce.add_argument("--a-margin", type=number, metavar="R",
                    help="assume the controller tracks the plan's acceleration within a relative margin R: an axis "
                         "the plan accelerates is bounded by its planned peak x (1 + R) instead of the robot's a_max "
                         "(an assumption about the controller, printed with the certificate; default: none)")
    ce.add_argument("--eps-q", type=number, help=f"encoder error bound, {_unit(robot, 'eps_q')} (" + _robot_default(robot, "eps_q") + ")")
    ce.add_argument("--tracking-error", type=number, default=0.0, help="extra joint tracking error allowed, rad")
    ce.add_argument("--execution", choices=[k.value for k in ExecutionKind],
                    help="executions the certificate covers: 'cartesian' follow the planned path with any geometry "
                         "in the calibration box; 'joint' keep the joints within eps_q + tracking error of the plan "
                         "(default: cartesian; with --plan, joint when the file gives no poses)")
    ce.add_argument("--a-peak", type=number, default=PLAN_A_PEAK, help="peak acceleration of the planned ramps, m/s^2")
    ce.add_argument("--method", choices=[m.value for m in Method], default=Method.SMOOTHSTEP.value, help=METHOD_HELP)
    ce.add_argument("--one-motion", type=count, default=ONE_MOTION_SAMPLES, metavar="SAMPLES",
                    help="samples of the one-motion step: in the window passes, every geometry sub-box left when the "
                         f"budget is spent is refuted or narrowed by one geometry and one motion over this many samples "
                         f"(default {ONE_MOTION_SAMPLES}: v_min 0.929 m/s on the default task; 0: off, v_min 0.961 m/s "
                         "in about half the time)")
    ce.add_argument("--v-low", type=number, default=V_LOW, help="slowest speed tried, m/s")
    ce.add_argument("--v-high", type=number, help="fastest speed tried, m/s (default: the fastest the segment allows)")
    ce.add_argument("--tol", type=number, default=0.01, help="resolution of v_min, m/s")
    ce.add_argument("--refute-tol", type=number, metavar="TOL",
                    help="resolution of the refutation bound, m/s (default: a tenth of --tol; each halving is one "
                         "more counterexample search, run beside the Monte Carlo run)")
    ce.add_argument("--monte-carlo", type=count, default=50, help="simulated executions at v_min (0 skips)")
    ce.add_argument("--no-refute", action="store_true", help="skip the counterexample search")
    ce.add_argument("--seed", type=count, default=0, help="seed of the Monte Carlo executions and search starts")
    ce.add_argument("--out", default="crosscert-certify", help="folder for the PNG plot and the JSON report")
    ce.add_argument("--json", action="store_true", help="print the JSON report instead of the table")
    ce.add_argument("--no-progress", action="store_true", help="no progress bar")

    pl = command("plan", "plan a crossing at a given speed and write it as a trajectory file")
    _task_options(pl)
    pl.add_argument("--v-sing", type=number, required=True, help="speed at the singularity, m/s")
    pl.add_argument("--a-peak", type=number, default=PLAN_A_PEAK, help="peak acceleration of the ramps, m/s^2")
    pl.add_argument("--method", choices=[m.value for m in Method], default=Method.SMOOTHSTEP.value, help=METHOD_HELP)
    pl.add_argument("-o", "--output", required=True, help="CSV file to write (t, q1..qn, x1..xn)")

    w = command("sweep", "the paper's Table II on the simulated benchmark crossing")
    _robot_option(w)
    w.add_argument("--speeds", help="comma-separated speeds at the singularity, m/s (default: "
                                    f"{','.join(map(str, TABLE2_SPEEDS))})")
    w.add_argument("--seed", type=count, default=0,
                   help="seed of the true geometry drawn in the calibration box (0: its centre)")
    w.add_argument("--out", default="crosscert-sweep", help="folder for the PNG figures")
    w.add_argument("--no-progress", action="store_true", help="no progress bar")

    ro = command("robots", "list the robots (n, m, defaults, where each comes from: built-in, an installed entry point "
                           "or a file), or check one definition with --validate")
    ro.add_argument("--validate", metavar="NAME", help=f"run crosscert.validate on robot NAME ({', '.join(available_robots())}, "
                                                       "or path/to/robot.py:NAME)")
    ro.add_argument("--robot", dest="files", action="append", default=[], metavar="FILE.py:NAME",
                    help="list the robot of this file too (repeatable)")
    ro.add_argument("--seed", type=count, default=0, help="seed of the random configurations checked")
    ro.set_defaults(robot=DEFAULT_ROBOT)

    st = command("study", "design study: certify every point of a grid of bounds on Dask, one CSV row per case")
    st.add_argument("grid", help="TOML file: robot = NAME (optional), [grid] {input: [values]}, optional [bounds] "
                                 "and [certify] tables (docs/cli.md)")
    st.add_argument("--robot", default=DEFAULT_ROBOT,
                    help=f"robot of the cases: one of {', '.join(available_robots())} (the grid file's robot wins)")
    st.add_argument("-o", "--output", required=True,
                    help="CSV file the rows are appended to as cases finish; a rerun skips the cases already in it")
    where = st.add_mutually_exclusive_group()
    where.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://host:8786 "
                                           "(default: a local cluster)")
    where.add_argument("--workers", type=count,
                       help="single-threaded worker processes of the local cluster (default: one per core)")
    st.add_argument("--plot", help="write a PNG figure: v_min and the refutation bound against each swept input")
    st.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p
