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


def test_settled_pieces_change_no_result_below_the_piece_budget(monkeypatch):
    """A piece left whole because splitting it can change neither result (``contractors._settled``) gives
    the boxes and modes of splitting it, float for float, while no scenario reaches its piece budget: the
    rule spares work only.  It does spare some on these boxes (pieces of both modes around the locus)."""
    model = interval_model()
    settled = []
    real = ref._settled

    def spy(*args):
        out = real(*args)
        settled.append(int(out.sum()))
        return out

    cases = list(_cases())
    X, Q, XI = (np.concatenate(b) for b in zip(*cases))
    box = lambda a: (a[:, 0], a[:, 1])  # noqa: E731
    monkeypatch.setattr(ref, "_settled", spy)
    (lo, hi), mode = ref.split_prune(model, box(X), box(Q), box(XI), max_pieces=10_000, tol=2e-4)
    monkeypatch.setattr(ref, "_settled", lambda lo, hi, *rest: np.zeros(len(lo), bool))
    (lo0, hi0), mode0 = ref.split_prune(model, box(X), box(Q), box(XI), max_pieces=10_000, tol=2e-4)
    np.testing.assert_array_equal(lo, lo0)
    np.testing.assert_array_equal(hi, hi0)
    np.testing.assert_array_equal(mode, mode0)
    assert sum(settled) > 0


def test_settled_needs_final_pieces_of_no_common_mode_holding_the_piece():
    """``_settled`` case by case: the final pieces' modes must leave no common one (a 0, or both signs),
    the piece must lie inside their hull (bounds compared as floats, ends included), scenarios apart, and
    a NaN bound settles nothing."""
    lo = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.2], [0.5, 0.2], [0.0, 0.0], [0.2, 0.2]])
    hi = np.array([[0.4, 1.0], [2.0, 1.0], [1.5, 0.8], [2.5, 0.8], [1.0, 1.0], [0.3, 0.3]])
    owner = np.array([0, 0, 0, 0, 1, 1])
    final = np.array([True, True, False, False, True, False])

    def settled(mode, lo=lo, hi=hi):
        return ref._settled(lo, hi, np.array(mode), owner, final, 2).tolist()

    # both signs among scenario 0's finals: the piece inside their hull [0, 2] x [0, 1] is settled,
    # the one reaching 2.5 is not; scenario 1's only final is certified, so its piece is not settled
    assert settled([1, -1, 0, 0, 1, 0]) == [False, False, True, False, False, False]
    assert settled([0, 1, 0, 0, 0, 0]) == [False, False, True, False, False, True]  # a final of mode 0
    assert settled([1, 1, 0, 0, 1, 0]) == [False] * 6  # a common mode (+1) may still be certified
    edge = hi.copy()
    edge[2] = [2.0, 1.0]  # on the hull's upper ends: inside
    assert settled([1, -1, 0, 0, 1, 0], hi=edge)[2]
    edge[2, 0] = np.nextafter(2.0, 3.0)
    assert not settled([1, -1, 0, 0, 1, 0], hi=edge)[2]
    nan = lo.copy()
    nan[0, 1] = np.nan
    assert settled([1, -1, 0, 0, 1, 0], lo=nan)[:4] == [False] * 4
    assert not any(ref._settled(lo, hi, np.zeros(6, np.int64), owner, np.zeros(6, bool), 2))  # no final piece


@pytest.mark.parametrize("modes", [[1, -1, 0, 0], [0, 1, 0, 0], [1, 1, 0, 0], [-1, -1, 0, 0], [1, 0, 0, 0]])
@pytest.mark.parametrize("change", ["none", "edge", "past_edge", "nan_final", "nan_piece"])
def test_compiled_settle_agrees_with_the_reference(modes, change):
    """The compiled ``_settle`` clears the split flags of exactly the pieces the reference's ``_settled``
    finds (one scenario: two final pieces, two split), and says whether any piece still splits."""
    lo = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.2], [0.5, 0.2]])
    hi = np.array([[0.4, 1.0], [2.0, 1.0], [1.5, 0.8], [2.5, 0.8]])
    if change == "edge":
        hi[2] = [2.0, 1.0]
    elif change == "past_edge":
        hi[2] = [np.nextafter(2.0, 3.0), 1.0]
    elif change == "nan_final":
        lo[1, 1] = np.nan
    elif change == "nan_piece":
        hi[2, 0] = np.nan
    final = np.array([True, True, False, False])
    mode = np.array(modes, np.int64)
    want = ref._settled(lo, hi, mode, np.zeros(4, np.int64), final, 1)
    P = np.stack([lo, hi], axis=1)
    wi = np.concatenate([mode, (~final).astype(np.int64)])
    tb = np.zeros((K.TB_DQ + 1, 2, 2))
    still = K._settle(P, 4, wi, 0, 4, tb, 2)
    np.testing.assert_array_equal(wi[4:] == 0, final | want)
    assert still == bool(np.any(~final & ~want))
