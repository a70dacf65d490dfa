"""The compiled tracker against the numpy reference (``backend="numpy"``).

Both backends perform the same float operations in the same order, so on the
reference problems and a seeded Monte Carlo batch their boxes must be equal
bit for bit.  The one admitted difference: numpy may evaluate ``sin``/``cos``
with its own SIMD kernels where the compiled code calls the C library; where
the two disagree on this machine (checked below), boxes may differ by a few
ulp, bounded here by ``TRIG_REL`` relative plus 1e-15 absolute, and verdicts
must still agree.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from problems import CATALOGUE, default_settings, interval_model, run_of, simulate
from crosscert.verifier.step import configure
from crosscert.verifier.tracker import Tracker
from crosscert.verifier.tracker import VelocityModel, initial_box_from_mode, track, track_batch

_probe = np.random.default_rng(5).uniform(-7.0, 7.0, 20000)
TRIG_SAME = bool(np.all(np.sin(_probe) == [math.sin(v) for v in _probe])
                 and np.all(np.cos(_probe) == [math.cos(v) for v in _probe]))
TRIG_REL = 1e-9  # relative, where numpy's and libm's sin/cos differ
FIELDS = ("x_lo", "x_hi", "xd_lo", "xd_hi")


def _assert_same_boxes(a, b, what):
    """Equal bit for bit (NaN where both NaN), or within the stated bound when trig differs."""
    for f in FIELDS:
        u, v = np.asarray(a[f]), np.asarray(b[f])
        if TRIG_SAME:
            assert np.array_equal(u, v, equal_nan=True), (what, f, np.nanmax(np.abs(u - v)))
        else:
            assert np.allclose(u, v, rtol=TRIG_REL, atol=1e-15, equal_nan=True), (what, f)


def _boxes(res):
    return {f: getattr(res, f) for f in FIELDS}


@pytest.mark.parametrize("name", sorted(CATALOGUE))
def test_catalogue_backends_agree(name, imodel, settings):
    run = run_of(CATALOGUE[name])
    model, s = imodel, settings
    mode = int(run.mode_true[0])
    ref = track(model, run.q_meas, s, initial_mode=mode, backend="numpy")
    fast = track(model, run.q_meas, s, initial_mode=mode, backend="compiled")
    assert fast.verdict is ref.verdict
    assert (fast.certified_at_step, fast.inconsistent_at_step) == (ref.certified_at_step, ref.inconsistent_at_step)
    assert np.array_equal(fast.mode, ref.mode)
    _assert_same_boxes(_boxes(ref), _boxes(fast), name)
    assert fast.max_width_pose == ref.max_width_pose and fast.max_width_velocity == ref.max_width_velocity


@pytest.mark.parametrize("overrides", [
    dict(velocity_model=VelocityModel.JOINT_FD),
    dict(velocity_model=VelocityModel.PAPER),
    dict(keep_xi=True, split_boxes=8),
    dict(eps_q_fast=1e-5, drift_rate=0.01, baselines=(1, 3, 7)),
], ids=["joint-fd", "paper", "keep-xi", "drift"])
def test_options_backends_agree(overrides, imodel):
    """Every velocity model and option runs the same maths in both backends."""
    run = run_of(CATALOGUE["crossing_1458"])
    model, s = imodel, default_settings(**overrides)
    q = run.q_meas[:160]  # through the crossing (true singular instant at sample 100)
    x0 = initial_box_from_mode(model, q[0], int(run.mode_true[0]), s)
    ref = track(model, q, s, x0=x0, backend="numpy")
    fast = track(model, q, s, x0=x0, backend="compiled")
    assert fast.verdict is ref.verdict
    assert np.array_equal(fast.mode, ref.mode)
    _assert_same_boxes(_boxes(ref), _boxes(fast), overrides)
    assert np.array_equal(fast.qdd_bound, ref.qdd_bound)


def _monte_carlo_batch():
    rng = np.random.default_rng(77)
    runs = [simulate(round(float(rng.uniform(0.7, 1.7)), 3), i % 4 == 3, 300 + i, ("floor", "round", "uniform")[i % 3])
            for i in range(8)]
    K = max(r.n_samples for r in runs)
    pad = lambda a: np.vstack([a, np.repeat(a[-1:], K - len(a), axis=0)])  # noqa: E731  (rest at the end)
    q = np.stack([pad(r.q_meas) for r in runs])
    model, s = interval_model(), default_settings()
    boxes = [initial_box_from_mode(model, r.q_meas[0], int(r.mode_true[0]), s) for r in runs]
    x0 = (np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes]))
    return model, s, q, x0


def test_monte_carlo_batch_backends_agree():
    """A seeded batch of crossings and bounces (random geometry, speed,
    quantisation): same verdicts, steps and boxes in both backends."""
    model, s, q, x0 = _monte_carlo_batch()
    ref, rref = track_batch(model, q, s, x0, record=True, backend="numpy")
    fast, rfast = track_batch(model, q, s, x0, record=True, backend="compiled")
    assert list(fast.verdict) == list(ref.verdict)
    for f in ("initial_mode", "final_mode", "certified_at_step", "inconsistent_at_step"):
        assert np.array_equal(getattr(fast, f), getattr(ref, f)), f
    assert np.array_equal(rfast["mode"], rref["mode"])
    _assert_same_boxes(rref, rfast, "monte carlo")


def test_batch_member_equals_single_run():
    """Each row runs its own fixpoint: a scenario's boxes do not depend on the
    other scenarios of its batch (so batching is only a matter of speed)."""
    model, s, q, x0 = _monte_carlo_batch()
    _, rec = track_batch(model, q, s, x0, record=True)
    for b in (0, 3, 5):
        _, one = track_batch(model, q[b:b + 1], s, (x0[0][b], x0[1][b]), record=True)
        for f in FIELDS:
            assert np.array_equal(rec[f][b], one[f][0], equal_nan=True), (b, f)


@pytest.mark.parametrize("backend", ["compiled", "numpy"])
def test_online_tracker_equals_track(backend, imodel, settings):
    """``Tracker.update`` one sample at a time gives the boxes and modes of ``track``."""
    run = run_of(CATALOGUE["crossing_1458"])
    model, s = imodel, settings
    q = run.q_meas[:130]
    x0 = initial_box_from_mode(model, q[0], int(run.mode_true[0]), s)
    ref = track(model, q, s, x0=x0, backend=backend)
    tr = Tracker(model, s, x0, backend=backend)
    events = []
    for k, qk in enumerate(q):
        r = tr.update(qk)
        assert r.k == k and r.mode == ref.mode[k]
        assert np.array_equal(r.x[0], ref.x_lo[k]) and np.array_equal(r.x[1], ref.x_hi[k])
        assert np.array_equal(r.xd[0], ref.xd_lo[k]) and np.array_equal(r.xd[1], ref.xd_hi[k])
        events += [(k, e.value) for e in r.events]
    gained = [k for k, e in events if e == "mode-gained"]
    assert gained and gained[-1] == ref.certified_at_step


def test_unknown_backend_is_refused(imodel, settings):
    from crosscert.robots.errors import InputError

    with pytest.raises(InputError, match="backend"):
        configure(imodel, settings, "fortran")


@pytest.mark.parametrize("name", ["crossing_1458", "bounce_0800"])
def test_initial_box_backends_agree(name, imodel, settings):
    """The branch and prune of the first sample: same boxes, same modes."""
    from crosscert.verifier.step import pose_solutions

    run = run_of(CATALOGUE[name])
    model, s = imodel, settings
    eps = s.validated(model.n).eps_q
    # at rest, and 30 samples before the locus (several boxes; next to the locus
    # the numpy reference needs about a minute for its 8 000 boxes)
    for q0 in (run.q_meas[0], run.q_meas[run.k_sing - 30]):
        Q = (q0 - eps, q0 + eps)
        X = tuple(np.asarray(v, dtype=float) for v in model.robot.x_bounds)
        ref = pose_solutions(model, Q, model.xi_box(), X, tol=1e-5, backend="numpy")
        fast = pose_solutions(model, Q, model.xi_box(), X, tol=1e-5, backend="compiled")
        assert len(ref) == len(fast) > 0
        for (rb, rm), (fb, fm) in zip(ref, fast):
            assert rm == fm and np.array_equal(rb[0], fb[0]) and np.array_equal(rb[1], fb[1])


def test_the_enumeration_does_not_depend_on_the_call_before(imodel, settings):
    """The compiled enumeration keeps its output and stack arrays from call to call (per thread and
    size): a call after another one with more solutions, a budget that runs out, or another size gives
    what it gives in a fresh process — the arrays it returns are its own, not views of the buffers."""
    from crosscert.verifier.step import pose_solution_arrays

    run = run_of(CATALOGUE["crossing_1458"])
    eps = settings.validated(imodel.n).eps_q
    X = tuple(np.asarray(v, dtype=float) for v in imodel.robot.x_bounds)

    def enum(k, **kw):
        q = run.q_meas[k]
        return pose_solution_arrays(imodel, (q - eps, q + eps), imodel.xi_box(), X, tol=1e-5, **kw)

    near, rest = run.k_sing - 30, 0
    first = enum(rest)
    assert first is not None and len(first[1]) > 0
    again_near = enum(near)
    assert enum(near, max_boxes=3) is None  # the budget ran out: no partial answer left behind
    assert enum(rest, max_boxes=5000) is not None  # another size: other buffers
    for before, after in ((first, enum(rest)), (again_near, enum(near))):
        assert np.array_equal(before[0], after[0]) and np.array_equal(before[1], after[1])
    assert not np.shares_memory(enum(rest)[0], enum(rest)[0])


def test_threads_change_nothing():
    """Scenarios or hypotheses spread over threads: the serial kernel's boxes."""
    model, s, q, x0 = _monte_carlo_batch()
    q = q[:3, :300]
    x0 = (x0[0][:3], x0[1][:3])
    for b in range(3):  # a lone scenario: its hypotheses in parallel
        one = (x0[0][b], x0[1][b])
        serial = track(model, q[b], s, x0=one)
        threaded = track(model, q[b], s, x0=one, spread_hypotheses=True)
        assert threaded.verdict is serial.verdict and np.array_equal(threaded.mode, serial.mode)
        _assert_same_boxes(_boxes(serial), _boxes(threaded), ("hypotheses", b))
    _, serial = track_batch(model, q, s, x0, record=True, parallel=False)  # scenarios in parallel
    _, threaded = track_batch(model, q, s, x0, record=True, parallel=True)
    _assert_same_boxes(serial, threaded, "scenarios")


def test_read_only_readings_use_the_same_kernel(imodel, settings):
    """A read-only recording (a frozen plan's joints) runs the kernel compiled
    for writable arrays: no second compilation, the same boxes."""
    from crosscert.verifier.compiled.step import run_slot

    run = run_of(CATALOGUE["crossing_1458"])
    model, s = imodel, settings
    q = np.array(run.q_meas[:40])
    x0 = initial_box_from_mode(model, q[0], int(run.mode_true[0]), s)
    ref = track(model, q, s, x0=x0)
    q.setflags(write=False)
    tr = Tracker(model, s, x0)
    for k in range(len(q)):
        r = tr.update(q[k])
        assert np.array_equal(r.x[0], ref.x_lo[k]) and np.array_equal(r.x[1], ref.x_hi[k])
    frozen = track(model, q, s, x0=x0)
    assert np.array_equal(frozen.x_lo, ref.x_lo)
    assert all(not any(getattr(t, "readonly", False) for t in sig if hasattr(t, "readonly"))
               for sig in run_slot.signatures)


def test_drivers_have_their_own_cache_entries():
    """numba keys its on-disk cache by a function's qualified name: the batch
    driver and the hypotheses' parallel one must not share one, or one loads
    the other (a serial tracker waking the thread pool at every sample)."""
    from crosscert.verifier.compiled import step as kernels

    names = {d.py_func.__qualname__ for d in (kernels.run_slot, kernels.run_hypotheses_parallel)}
    assert len(names) == 2


def test_a_parallel_batch_runs_one_slot_per_thread(monkeypatch):
    """``parallel=True`` runs the one batch driver once per thread slot, the slots on the process's pool of
    Python threads (the kernels release the GIL); a serial batch runs it once, on the calling thread.  The
    boxes are the same (:func:`test_threads_change_nothing`)."""
    import numba

    from crosscert.verifier.compiled import driver as S

    asked, real = [], S._slot_pool
    monkeypatch.setattr(S, "_slot_pool", lambda n: asked.append(n) or real(n))
    model, s, q, x0 = _monte_carlo_batch()
    q, x0 = q[:3, :20], (x0[0][:3], x0[1][:3])
    track_batch(model, q, s, x0, parallel=False)
    assert asked == []
    track_batch(model, q, s, x0, parallel=True)
    threads = min(numba.config.NUMBA_NUM_THREADS, 3)
    # one pool request per kernel call, for the slots beside the calling thread's
    assert (set(asked) == {threads - 1}) if threads > 1 else asked == [], asked


def test_scratch_follows_the_configuration(imodel, settings):
    """The compiled step sizes its per-state scratch from the configuration
    (split pieces, baselines): a state stepped under another configuration
    gets new scratch, never the old one (the kernels do not check bounds)."""
    import dataclasses

    run = run_of(CATALOGUE["crossing_1458"])
    q = np.array(run.q_meas[:3])
    x0 = initial_box_from_mode(imodel, q[0], int(run.mode_true[0]), settings)
    small = configure(imodel, dataclasses.replace(settings, split_boxes=2))
    big = configure(imodel, settings)
    from crosscert.verifier.step import init_state, step

    st = init_state(small, x0)
    step(small, st, q[:1])
    pieces = st.kernel_args["scratch"].pieces.shape
    step(big, st, q[1:2])
    assert st.kernel_args["config"] is big and st.kernel_args["scratch"].pieces.shape[1] > pieces[1]


def test_the_state_schema_is_written_once():
    """Every array of the state is a row or a scenario array, and the compiled kernels receive exactly those
    parts under the state's own names (built from verifier.state, never listed again)."""
    import dataclasses

    from crosscert.verifier.compiled import step as kernels
    from crosscert.verifier.state import ROW_FIELDS, SCENARIO_FIELDS, TrackerState

    arrays = [f.name for f in dataclasses.fields(TrackerState) if f.type in ("np.ndarray", np.ndarray)]
    assert sorted(arrays) == sorted(ROW_FIELDS + SCENARIO_FIELDS) and not set(ROW_FIELDS) & set(SCENARIO_FIELDS)
    assert kernels.Rows._fields == ROW_FIELDS and kernels.Scenarios._fields == SCENARIO_FIELDS
