"""``linear_enclosure`` on random interval systems (seeded).

Point matrices ``A = Q diag(s) R`` with ``Q, R`` random orthogonal and
singular values in [1, 4] (condition number <= 4), interval matrices and
right-hand sides around them with radii from 0 (point systems) to 1e-2
relative; every point system inside the intervals, its corners included,
must have its solution inside the enclosure.  The point solutions are
computed in extended precision (one step of iterative refinement in
``np.longdouble``), so a float solver's own error cannot hide a miss by a few
ulp: the enclosure is checked against a value ~1e-18 from the exact one.
"""

from __future__ import annotations

import numpy as np
import pytest

from crosscert.verifier.linalg import linear_enclosure

B = 60  # systems per size
SAMPLES = 16  # point systems per interval system, besides the corners


def _orthogonal(rng, n):
    q, r = np.linalg.qr(rng.normal(size=(n, n)))
    return q * np.sign(np.diag(r))


def _systems(rng, n):
    """Interval systems ``(Al, Ah, bl, bh)`` around well-conditioned point systems, batch ``B``."""
    A = np.stack([_orthogonal(rng, n) @ np.diag(rng.uniform(1, 4, n)) @ _orthogonal(rng, n) for _ in range(B)])
    b = rng.normal(size=(B, n)) * 10.0 ** rng.uniform(-3, 3, (B, 1))
    rel = 10.0 ** rng.uniform(-12, -2, (B, 1, 1))
    rel[: B // 6] = 0.0  # point systems: the enclosure is only rounding wide
    rA = rel * np.abs(A).max(axis=(1, 2), keepdims=True) * rng.random((B, n, n))
    rb = rel[:, :, 0] * np.abs(b) * rng.random((B, n))
    return A - rA, A + rA, b - rb, b + rb


def _solve_refined(A, b):
    """``A^-1 b`` to ~1e-18 relative: a float solve and one refinement step with long-double residuals."""
    y = np.linalg.solve(A, b[..., None])[..., 0]
    Al, bl, yl = A.astype(np.longdouble), b.astype(np.longdouble), y.astype(np.longdouble)
    res = bl - np.einsum("...ij,...j->...i", Al, yl)
    d = np.linalg.solve(A, res.astype(np.float64)[..., None])[..., 0]
    return yl + d.astype(np.longdouble)


@pytest.mark.parametrize("n", [2, 3, 4])
def test_enclosure_contains_every_sampled_solution(n):
    """The enclosure of a random interval system holds the solutions of its sampled point systems and corners."""
    rng = np.random.default_rng(100 + n)
    Al, Ah, bl, bh = _systems(rng, n)
    lo, hi = linear_enclosure(Al, Ah, bl, bh)
    assert lo.shape == hi.shape == (B, n)
    assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))  # not vacuous: beta < 1 everywhere
    LO, HI = lo.astype(np.longdouble), hi.astype(np.longdouble)
    for s in range(SAMPLES + 4):
        if s < SAMPLES:  # interior points
            A = Al + (Ah - Al) * rng.random(Al.shape)
            b = bl + (bh - bl) * rng.random(bl.shape)
        else:  # vertices: every entry at one of its bounds
            A = np.where(rng.random(Al.shape) < 0.5, Al, Ah)
            b = np.where(rng.random(bl.shape) < 0.5, bl, bh)
        y = _solve_refined(A, b)
        out = ~((LO <= y) & (y <= HI)).all(axis=1)
        assert not out.any(), (s, np.flatnonzero(out), lo[out], hi[out], y[out])


def test_enclosure_of_a_point_system_is_tight():
    """Point systems: the enclosure is a few ulp wide around the solution (the checks above are not vacuous)."""
    rng = np.random.default_rng(7)
    Al, Ah, bl, bh = _systems(rng, 3)
    point = slice(0, B // 6)
    lo, hi = linear_enclosure(Al[point], Ah[point], bl[point], bh[point])
    y = _solve_refined(Al[point], bl[point]).astype(np.float64)
    scale = np.abs(y).max(axis=1, keepdims=True)
    assert np.all(hi - lo <= 1e-12 * scale), (hi - lo) / scale


def test_a_system_holding_a_singular_matrix_is_unbounded():
    """``A(t) = [[1, 1], [1, t]]``, ``t`` in ``[0.9, 1.1]``, ``b = (1, 1.05)``: ``y_2 = 0.05 / (t - 1)`` is a true
    solution for every ``t != 1`` of the box, of any size.  With no start box the enclosure has no bound to
    give: ``[-inf, inf]``, never the largest float (a finite claim the solutions at ``t`` near 1 exceed; the
    reference gave it until 2026-12-08), in numpy and in the compiled kernels alike."""
    from crosscert.verifier.compiled.implicit import scratch_size, solve_columns

    Al = np.array([[[1.0, 1.0], [1.0, 0.9]]])
    Ah = np.array([[[1.0, 1.0], [1.0, 1.1]]])
    bl = bh = np.array([[1.0, 1.05]])
    lo, hi = linear_enclosure(Al, Ah, bl, bh)
    assert np.all(lo == -np.inf) and np.all(hi == np.inf), (lo, hi)
    yl, yh = np.empty((1, 1, 2)), np.empty((1, 1, 2))
    solve_columns(Al, Ah, bl[:, None], bh[:, None], yl, yh, 2, np.empty(scratch_size(2)))
    assert np.all(yl == -np.inf) and np.all(yh == np.inf), (yl, yh)
