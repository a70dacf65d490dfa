"""What the commands share: robots from the registry, tasks, tracker settings, progress bars."""

from __future__ import annotations

import sys
import threading

import numpy as np

from crosscert.robots import KinematicModel
from crosscert.robots.errors import InputError, ModelError
from crosscert.robots.registry import RobotEntry, RobotSource, get_entry, robot_origin
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.settings import TrackerSettings
from crosscert.verifier.trajfile import parse_number
from crosscert.verifier.validation import validate

from ..simulate import random_geometry
from ..simulate.run import CRUISE
from ..sweep import cruise_for
from ..task import CrossingTask, benchmark_task

__all__ = ["checked_entry", "simulation_cruise",
           "floats_option", "tracker_setup", "task_setup", "benchmark_setup", "true_geometry", "progress_bar", "PhaseBar",
           "phase_bar", "COMPILING", "compile_ahead", "compile_note", "FIRST_COMPILE_S"]


def floats_option(text: str, count: int | None, what: str) -> list[float]:
    """The comma-separated numbers of option ``what`` (``count`` of them, any number when None)."""
    try:
        vals = [parse_number(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{what}: expected comma-separated numbers, got {text!r}") from None
    if count is not None and len(vals) != count:
        raise InputError(f"{what}: expected {count} comma-separated numbers, got {len(vals)}")
    return vals


#: Robots from a file or an entry point that passed every check of ``crosscert.validate`` in this process.
_VALIDATED: set[str] = set()


def checked_entry(name: str) -> RobotEntry:
    """The registry entry of robot ``name``; a robot from a file or an entry point is validated first (every
    check of :func:`crosscert.validate`, about 0.3 s, once per process), the built-in ones are tested.

    Raises
    ------
    ModelError
        One line naming the failed checks and the command that prints the report.
    """
    entry = get_entry(name)
    origin = robot_origin(name)
    if origin.source is not RobotSource.BUILT_IN and name not in _VALIDATED:
        report = validate(entry.robot)
        if not report.ok:
            failed = "; ".join(f"{c.name}: {c.message}" for c in report.failures)
            raise ModelError(f"robot {entry.robot.name!r} ({origin}) fails validation ({' '.join(failed.split())}); "
                             f"'crosscert robots --validate {name}' prints every check")
        _VALIDATED.add(name)
    return entry


def tracker_setup(a):
    """Robot, interval model, the settings maker ``t_s -> TrackerSettings`` and the ``--x0`` box (or None)."""
    robot = get_entry(a.robot).robot
    x0 = None
    if a.x0 is not None:
        v = floats_option(a.x0, 2 * robot.n, "--x0")
        x0 = (np.array(v[0::2]), np.array(v[1::2]))

    def settings(t_s):
        return TrackerSettings.for_robot(robot, t_s=t_s, eps_q=a.eps_q, a_max=a.a_max, xd0=a.xd0,
                                         velocity_model=a.velocity_model)

    return robot, IntervalModel(robot), settings, x0


def compile_ahead(velocity_model: str = "sound") -> None:
    """Before a command's setup: the tracker's driver compiled in a child process meanwhile, when it is
    not cached yet (the first run after an install; :mod:`verifier.compiled.warm`)."""
    from crosscert.verifier.compiled import warm

    warm.start(velocity_model)


#: Wall time of the kernels' first compilation, s: ``crosscert sweep``'s first run after an install took about
#: 20 s more than the next ones on 2 shared cores (benchmarks/README.md#timings).
FIRST_COMPILE_S = 20


def compile_note(*velocity_models) -> bool:
    """Say on stderr, in one line, that the kernels compile now when the driver of one of ``velocity_models``
    (names or :class:`verifier.settings.VelocityModel`) is not in numba's disk cache yet: the first run after
    an install waits for it without a terminal's progress bar.  Returns whether it said so."""
    from crosscert.verifier.compiled import warm
    from crosscert.verifier.constants import velocity_model_code

    if all(warm.cached(velocity_model_code(vm)) for vm in velocity_models):
        return False
    print(f"crosscert: compiling the kernels (first run only, about {FIRST_COMPILE_S} s)", file=sys.stderr)
    return True


def benchmark_setup(name: str):
    """Registry entry, kinematic model and nominal benchmark crossing of robot ``name``."""
    entry = get_entry(name)
    bench = entry.benchmark_crossing()
    return entry, KinematicModel(entry.robot), bench


def task_setup(a):
    """Registry entry, kinematic model and the task of ``--start``/``--goal`` (default: the benchmark task)."""
    entry, kin, bench = benchmark_setup(a.robot)
    n = entry.robot.n
    task = benchmark_task(entry)
    if a.start is not None or a.goal is not None:
        start = task.start if a.start is None else np.array(floats_option(a.start, n, "--start"))
        goal = task.goal if a.goal is None else np.array(floats_option(a.goal, n, "--goal"))
        task = CrossingTask(start, goal, bench.q_point)
    return entry, kin, task


def true_geometry(robot, seed: int):
    """The true geometry of a simulation: the box centre for seed 0 (None), else a seeded draw in ``[xi]``."""
    if seed == 0:
        return None
    return random_geometry(robot, np.random.default_rng(seed))


def simulation_cruise(a) -> float:
    """Half-length (m) of ``simulate``'s constant-speed zone around the crossing: the default, or long enough
    that the start lies ``--start-distance`` before the crossing point (a crossing starts its ramp plus this
    zone before it; a bounce twice that before its turning point)."""
    if a.start_distance is None:
        return CRUISE
    return cruise_for(a.v_sing, a.a_peak, a.start_distance / 2 if a.bounce else a.start_distance, CRUISE)


def progress_bar(total, enabled: bool, desc: str):
    """A tqdm bar on stderr (``total`` None: open-ended) and its per-sample callback, or ``(None, None)``
    (progress off, or stderr not a terminal)."""
    if not enabled or not _terminal():
        return None, None
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="step", file=sys.stderr, leave=False)
    return bar, (lambda k: bar.update(1))


#: What the bar says while numba compiles (the first run after an install; loads from the cache are quick).
COMPILING = "compiling kernels (once after install)"


class PhaseBar:
    """One tqdm bar per named phase on stderr, with its total and elapsed time (:class:`planner.progress.Progress`).

    A thread redraws the bar every half second, so a phase that counts nothing for a while (a wait
    for the counterexample searches) still shows its time going; while numba compiles a kernel (a
    cache miss: the first run after an install) the bar says so instead of the phase.
    """

    def __init__(self, desc: str):
        from numba.core import event
        from tqdm import tqdm

        self._tqdm, self._event, self._desc = tqdm, event, desc
        self._lock = threading.RLock()
        self._bar = None
        self._name = desc
        self._compiling = 0
        self._stop = threading.Event()
        self._listener = _compile_listener(self)
        event.register("numba:compile", self._listener)
        self._ticker = threading.Thread(target=self._tick, name="crosscert-progress", daemon=True)
        self._ticker.start()
        self.phase("starting", unit="")

    def phase(self, name: str, total: int | None = None, unit: str = "step") -> None:
        """A new bar for phase ``name`` (``unit`` empty: a wait, drawn as its name and elapsed time)."""
        with self._lock:
            if self._bar is not None:
                self._bar.close()
            self._name = name
            # a phase that counts nothing (a wait) shows its name and elapsed time only
            fmt = "{desc} [{elapsed}]" if total is None and not unit else None
            self._bar = self._tqdm(total=total, desc=self._label(), unit=unit or "step", file=sys.stderr, leave=False,
                                   bar_format=fmt)

    def __call__(self, done=1) -> None:
        with self._lock:
            if self._bar is not None:
                self._bar.update(1)

    def _label(self) -> str:
        return f"{self._desc}: {COMPILING}" if self._compiling else f"{self._desc}: {self._name}"

    def compiling(self, started: bool) -> None:
        with self._lock:
            self._compiling += 1 if started else -1
            if self._bar is not None and self._compiling <= 1:
                self._bar.set_description_str(self._label(), refresh=False)

    def _tick(self) -> None:
        while not self._stop.wait(0.5):
            with self._lock:
                if self._bar is not None:
                    self._bar.refresh()

    def close(self) -> None:
        """End the display (again: nothing)."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._event.unregister("numba:compile", self._listener)
        with self._lock:
            if self._bar is not None:
                self._bar.close()
                self._bar = None


def _compile_listener(bar: PhaseBar):
    """numba's compile events (start and end of a compilation, not of a cache load) to :meth:`PhaseBar.compiling`."""
    from numba.core import event

    class Listener(event.Listener):
        def on_start(self, ev):
            bar.compiling(True)

        def on_end(self, ev):
            bar.compiling(False)

    return Listener()


def phase_bar(enabled: bool, desc: str):
    """A :class:`PhaseBar` (None when progress is off, or stderr is not a terminal: a log gets no bar)."""
    return PhaseBar(desc) if enabled and _terminal() else None


def _terminal() -> bool:
    """Whether stderr is a terminal (progress bars are drawn there only)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced or closed stderr
        return False
