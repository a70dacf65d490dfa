"""Rows in lanes (:mod:`verifier.compiled.lanes`): the same boxes as the per-row kernels, sound on
their own, and vectorised.

* the lanes' outward steps are ``np.nextafter``'s floats, and their sums and products are
  :mod:`verifier.compiled.interval`'s, bit for bit;
* the lanes' operations contain the exact result on their own (a containment test, not an
  agreement: it fails when the outward step is removed from the lane ``add``, ``sub`` or ``mul``);
* the rows-in-lanes driver gives the per-row driver's boxes bit for bit, on every shipped robot, on
  the window's passes, and keeps the truth inside every box of the adversarial DexTAR runs;
* the loops over lanes compiled to packed (vector) instructions.
"""

from __future__ import annotations

import math
import re
from fractions import Fraction

import numpy as np
import pytest
from numba import njit

from problems import default_settings, interval_model
from test_backends import _assert_same_boxes, _monte_carlo_batch
from test_compiled_interval import BINARY_ARGS, SPECIAL, TINY, SUB, _mismatch
from crosscert.verifier.compiled import driver
from crosscert.verifier.compiled import interval as ops
from crosscert.verifier.compiled.lanes import interval as lane
from crosscert.verifier.tracker import initial_box_from_mode, track_batch

INF = math.inf


@njit(cache=False)
def _steps(c, dn, up):
    for i in range(c.shape[0]):
        dn[i] = lane.dn(c[i])
        up[i] = lane.up(c[i])


@njit(cache=False)
def _binary(which, al, ah, bl, bh, lo, hi):
    """One lane operation over arrays, as the tape runs it (the product's general path on the flagged lanes
    in a second loop)."""
    flag = np.zeros(al.shape[0], np.bool_)
    for r in range(al.shape[0]):
        if which == 0:
            lo[r], hi[r] = lane.add(al[r], ah[r], bl[r], bh[r])
        elif which == 1:
            lo[r], hi[r] = lane.sub(al[r], ah[r], bl[r], bh[r])
        elif which == 2:
            lo[r], hi[r], flag[r] = lane.mul_fast(al[r], ah[r], bl[r], bh[r])
        else:
            lo[r], hi[r] = lane.pmul(al[r], bl[r], bh[r])
    if which == 2:
        for r in range(al.shape[0]):
            if not flag[r]:
                lo[r], hi[r] = ops._mul_general(al[r], ah[r], bl[r], bh[r])


_WHICH = {"add": 0, "sub": 1, "mul": 2, "pmul": 3}


def _lane_op(name, al, ah, bl, bh):
    lo, hi = np.empty_like(al), np.empty_like(al)
    _binary(_WHICH[name], al, ah, bl, bh, lo, hi)
    return lo, hi


def test_lane_steps_equal_nextafter():
    """The select-form steps are ``np.nextafter`` toward ``+-inf`` bit for bit: signed zeros, subnormals,
    the smallest normal numbers (where the branch-free step of Rump et al. is a float further out), the
    largest floats, infinities, NaN, and seeded floats of every binade."""
    rng = np.random.default_rng(43)
    values = SPECIAL + [math.nan, 2 * SUB, -2 * SUB, math.nextafter(TINY, 0.0), -math.nextafter(TINY, 0.0),
                        2 * TINY, -2 * TINY, 4 * TINY]
    values = np.array(values + list(rng.standard_normal(20000) * 2.0 ** rng.integers(-1074, 1024, 20000)))
    dn, up = np.empty_like(values), np.empty_like(values)
    with np.errstate(over="ignore", invalid="ignore"):
        _steps(values, dn, up)
        assert not _mismatch(dn, np.nextafter(values, -INF)).any()
        assert not _mismatch(up, np.nextafter(values, INF)).any()


@pytest.mark.parametrize("name", ["add", "sub", "mul", "pmul"])
def test_lane_ops_equal_compiled_ops(name):
    """Over every pair of special intervals and 20 000 seeded ones: the scalar kernels' floats."""
    al, ah, bl, bh = BINARY_ARGS
    if name == "pmul":
        ah = al  # a point times an interval
    got = _lane_op(name, al, ah, bl, bh)
    ref = getattr(ops, name)
    want = [ref(a, b, c) if name == "pmul" else ref(a, x, b, c)
            for a, x, b, c in zip(al.tolist(), ah.tolist(), bl.tolist(), bh.tolist())]
    for k in range(2):
        bad = np.flatnonzero(_mismatch(got[k], np.array([w[k] for w in want])))
        assert bad.size == 0, (name, k, bad.size, [(al[i], ah[i], bl[i], bh[i], got[k][i]) for i in bad[:3]])


_EXACT = {"add": lambda a, b: a + b, "sub": lambda a, b: a - b, "mul": lambda a, b: a * b,
          "pmul": lambda a, b: a * b}


@pytest.mark.parametrize("name", sorted(_EXACT))
def test_lane_ops_contain_the_exact_result(name):
    """``[x, x] op [y, y]`` holds the exact rational ``x op y``, with distinct bounds where it is not a
    float: without the outward step the nearest float misses the exact value and this fails."""
    rng = np.random.default_rng(20261207)
    x = rng.uniform(-4.0, 4.0, 2000) * 10.0 ** rng.integers(-6, 6, 2000)
    y = rng.uniform(-4.0, 4.0, 2000) * 10.0 ** rng.integers(-6, 6, 2000)
    lo, hi = _lane_op(name, x, x, y, y)
    inexact = 0
    for a, b, l, h in zip(x.tolist(), y.tolist(), lo.tolist(), hi.tolist()):
        exact = _EXACT[name](Fraction(a), Fraction(b))
        assert Fraction(l) <= exact <= Fraction(h), (name, a, b, l, h)
        if Fraction(_EXACT[name](a, b)) != exact:
            inexact += 1
            assert l < h, (name, a, b, l, h)
    assert inexact > 500


# ------------------------------------------------------------------------------------ the driver


@pytest.fixture
def lanes(monkeypatch):
    """Switch between the drivers: ``lanes(True)`` runs every ``SOUND`` batch in lanes, ``lanes(False)``
    none; returns the name of the driver the last batch ran."""
    used = []
    real = driver.CompiledStep._threads

    def spy(config, st):
        run, threads = real(config, st)
        used.append(run.__name__)
        return run, threads

    monkeypatch.setattr(driver.CompiledStep, "_threads", staticmethod(spy))
    monkeypatch.setattr(driver, "LANES_COMPILE_HERE", True)  # compiled here if not cached

    def set_lanes(on):
        monkeypatch.setattr(driver, "LANES_MIN_ROWS", 1 if on else 10**9)
        return used

    return set_lanes


def _both(lanes, fn):
    """``fn()`` with the per-row driver, then in lanes; checks which driver ran."""
    used = lanes(False)
    per_row = fn()
    assert used and set(used) == {"run_slot"}, used
    used.clear()
    lanes(True)
    in_lanes = fn()
    assert used and set(used) == {"run_lanes"}, used
    return per_row, in_lanes


def test_lanes_equal_per_row_on_the_monte_carlo_batch(lanes):
    """Crossings and bounces, random geometry, speed and quantisation, 4 geometry hypotheses each: every
    box, mode, verdict and step is the per-row driver's."""
    model, s, q, x0 = _monte_carlo_batch()
    (ra, a), (rb, b) = _both(lanes, lambda: track_batch(model, q, s, x0, record=True))
    assert list(ra.verdict) == list(rb.verdict)
    for f in ("initial_mode", "final_mode", "certified_at_step", "inconsistent_at_step"):
        assert np.array_equal(getattr(ra, f), getattr(rb, f)), f
    _assert_same_boxes(a, b, "lanes")


def test_lanes_equal_per_row_on_small_chunks(lanes, monkeypatch):
    """Chunks of one scenario (the chunk loop, its ends and the threads' share of the chunks): the same."""
    model, s, q, x0 = _monte_carlo_batch()
    q, x0 = q[:5, :200], (x0[0][:5], x0[1][:5])
    _, a = track_batch(model, q, s, x0, record=True, parallel=False, backend="numpy")
    monkeypatch.setattr(driver, "LANES_CHUNK_ROWS", 1)
    lanes(True)
    for parallel in (False, True):
        _, b = track_batch(model, q, s, x0, record=True, parallel=parallel)
        _assert_same_boxes(a, b, ("one-scenario chunks", parallel))


@pytest.mark.parametrize("robot", ["3rpr", "gough-stewart", "iri-five-bar"])
def test_lanes_equal_per_row_on_every_robot(lanes, robot):
    """Other dimensions (n = 3 and 6: the general Gauss–Jordan inverse) and other tapes, corner geometries
    through the robot's benchmark crossing (its reference motion when it has none): the same boxes."""
    from crosscert.planner.simulate import random_geometry, simulate_crossing, simulate_motion
    from crosscert.robots import KinematicModel, get_entry
    from crosscert.verifier import IntervalModel, TrackerSettings

    entry = get_entry(robot)
    r = entry.robot
    km, im, s = KinematicModel(r), IntervalModel(r), TrackerSettings.for_robot(r)
    runs = []
    for i in range(4):
        xi = random_geometry(r, np.random.default_rng(30 + i), corners=True)
        if entry.benchmark is not None:
            b = entry.benchmark_crossing()
            runs.append(simulate_crossing(km, b.point, b.direction, 1.2, xi_true=xi, t_rest=0.02, seed=i,
                                          working_guess=b.q_point, cruise=0.01))
        else:
            m = entry.reference_motion(xi)
            runs.append(simulate_motion(km, m.start, m.goal, 0.25, xi_true=xi, working_guess=m.q_start, seed=i,
                                        t_rest=0.02, t_rest_end=0.02))
    K = min(len(run.t) for run in runs)
    q = np.stack([run.q_meas[:K] for run in runs])
    boxes = [initial_box_from_mode(im, q[b, 0], int(run.mode_true[0]), s) for b, run in enumerate(runs)]
    x0 = (np.array([bx[0] for bx in boxes]), np.array([bx[1] for bx in boxes]))
    (_, a), (_, b) = _both(lanes, lambda: track_batch(im, q, s, x0, record=True))
    _assert_same_boxes(a, b, robot)
    assert np.all(a["mode"][:, 0] != 0)  # not vacuous: every run starts certified


def _window_arrays(w):
    out = [w.verdict, w.forward_verdict, w.hypotheses]
    for x in (w, *w.hypotheses):
        out += [getattr(x, name, None) for name in ("x_lo", "x_hi", "xd_lo", "xd_hi", "xi_lo", "xi_hi")]
    return out


def test_lanes_equal_per_row_in_the_window(lanes):
    """A 1.0 m/s crossing the forward tracker leaves undecided: the window's passes (its sub-boxes as rows,
    the tubes of the last pass as priors, forward and backward) report the same verdicts, hypotheses,
    sub-boxes and tubes in lanes, bit for bit."""
    from crosscert.verifier.window import track_window
    from problems import simulate

    run, s = simulate(1.0, False, 4), default_settings()
    (a, b) = _both(lanes, lambda: track_window(interval_model(), run.q_meas, s, initial_mode=1))
    assert a.forward_verdict.value == "unknown" and sum(h.passes for h in a.hypotheses) >= 3, a.summary()
    for u, v in zip(_window_arrays(a), _window_arrays(b)):
        assert (u is None) == (v is None)
        if isinstance(u, np.ndarray):
            assert np.array_equal(u, v, equal_nan=True) and u.tobytes() == v.tobytes()
        else:
            assert u == v


def test_adversarial_runs_are_contained_in_lanes(lanes):
    """The bang-bang crossings and bounces of tests/test_containment.py (the acceleration budget spent,
    readings at the edges of ``+-eps_q``, corner geometries) through the lanes driver: the truth in every
    box, the right modes.  (One rounding removed from the lanes' ``add`` leaves these boxes sound but
    not the per-row kernel's: the bit-for-bit tests above and the containment of each operation catch it.)"""
    from adversarial import near_scenarios
    from test_containment import N_NEAR, NEAR_SEED, _violations

    sc = near_scenarios(N_NEAR, NEAR_SEED)
    m, s = interval_model(), default_settings()
    boxes = [initial_box_from_mode(m, x.q_meas[0], int(x.mode[0]), s) for x in sc]
    x0 = (np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes]))
    used = lanes(True)
    res, rec = track_batch(m, np.stack([x.q_meas for x in sc]), s, x0, record=True)
    assert set(used) == {"run_lanes"}
    bad = _violations(sc, res, rec)
    assert not bad, "\n".join(bad)


def _vector_ops(dispatcher) -> int:
    """Vector double operations in the LLVM IR numba generated for ``dispatcher``'s first signature."""
    ir = dispatcher.inspect_llvm(dispatcher.signatures[0])
    return len(re.findall(r"= f(?:add|sub|mul) <\d+ x double>", ir))


def test_loops_over_lanes_vectorise():
    """The loops over lanes of the sums and products compile to vector instructions (``<4 x double>`` with
    AVX, ``<2 x double>`` with SSE2): the outward step as selects on the bit pattern allows it (a call of
    ``np.nextafter`` or of a kernel that is not inlined would not)."""
    x = np.linspace(0.5, 2.0, 64)
    out = np.empty_like(x), np.empty_like(x)
    for which in range(4):
        _binary(which, x, x + 1.0, -x, x, *out)
    assert _vector_ops(_binary) > 0


def test_the_lanes_tape_vectorises(imodel):
    """The tape interpreter over lanes (:func:`verifier.compiled.lanes.tape.forward`) holds vector sums and
    products, read from the LLVM IR of a fresh compilation of it (the cached driver cannot be inspected);
    and it gives the per-row interpreter's floats, lane by lane."""
    from crosscert.verifier.compiled.lanes.tape import forward
    from crosscert.verifier.compiled.tape import T_VEL, interpret, trig_memo

    @njit(cache=False)
    def run(prog, il, ih, nl, nh, L, mk, mv, flag):
        forward(prog, T_VEL, il, ih, nl, nh, L, mk, mv, flag)

    prog, n, m = imodel.program, imodel.n, imodel.m
    L = 32
    rng = np.random.default_rng(3)
    mid = rng.uniform(-0.5, 0.5, (3 * n + m, L))
    il, ih = mid - rng.uniform(0, 1e-3, mid.shape), mid + rng.uniform(0, 1e-3, mid.shape)
    nl, nh = np.zeros((prog.n_nodes, L)), np.zeros((prog.n_nodes, L))
    mk, mv = trig_memo()
    run(prog, il, ih, nl, nh, L, mk, mv, np.zeros(L, np.bool_))
    assert _vector_ops(run) > 0
    count = prog.meta[int(T_VEL), 1]
    for r in range(L):
        lo, hi = np.zeros(prog.n_nodes), np.zeros(prog.n_nodes)
        interpret(prog, T_VEL, il[:, r].copy(), ih[:, r].copy(), lo, hi, *trig_memo())
        assert lo[:count].tobytes() == nl[:count, r].tobytes() and hi[:count].tobytes() == nh[:count, r].tobytes()
