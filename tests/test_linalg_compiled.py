"""The compiled 2 x 2 linear algebra written out on scalars against the numpy reference, bit for bit.

:func:`verifier.compiled.linalg.point_inverse` takes a path of its own for ``n = 2`` (every sample
of a planar robot inverts six such matrices); its floats must be those of the general loops and of
:func:`verifier.linalg.point_inverse`, signed zeros included (compared as bit patterns).
"""

from __future__ import annotations

import numpy as np
import pytest

from crosscert.verifier import linalg as ref
from crosscert.verifier.compiled import linalg as K


def _edge_matrices(n, rng):
    """Random matrices and the cases where the elimination branches: ties and swaps of the pivot,
    zero and negative pivots (signed zeros in the inverse), singular, overflowing and non-finite."""
    out = [rng.normal(size=(n, n)) * 10.0 ** rng.integers(-3, 4) for _ in range(300)]
    out += [rng.integers(-2, 3, size=(n, n)).astype(float) for _ in range(300)]  # zeros, ties, singular
    special = [0.0, -0.0, 1.0, -1.0, 1e-310, 1e300, -1e300, np.inf, -np.inf, np.nan]
    for _ in range(300):
        out.append(rng.choice(special, size=(n, n)))
    for v in (np.eye(n), -np.eye(n), np.ones((n, n)), np.zeros((n, n)), np.eye(n)[::-1]):
        out.append(v.copy())
    return np.array(out)


def _compiled_inverse(A, n):
    w = np.zeros(3 * n * n)
    C = np.empty_like(A)
    for s in range(len(A)):
        w[: n * n] = A[s].ravel()
        K.point_inverse(w, np.int64(0), np.int64(n * n), np.int64(2 * n * n), np.int64(n))
        C[s] = w[n * n: 2 * n * n].reshape(n, n)
    return C


@pytest.mark.parametrize("n", [2, 3])
def test_point_inverse_bitwise(n):
    """n = 2 is the path written out, n = 3 the general loops.  In the n = 2 path, a pivot test
    ``>=`` instead of ``>``, a dropped division by the pivot, a dropped last elimination step or a
    dropped finiteness check of the inverse each fails this test."""
    rng = np.random.default_rng(17)
    A = _edge_matrices(n, rng)
    with np.errstate(all="ignore"):
        want = ref.point_inverse(A)
    got = _compiled_inverse(A, n)
    bad = np.nonzero(np.any(got.view(np.int64) != want.view(np.int64), axis=(1, 2)))[0]
    assert bad.size == 0, f"{bad.size} matrices differ, first {A[bad[0]]}: {got[bad[0]]} != {want[bad[0]]}"


@pytest.mark.parametrize("n", [2, 3])
def test_one_preconditioning_serves_several_right_hand_sides(n):
    """The velocity contractor preconditions a matrix once for the baselines whose ``[J_x]`` has the
    same bits (:func:`verifier.compiled.contractors._solve_vel`): :func:`precondition` once, then
    :func:`solve_preconditioned` for each ``[b]`` and start box, gives the reference's
    ``linear_enclosure`` of every system bit for bit."""
    rng = np.random.default_rng(31 + n)
    nn = n * n
    al, ah, bl, bh, yl, yh, t = 0, nn, 2 * nn, 2 * nn + n, 2 * nn + 2 * n, 2 * nn + 3 * n, 2 * nn + 4 * n
    for _ in range(60):
        mid = rng.normal(size=(n, n)) + 3 * np.eye(n)
        rad = np.abs(rng.normal(size=(n, n))) * 10.0 ** rng.integers(-6, 0)
        w = np.zeros(t + K.enclosure_scratch(n))
        w[al:ah], w[ah:bl] = (mid - rad).ravel(), (mid + rad).ravel()
        K.precondition(w, np.int64(al), np.int64(ah), np.int64(n), np.int64(t))
        for _ in range(4):
            b = rng.normal(size=n)
            b_lo, b_hi = b - 0.1 * rng.random(n), b + 0.1 * rng.random(n)
            y0 = np.abs(rng.normal(size=n)) * rng.choice([0.5, 100.0])
            w[bl:bh], w[bh:yl], w[yl:yh], w[yh:t] = b_lo, b_hi, -y0, y0
            K.solve_preconditioned(w, np.int64(bl), np.int64(bh), np.int64(yl), np.int64(yh), np.int64(n),
                                   True, np.int64(1), np.int64(t))
            want = ref.linear_enclosure((mid - rad)[None], (mid + rad)[None], b_lo[None], b_hi[None], -y0[None],
                                        y0[None], sweeps=1)
            for got, exp in ((w[yl:yh], want[0][0]), (w[yh:t], want[1][0])):
                assert np.array_equal(got.view(np.int64), exp.view(np.int64)), (got, exp)


@pytest.mark.parametrize("n", [2, 3])
def test_the_execution_proofs_systems_are_the_references_bit_for_bit(n):
    """:func:`verifier.compiled.implicit.solve_columns` (each matrix of a batch preconditioned once for its
    right-hand sides, the Neumann start box) gives the reference's ``linear_enclosure`` of every system bit
    for bit: well-conditioned, wide (``beta >= 1``: unbounded) and non-finite matrices, point and wide
    right-hand sides."""
    from crosscert.verifier.compiled.implicit import scratch_size, solve_columns

    rng = np.random.default_rng(47 + n)
    B, C = 40, 3
    mid = rng.normal(size=(B, n, n)) + 3 * np.eye(n)
    rad = np.abs(rng.normal(size=(B, n, n))) * 10.0 ** rng.integers(-9, 1, (B, 1, 1))
    Al, Ah = mid - rad, mid + rad
    Al[0, 0, 0], Ah[1, 0, 1] = -np.inf, np.nan
    b = rng.normal(size=(B, C, n))
    w_b = rng.random((B, C, n)) * (rng.random((B, C, 1)) < 0.7)
    bl, bh = b - w_b, b + w_b
    with np.errstate(all="ignore"):
        want = ref.linear_enclosure(Al[:, None], Ah[:, None], bl, bh, sweeps=2)
    yl, yh = np.empty((B, C, n)), np.empty((B, C, n))
    solve_columns(Al, Ah, bl, bh, yl, yh, 2, np.empty(scratch_size(n)))
    for got, exp in ((yl, want[0]), (yh, want[1])):
        assert np.array_equal(got.view(np.int64), exp.view(np.int64))
    assert np.isinf(yh).any() and np.isfinite(yh).any()
