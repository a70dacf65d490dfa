"""The pair contraction of :mod:`verifier.motion_model` compiled: one loop over rows, pose coordinates and pairs.

:func:`pair_kernel` computes what ``verifier.motion_model._pair`` computes, operation for
operation, with the scalar interval operations of :mod:`verifier.compiled.interval` (which
give numpy's floats bit for bit, docs/rounding.md), in the same order of reads and
writes: every pair is read before any is written, the ``k`` ends are written, then
each ``l`` end is intersected with what is there.  The same floats at a fraction of
numpy's per-call cost (tests/test_motion_model.py compares the two bit for bit).
Imported on first use only, so that the numpy backend never loads numba.
"""

from __future__ import annotations

import numpy as np

from .interval import add, cached_jit, div, intersect, jit, mul, sqr, sub

#: Columns of ``new`` holding a pair's velocity and pose bounds (numpy scalars: a Python literal
#: would compile :func:`_write_ends` once per value, tests/test_kernel_compilation.py).
_VELOCITY = np.int64(0)
_POSE = np.int64(4)


@cached_jit
def pair_kernel(x, xd, k, j, tau_lo, tau_hi, it_lo, it_hi, half_lo, half_hi, e4, fa_lo, fa_hi, new, dead):
    """Contract the boxes of samples ``k`` and ``k + j`` of tubes ``x``, ``xd`` ``(R, K, 2, n)`` in place.

    Per pair ``i`` (the pair ``(k[i], k[i] + j)``): ``tau``, ``it`` (``2 / tau``) and ``half``
    (``tau / 2``) are enclosures, arrays ``(len(k),)``; ``e4`` ``(len(k), n)`` the upper bound of
    ``a tau^2 / 4``.  Per pair, because sampled at stamped times each pair has a ``tau`` of its own; on
    a constant step the caller repeats the same values.  ``fa`` ``(n,)`` is the enclosure of ``4 a``.
    ``new`` ``(len(k), 8)`` is scratch; ``dead`` ``(R,)`` is set where a remainder bound is negative.
    """
    R, n, P = x.shape[0], x.shape[3], k.shape[0]
    for r in range(R):
        for c in range(n):
            for i in range(P):
                a, b = k[i], k[i] + j
                xkl, xkh, xll, xlh = x[r, a, 0, c], x[r, a, 1, c], x[r, b, 0, c], x[r, b, 1, c]
                vkl, vkh, vll, vlh = xd[r, a, 0, c], xd[r, a, 1, c], xd[r, b, 0, c], xd[r, b, 1, c]
                # the remainder bound: a tau^2 / 4 - (v_l - v_k)^2 / (4 a), rounded up
                dl, dh = sub(vll, vlh, vkl, vkh)
                d2 = sqr(dl, dh)[0]
                q = div(d2, d2, fa_lo[c], fa_hi[c])[0]
                rem = sub(e4[i, c], e4[i, c], q, q)[1]
                if rem < 0.0:
                    dead[r] = True
                # velocities
                sl, sh = mul(*sub(xll, xlh, xkl, xkh), it_lo[i], it_hi[i])
                r2 = mul(rem, rem, it_lo[i], it_hi[i])[1]
                tl, th = sub(sl, sh, vll, vlh)
                vkl, vkh = intersect(vkl, vkh, *add(tl, th, -r2, r2))
                tl, th = sub(sl, sh, vkl, vkh)
                vll, vlh = intersect(vll, vlh, *add(tl, th, -r2, r2))
                # positions
                ml, mh = add(vkl, vkh, vll, vlh)
                ml, mh = mul(ml, mh, half_lo[i], half_hi[i])
                tl, th = add(xkl, xkh, ml, mh)
                xll, xlh = intersect(xll, xlh, *add(tl, th, -rem, rem))
                tl, th = sub(xll, xlh, ml, mh)
                xkl, xkh = intersect(xkl, xkh, *add(tl, th, -rem, rem))
                new[i, 0], new[i, 1], new[i, 2], new[i, 3] = vkl, vkh, vll, vlh
                new[i, 4], new[i, 5], new[i, 6], new[i, 7] = xkl, xkh, xll, xlh
            # the k ends first, then each l end intersected with what is there (a sample is the k of
            # one pair and the l of another)
            _write_ends(xd, r, c, k, j, new, _VELOCITY)
            _write_ends(x, r, c, k, j, new, _POSE)


@jit
def _write_ends(T, r, c, k, j, new, col):
    """Tube ``T``'s coordinate ``c`` of row ``r``: the ``k`` ends take ``new[:, col:col + 2]``, then each
    ``k + j`` end is intersected with ``new[:, col + 2:col + 4]``."""
    for i in range(k.shape[0]):
        a = k[i]
        T[r, a, 0, c], T[r, a, 1, c] = new[i, col], new[i, col + 1]
    for i in range(k.shape[0]):
        b = k[i] + j
        T[r, b, 0, c], T[r, b, 1, c] = intersect(T[r, b, 0, c], T[r, b, 1, c], new[i, col + 2], new[i, col + 3])
