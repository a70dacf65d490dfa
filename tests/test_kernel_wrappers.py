"""Kernels without numba's wrappers are never entered from Python through a null address.

The kernels that only compiled code calls are built without numba's CPython
and C wrappers (:class:`verifier.compiled.interval.Kernel`): numba compiles and
optimises every function's library with everything it calls, so each wrapper
cost in every caller's compilation too (measured; benchmarks/README.md's git
history).  numba would run such a function, called from Python,
through a null address (a segfault): a :class:`Kernel` called from Python runs
a twin compiled with the wrappers instead.  The entry points :mod:`verifier`
calls keep their wrappers and the on-disk cache.
"""

from __future__ import annotations

import ast
import importlib
import os
import subprocess
import sys

import numpy as np
import pytest
from numba.core.caching import NullCache
from numba.core.registry import CPUDispatcher

from problems import CATALOGUE, default_settings, interval_model, run_of, simulate
from crosscert.verifier import interval as I
from crosscert.verifier.compiled.interval import NO_WRAPPERS, Kernel

MODULES = ("interval", "tape", "linalg", "contractors", "step", "motion_model", "vectorized", "one_motion", "implicit")

#: The dispatchers called from Python, with numba's wrappers and cached on disk with all they call.
ENTRY_POINTS = {
    "contractors.pose_solutions", "motion_model.pair_kernel", "step.run_slot", "step.run_hypotheses_parallel",
    "one_motion.dual_bound", "one_motion.taylor_rows", "one_motion.tape_points", "implicit.solve_columns",
    "vectorized._unary_loop", "vectorized._binary_loop", "vectorized._scalar_loop", "vectorized._scale_loop",
    "vectorized._pown_loop",
}


def _dispatchers():
    for m in MODULES:
        mod = importlib.import_module(f"crosscert.verifier.compiled.{m}")
        for name, obj in vars(mod).items():
            if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == mod.__name__:
                yield f"{m}.{name}", obj


def test_every_dispatcher_is_a_kernel_or_an_entry_point():
    found = dict(_dispatchers())
    assert ENTRY_POINTS <= set(found), ENTRY_POINTS - set(found)
    for name, d in found.items():
        wrapperless = {k: d.targetoptions.get(k) for k in NO_WRAPPERS} == NO_WRAPPERS
        if name in ENTRY_POINTS:
            assert not isinstance(d, Kernel) and not any(k in d.targetoptions for k in NO_WRAPPERS), name
            assert not isinstance(d._cache, NullCache), f"{name}: an entry point is cached with all it calls"
        else:
            assert isinstance(d, Kernel) and wrapperless, (
                f"{name}: a kernel called only from compiled code is built with ops.jit (no wrappers); "
                "one called from the package's Python code is an entry point (ops.cached_jit, and ENTRY_POINTS)")


def test_a_kernel_compiled_as_a_callee_is_safe_to_call_from_python(tmp_path):
    """In a fresh process (a segfault fails the test instead of ending the run): a kernel first compiled
    for a caller has an overload without a CPython entry, which numba's own call would jump into; the
    Kernel runs its twin instead.  A recursive kernel's twin (``pown`` calls itself) is a function object
    of its own: numba refuses a function whose compilation re-enters itself."""
    script = (
        "from numba import njit\n"
        "from crosscert.verifier.compiled import interval as ops\n"
        "first = ops.pown(0.5, 3.0, -2)\n"  # the twin first: it compiles the kernel it calls, itself
        "@njit\n"
        "def caller(a, b):\n"
        "    return ops.add(a, 1.0, b, 2.0), ops.pown(a, 3.0, -2)\n"
        "print(caller(0.5, 0.25))\n"
        "print((ops.add(0.5, 1.0, 0.25, 2.0), first))\n"
        "print(dict(ops.Kernel.python_calls))\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    compiled, from_python, calls = (ast.literal_eval(line) for line in proc.stdout.splitlines())
    expected = (I.add(0.5, 1.0, 0.25, 2.0), I.pown(0.5, 3.0, -2))
    assert compiled == from_python == tuple(tuple(float(v) for v in r) for r in expected)
    assert calls == {"add": 1, "pown": 1}  # the Python calls went through the twins


def test_a_twin_computes_what_the_kernel_computes():
    from crosscert.verifier.compiled import interval as ops, vectorized

    rng = np.random.default_rng(17)
    a = np.sort(rng.uniform(-3.0, 3.0, (2, 200)), axis=0)
    b = np.sort(rng.uniform(-3.0, 3.0, (2, 200)), axis=0)
    for name in ("add", "mul", "div", "sub"):
        lo, hi = getattr(vectorized, name)(a[0], a[1], b[0], b[1])  # the kernel, inside a compiled loop
        twin = np.array([getattr(ops, name)(a[0, i], a[1, i], b[0, i], b[1, i]) for i in range(200)])
        assert np.array_equal(twin[:, 0], lo) and np.array_equal(twin[:, 1], hi), name
        ref_lo, ref_hi = getattr(I, name)(a[0], a[1], b[0], b[1])
        assert np.array_equal(ref_lo, lo) and np.array_equal(ref_hi, hi), name


@pytest.fixture(scope="module")
def crossing_csv(tmp_path_factory):
    from crosscert.verifier.trajfile import write_trajectory

    run = simulate(1.0, False, 0)  # decided by the window's rounds, not by the forward tracker
    path = tmp_path_factory.mktemp("traj") / "crossing.csv"
    write_trajectory(path, run.t, run.q_meas)
    return path


def test_the_package_calls_no_kernel_from_python(crossing_csv, capsys):
    """The package's own paths reach the kernels through entry points only: a twin would compile the kernel
    and its callees once more on the first run.  Covered: ``check`` (the initial box's enumeration, the
    tracker, window passes with the compiled contraction), a threaded batch, the hypotheses spread over
    threads, the online monitor's anchored window."""
    from crosscert.planner.cli import main
    from crosscert.verifier.tracker import Tracker, track_batch
    from crosscert.verifier.window import OnlineMonitor

    before = dict(Kernel.python_calls)
    assert main(["check", str(crossing_csv), "--initial-mode", "1", "--no-progress"]) == 0
    capsys.readouterr()
    run, model, s = run_of(CATALOGUE["crossing_1458"]), interval_model(), default_settings()
    x = run.x_true[0]
    x0 = (x - 1e-3, x + 1e-3)
    q = np.stack([run.q_meas[:40], run.q_meas[:40]])
    track_batch(model, q, s, x0=x0, parallel=True)
    tracker = Tracker(model, s, x0, spread_hypotheses=True)
    for qk in run.q_meas[:10]:
        tracker.update(qk)
    slow = simulate(1.0, False, 0)  # the tracker alone leaves it open: the anchored window decides it
    x = slow.x_true[0]
    with OnlineMonitor(model, s, (x - 1e-3, x + 1e-3), worker=False) as online:
        for qk in slow.q_meas:
            online.update(qk)
    assert online.decisions >= 1
    assert dict(Kernel.python_calls) == before
