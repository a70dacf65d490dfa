"""The interval linear systems of :mod:`verifier.implicit`, compiled: :func:`solve_columns`.

The per-scenario operations of :mod:`verifier.compiled.linalg` (numpy's floats bit for bit, as the tracker's
compiled backend uses them) over a batch of matrices and right-hand sides, so that the execution proofs'
systems cost microseconds instead of numpy's overhead per array operation.  Imported on first use only.
"""

from __future__ import annotations

from .contractors import I0, NO
from .interval import cached_jit
from .linalg import enclosure_scratch, precondition, solve_preconditioned

__all__ = ["scratch_size", "solve_columns"]


@cached_jit
def solve_columns(Al, Ah, bl, bh, yl, yh, sweeps, w):
    """``y[r, c]`` enclosing ``{y : A y = b}`` for ``A`` in ``[A[r]]`` ``(B, n, n)`` and ``b`` in ``[b[r, c]]``
    ``(B, C, n)``: :func:`verifier.linalg.linear_enclosure` without a given ``[y]`` (the Neumann-series start
    box, then ``sweeps`` Gauss–Seidel sweeps), each matrix preconditioned once for its ``C`` right-hand sides.
    Results into ``yl, yh`` ``(B, C, n)``; ``w`` scratch of :func:`scratch_size` floats."""
    B, C, n = bl.shape
    nn = n * n
    ah, b0, b1, y0, y1 = nn, 2 * nn, 2 * nn + n, 2 * nn + 2 * n, 2 * nn + 3 * n
    t = 2 * nn + 4 * n
    for r in range(B):
        for i in range(n):
            for j in range(n):
                w[i * n + j] = Al[r, i, j]
                w[ah + i * n + j] = Ah[r, i, j]
        precondition(w, I0, ah, n, t)
        for c in range(C):
            for i in range(n):
                w[b0 + i] = bl[r, c, i]
                w[b1 + i] = bh[r, c, i]
            solve_preconditioned(w, b0, b1, y0, y1, n, NO, sweeps, t)
            for i in range(n):
                yl[r, c, i] = w[y0 + i]
                yh[r, c, i] = w[y1 + i]


def scratch_size(n: int) -> int:
    """Floats of :func:`solve_columns`'s scratch for ``n x n`` systems."""
    return 2 * n * n + 4 * n + enclosure_scratch.py_func(n)  # the plain function: no compilation for a size
