"""Every option of every command checked against its meaning before any work starts.

Three kinds of checks, all cheap (no model is evaluated):

* **form** — numbers in ASCII decimal notation (``number`` and ``count`` of
  :mod:`planner.cli.parser` are its ``type=``), so ``1_0.5``, other
  scripts' digits, ``nan`` and ``inf`` are refused by the parser itself;
* **meaning** — sign, range and consistency with the robot (a plan may not
  accelerate beyond the robot's ``a_max``);
* **cost** — the samples a motion needs, and the memory and time they imply,
  refused above :data:`MEMORY_LIMIT` / :data:`TIME_LIMIT` with the number
  that would have been needed;

and every output path is checked (:func:`verifier.files.check_output_path`)
before the work whose result it receives.  docs/cli.md lists the limits.
"""

from __future__ import annotations

import math
import importlib.util
import os
from pathlib import Path

import numpy as np

from crosscert.robots.errors import InputError
from crosscert.robots.registry import get_entry, robot_key
from crosscert.verifier.files import check_output_path
from crosscert.verifier.recordings import RecordingFormat, recording_format, require_rosbags

from crosscert.robots.assumptions import check_bound

from ..certify.crossing import V_LOW
from ..simulate import ramp_length
from ..simulate.run import A_PEAK as SIM_A_PEAK, REST_END
from ..study import COLUMNS, GRID_KEYS, read_results, study_cases
from ..sweep import T_REST as SWEEP_T_REST
from ..task import Method, PlanningBounds, benchmark_task
from .parser import TABLE2_SPEEDS
from .setup import floats_option, simulation_cruise
from .study import read_grid

__all__ = ["MEMORY_LIMIT", "TIME_LIMIT", "MAX_CASES", "MAX_WORKERS", "check_command"]

#: Memory a command may plan to use, bytes: well below the 24 GiB of the
#: machines we run on, and far above any sensible crossing (~1 MB).
MEMORY_LIMIT = 1 << 30
#: Run time a command may plan for, s: a default certification takes ~30 s.
TIME_LIMIT = 3600.0
#: Bytes held per sample and joint by a simulated or planned motion: truth
#: (q, qd, qdd, x, xd, xdd), readings, the time law and IK scratch, ~24 float64.
_BYTES_PER_SAMPLE_JOINT = 24 * 8
#: Tracker cost per sample and scenario, s (benchmarks/README.md: ~0.1 ms,
#: with a margin for slower machines).
_TRACK_S_PER_SAMPLE = 5e-4
#: Largest encoder error or tracking error accepted, in the joint's unit (rad or m): 0.05 rad is an
#: encoder of ~126 counts per turn, coarser than any robot joint we know of; 0.05 m of a leg's stroke likewise.
MAX_JOINT_ERROR = 0.05
#: Largest acceleration bound accepted, in the axis' unit per s^2 (beyond is a typo).
MAX_ACCELERATION = 1e6
#: Largest initial speed bound accepted, in the axis' unit per s.
MAX_INITIAL_SPEED = 1e3
#: Longest sampling period accepted, s.
MAX_T_S = 10.0
#: Largest time stamp error accepted, s (half of the longest period: two stamps of one step would touch).
MAX_STAMP_ERROR = MAX_T_S / 2
#: Speeds at the singularity accepted, m/s (a plan or simulation beyond is a typo).
MAX_SPEED = 20.0
#: Finest resolution of v_min and of the refutation bound, m/s: each halving
#: below costs a certification (seconds) for digits nobody can act on.
MIN_TOL = 1e-4
#: Largest Monte Carlo confirmation, executions (memory: boxes of every sample).
MAX_MONTE_CARLO = 100_000
#: Longest anchored window of ``check``/``monitor --horizon``, samples (the readings and pose boxes it keeps,
#: and one attempt's work grow with it).
MAX_HORIZON = 100_000
#: Largest design study, cases (each is a certification of seconds to minutes).
MAX_CASES = 10_000
#: Largest local cluster of ``study --workers``, worker processes.
MAX_WORKERS = 256
#: Largest ``simulate --start-distance``, m: a typo guard (no robot's workspace is that large).
MAX_START_DISTANCE = 10.0
#: Largest ``width_scale`` of a study: a calibration box 100 times the robot's is far beyond any calibration.
MAX_WIDTH_SCALE = 100.0
#: Schemes of the Dask scheduler addresses ``study --scheduler`` takes with a HOST:PORT.
_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")


def _bound(option: str, field: str, v, robot, cap: float, *, axis: int | None = None) -> None:
    """A bound given on the command line (for every axis, or for ``axis``): admissible by the rule of its
    assumption (robots.assumptions, the one owner), and at most ``cap``, a typo guard of the CLI in its unit."""
    if v is None:
        return
    units = robot.assumptions.unit(field) if axis is None else robot.acceleration_units[axis]
    try:
        check_bound(field, v, robot.n, joint_units=robot.joint_units, pose_units=robot.pose_units)
        if v > cap:
            raise InputError(f"at most {cap:g} {units}")
    except InputError as exc:
        raise InputError(f"{option} = {v:g} {units} is out of range: {exc}") from None


def _in(name: str, v, lo: float, hi: float, *, lo_open: bool = True, unit: str = "") -> None:
    if v is None:
        return
    if not (lo < v if lo_open else lo <= v) or v > hi:
        left = "(" if lo_open else "["
        raise InputError(f"{name} = {v:g}{unit} is out of range: it must lie in {left}{lo:g}, {hi:g}]{unit}")


def _a_max_per_axis(a, robot) -> None:
    """``certify --a-max``: one bound per pose axis in its unit, or one number when every axis has the same unit."""
    if a.a_max is None:
        return
    units = robot.acceleration_units
    if len(a.a_max) not in (1, robot.n):
        raise InputError(f"--a-max takes 1 or {robot.n} comma-separated bounds for robot {robot.name} (axes in "
                         f"{', '.join(units)}), got {len(a.a_max)}")
    if len(a.a_max) == 1 and robot.mixed_units:
        raise InputError(f"--a-max {a.a_max[0]:g}: robot {robot.name}'s pose axes are in {', '.join(units)}, so one "
                         f"number cannot bound them all; give one per axis, e.g. --a-max "
                         f"{','.join(f'{v:g}' for v in robot.a_max)} (its physical a_max)")
    for i, v in enumerate(a.a_max):
        option = "--a-max" if len(a.a_max) == 1 else f"--a-max (axis {i + 1})"
        _bound(option, "a_max", v, robot, MAX_ACCELERATION, axis=None if len(a.a_max) == 1 else i)
    if len(a.a_max) == 1 and a.a_max[0] < a.a_peak:
        raise InputError(f"--a-max {a.a_max[0]:g} {units[0]} is below --a-peak {a.a_peak:g} {units[0]}: the plans "
                         "accelerate up to a_peak, so no plan would satisfy the bound")


def _budget(what: str, samples: float, n: int, *, scenarios: int = 1, tracked: bool = False,
            hint: str = "shorten the motion") -> None:
    """Refuse a run whose samples would need more than the memory or time limits."""
    memory = samples * scenarios * n * _BYTES_PER_SAMPLE_JOINT
    seconds = samples * scenarios * _TRACK_S_PER_SAMPLE if tracked else 0.0
    if memory > MEMORY_LIMIT or seconds > TIME_LIMIT or not math.isfinite(samples):
        raise InputError(
            f"{what} needs {samples * scenarios:.3g} samples (about {memory / 2**30:.3g} GiB"
            + (f" and {seconds:.3g} s of tracking" if tracked else "")
            + f"), above the limits of {MEMORY_LIMIT / 2**30:g} GiB and {TIME_LIMIT:g} s: {hint}")


def _a_peak_within_robot(a_peak: float, direction, robot) -> None:
    """A plan or simulation ramping at ``a_peak`` along ``direction`` stays within the robot's ``a_max``."""
    u = np.asarray(direction, dtype=float)
    u = u / np.linalg.norm(u)
    peak = a_peak * np.abs(u)
    if np.any(peak > robot.a_max_array):
        raise InputError(f"--a-peak {a_peak:g} m/s^2 exceeds the robot's bound a_max = {list(robot.a_max)} m/s^2 "
                         "along the motion; choose a smaller --a-peak")


def _output_file(path, what: str, suffixes: tuple[str, ...], inputs=()) -> None:
    if path is None:
        return
    if Path(path).suffix.lower() not in suffixes:
        raise InputError(f"{what}: {path!r} must end in {' or '.join(suffixes)} (the format written)")
    real = check_output_path(path, what=what)
    for src in inputs:
        if src not in (None, "-") and real.exists() and os.path.exists(src) and os.path.samefile(real, src):
            raise InputError(f"{what}: {path} is the input recording; choose another file")


def _output_folder(path, what: str, files: tuple[str, ...]) -> None:
    p = Path(path)
    if str(path) == "":
        raise InputError(f"{what}: empty path")
    if p.exists() and not p.is_dir():
        raise InputError(f"{what}: {p} exists and is not a folder")
    parent = p if p.exists() else p.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{what}: cannot create or write in {p}")
    for name in files:
        if (p / name).exists():
            check_output_path(p / name, what=what)


def _tracker(a, robot) -> None:
    for name, value, field in (("--a-max", a.a_max, "a_max"), ("--xd0", a.xd0, "xd0")):
        if value is not None and robot.mixed_units:
            raise InputError(f"{name} {value:g} bounds every pose axis with one number, but robot {robot.name}'s "
                             f"axes are in {', '.join(robot.pose_units)}: omit {name} to use the robot's per-axis "
                             f"{field} ({', '.join(f'{v:g}' for v in getattr(robot, field))})")
    _bound("--eps-q", "eps_q", a.eps_q, robot, MAX_JOINT_ERROR)
    _bound("--a-max", "a_max", a.a_max, robot, MAX_ACCELERATION)
    _bound("--xd0", "xd0", a.xd0, robot, MAX_INITIAL_SPEED)
    _bound("--t-s", "t_s", getattr(a, "t_s", None), robot, MAX_T_S)
    _in("--stamp-error", getattr(a, "stamp_error", None), 0.0, MAX_STAMP_ERROR, lo_open=False, unit=" s")
    if getattr(a, "certificate", None) and getattr(a, "stamp_error", 0.0):
        raise InputError("--certificate pairs each reading with the certified plan's sample of the same index, so it "
                         "covers executions sampled every period of the plan: drop --stamp-error, or --certificate")
    if a.x0 is not None:
        v = floats_option(a.x0, 2 * robot.n, "--x0")
        for i, (lo, hi) in enumerate(zip(v[0::2], v[1::2])):
            if lo > hi:
                raise InputError(f"--x0: component {i + 1} has lower bound {lo:g} above upper bound {hi:g}; "
                                 "write the box as XLO,XHI,YLO,YHI,... (each lower bound first)")


def joint_names(text: str, n: int) -> tuple[str, ...]:
    """``--joints NAME,NAME``: ``n`` distinct names (blanks around each ignored)."""
    names = tuple(v.strip() for v in text.split(","))
    if len(names) != n or not all(names):
        raise InputError(f"--joints {text!r}: give the {n} names of q1..q{n}, comma-separated, in order")
    if len(set(names)) != n:
        raise InputError(f"--joints {text!r}: a joint named twice")
    return names


def _recording(a, robot) -> None:
    """The bag options with a bag only; a bag needs the bags extra: said before any work."""
    fmt = recording_format(a.trajectory)
    given = [f"--{name}" for name in ("topic", "joints", "stamp") if getattr(a, name) is not None]
    if fmt is not RecordingFormat.BAG:
        if given:
            raise InputError(f"{', '.join(given)} read ROS 2 bags (.mcap, .db3 or a bag's folder); "
                             f"{a.trajectory} is read as {fmt.value}")
        return
    require_rosbags(a.trajectory)
    if a.joints is not None:
        joint_names(a.joints, robot.n)


def check_command(a, entry) -> None:
    """Check the options of command ``a.command`` for the registry ``entry``; InputError on the first bad one."""
    robot = entry.robot
    cmd = a.command
    if cmd == "study":
        missing = [m for m in ("distributed", "pandas") if importlib.util.find_spec(m) is None]
        if missing:
            raise InputError(f"crosscert study needs {' and '.join(missing)}: pip install 'crosscert[study]'")
        _study(a)
        return
    if cmd == "robots":
        if a.validate is not None:
            get_entry(a.validate)  # an unknown name fails here, listing the known ones
        return
    if cmd in ("check", "monitor"):
        _check_options(a, robot)
        return
    if cmd in ("simulate", "plan", "certify"):
        _in("--a-peak", a.a_peak, 0.0, 1e6, unit=" m/s^2")
    if cmd in ("simulate", "plan"):
        _in("--v-sing", a.v_sing, 0.0, MAX_SPEED, unit=" m/s")
    if cmd == "simulate":
        _simulate_options(a, entry, robot)
        return
    if cmd == "certify" and a.plan is not None:
        _given_plan(a, robot)
        return
    if cmd == "certify" and (a.initial_mode is not None or a.xd0 is not None or a.retime):
        raise InputError("--initial-mode, --xd0 and --retime are about a given plan: use them with --plan")
    if cmd in ("plan", "certify"):
        direction, length = _task_segment(a, entry)
        _a_peak_within_robot(a.a_peak, direction, robot)
    if cmd == "plan":
        _plan_options(a, robot, length)
        return
    if cmd == "certify":
        _certify_options(a, robot, length)
        return
    if cmd == "sweep":
        _sweep_options(a, robot)


def _check_options(a, robot) -> None:
    """``check`` and ``monitor``: the tracker's options, the recording, ``--horizon`` and ``--plot``."""
    cmd = a.command
    _tracker(a, robot)
    _recording(a, robot)
    _in("--horizon", a.horizon, 2, MAX_HORIZON, lo_open=False, unit=" samples")
    if cmd == "check" and a.plot is not None:
        _output_file(a.plot, "--plot", (".png",), inputs=(a.trajectory,))


def _simulate_options(a, entry, robot) -> None:
    """``simulate`` (after ``--a-peak`` and ``--v-sing``): ``--t-rest``, the bounce or reference motion, the
    start distance (m), the ramp's acceleration along the motion, the run's size and ``--output``."""
    _in("--t-rest", a.t_rest, 0.0, 600.0, lo_open=False, unit=" s")
    if entry.benchmark is None and entry.motion is not None:
        if a.bounce:
            raise InputError(f"robot {entry.name!r} ships no crossing, so there is no bounce to simulate; "
                             "drop --bounce to simulate its reference motion")
        if a.start_distance is not None:
            raise InputError(f"robot {entry.name!r} ships no crossing, so there is no locus to start away from; "
                             "drop --start-distance to simulate its reference motion")
        m = entry.reference_motion()
        direction = m.goal - m.start
    else:
        direction = entry.benchmark_crossing().direction
    if a.start_distance is not None:
        _in("--start-distance", a.start_distance, 0.0, MAX_START_DISTANCE, unit=" m")
    _a_peak_within_robot(a.a_peak, direction, robot)
    T = ramp_length(a.v_sing, a.a_peak)[0]
    # a bounce runs its ramps and cruise twice (there and back)
    duration = a.t_rest + (2 if a.bounce else 1) * (2 * T + 2 * simulation_cruise(a) / a.v_sing) + REST_END
    _budget(f"simulate at --v-sing {a.v_sing:g} m/s, --a-peak {a.a_peak:g} m/s^2, --t-rest {a.t_rest:g} s",
            duration / robot.t_s, robot.n)
    _output_file(a.output, "--output", (".csv",))


def _plan_options(a, robot, length: float) -> None:
    """``plan`` (after the task's segment, ``length`` m): the plan's size and ``--output``."""
    T = ramp_length(a.v_sing, a.a_peak)[0]
    duration = 2 * PlanningBounds.t_rest + 2 * T + length / a.v_sing  # rests, ramps, the whole segment at v_sing at most
    _budget(f"plan at --v-sing {a.v_sing:g} m/s", duration / robot.t_s, robot.n)
    _output_file(a.output, "--output", (".csv",))


def _certify_options(a, robot, length: float) -> None:
    """``certify`` of a task (after its segment, ``length`` m): the bounds, the speed bracket and tolerances
    (m/s), ``--monte-carlo``, the slowest plan's size and ``--out``."""
    _certify_bounds(a, robot)
    _in("--v-low", a.v_low, 0.0, MAX_SPEED, unit=" m/s")
    _in("--v-high", a.v_high, a.v_low, MAX_SPEED, unit=" m/s")
    _in("--tol", a.tol, MIN_TOL, 1.0, lo_open=False, unit=" m/s")
    _in("--refute-tol", a.refute_tol, MIN_TOL / 10, 1.0, lo_open=False, unit=" m/s")
    _in("--monte-carlo", a.monte_carlo, 0, MAX_MONTE_CARLO, lo_open=False)
    # the slowest plan bounds every batch: samples of a crossing at v_low
    T = ramp_length(a.v_low, a.a_peak)[0]
    samples = (2 * PlanningBounds.t_rest + 2 * T + length / a.v_low) / robot.t_s
    _budget(f"certify down to --v-low {a.v_low:g} m/s with --monte-carlo {a.monte_carlo}", samples, robot.n,
            scenarios=max(a.monte_carlo, 1), tracked=True, hint="raise --v-low or lower --monte-carlo")
    _output_folder(a.out, "--out", ("certificate.json",))


def _sweep_options(a, robot) -> None:
    """``sweep``: ``--speeds`` (m/s; parsed into ``a.speeds_list``), the slowest run's size and ``--out``."""
    a.speeds_list = tuple(floats_option(a.speeds, None, "--speeds")) if a.speeds else TABLE2_SPEEDS
    for v in a.speeds_list:
        _in("--speeds", v, 0.0, MAX_SPEED, unit=" m/s")
    if len(a.speeds_list) > 100:
        raise InputError(f"--speeds: {len(a.speeds_list)} speeds; at most 100")
    slowest = min(a.speeds_list)
    T = ramp_length(slowest, SIM_A_PEAK)[0]
    _budget(f"sweep at {slowest:g} m/s", (SWEEP_T_REST + 2 * T + 0.07 / slowest + REST_END) / robot.t_s, robot.n,
            scenarios=2 * len(a.speeds_list), tracked=True, hint="drop the slowest speeds")
    _output_folder(a.out, "--out", ())


def _study_output(path) -> None:
    """``study -o``: a new CSV, or the output of a study (its rows are kept and its finished cases skipped)."""
    _output_file(path, "--output", (".csv",))
    p = Path(path)
    if p.exists() and p.stat().st_size > 0:
        with p.open(newline="") as fh:
            head = fh.readline(4096).rstrip("\r\n")
        if head != ",".join(COLUMNS):
            raise InputError(f"--output: {path} is not the CSV of a study (its header differs); choose a new file "
                             "or the output of an earlier run of this study")


def _scheduler(address) -> None:
    """``study --scheduler``: the form of a Dask scheduler address (a reachable one is the run's business)."""
    if address is None:
        return
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address, strict=False)
        if scheme in _SCHEMES:
            parse_host_port(location)
    except (ValueError, TypeError) as exc:
        raise InputError(f"--scheduler {address!r} is not the address of a Dask scheduler ({exc}); "
                         "write tcp://HOST:PORT, e.g. tcp://127.0.0.1:8786") from None


def _same_study(path, cases, grid_file) -> None:
    """``study -o``: the rows already in the CSV are cases of this grid (one CSV holds one study)."""
    ids = {c.case_id for c in cases}
    foreign = [r for r in read_results(path) if r["case_id"] not in ids]
    if foreign:
        r = foreign[0]
        inputs = ", ".join(f"{k} = {r[k]}" for k in GRID_KEYS if r.get(k, "") != "")
        raise InputError(f"--output: {path} holds {len(foreign)} row(s) of another grid (e.g. {inputs or 'no input'}) "
                         f"that {grid_file} does not have; one CSV holds one study: choose a new -o, or the grid "
                         "that wrote it (values may be added to a grid, not removed)")


def _width_scales(name: str, values, robot) -> None:
    """A study's ``width_scale`` values: at most :data:`MAX_WIDTH_SCALE`, and no parameter of the box changes sign."""
    lo, hi = robot.xi_lo_array, robot.xi_hi_array
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    offsets = np.isin(np.arange(robot.m), [j for j in (robot.joint_offsets or ()) if j is not None])
    scaled = {"width_scale.lengths": ~offsets, "width_scale.offsets": offsets}.get(name, np.ones(robot.m, bool))
    for v in values:
        _in(f"[grid] {name}", v, 0.0, MAX_WIDTH_SCALE)
        flips = np.flatnonzero(scaled & (centre != 0) & (v * half >= np.abs(centre)))
        if flips.size:
            i = int(flips[0])
            raise InputError(f"[grid] {name} = {v:g} widens the calibration box of {robot.name} past zero for "
                             f"parameter {robot.param_names[i]} (centre {centre[i]:g}, half-width {half[i]:g} before "
                             "scaling): a length would change sign; choose a smaller scale")


def _study(a) -> None:
    """``study``: the options, the grid file (read once, kept as ``a.spec``), and the size of the study."""
    _in("--workers", a.workers, 1, MAX_WORKERS, lo_open=False)
    _scheduler(a.scheduler)
    _study_output(a.output)
    _output_file(a.plot, "--plot", (".png",))
    spec = read_grid(a.grid)
    if spec["robot"] is not None:
        a.robot = robot_key(spec["robot"])  # the grid file's robot wins over --robot
    grid, bounds, cert = spec["grid"], spec["bounds"], spec["certify"]
    cases = study_cases(grid)
    if len(cases) > MAX_CASES:
        raise InputError(f"{a.grid}: the grid has {len(cases)} cases, more than {MAX_CASES}; drop some values")
    _same_study(a.output, cases, a.grid)
    values = {k: [c.values[k] for c in cases] for k in grid}
    study_robot = get_entry(a.robot).robot
    for v in values.get("eps_q", ()):
        _bound("[grid] eps_q", "eps_q", v, study_robot, MAX_JOINT_ERROR)
    for v in values.get("a_max", ()):
        _bound("[grid] a_max", "a_max", v, study_robot, MAX_ACCELERATION)
    if isinstance(bounds.get("eps_q"), (int, float)) and not isinstance(bounds["eps_q"], bool):
        _bound("[bounds] eps_q", "eps_q", bounds["eps_q"], study_robot, MAX_JOINT_ERROR)
    if isinstance(bounds.get("tracking_error"), (int, float)) and not isinstance(bounds["tracking_error"], bool):
        _in("[bounds] tracking_error", bounds["tracking_error"], 0.0, MAX_JOINT_ERROR, lo_open=False,
            unit=" " + study_robot.assumptions.unit("eps_q"))
    if isinstance(bounds.get("a_peak"), (int, float)) and not isinstance(bounds.get("a_peak"), bool):
        _in("[bounds] a_peak", bounds["a_peak"], 0.0, 1e6, unit=" m/s^2")
    _in("[certify] tol", cert.get("tol"), MIN_TOL, 1.0, lo_open=False, unit=" m/s")
    _in("[certify] refute_tol", cert.get("refute_tol"), MIN_TOL / 10, 1.0, lo_open=False, unit=" m/s")
    v_low = cert.get("v_low", V_LOW)
    _in("[certify] v_low", v_low, 0.0, MAX_SPEED, unit=" m/s")
    _in("[certify] v_high", cert.get("v_high"), v_low, MAX_SPEED, unit=" m/s")
    _in("[certify] monte_carlo_runs", cert.get("monte_carlo_runs"), 0, MAX_MONTE_CARLO, lo_open=False)
    runs = cert.get("monte_carlo_runs", 50)
    for name in sorted(set(values.get("robot", [a.robot]))):
        entry = get_entry(name)
        for k in ("width_scale", "width_scale.lengths", "width_scale.offsets"):
            _width_scales(k, sorted(set(values.get(k, ()))), entry.robot)
        dynamic = bounds.get("method") == Method.DYNAMIC or Method.DYNAMIC in values.get("method", ())
        kw = dict(bounds, dynamics=entry.require_dynamics() if dynamic else None)
        try:
            b = PlanningBounds(**kw).resolve(entry.robot)
        except TypeError as exc:  # a value of the wrong kind deep inside numpy
            raise InputError(f"{a.grid}: [bounds]: {exc}") from None
        # the slowest plan of a case bounds its batches: a crossing at v_low with the lowest ramps
        a_peak = min([b.a_peak, *values.get("a_max", ())])
        T = ramp_length(v_low, a_peak)[0]
        task = benchmark_task(entry)
        length = float(np.linalg.norm(task.goal - task.start))
        samples = (2 * b.t_rest + 2 * T + length / v_low) / b.t_s
        _budget(f"a study case of {name} down to [certify] v_low = {v_low:g} m/s with monte_carlo_runs = {runs}",
                samples, entry.robot.n, scenarios=max(runs, 1), tracked=True,
                hint="raise [certify] v_low or lower monte_carlo_runs")
    a.spec = spec


def _certify_bounds(a, robot) -> None:
    """``certify``'s bounds, with or without ``--plan``: reading error, tracking error, acceleration."""
    _bound("--eps-q", "eps_q", a.eps_q, robot, MAX_JOINT_ERROR)
    _in("--tracking-error", a.tracking_error, 0.0, MAX_JOINT_ERROR, lo_open=False,
        unit=" " + robot.assumptions.unit("eps_q"))
    _a_max_per_axis(a, robot)
    if a.a_margin is not None and a.a_max is not None:
        raise InputError("--a-margin and --a-max both set the acceleration bound: give one")
    _in("--a-margin", a.a_margin, 0.0, 10.0, lo_open=False)


def _given_plan(a, robot) -> None:
    """``certify --plan``: the options that apply, the file readable, its samples within the limits."""
    given = [o for o, v in (("--start", a.start), ("--goal", a.goal), ("--v-high", a.v_high)) if v is not None]
    if given:
        raise InputError(f"--plan certifies the given trajectory: {', '.join(given)} plan a task; drop them")
    _certify_bounds(a, robot)
    _in("--monte-carlo", a.monte_carlo, 0, MAX_MONTE_CARLO, lo_open=False)
    if a.retime:
        _in("--v-low", a.v_low, 0.0, MAX_SPEED, unit=" m/s")
        _in("--tol", a.tol, MIN_TOL, 1.0, lo_open=False, unit=" m/s")
        _in("--refute-tol", a.refute_tol, MIN_TOL / 10, 1.0, lo_open=False, unit=" m/s")
    if a.xd0 is not None:
        if len(a.xd0) not in (1, robot.n) or (len(a.xd0) == 1 and robot.mixed_units):
            raise InputError(f"--xd0 takes {robot.n} comma-separated bounds for robot {robot.name} (axes in "
                             f"{', '.join(robot.velocity_units)}){' or one for all' if not robot.mixed_units else ''}, "
                             f"got {len(a.xd0)}")
        for i, v in enumerate(a.xd0):
            _bound("--xd0" if len(a.xd0) == 1 else f"--xd0 (axis {i + 1})", "xd0", v, robot, MAX_SPEED)
    path = Path(a.plan)
    if not path.is_file():
        raise InputError(f"--plan: {a.plan} is not a readable file")
    with open(path, "rb") as fh:
        samples = sum(1 for _ in fh) - 1
    _budget(f"certify --plan {a.plan} with --monte-carlo {a.monte_carlo}", samples, robot.n,
            scenarios=max(a.monte_carlo, 1), tracked=True, hint="shorten the plan or lower --monte-carlo")
    _output_folder(a.out, "--out", ("certificate.json",))


def _task_segment(a, entry) -> tuple[np.ndarray, float]:
    """Unit direction and length (m) of the task of ``--start``/``--goal`` (the benchmark's by default), without IK."""
    task = benchmark_task(entry)
    n = entry.robot.n
    start = np.array(floats_option(a.start, n, "--start")) if a.start is not None else task.start
    goal = np.array(floats_option(a.goal, n, "--goal")) if a.goal is not None else task.goal
    d = goal - start
    length = float(np.linalg.norm(d))
    if not length > 0:
        raise InputError("--start and --goal coincide")
    return d / length, length
