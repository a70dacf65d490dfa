"""The tracker's driver compiled in a child process (``verifier.compiled.warm``).

The child only fills numba's disk cache: the signature it compiles must be the tracker's (else the parent
compiles again), the parent must load the child's entry instead of compiling its own, the results must be
those of an in-process compilation, and a child that fails or hangs must change nothing but the time.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import textwrap

import numba
import numpy as np
import pytest

from crosscert.robots import available_robots, get_robot
from crosscert.verifier.compiled import step as kernels
from crosscert.verifier.compiled import warm
from crosscert.verifier.constants import JOINT_FD, PAPER, SOUND
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.settings import TrackerSettings
from crosscert.verifier.compiled.driver import CompiledStep
from crosscert.verifier.step import configure, init_state


def _tracker_signature(name: str, velocity_model: str) -> tuple:
    """numba's types of the arguments the tracker passes to ``run_slot`` (the online path of
    :meth:`CompiledStep.advance`) for robot ``name``."""
    robot = get_robot(name)
    model = IntervalModel(robot)
    config = configure(model, TrackerSettings.for_robot(robot, velocity_model=velocity_model), parallel=False)
    box = tuple(np.asarray(v, dtype=np.float64) for v in robot.x_bounds)
    st = init_state(config, box)
    a = CompiledStep()._args(config, st)
    assert a["run"] is kernels.run_slot
    head = (config.model.program, config.const, a["vel"], a["rows"], a["scen"], a["scratch"])
    q = np.zeros((1, 1, robot.n))
    args = head + a["slots"][0] + (int(st.k), q, False, a["no_record"], False, a["no_prior"])
    return tuple(numba.typeof(v) for v in args)


@pytest.mark.parametrize("velocity_model", ["sound", "joint-fd", "paper"])
@pytest.mark.parametrize("name", available_robots())
def test_the_child_compiles_the_signature_the_tracker_calls(name, velocity_model):
    """Every robot, every velocity model: the driver's types do not depend on the robot, and the child's
    example arguments have them (a changed state array would leave the child compiling a useless one)."""
    code = {"sound": SOUND, "joint-fd": JOINT_FD, "paper": PAPER}[velocity_model]
    assert warm.signature(code) == _tracker_signature(name, velocity_model)


@pytest.mark.parametrize("name", available_robots())
def test_the_child_compiles_the_lanes_signature_the_tracker_calls(name, monkeypatch):
    """Every robot: the rows-in-lanes driver's types (a batch of many rows, ``SOUND``) are the child's."""
    from crosscert.verifier.compiled import driver
    from crosscert.verifier.compiled.lanes.step import run_lanes

    robot = get_robot(name)
    monkeypatch.setattr(driver, "LANES_MIN_ROWS", 1)
    monkeypatch.setattr(driver, "LANES_COMPILE_HERE", True)
    config = configure(IntervalModel(robot), TrackerSettings.for_robot(robot, velocity_model="sound"), parallel=False)
    box = tuple(np.asarray(v, dtype=np.float64) for v in robot.x_bounds)
    st = init_state(config, box)
    a = CompiledStep()._args(config, st)
    assert a["run"] is run_lanes
    head = (config.model.program, config.const, a["vel"], a["rows"], a["scen"], a["scratch"])
    args = head + a["slots"][0] + (int(st.k), np.zeros((1, 1, robot.n)), False, a["no_record"], False, a["no_prior"])
    assert warm.lanes_signature() == tuple(numba.typeof(v) for v in args)


def _after_an_install(monkeypatch):
    """Nothing in numba's cache, as after an install (whatever this machine's cache holds): a child compiles
    the driver, and the command waits for it."""
    monkeypatch.setattr(warm, "cached", lambda code=SOUND: False)
    monkeypatch.setattr(warm, "_in_cache", lambda dispatcher, sig: False)


def test_a_child_past_the_one_motion_kernels_is_left_to_compile_the_lanes_driver(monkeypatch):
    """The child says the driver is cached, then the one-motion kernels: the one-motion wait (``finish``) ends
    on that line, and at exit the child, compiling the lanes driver that nobody waits for, is not stopped;
    a child that has not said it is stopped."""
    _after_an_install(monkeypatch)
    monkeypatch.setenv(warm.DISABLE, "1")
    say = (f"import sys, time; print({warm.READY!r}, sys.argv[1], flush=True); time.sleep(0.3); "
           f"print({warm.ONE_MOTION_READY!r}, flush=True); sys.stdout.close(); time.sleep(%s)")
    monkeypatch.setattr(warm, "CHILD", [sys.executable, "-c", say % 3])
    assert warm.start("sound")
    child = warm._CHILDREN[SOUND]
    assert warm.wait(SOUND, timeout=60) == 0
    warm.finish(timeout=60)
    assert child.poll() is None and warm._FINISHING == []
    warm._stop_all()
    assert child.poll() is None  # left to finish
    child.wait(30)
    monkeypatch.setattr(warm, "CHILD", [sys.executable, "-c", "import time; time.sleep(600)"])
    assert warm.start("sound")
    child = warm._CHILDREN[SOUND]
    warm._stop_all()
    assert child.poll() is not None


def test_batches_run_row_by_row_until_the_lanes_driver_is_cached(monkeypatch):
    """Without the lanes driver in the cache (and no leave to compile it here) a batch of many rows takes
    the per-row driver; once it is cached, the lanes driver."""
    from crosscert.verifier.compiled import driver
    from crosscert.verifier.compiled.lanes.step import run_lanes

    robot = get_robot("dextar")
    config = configure(IntervalModel(robot), TrackerSettings.for_robot(robot), parallel=False)
    lo, hi = (np.asarray(v, dtype=np.float64) for v in robot.x_bounds)
    st = init_state(config, (np.tile(lo, (64, 1)), np.tile(hi, (64, 1))), batch=64)
    monkeypatch.setattr(driver, "LANES_COMPILE_HERE", False)
    monkeypatch.setattr(warm, "lanes_cached", lambda: False)
    assert CompiledStep._threads(config, st)[0] is kernels.run_slot
    monkeypatch.setattr(warm, "lanes_cached", lambda: True)
    assert CompiledStep._threads(config, st)[0] is run_lanes


def test_the_signatures_differ_by_velocity_model():
    assert len({warm.signature(c) for c in (SOUND, JOINT_FD, PAPER)}) == 3


def test_a_failing_child_changes_nothing_but_the_time(monkeypatch, simulated_recording, capsys):
    """The child's command exits 1: ``check`` answers as without it (the driver is compiled or loaded
    here as usual), and the child's exit code was read before the first call of the driver."""
    from crosscert.planner.cli import main

    argv = ["check", str(simulated_recording), "--initial-mode", "1", "--json", "--no-progress"]
    monkeypatch.setenv(warm.DISABLE, "0")
    assert main(argv) == 0
    expected = json.loads(capsys.readouterr().out)
    codes = []
    wait = warm.wait
    monkeypatch.setattr(warm, "wait", lambda *a, **k: codes.append(wait(*a, **k)))
    monkeypatch.setattr(warm, "CHILD", [sys.executable, "-c", "import sys; sys.exit(1)"])
    _after_an_install(monkeypatch)
    monkeypatch.setenv(warm.DISABLE, "1")
    assert main(argv) == 0
    got = json.loads(capsys.readouterr().out)
    assert codes[0] == 1
    for key in ("elapsed_s",):
        expected.pop(key), got.pop(key)
    assert got == expected


def test_a_hanging_child_is_stopped(monkeypatch):
    monkeypatch.setattr(warm, "CHILD", [sys.executable, "-c", "import time; time.sleep(600)"])
    _after_an_install(monkeypatch)
    monkeypatch.setenv(warm.DISABLE, "1")
    assert warm.start("sound") and warm.pending() == [SOUND]
    assert warm.wait(SOUND, timeout=0.5) is None  # not finished: stopped, the caller compiles
    assert warm.pending() == [] and warm.wait(SOUND) is None


def test_no_child_when_disabled_or_cached(monkeypatch):
    started = []
    monkeypatch.setattr(warm.subprocess, "Popen", lambda *a, **k: started.append(a))
    monkeypatch.setenv(warm.DISABLE, "0")
    monkeypatch.setattr(warm, "cached", lambda code=SOUND: False)
    assert not warm.start("sound")
    monkeypatch.setenv(warm.DISABLE, "1")
    monkeypatch.setattr(warm, "cached", lambda code=SOUND: True)
    assert not warm.start("sound") and not warm.start("no such model")
    assert started == []


_COLD = textwrap.dedent("""
    import json, sys
    from crosscert.planner.cli import main
    from crosscert.verifier.compiled import step, warm
    codes = []
    wait = warm.wait
    warm.wait = lambda *a, **k: codes.append(wait(*a, **k))
    rc = main(["check", sys.argv[1], "--initial-mode", "1", "--json", "--no-progress"])
    st = step.run_slot.stats
    print(json.dumps({"rc": rc, "codes": codes, "hits": sum(st.cache_hits.values()),
                      "misses": sum(st.cache_misses.values())}))
""")


def test_the_driver_compiled_by_the_child_gives_the_same_answer(tmp_path, simulated_recording, capsys):
    """After an install (an empty numba cache): the child compiles the driver, this process loads it from
    the cache instead of compiling it, and ``check`` prints what an in-process compilation prints."""
    from crosscert.planner.cli import main

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), **{warm.DISABLE: "1"})
    proc = subprocess.run([sys.executable, "-c", _COLD, str(simulated_recording)], capture_output=True, text=True,
                          env=env, timeout=900, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    got, stats = json.loads(lines[0]), json.loads(lines[-1])
    # the first configure waits for the child; later ones (the anchored windows' passes) find none to wait for
    assert stats["codes"][0] == 0 and all(c is None for c in stats["codes"][1:])
    assert {k: stats[k] for k in ("rc", "hits", "misses")} == {"rc": 0, "hits": 1, "misses": 0}
    assert main(["check", str(simulated_recording), "--initial-mode", "1", "--json", "--no-progress"]) == 0
    expected = json.loads(capsys.readouterr().out)
    for d in (got, expected):
        d.pop("elapsed_s")
    assert got == expected


def test_by_default_a_child_only_when_a_core_is_free(monkeypatch, tmp_path):
    """Unset: a child when a core is free, none on a busy machine (it would only add the CPU time of the
    callees it compiles again); ``1`` starts one whatever the load.  A core is free when, besides this
    thread, fewer threads are runnable at once than the other CPUs (Linux's snapshot); where that cannot
    be read, when the one-minute load average is below their number."""
    started = []
    monkeypatch.setattr(warm.subprocess, "Popen", lambda *a, **k: started.append(a) or _Done())
    _after_an_install(monkeypatch)
    monkeypatch.setattr(warm.os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    monkeypatch.setattr(warm, "PROBE_S", 0.0)
    loadavg = tmp_path / "loadavg"
    monkeypatch.setattr(warm, "LOADAVG", str(loadavg))
    monkeypatch.delenv(warm.DISABLE, raising=False)

    def child(load, snapshot=None):
        monkeypatch.setattr(warm.os, "getloadavg", lambda: (load, 1.0, 1.0))
        if snapshot is None:
            loadavg.unlink(missing_ok=True)
        else:
            loadavg.write_text(f"{load:.2f} 1.00 1.00 {snapshot}/345 12345\n")
        n = len(started)
        running = warm.start("sound") and warm.wait(SOUND) == 0
        assert running == (len(started) == n + 1)
        return running

    assert not child(1.5)  # no snapshot: the load average decides
    assert child(0.3)
    assert child(1.5, snapshot=1)  # an idle machine after an install: the average still counts the install
    assert not child(0.3, snapshot=2)  # another thread runs now
    loadavg.write_text("garbage")
    assert warm.runnable_now() is None
    monkeypatch.setattr(warm.os, "sched_getaffinity", lambda pid: {0}, raising=False)
    assert not child(0.0, snapshot=1)  # one CPU
    monkeypatch.setattr(warm.os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    monkeypatch.setenv(warm.DISABLE, "1")
    assert child(1.5, snapshot=3)
    monkeypatch.setenv(warm.DISABLE, "0")
    assert not child(0.0, snapshot=1)


def test_the_snapshot_is_the_fewest_runnable_of_several(monkeypatch, tmp_path):
    """A thread that runs at one instant does not hide an idle core: the least of :data:`warm.PROBES` reads."""
    counts = iter([3, 2, 1, 2, 3, 3, 3])
    real_open = open

    def fake_open(path, *a, **k):
        if path == "loadavg-file":
            return io.StringIO(f"0.50 0.40 0.30 {next(counts)}/100 999\n")
        return real_open(path, *a, **k)

    monkeypatch.setattr(warm, "LOADAVG", "loadavg-file")
    monkeypatch.setattr(warm, "PROBE_S", 0.0)
    monkeypatch.setattr("builtins.open", fake_open)
    assert warm.runnable_now() == 1
    monkeypatch.setattr(warm, "LOADAVG", str(tmp_path / "missing"))
    assert warm.runnable_now() is None


class _Done:
    """A child that has finished, successfully."""

    def poll(self):
        return 0

    def wait(self, timeout=None):
        return 0


def test_the_wait_ends_once_the_driver_is_cached_and_the_child_is_stopped_at_exit(monkeypatch):
    """The child says the driver is cached, then goes on (the one-motion kernels): ``wait`` returns 0 then,
    without waiting for its exit, and the exit handler stops it and joins the thread reading its output.  A
    line for another velocity model, or none, does not end the wait."""
    _after_an_install(monkeypatch)
    monkeypatch.setenv(warm.DISABLE, "1")
    say = f"import sys, time; print({warm.READY!r}, int(sys.argv[1]) + 1, flush=True); time.sleep(%s); " \
          f"print({warm.READY!r}, sys.argv[1], flush=True); time.sleep(600)"
    monkeypatch.setattr(warm, "CHILD", [sys.executable, "-c", say % 3])
    assert warm.start("sound")
    child = warm._CHILDREN[SOUND]
    assert warm.wait(SOUND, timeout=1.0) is None  # only the other model's line within the timeout: stopped
    assert child.poll() is not None
    monkeypatch.setattr(warm, "CHILD", [sys.executable, "-c", say % 0])
    assert warm.start("sound")
    child = warm._CHILDREN[SOUND]
    assert warm.wait(SOUND, timeout=60) == 0
    assert child.poll() is None and warm.pending() == [] and warm._FINISHING == [child]
    reader = warm._READERS[child]
    assert reader.is_alive()
    warm._stop_all()
    # stopped, and its reader joined: no thread reads a pipe while the interpreter finalises
    assert child.poll() is not None and warm._FINISHING == [] and not reader.is_alive() and warm._READERS == {}
    joined = []

    class Reader:
        def join(self, timeout=None):
            joined.append(timeout)

    warm._READERS[_Done()] = Reader()
    warm._stop_all()
    assert joined and warm._READERS == {}


def test_the_one_motion_kernels_wait_for_a_finishing_child(monkeypatch):
    """A child whose driver is cached is still compiling the one-motion kernels: their first call here waits
    for it (then loads them) instead of compiling them beside it; a child that does not end in time is
    stopped."""
    from crosscert.verifier import certified_lp

    quick = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(0.5)"])
    monkeypatch.setattr(warm, "_FINISHING", [quick])
    kernels = certified_lp.one_motion_kernels()
    assert quick.poll() == 0 and warm._FINISHING == [] and callable(kernels.dual_bound)
    slow = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    monkeypatch.setattr(warm, "_FINISHING", [slow])
    warm.finish(timeout=0.2)
    assert slow.poll() is not None and warm._FINISHING == []


def test_the_pair_contraction_is_loaded_while_the_child_compiles(monkeypatch):
    """While a child compiles the driver, the parent compiles the window's pair contraction instead of waiting
    idle, with the argument types of the window's own calls (one compilation serves both)."""
    import crosscert.verifier.compiled.motion_model as motion
    import crosscert.verifier.compiled.driver as step_module
    from crosscert.verifier.window import track_window

    from problems import default_settings, interval_model, simulate

    kinds = []
    real = motion.pair_kernel

    def spy(*args):
        kinds.append(tuple(numba.typeof(a) for a in args))
        return real(*args)

    monkeypatch.setattr(motion, "pair_kernel", spy)
    step_module._load_pair_kernel(2)
    assert len(kinds) == 1
    run = simulate(1.0, False, 0)
    track_window(interval_model(), run.q_meas, default_settings(), initial_mode=1, max_geometries=4)
    assert len(kinds) > 1 and set(kinds) == {kinds[0]}  # the window's calls: the same types
    # the order in the step: the contraction first, then the wait for the child
    order = []
    monkeypatch.setattr(step_module, "_load_pair_kernel", lambda n: order.append("pair"))
    monkeypatch.setattr(warm, "pending", lambda: [SOUND])
    monkeypatch.setattr(warm, "wait", lambda code, timeout=None: order.append("wait"))
    model = interval_model()
    robot = model.robot
    config = configure(model, TrackerSettings.for_robot(robot), parallel=False)
    CompiledStep()._args(config, init_state(config, tuple(np.asarray(v, float) for v in robot.x_bounds)))
    assert order == ["pair", "wait"]


def test_one_child_at_a_time_compiles_the_lanes_driver(monkeypatch, tmp_path):
    """While a live process holds the lanes compile lock, a command whose per-row driver is cached starts no
    second child for the lanes driver; a lock left by a dead process does not count."""
    from crosscert.verifier.compiled.step import run_slot

    lock = tmp_path / "lanes.compiling"
    monkeypatch.setattr(warm, "_lanes_lock", lambda: lock)
    monkeypatch.setenv(warm.DISABLE, "1")
    monkeypatch.setattr(warm, "cached", lambda code=SOUND: False)  # the lanes driver is missing
    monkeypatch.setattr(warm, "_in_cache", lambda dispatcher, sig: dispatcher is run_slot)
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    try:
        lock.write_text(str(holder.pid))
        assert warm.lanes_compiling() and not warm.start("sound")
    finally:
        holder.kill()
        holder.wait()
    assert not warm.lanes_compiling()  # a dead holder
    lock.write_text("not a pid")
    assert not warm.lanes_compiling()


def test_only_the_lanes_driver_missing_starts_a_child_nobody_waits_for(monkeypatch):
    """The per-row driver and the one-motion kernels cached, the lanes driver not: the child compiles the lanes
    driver alone (``lanes``), and the command has no child to wait for; with the one-motion kernels missing
    too, the full child (it compiles them beside the command)."""
    from crosscert.verifier.compiled.step import run_slot

    class Exited:  # a child that has already exited, with no output
        stdout = None

        def __init__(self, args, **kwargs):
            started.append(args[len(warm.CHILD):])

        def poll(self):
            return 0

    started = []
    monkeypatch.setattr(warm.subprocess, "Popen", Exited)
    monkeypatch.setenv(warm.DISABLE, "1")
    monkeypatch.setattr(warm, "cached", lambda code=SOUND: False)  # the lanes driver is missing
    monkeypatch.setattr(warm, "lanes_cached", lambda: False)
    monkeypatch.setattr(warm, "lanes_compiling", lambda: False)
    monkeypatch.setattr(warm, "_in_cache", lambda dispatcher, sig: dispatcher is run_slot)
    monkeypatch.setattr(warm, "one_motion_cached", lambda: True)
    assert not warm.start("sound") and warm.pending() == [] and warm.wait(SOUND) is None
    assert started == [["lanes"]]
    monkeypatch.setattr(warm, "one_motion_cached", lambda: False)
    assert warm.start("sound") and started[-1] == [str(SOUND)]
    assert warm.wait(SOUND) == 0  # the (exited) full child, waited for


def test_one_motion_cached_reads_the_kernels_signatures(monkeypatch):
    from crosscert.verifier.compiled import one_motion

    seen = []
    monkeypatch.setattr(warm, "_in_cache", lambda dispatcher, sig: seen.append((dispatcher, len(sig))) or True)
    assert warm.one_motion_cached()
    assert [d for d, _ in seen] == [one_motion.dual_bound, one_motion.taylor_rows, one_motion.tape_points]
    assert [n for _, n in seen] == [17, 14, 12]


def test_a_batch_that_finds_the_lanes_driver_missing_asks_once_for_a_child(monkeypatch):
    """Outside a command (a script's batches), the first batch that would run in lanes but finds the driver
    missing starts one child compiling it alone (argument ``lanes``); later batches do not ask again; none
    when the driver is cached or another child holds the lock."""
    from crosscert.verifier.compiled import driver

    started = []
    monkeypatch.setenv(warm.DISABLE, "1")
    monkeypatch.setattr(warm.subprocess, "Popen", lambda args, **kw: started.append(list(args)))
    monkeypatch.setattr(warm, "lanes_cached", lambda: False)
    monkeypatch.setattr(warm, "lanes_compiling", lambda: False)
    monkeypatch.setattr(driver, "LANES_COMPILE_HERE", False)
    monkeypatch.setattr(driver, "_ASKED_FOR_LANES", [])
    assert not driver._lanes_ready() and not driver._lanes_ready()
    assert started == [[*warm.CHILD, "lanes"]]
    monkeypatch.setattr(warm, "lanes_compiling", lambda: True)
    assert not warm.start_lanes()
    monkeypatch.setattr(warm, "lanes_compiling", lambda: False)
    monkeypatch.setattr(warm, "lanes_cached", lambda: True)
    assert not warm.start_lanes() and driver._lanes_ready()
    assert len(started) == 1


def test_the_lanes_path_can_be_switched_off(monkeypatch):
    """``CROSSCERT_LANES=0``: no batch takes the lanes path, even when its driver may compile here."""
    from crosscert.verifier.compiled import driver

    monkeypatch.setattr(driver, "LANES_COMPILE_HERE", True)
    assert driver._lanes_ready()
    monkeypatch.setenv(driver.LANES_ENV, "0")
    assert not driver._lanes_ready()
