"""The batched tracker is only a matter of speed (seeded scenarios).

* batch independence: ``track_batch`` on ``B`` scenarios gives each one the
  boxes, modes, steps and verdict of a lone ``track`` run on it, exactly;
* streaming: a :class:`~verifier.tracker.SampleStream` handing out one sample
  at a time gives the boxes and verdicts of the array it streams, exactly,
  and is asked for each sample once, in order.

The scenarios are simulated crossings and bounces at seeded random speeds,
geometries and quantisations, plus one whose readings jump (it turns
inconsistent mid-run), so a batch mixes every kind of row.
"""

from __future__ import annotations

import numpy as np
import pytest

from problems import simulate
from crosscert.verifier.tracker import SampleStream, Verdict, initial_box_from_mode, track, track_batch

FIELDS = ("x_lo", "x_hi", "xd_lo", "xd_hi", "mode")
#: scenarios and samples per backend: whole runs (padded at rest to the longest, through the
#: crossing and past a kernel block of 256 samples) for the compiled kernels, the first 70
#: samples for the slower numpy reference
SIZES = {"compiled": (6, None), "numpy": (3, 70)}


def _scenarios(seed, B, K, imodel, settings):
    """Readings ``(B, K, 2)`` of ``B`` seeded runs from rest and their initial boxes; the last one's readings jump."""
    rng = np.random.default_rng(seed)
    runs = []
    for b in range(B):
        bounce = b % 3 == 1
        v = round(float(rng.uniform(0.7, 1.4) if bounce else rng.uniform(1.2, 1.8)), 3)
        runs.append(simulate(v, bounce, 500 + b, ("floor", "round", "uniform")[b % 3]))
    K = max(r.n_samples for r in runs) if K is None else K
    q = np.stack([np.vstack([r.q_meas[:K], np.repeat(r.q_meas[-1:], max(0, K - r.n_samples), axis=0)])
                  for r in runs])
    q[-1, 10:, 0] += 0.05  # a 50 mrad jump in 1 ms: no motion within a_max explains it
    boxes = [initial_box_from_mode(imodel, q[b, 0], int(r.mode_true[0]), settings) for b, r in enumerate(runs)]
    return q, (np.array([x[0] for x in boxes]), np.array([x[1] for x in boxes]))


def _same(u, v):
    return np.array_equal(np.asarray(u), np.asarray(v), equal_nan=True)


@pytest.mark.parametrize("backend", ["compiled", "numpy"])
def test_batch_rows_equal_single_runs(backend, imodel, settings):
    """Each row of a batch: the boxes, modes, steps and verdict of ``track`` on that scenario alone."""
    q, x0 = _scenarios(11, *SIZES[backend], imodel, settings)
    B, K = q.shape[:2]
    res, rec = track_batch(imodel, q, settings, x0, record=True, backend=backend)
    assert res.verdict[-1] is Verdict.INCONSISTENT  # the jumping row is in the batch
    assert any(v is not Verdict.INCONSISTENT for v in res.verdict[:-1])
    for b in range(B):
        one = track(imodel, q[b], settings, x0=(x0[0][b], x0[1][b]), backend=backend)
        assert one.verdict is res.verdict[b], (b, one.verdict, res.verdict[b])
        assert (one.initial_mode, one.final_mode) == (res.initial_mode[b], res.final_mode[b]), b
        assert (one.certified_at_step, one.inconsistent_at_step) == (res.certified_at_step[b],
                                                                     res.inconsistent_at_step[b]), b
        assert (one.max_width_pose, one.max_width_velocity) == (res.max_width_pose[b], res.max_width_velocity[b]), b
        for f in FIELDS:
            assert _same(getattr(one, f), rec[f][b]), (b, f)
        assert _same(one.qdd_bound, rec["qdd_hi"][b]), b


class _Feed:
    """Readings handed out one sample at a time, as fresh arrays; records which samples were asked for."""

    def __init__(self, q):
        self._rows = [np.array(q[:, k, :]) for k in range(q.shape[1])]  # (B, n) per sample
        self.asked = []

    def __call__(self, k):
        self.asked.append(k)
        return self._rows[k].tolist()  # not even an array: the stream promises only "array-like (B, n)"


@pytest.mark.parametrize("backend", ["compiled", "numpy"])
def test_stream_equals_array_input(backend, imodel, settings):
    """A SampleStream fed sample by sample gives the array input's boxes and verdicts; each sample asked once, in order."""
    q, x0 = _scenarios(12, *SIZES[backend], imodel, settings)
    B, K = q.shape[:2]
    ref, rref = track_batch(imodel, q, settings, x0, record=True, backend=backend)
    feed = _Feed(q)
    done = []
    res, rec = track_batch(imodel, SampleStream(B, K, feed), settings, x0, record=True, backend=backend,
                           progress=done.append)
    assert feed.asked == list(range(K))
    assert done == list(range(K))
    assert list(res.verdict) == list(ref.verdict)
    for f in ("initial_mode", "final_mode", "certified_at_step", "inconsistent_at_step",
              "max_width_pose", "max_width_velocity"):
        assert _same(getattr(res, f), getattr(ref, f)), f
    for f in FIELDS + ("qdd_hi",):
        assert _same(rec[f], rref[f]), f
