"""The step's driver compiled in a child process while this one compiles the rest.

After an install nothing is in numba's on-disk cache: a command's first run
compiles the robot's tape callback (:mod:`verifier.compiled.straight`), the
pose enumeration (:func:`verifier.compiled.contractors.pose_solutions`) and the
tracker's driver (:func:`verifier.compiled.step.run_slot`, the largest) and the
window's one-motion kernels, one after the other on one core.  :func:`start` runs
``python -m`` this module in a child process that compiles the driver for the
velocity model in use, then the one-motion kernels, and writes them to numba's
disk cache, while this process goes on; :func:`wait`, before the
driver's first call, waits until the driver is in the cache (not for the
one-motion kernels, which the child goes on compiling beside this process),
and the call then loads the driver from the cache.  Last, for the ``SOUND``
model, the child compiles the rows-in-lanes driver
(:func:`verifier.compiled.lanes.step.run_lanes`, about 40 s of CPU), niced
and with its output closed; nobody waits for it: batches run row by row (the
same boxes) until it is in the cache (:func:`lanes_cached`), and it finishes
even after the command that started it has exited.

The child is never needed for correctness: whatever it does (fails, is
killed, compiles another signature, writes nothing), the driver's first call
compiles in this process as without it.  What the cache holds is what this
process would have compiled: numba keys an entry on the function's bytecode,
the signature, the CPU and numba's version, and writes each file through a
new name and a rename, so a reader never sees half a file.  An entry loaded
from the cache is the machine code of the same source, and the kernels'
sources are stamped (:mod:`verifier.compiled`), so the results are those of an
in-process compilation bit for bit (tests/test_warm.py).
"""

from __future__ import annotations

import atexit
import os
import subprocess
import sys
import threading
import time

import numpy as np

from ..constants import AXIS_DTYPE, BASELINE_DTYPE, JOINT_FD, PAPER, SOUND, StepConstants, velocity_model_code

__all__ = ["CHILD", "DISABLE", "WAIT_S", "POLL_S", "READY", "ONE_MOTION_READY", "LOADAVG", "PROBES", "PROBE_S",
           "example_arguments", "signature", "lanes_signature", "cached", "lanes_cached", "one_motion_cached",
           "runnable_now", "core_free", "start", "start_lanes", "wait", "finish", "pending", "main"]

#: The child's command before its arguments (tests replace it by one that fails).
CHILD = [sys.executable, "-m", "crosscert.verifier.compiled.warm"]

#: Environment variable: ``0`` starts no child (the driver compiles in the process that calls it), ``1`` one
#: whenever the driver is not cached; unset (or anything else), one when a core is free (:func:`core_free`).
DISABLE = "CROSSCERT_COMPILE_CHILD"

#: Longest wait for a child, s; then it is stopped and the driver compiles here (a cold compilation takes
#: 15-25 s of CPU on the machines of benchmarks/README.md).
WAIT_S = 600.0

#: How often :func:`wait` looks whether the child has exited, s.
POLL_S = 0.05
#: The line the child prints (with the velocity model code) once the driver is in numba's disk cache:
#: ``Dispatcher.compile`` returns after numba wrote the entry's data and its index.
READY = "driver-cached"
#: The line the child prints once the window's one-motion kernels are in the cache (then, for ``SOUND``, it
#: compiles the rows-in-lanes driver, :func:`verifier.compiled.lanes.step.run_lanes`, which nobody waits for).
ONE_MOTION_READY = "one-motion-cached"

_LOCK = threading.Lock()
#: velocity model code -> the child compiling the driver for it
_CHILDREN: dict[int, subprocess.Popen] = {}
#: pending child -> set once it printed :data:`READY` (read by a thread per child, which drains its output)
_READY: dict[subprocess.Popen, threading.Event] = {}
#: Children whose driver is in the cache, still compiling the one-motion kernels (stopped at exit)
_FINISHING: list[subprocess.Popen] = []
#: child -> the thread reading its output (joined once the child is stopped at exit)
_READERS: dict[subprocess.Popen, threading.Thread] = {}
#: child -> set once it printed :data:`ONE_MOTION_READY` (read by :func:`finish`)
_ONE_MOTION: dict[subprocess.Popen, threading.Event] = {}


def example_arguments(velocity_model: int = SOUND) -> tuple:
    """Arguments of :func:`verifier.compiled.step.run_slot` of the types the tracker passes
    (:class:`verifier.step.CompiledStep`) for velocity model ``velocity_model``: tiny arrays, never run.

    The types do not depend on the robot (tests/test_warm.py compares them with the tracker's on every
    robot of the registry and every velocity model)."""
    from . import step as kernels
    from .contractors import scratch_arrays
    from .tape import Program

    f, i = np.float64, np.int64

    def z(*shape, dtype=f):
        return np.zeros(shape, dtype)

    prog = Program(z(1, 3, dtype=i), z(1), z(1, dtype=i), z(1, 3, dtype=i), 1, z(2, 1, dtype=i))
    const = StepConstants(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, int(velocity_model), 0, 0, 1, False, False, np.zeros(1, AXIS_DTYPE),
                          np.zeros(1, BASELINE_DTYPE), z(1, 2, 1), 1)
    rows = kernels.Rows(z(1, 2, 1), z(1, 2, 1), z(1, 2, 1), z(1, 2, 1), z(1, 1, 2, 1), z(1, 1, 2, 1), z(1, 1, 1),
                        z(1, dtype=i))
    scen = kernels.Scenarios(z(1, dtype=i), z(1, dtype=i), z(1, dtype=i), z(1, dtype=i), z(1), z(1), z(1, 2, 1),
                             z(1, 2, 1), z(1, 1))
    rec = kernels.Record(z(1, 0, 2, 1), z(1, 0, 2, 1), z(1, 0, dtype=i), z(1, 0, 1))
    prior = kernels.Prior(z(1, 0, 2, 1), z(1, 0, 2, 1))
    return (prog, const, kernels.velocity_strategy(int(velocity_model)), rows, scen,
            scratch_arrays(1, 1, 1, 1, 1, 0, 1), 0, 1, 0, z(1, 1, 1), False, rec, False, prior)


def _lanes_arguments() -> tuple:
    """Arguments of :func:`verifier.compiled.lanes.step.run_lanes` of the types the tracker passes: those of
    :func:`example_arguments` (``SOUND``) with the lanes scratch before the slot."""
    from .lanes.step import lane_scratch_arrays

    a = example_arguments(SOUND)
    return a[:6] + (lane_scratch_arrays(1, 1, 1, 1, 1, 1, 1),) + a[6:]


def signature(velocity_model: int = SOUND) -> tuple:
    """numba's argument types of :func:`example_arguments`: the driver's signature."""
    import numba

    return tuple(numba.typeof(v) for v in example_arguments(velocity_model))


def lanes_signature() -> tuple:
    """numba's argument types of the rows-in-lanes driver (``SOUND`` only)."""
    import numba

    return tuple(numba.typeof(v) for v in _lanes_arguments())


def _in_cache(dispatcher, sig) -> bool:
    if sig in dispatcher.overloads:
        return True
    try:  # numba's private cache API (0.68): the index of the function's file, keyed as numba keys it
        cache = dispatcher._cache
        return cache._cache_file._load_index().get(cache._index_key(sig, dispatcher.targetctx.codegen())) is not None
    except Exception:
        return False


def cached(velocity_model: int = SOUND) -> bool:
    """Whether the drivers of ``velocity_model`` (for ``SOUND`` the lanes driver too) are compiled in this
    process or in numba's disk cache (read without loading them; False when numba's cache cannot be read)."""
    from .step import run_slot

    if not _in_cache(run_slot, signature(velocity_model)):
        return False
    return int(velocity_model) != SOUND or lanes_cached()


#: When :func:`lanes_cached` last found no entry (``time.monotonic``): it looks again at most every
#: :data:`LANES_LOOK_S` s (a window asks at each of its passes).
_LANES_LOOKED = [-float("inf"), False]
LANES_LOOK_S = 1.0


def _lanes_lock():
    """The file a child holds while it compiles the lanes driver (its pid), beside the driver's cache."""
    from pathlib import Path

    return Path(__file__).resolve().parent / "lanes" / "__pycache__" / "lanes.compiling"


def lanes_compiling() -> bool:
    """Whether a live process holds the lanes driver's compile lock (:func:`_lanes_lock`)."""
    try:
        pid = int(_lanes_lock().read_text())
        os.kill(pid, 0)
    except (OSError, ValueError):
        return False
    return True


def lanes_cached() -> bool:
    """Whether the rows-in-lanes driver is compiled in this process or in numba's disk cache."""
    if _LANES_LOOKED[1]:
        return True
    now = time.monotonic()
    if now - _LANES_LOOKED[0] < LANES_LOOK_S:
        return False
    from .lanes.step import run_lanes

    _LANES_LOOKED[:] = [now, _in_cache(run_lanes, lanes_signature())]
    return _LANES_LOOKED[1]


def one_motion_cached() -> bool:
    """Whether the window's one-motion kernels are compiled in this process or in numba's disk cache."""
    import numba

    from .one_motion import example_arguments

    return all(_in_cache(k, tuple(numba.typeof(a) for a in args)) for k, args in example_arguments())


def start(velocity_model="sound") -> bool:
    """Start a child compiling the driver of ``velocity_model`` (a name, a
    :class:`verifier.settings.VelocityModel` or its code) into numba's disk cache, unless it is cached, a
    child already does, or ``$CROSSCERT_COMPILE_CHILD`` is ``0``.

    Returns whether a child runs for it now.  Never raises: without a child the driver compiles here."""
    try:
        code = velocity_model if isinstance(velocity_model, (int, np.integer)) else velocity_model_code(velocity_model)
    except KeyError:
        return False
    code = int(code)
    if code not in (SOUND, JOINT_FD, PAPER):
        return False
    choice = os.environ.get(DISABLE, "").strip()
    if choice == "0":
        return False
    with _LOCK:
        child = _CHILDREN.get(code)
        if child is not None and child.poll() is None:
            return True
        try:
            if cached(code) or (choice != "1" and not core_free()):  # the probe (about 16 ms) only on a first run
                return False
            from .step import run_slot

            if _in_cache(run_slot, signature(code)):  # the driver cached: the lanes driver is missing
                if lanes_compiling():  # another child compiles it
                    return False
                if one_motion_cached():  # a niced child for it alone, which no command waits for
                    start_lanes()
                    return False
            child = subprocess.Popen([*CHILD, str(code)], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL)
            _CHILDREN[code] = child
            ready = _READY[child] = threading.Event()
            one_motion = _ONE_MOTION[child] = threading.Event()
            reader = _READERS[child] = threading.Thread(target=_watch, args=(child, code, ready, one_motion),
                                                        name="crosscert-compile-child", daemon=True)
            reader.start()
        except Exception:  # no child: the driver compiles in this process
            return False
    return True


def start_lanes() -> bool:
    """Start a child that compiles only the lanes driver (niced, output discarded, left to finish), unless it
    is cached, another child compiles it, ``$CROSSCERT_COMPILE_CHILD`` is ``0``, or no core is free (unless
    it is ``1``).  For a batch that finds it missing outside a command (a script's first batches); nobody
    waits for it.  Returns whether a child was started.  Never raises."""
    choice = os.environ.get(DISABLE, "").strip()
    try:
        if choice == "0" or lanes_cached() or lanes_compiling() or (choice != "1" and not core_free()):
            return False
        subprocess.Popen([*CHILD, "lanes"], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    except Exception:
        return False
    return True


def _watch(child, code: int, ready: threading.Event, one_motion: threading.Event | None = None) -> None:
    """Read the child's output to its end; set ``ready`` when it says the driver of ``code`` is cached,
    ``one_motion`` when it says the one-motion kernels are."""
    stream = getattr(child, "stdout", None)
    if stream is None:
        return
    with stream:
        for line in stream:
            words = line.split()
            if words == [READY.encode(), str(code).encode()]:
                ready.set()
            elif one_motion is not None and words == [ONE_MOTION_READY.encode()]:
                one_motion.set()


#: Linux's snapshot of the scheduler: the fourth field of this file counts the threads runnable at this instant
#: (the reader included).  The one-minute load average still counts work that has just ended, such as the
#: install before a first run: after ``pip install .`` on 2 cores it stays above 1 for a minute, and no child
#: was started on an idle machine.
LOADAVG = "/proc/loadavg"
#: Snapshots :func:`runnable_now` takes, :data:`PROBE_S` s apart (s): the fewest counts, so that a thread that
#: happened to run at one instant does not hide an idle core.
PROBES = 5
PROBE_S = 0.004


def runnable_now() -> int | None:
    """The fewest threads runnable at once in :data:`PROBES` snapshots of :data:`LOADAVG` (the calling thread
    included), or None when the file cannot be read or parsed (not Linux)."""
    least = None
    for i in range(PROBES):
        if i:
            time.sleep(PROBE_S)
        try:
            with open(LOADAVG, encoding="ascii") as f:
                count = int(f.read().split()[3].split("/")[0])
        except (OSError, ValueError, IndexError):
            return None
        least = count if least is None else min(least, count)
    return least


def core_free() -> bool:
    """Whether a second core may compile beside this process: at least two CPUs for this process and, besides
    the calling thread, fewer threads runnable than the other CPUs (:func:`runnable_now`), or where that
    cannot be read, a one-minute load average below one less than their number.  On a busy machine a child
    adds its CPU time (the callees it shares with the pose enumeration, compiled in both processes) and gains
    no wall time (benchmarks/README.md)."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = os.cpu_count() or 1
    if cpus < 2:
        return False
    now = runnable_now()
    if now is not None:
        return now < cpus  # besides this thread, fewer runnable than the other CPUs
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):
        load = 0.0
    return load < cpus - 1


def pending() -> list[int]:
    """The velocity models whose child is still running."""
    with _LOCK:
        return [code for code, child in _CHILDREN.items() if child.poll() is None]


def wait(velocity_model: int, timeout: float | None = None) -> int | None:
    """Before the driver's first call for ``velocity_model``: wait for its child, if one was started,
    until it exits or says the driver is in numba's disk cache, at most ``timeout`` s (default
    :data:`WAIT_S`; then it is stopped).

    Returns the child's exit code, 0 as soon as the child says the driver is in the cache (:data:`READY`;
    it then goes on with the one-motion kernels beside this process, which loads them if the child wrote
    them first; it is stopped at exit), or None when there was no child.  Whatever it returns, the caller
    calls the driver as usual: numba loads it from the cache or compiles it."""
    code = int(velocity_model)
    with _LOCK:
        child = _CHILDREN.pop(code, None)
        ready = _READY.pop(child, None)
    if child is None:
        return None
    deadline = time.monotonic() + (WAIT_S if timeout is None else timeout)
    while True:
        if ready is not None and ready.wait(POLL_S):
            with _LOCK:
                _FINISHING.append(child)
            return 0
        rc = child.poll()
        if rc is not None:
            return rc
        if time.monotonic() >= deadline:
            _stop(child)
            return None
        if ready is None:
            time.sleep(POLL_S)


def finish(timeout: float | None = None) -> None:
    """Before a call of the one-motion kernels: wait for the children that put their driver in the cache and
    still compile those kernels (:func:`wait`), at most ``timeout`` s each (default :data:`WAIT_S`; then they
    are stopped), so that this process loads the kernels instead of compiling them beside the child.  Nothing
    to do (one list read) when no child is finishing."""
    if not _FINISHING:
        return
    with _LOCK:
        children = list(_FINISHING)
        _FINISHING[:] = []
    deadline = time.monotonic() + (WAIT_S if timeout is None else timeout)
    for child in children:
        # until it says the kernels are cached (it then compiles the lanes driver) or exits
        with _LOCK:
            said = _ONE_MOTION.get(child)
        while child.poll() is None and not (said is not None and said.wait(POLL_S)):
            if said is None:
                time.sleep(POLL_S)
            if time.monotonic() >= deadline:
                _stop(child)
                break
        # a child past the one-motion kernels compiles the lanes driver, niced, and is left to finish it


def _stop(child) -> None:
    child.kill()
    try:
        child.wait(5.0)
    except subprocess.TimeoutExpired:  # pragma: no cover - a killed process is reaped at once
        pass


@atexit.register
def _stop_all() -> None:
    """A child still compiling the driver or the one-motion kernels when the process ends (the command
    failed, or never ran the driver) is stopped: numba writes its files through a rename, so at worst a
    temporary file stays.  A child past the one-motion kernels is left to finish the lanes driver (niced, it
    closed its output): stopping it would lose a compilation no command waits for."""
    with _LOCK:
        children = list(_CHILDREN.values()) + _FINISHING
        _CHILDREN.clear()
        _FINISHING[:] = []
        readers = list(_READERS.values())
        _READERS.clear()
        past = {child for child, said in _ONE_MOTION.items() if said.is_set()}
        _ONE_MOTION.clear()
    for child in children:
        if child.poll() is None and child not in past:
            _stop(child)
    for reader in readers:  # the pipes are at their end: no thread reads while the interpreter finalises
        reader.join(2.0)


def main(argv=None) -> int:
    """The child: compile the driver for each velocity model code of ``argv`` and write it to numba's
    disk cache, then the window's one-motion kernels (:func:`verifier.compiled.one_motion.compile_kernels`:
    their first call in the parent comes later, and loads them when the child was first), then (``SOUND``)
    the rows-in-lanes driver; exit code 0 when every one is compiled (or was cached)."""
    args = sys.argv[1:] if argv is None else list(argv)
    if args == ["lanes"]:  # start_lanes: the lanes driver alone
        os.nice(10)
        _compile_lanes()
        return 0
    try:
        from .one_motion import compile_kernels
        from .step import run_slot

        for code in args:
            run_slot.compile(signature(int(code)))
            print(READY, int(code), flush=True)  # the parent's wait ends: the one-motion kernels follow
        compile_kernels()
        print(ONE_MOTION_READY, flush=True)
        if SOUND in [int(code) for code in args]:
            # last, and no command waits for it (batches run row by row until it is cached): output closed
            # (the parent's reader ends), niced, finished even after the parent exits
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            os.nice(10)
            _compile_lanes()
    except KeyboardInterrupt:  # the user's Ctrl-C reaches the whole process group: quietly
        return 130
    return 0


def _compile_lanes() -> None:
    """Compile the lanes driver into the cache unless it is cached or another child holds the lock."""
    from .lanes.step import run_lanes

    lock = _lanes_lock()
    if lanes_cached() or lanes_compiling():
        return
    try:
        lock.parent.mkdir(exist_ok=True)
        lock.write_text(str(os.getpid()))
    except OSError:  # a read-only install: compile without the lock
        pass
    try:
        run_lanes.compile(lanes_signature())
    finally:
        try:
            if lock.read_text() == str(os.getpid()):
                lock.unlink()
        except OSError:
            pass


if __name__ == "__main__":
    sys.exit(main())
