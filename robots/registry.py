"""The registry: the only place commands and studies find a robot by name.

A :class:`RobotEntry` bundles what the layers above need besides the robot's
kinematics: an optional lumped dynamic model (the ``dynamic`` time law) and an
optional benchmark crossing (the default task of ``plan``, ``certify``,
``simulate`` and ``sweep``).  Nothing outside ``robots/`` names a robot.

A robot comes from one of three places (:class:`RobotSource`): the built-in
table :data:`ROBOTS`, an installed distribution's entry point in the group
:data:`ENTRY_POINT_GROUP` (found the way pytest finds its plugins, loaded only
when its name is asked for or the robots are listed), or a Python file named
as ``path/to/file.py:NAME``.  :func:`get_entry` takes any of these names.
"""

from __future__ import annotations

import enum
import hashlib
import importlib.metadata
import importlib.util
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .base import BenchmarkCrossing, ReferenceMotion, Robot
from .gough_stewart import GOUGH_STEWART, gs_reference_motion
from .dextar import DEXTAR, DEXTAR_DYNAMICS, benchmark_crossing
from .iri_five_bar import IRI_FIVE_BAR, iri_benchmark_crossing
from .mass_model import LumpedMassModel
from .rpr3 import RPR3, rpr3_benchmark_crossing
from .errors import InputError, RobotSourceError, UnknownRobotError

__all__ = ["RobotEntry", "ROBOTS", "DEFAULT_ROBOT", "ENTRY_POINT_GROUP", "RobotSource", "RobotOrigin", "available_robots",
           "get_entry", "get_robot", "robot_origin", "robot_key", "listed_robots", "is_robot_file"]


@dataclass(frozen=True, eq=False)
class RobotEntry:
    """A registered robot and what it ships with.

    Attributes
    ----------
    robot : Robot
        Parameters and loop closure.
    dynamics : LumpedMassModel or None
        Lumped dynamic model, when the robot has one.
    benchmark : callable ``xi -> BenchmarkCrossing`` or None
        Its reference crossing for a geometry (``None``: nominal).
    motion : callable ``xi -> ReferenceMotion`` or None
        A regular reference motion for ``simulate`` (robots without a
        benchmark crossing).
    """

    robot: Robot
    dynamics: LumpedMassModel | None = None
    benchmark: Callable[..., BenchmarkCrossing] | None = None
    motion: Callable[..., ReferenceMotion] | None = None

    @property
    def name(self) -> str:
        """Registry name (lower case)."""
        return self.robot.name.lower()

    def require_dynamics(self) -> LumpedMassModel:
        """The dynamic model, or InputError naming what to use instead."""
        if self.dynamics is None:
            raise InputError(f"robot {self.robot.name!r} has no dynamic model; use method smoothstep or time-optimal")
        return self.dynamics

    def benchmark_crossing(self, xi=None) -> BenchmarkCrossing:
        """The benchmark crossing for geometry ``xi`` (nominal when None), or InputError if there is none."""
        if self.benchmark is None:
            raise InputError(f"robot {self.robot.name!r} ships no crossing benchmark, so crossing planning "
                             "(plan, certify, sweep, study) is not available for it; check, monitor and simulate are")
        return self.benchmark(xi)

    def reference_motion(self, xi=None) -> ReferenceMotion:
        """The reference motion for geometry ``xi`` (nominal when None), or InputError if there is none."""
        if self.motion is None:
            raise InputError(f"robot {self.robot.name!r} has no reference motion")
        return self.motion(xi)


#: Built-in robots by lower-case name (a program may add its own entries here).
ROBOTS: dict[str, RobotEntry] = {
    e.name: e
    for e in (
        RobotEntry(DEXTAR, DEXTAR_DYNAMICS, benchmark_crossing),
        RobotEntry(IRI_FIVE_BAR, None, iri_benchmark_crossing),
        RobotEntry(RPR3, None, rpr3_benchmark_crossing),
        RobotEntry(GOUGH_STEWART, None, None, gs_reference_motion),
    )
}

#: The robot commands use when ``--robot`` is not given.
DEFAULT_ROBOT = "dextar"

#: The entry-point group in which an installed distribution registers robots: each entry point is named
#: after its robot and refers to a :class:`RobotEntry` (or a :class:`Robot`), e.g. in ``pyproject.toml``
#: ``[project.entry-points."crosscert.robots"]`` ``my-five-bar = "my_robots.five_bar:ENTRY"``.
ENTRY_POINT_GROUP = "crosscert.robots"


class RobotSource(enum.Enum):
    """Where a robot definition comes from."""

    BUILT_IN = "built-in"  #: the table :data:`ROBOTS`
    ENTRY_POINT = "entry point"  #: an installed distribution's entry point in :data:`ENTRY_POINT_GROUP`
    FILE = "file"  #: a Python file named as ``path/to/file.py:NAME``


@dataclass(frozen=True)
class RobotOrigin:
    """Where a robot comes from: its :class:`RobotSource` and, for an entry point or a file, which one.

    Attributes
    ----------
    source : RobotSource
    where : str
        Entry point: ``"DIST VERSION (module:attr)"``; file: ``"/absolute/path.py:NAME"``; built-in: ``""``.
    """

    source: RobotSource
    where: str = ""

    def __str__(self) -> str:
        return f"{self.source.value} {self.where}" if self.where else self.source.value


_BUILT_IN = RobotOrigin(RobotSource.BUILT_IN)
#: Entries loaded from entry points and files, by :func:`robot_key`: each is loaded once per process.
_LOADED: dict[str, tuple[RobotEntry, RobotOrigin]] = {}


def is_robot_file(name) -> bool:
    """Whether ``name`` names a robot file, ``path/to/file.py`` or ``path/to/file.py:NAME``."""
    if not isinstance(name, str):
        return False
    head, sep, _attr = name.strip().rpartition(":")
    return (head if sep else name.strip()).endswith(".py")


def _entry_points() -> dict:
    """The installed entry points of :data:`ENTRY_POINT_GROUP` by lower-case name (the first on ``sys.path``
    wins, as for a module); their targets are not imported."""
    out: dict = {}
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        out.setdefault(ep.name.strip().lower(), ep)
    return out


def available_robots() -> list[str]:
    """Sorted names of the built-in robots and of the installed entry points (robot files have no name here)."""
    return sorted(set(ROBOTS) | set(_entry_points()))


def _as_entry(obj, what: str) -> RobotEntry:
    """``obj`` as a :class:`RobotEntry` (a bare :class:`Robot` ships nothing), or RobotSourceError naming ``what``."""
    if isinstance(obj, RobotEntry):
        if not isinstance(obj.robot, Robot):
            raise RobotSourceError(f"{what}: its RobotEntry holds a {type(obj.robot).__name__}, not a Robot")
        return obj
    if isinstance(obj, Robot):
        return RobotEntry(obj)
    raise RobotSourceError(f"{what} is a {type(obj).__name__}, not a RobotEntry (or a Robot)")


def _failure(exc: BaseException, path: Path) -> str:
    """An exception raised while running a user's file, as one line with the file's line where it was raised."""
    line = exc.lineno if isinstance(exc, SyntaxError) else None
    tb = exc.__traceback__
    while tb is not None:  # the innermost frame of the user's file
        if Path(tb.tb_frame.f_code.co_filename) == path:
            line = tb.tb_lineno
        tb = tb.tb_next
    text = " ".join(str(exc).split()) or "(no message)"
    return f"{type(exc).__name__} at line {line}: {text}" if line else f"{type(exc).__name__}: {text}"


def _file_entry(spec: str) -> tuple[str, RobotEntry, RobotOrigin]:
    """Load ``path.py[:NAME]``: its key (absolute path and name), entry and origin."""
    spec = spec.strip()
    head, sep, attr = spec.rpartition(":")
    path_text, attr = (head, attr.strip()) if sep and head.endswith(".py") else (spec, "")
    try:
        path = Path(path_text).expanduser().resolve(strict=True)
    except (OSError, RuntimeError):
        raise RobotSourceError(f"robot file {path_text!r} does not exist") from None
    if not path.is_file():
        raise RobotSourceError(f"robot file {path_text!r} is not a file")
    for (key, (entry, origin)) in _LOADED.items():
        if origin.source is RobotSource.FILE and key.rpartition(":")[0] == str(path) and (not attr or key.endswith(f":{attr}")):
            return key, entry, origin
    # a module name of its own per file: dataclasses and pickle look a function's module up by this name
    module_name = "crosscert_robot_file_" + hashlib.sha1(str(path).encode()).hexdigest()[:12]
    module = sys.modules.get(module_name)
    if module is None:
        loader = importlib.util.spec_from_file_location(module_name, path)
        if loader is None or loader.loader is None:
            raise RobotSourceError(f"robot file {path} cannot be imported as Python")
        module = importlib.util.module_from_spec(loader)
        sys.modules[module_name] = module
        try:
            loader.loader.exec_module(module)
        except Exception as exc:  # the user's code: any error is reported as one line naming its file and line
            del sys.modules[module_name]
            raise RobotSourceError(f"robot file {path} failed: {_failure(exc, path)}") from None
    entries = sorted(k for k, v in vars(module).items() if isinstance(v, RobotEntry) and not k.startswith("_"))
    if not attr:
        if len(entries) != 1:
            which = f"it defines {', '.join(entries)}" if entries else "it defines no RobotEntry"
            raise RobotSourceError(f"robot file {path}: name the robot entry as {path_text}:NAME ({which})")
        attr = entries[0]
    if not hasattr(module, attr):
        which = f"its robot entries: {', '.join(entries)}" if entries else "it defines no RobotEntry"
        raise RobotSourceError(f"robot file {path} defines no {attr!r} ({which})")
    key = f"{path}:{attr}"
    entry = _as_entry(getattr(module, attr), f"{attr} in robot file {path}")
    origin = RobotOrigin(RobotSource.FILE, key)
    _LOADED[key] = (entry, origin)
    return key, entry, origin


def _entry_point_entry(name: str, ep) -> tuple[RobotEntry, RobotOrigin]:
    """Load the entry point ``ep`` called ``name`` (lower case)."""
    dist = getattr(ep, "dist", None)
    who = f"{dist.name} {dist.version}" if dist is not None else "an unknown distribution"
    key = f"entry-point:{name}"
    if key in _LOADED:
        return _LOADED[key]
    what = f"entry point {ep.name!r} of {who} ({ep.value})"
    try:
        obj = ep.load()
    except Exception as exc:  # the distribution's code: reported as one line naming the entry point
        raise RobotSourceError(f"{what} failed to load: {type(exc).__name__}: {' '.join(str(exc).split())}") from None
    entry = _as_entry(obj, what)
    if entry.name != name:
        raise RobotSourceError(f"{what} holds the robot {entry.robot.name!r}: name the entry point after its robot")
    _LOADED[key] = (entry, RobotOrigin(RobotSource.ENTRY_POINT, f"{who} ({ep.value})"))
    return _LOADED[key]


def _resolve(name) -> tuple[str, RobotEntry, RobotOrigin]:
    """Key, entry and origin of the robot ``name`` (built-in, entry point or file)."""
    if is_robot_file(name):
        return _file_entry(name)
    key = name.strip().lower() if isinstance(name, str) else name
    try:
        return key, ROBOTS[key], _BUILT_IN
    except (KeyError, TypeError):
        pass
    ep = _entry_points().get(key) if isinstance(key, str) else None
    if ep is not None:
        return (key, *_entry_point_entry(key, ep))
    raise UnknownRobotError(
        f"unknown robot {name!r}; known robots: {', '.join(available_robots())}; "
        "a robot of your own: path/to/file.py:NAME, NAME a RobotEntry the file defines"
    ) from None


def get_entry(name: str) -> RobotEntry:
    """The robot entry called ``name``: a built-in robot or an installed entry point (case and surrounding
    blanks ignored), or ``path/to/file.py:NAME`` (the ``RobotEntry`` or ``Robot`` called ``NAME`` in that
    file; ``:NAME`` may be left out when the file defines one ``RobotEntry``).

    A file or an entry point is loaded once per process.

    Raises
    ------
    UnknownRobotError
        If no robot has that name; the message lists the known names.
    RobotSourceError
        If a file or an entry point cannot be loaded (missing file, an exception in its code, no such
        name in it) or does not hold a robot entry; one line saying which and why.
    """
    return _resolve(name)[1]


def get_robot(name: str) -> Robot:
    """The :class:`Robot` called ``name`` (see :func:`get_entry`)."""
    return get_entry(name).robot


def robot_origin(name: str) -> RobotOrigin:
    """Where the robot ``name`` (as for :func:`get_entry`) comes from."""
    return _resolve(name)[2]


def robot_key(name: str) -> str:
    """The name that finds robot ``name`` again in any process: its lower-case name, or for a file
    ``/absolute/path.py:NAME`` (a relative path resolved against the current folder)."""
    return _resolve(name)[0]


def listed_robots(files=()) -> list[tuple[str, RobotEntry, RobotOrigin]]:
    """Every built-in robot, every installed entry point (loaded now) and the robots of ``files``
    (``path.py:NAME`` each), as ``(key, entry, origin)``: built-ins and entry points sorted by name, then
    the files in the order given.  An entry point named like a built-in robot is left out (the built-in
    one answers to that name).

    Raises
    ------
    RobotSourceError
        If an entry point or a file cannot be loaded (see :func:`get_entry`).
    """
    names = available_robots()
    out = [_resolve(name) for name in names]
    return out + [_resolve(spec) for spec in files]
