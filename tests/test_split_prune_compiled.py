"""The compiled branch and prune against the reference, bit for bit, on boxes
around the singular locus, and the box comparison its skipped work rests on.

The compiled :func:`verifier.compiled.contractors.split_prune` skips two
computations of the reference whose results it already has (the mode of a
piece kept unsplit, the sweeps after one that left a piece unchanged); these
boxes make it split for several generations, keep pieces, prune others and
reach the piece budget, so a skip that changed a float fails here (and in
tests/test_backends.py's catalogue).
"""

from __future__ import annotations

import numpy as np
import pytest

from crosscert.verifier import contractors as ref
from crosscert.verifier.compiled import contractors as K
from crosscert.verifier.step import partition_xi, reading_box

from problems import CATALOGUE, default_settings, interval_model, run_of


def test_same_box_compares_bit_patterns():
    A = np.zeros((2, 2, 2))
    A[0] = [[0.0, np.nan], [1.0, 2.0]]
    A[1] = A[0]
    assert K.same_box(A, 0, A, 1, 2)
    A[1, 0, 0] = -0.0  # equal as floats, another input to a kernel
    assert not K.same_box(A, 0, A, 1, 2)
    A[1, 0, 0] = 0.0
    A[1, 1, 1] = np.nextafter(2.0, 3.0)
    assert not K.same_box(A, 0, A, 1, 2)
    assert K.same_box(A, 0, A, 1, 1)  # the first component only


def _cases():
    """(X, Q, XI) boxes ``(1, 2, k)`` like those the tracker gives the branch and prune on the 1.458 m/s
    crossing: around the true pose near the singular instant, about 1 mm by 1-3 cm (seeded offsets), the
    reading's box and each geometry hypothesis of the robot's partition of its calibration box."""
    run = run_of(CATALOGUE["crossing_1458"])
    model = interval_model()
    s = default_settings().validated(model.n)
    xi = model.xi_box()
    lo, hi = partition_xi((xi[0][None], xi[1][None]), s.xi_splits)
    rng = np.random.default_rng(17)
    for k in range(run.k_sing - 6, run.k_sing + 9, 3):
        ql, qh = reading_box(run.q_meas[k], s.eps_q)
        for w in ((1e-3, 1.3e-2), (2e-3, 3e-2), (5e-4, 5e-3)):
            c = run.x_true[k] + rng.uniform(-0.3, 0.3, model.n) * w
            X = np.array([[c - w * rng.uniform(0.5, 1.0, model.n), c + w * rng.uniform(0.5, 1.0, model.n)]])
            for p in range(lo.shape[1]):
                yield X, np.array([[ql, qh]]), np.array([[lo[0, p], hi[0, p]]])


@pytest.mark.parametrize("max_pieces, tol", [(64, 2e-4), (16, 1e-4)])
def test_split_prune_matches_the_reference(max_pieces, tol):
    model = interval_model()
    prog = model.program
    n, m = model.n, model.m
    sc = K.Scratch(*(a[0] for a in K.scratch_arrays(1, prog.n_nodes, n, m, 1, max_pieces, 1)))
    decided = undecided = 0
    for X, Q, XI in _cases():
        (lo, hi), mode = ref.split_prune(model, (X[:, 0], X[:, 1]), (Q[:, 0], Q[:, 1]), (XI[:, 0], XI[:, 1]),
                                         max_pieces=max_pieces, tol=tol, sweeps=2)
        got = X.copy()
        got_mode = K.split_prune(prog, got, 0, Q, 0, XI, 0, max_pieces, tol, 2, n, m, sc, 1)
        assert got_mode == mode[0]
        np.testing.assert_array_equal(got[0, 0], lo[0])
        np.testing.assert_array_equal(got[0, 1], hi[0])
        decided += got_mode != 0
        undecided += got_mode == 0
    assert decided > 0 and undecided > 0
