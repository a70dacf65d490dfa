"""The acceleration bound between two samples of a tube: a motion model over a window of samples.

The tracker's step couples neighbouring samples only (the Taylor prediction)
and the joints over its baselines (the displacement relation).  Over a whole
recording (:mod:`verifier.window`) every pair of samples is coupled by the
acceleration bound alone.  Per pose coordinate, with ``|x''| <= a`` on
``[t_k, t_l]``, ``tau = t_l - t_k``, positions ``x_k, x_l`` and velocities
``v_k, v_l`` at the two samples (docs/soundness.md, "Window reasoning", step 8)::

    |x_l - x_k - (v_k + v_l) tau / 2|  <=  a tau^2 / 4 - (v_l - v_k)^2 / (4 a).        (*)

The bound is sharp: it is what a motion that accelerates (or brakes) at
``a`` and then brakes (accelerates) at ``a`` reaches.  Its last term is what
the per-sample tracker misses near a Type 2 singularity: a motion that turns
back between two samples needs the distance ``(v_l - v_k)^2 / (4 a)`` that
plain Taylor remainders (``a tau^2 / 2`` about either end) give away.

:func:`contract_tubes` projects ``(*)`` onto each of the four quantities, for
the pairs ``(k, k + j)``, ``j`` in :data:`MOTION_OFFSETS`, whose velocity
boxes are disjoint in some row (elsewhere the square's lower bound is 0),
vectorised over ``k``, with outward rounding (:mod:`verifier.interval`); with ``compiled=True``
(the window's compiled backend) the pairs are contracted by the same operations compiled
(:mod:`verifier.compiled.motion_model`), the same floats at a fraction of numpy's cost per call.  Shapes:
``R`` rows, ``K`` samples, pose dimension ``n``; SI units.

Samples at stamped times (``times``: jitter, dropped samples): the pair's ``tau`` is not known, only an
enclosure of it.  The true ``t_k`` and ``t_l`` lie in their stamps' enclosures, so the true ``tau`` lies
in their difference (outward rounded), and ``(*)`` holds with that enclosure wherever the constant step
used ``j t_s``: its right side grows with ``tau`` (the upper bound takes ``tau``'s upper end), and the
projections multiply by enclosures of ``tau / 2`` and ``2 / tau``.  A pair whose enclosure reaches 0 or
below is not contracted (the bound needs ``tau > 0``).
"""

from __future__ import annotations

import functools

import numpy as np

from . import interval as I

__all__ = ["MOTION_OFFSETS", "contract_tubes"]

#: Sample distances ``j`` of the coupled pairs ``(k, k + j)``, in this order (measured on the certify
#: task's plan at 0.961 m/s: these certify it, 1 and 2 alone do not; docs/tracker.md, "Window reasoning").
MOTION_OFFSETS = (1, 2, 4, 8)


def _pm(box, r):
    """``[box] + [-r, r]`` (``r`` an upper bound; a negative one shrinks the box, towards empty)."""
    return I.add(*box, -r, r)


def _constants(j: int, t_s: float, a):
    """For pairs ``j`` samples apart: enclosures of ``tau = j t_s``, ``2 / tau`` and ``4 a``, and an upper
    bound of ``a tau^2 / 4`` (``a`` ``(n,)``)."""
    return _constants_of_tau(I.scale(float(j), t_s, t_s), a)


def _constants_of_tau(tau, a):
    """:func:`_constants` from an enclosure ``tau`` (``tau_lo > 0``) of the time between the two samples:
    floats, or ``(P, 1)`` arrays (one pair a row; the results broadcast over ``(R, P, n)``)."""
    # a tau * (tau / 4): the upper end of the product of two positive enclosures, from tau's upper end
    e4 = I.mul(*I.mul(a, a, *tau), *I.scale(0.25, *tau))[1]
    return tau, I.div(2.0, 2.0, *tau), e4, I.scale(4.0, a, a)


def _constants_of(j: int, t_s: float, a):
    """:func:`_constants`, remembered for the last few ``(j, t_s, a)`` (the window contracts with the same
    ones after every pass, and deriving them cost as much as the compiled contraction itself)."""
    return _constants_remembered(int(j), float(t_s), a.shape, a.tobytes())


@functools.lru_cache(maxsize=64)
def _constants_remembered(j: int, t_s: float, shape: tuple, a_bytes: bytes):
    # a pure function of its (hashable) arguments: the same floats as _constants
    return _constants(j, t_s, np.frombuffer(a_bytes, dtype=np.float64).reshape(shape))


def _kernel_constants(tau, inv_tau2, e4, four_a, P: int, n: int) -> tuple:
    """:func:`verifier.compiled.motion_model.pair_kernel`'s constants after ``(x, xd, k, j)``: the enclosures
    of ``tau``, ``2 / tau`` and ``tau / 2`` per pair ``(P,)`` each, ``e4`` ``(P, n)`` and ``4 a`` ``(n,)``
    (``tau`` ... ``four_a`` as :func:`_constants` or :func:`_constants_of_tau` give them)."""
    half = I.scale(0.5, *tau)
    per_pair = (_per_pair(v, P) for v in (*tau, *inv_tau2, *half))
    per_axis = (np.ascontiguousarray(np.broadcast_to(v, (n,)), np.float64) for v in four_a)
    return (*per_pair, _per_pair(e4, P, (n,)), *per_axis)


@functools.lru_cache(maxsize=64)
def _kernel_constants_remembered(j: int, t_s: float, shape: tuple, a_bytes: bytes, size: int, n: int) -> tuple:
    """:func:`_kernel_constants` of a constant step for ``size`` pairs ``j`` samples apart (the kernel reads the
    first ``P`` entries of each), remembered like :func:`_constants_of` (the window contracts with the same ones
    after every pass).  Shared by the calls: the kernel only reads them (writable all the same: a read-only
    array is another type to numba)."""
    return _kernel_constants(*_constants_remembered(j, t_s, shape, a_bytes), size, n)


def _remainder(vk, vl, e4, four_a):
    """Upper bound of ``a tau^2 / 4 - (v_l - v_k)^2 / (4 a)`` over the velocity boxes ``vk``, ``vl``: the
    square's lower bound, divided by ``4 a`` downwards, subtracted upwards (negative: no motion within
    ``a`` joins the two velocities)."""
    d2 = I.sqr(*I.sub(*vl, *vk))[0]
    q = I.div(d2, d2, *four_a)[0]
    return I.sub(e4, e4, q, q)[1]


def _pair(x, xd, k, l, tau, inv_tau2, e4, four_a):
    """Contract the boxes of samples ``k`` and ``l`` (index arrays of equal length, ``l`` later) with ``(*)``,
    in place (:func:`_constants` gives the other arguments, or :func:`_constants_of_tau` per pair).  Returns
    where the remainder bound is negative ``(R, *, n)``."""
    xk, xl = (x[:, k, 0], x[:, k, 1]), (x[:, l, 0], x[:, l, 1])
    vk, vl = (xd[:, k, 0], xd[:, k, 1]), (xd[:, l, 0], xd[:, l, 1])
    r = _remainder(vk, vl, e4, four_a)
    # velocities: v_k + v_l = 2 (x_l - x_k) / tau + [-2 r / tau, 2 r / tau]
    s2 = I.mul(*I.sub(*xl, *xk), *inv_tau2)
    r2 = I.mul(r, r, *inv_tau2)[1]
    vk = I.intersect(*vk, *_pm(I.sub(*s2, *vl), r2))
    vl = I.intersect(*vl, *_pm(I.sub(*s2, *vk), r2))
    # positions: x_l - x_k = (v_k + v_l) tau / 2 + [-r, r]
    m = I.mul(*I.add(*vk, *vl), *I.scale(0.5, *tau))
    xl = I.intersect(*xl, *_pm(I.add(*xk, *m), r))
    xk = I.intersect(*xk, *_pm(I.sub(*xl, *m), r))
    # a sample is the k of one pair and the l of another: the second write keeps what the first contracted
    for tube, new_k, new_l in ((xd, vk, vl), (x, xk, xl)):
        tube[:, k, 0], tube[:, k, 1] = new_k
        tube[:, l, 0], tube[:, l, 1] = I.intersect(tube[:, l, 0], tube[:, l, 1], *new_l)
    return r < 0.0


def _taus(times, j: int):
    """Enclosures ``(lo, hi)`` ``(K - j,)`` of ``t_{k+j} - t_k`` from enclosures ``times`` ``(K, 2)`` of the
    true times: each true time lies in its enclosure, so their difference lies in the difference of the
    enclosures (rounded outward)."""
    K = times.shape[0]
    return I.sub(times[j:, 0], times[j:, 1], times[:K - j, 0], times[:K - j, 1])


def _stamped_times(times, K: int):
    """``times`` checked: float64 ``(K, 2)``, finite, ``lo <= hi`` in every row."""
    t = np.asarray(times, dtype=np.float64)
    if t.shape != (K, 2):
        raise ValueError(f"times: shape {t.shape}, expected ({K}, 2) (one enclosure [lo, hi] per sample)")
    if not np.all(np.isfinite(t)) or np.any(t[:, 0] > t[:, 1]):
        raise ValueError("times: every enclosure must be finite with lo <= hi")
    return t


def _per_pair(v, P: int, shape=()):
    """``v`` (a float, or per pair ``(P, 1)`` / ``(P, n)``) as a new C-contiguous ``(P, *shape)`` array.
    Always a writable copy: a broadcast view is read-only, a different type to numba, and the kernel's
    argument types must not depend on ``times`` or on ``P`` (one compilation, tests/test_warm.py)."""
    v = np.asarray(v, dtype=np.float64)
    if not shape:
        v = v.reshape(-1)
    return np.array(np.broadcast_to(v, (P, *shape)), dtype=np.float64, order="C")


def contract_tubes(x, xd, t_s: float, a_max, offsets=MOTION_OFFSETS, *, compiled: bool = False, times=None):
    """Contract pose and velocity tubes with the acceleration bound between pairs of samples (module docstring).

    Parameters
    ----------
    x, xd : ndarray, shape (R, K, 2, n)
        Pose (m) and velocity (m/s) tubes, ``[..., 0, :]`` the lower and
        ``[..., 1, :]`` the upper bounds, at ``t_k = t_0 + k t_s`` (or at
        the times of ``times``).  Contracted in place.
    t_s : float
        Sampling period, s (assumption A6: exactly this float).  Unused
        with ``times``.
    a_max : array_like, shape (n,)
        Bound on ``|x''|`` per pose coordinate, m/s^2 (assumption A2), > 0.
    offsets : sequence of int
        Sample distances of the coupled pairs (in samples of the arrays:
        with ``times``, a dropped sample is no sample).
    compiled : bool
        Contract the pairs with :func:`verifier.compiled.motion_model.pair_kernel`
        (numba; the same floats bit for bit, without numpy's cost per call)
        instead of :func:`_pair`.
    times : array_like, shape (K, 2), optional
        For each sample an enclosure ``[lo, hi]`` of its true time, s (any
        origin common to all samples), finite, ``lo <= hi``, increasing
        in ``k``: recordings with jittered stamps or dropped samples.  The
        pair ``(k, l)`` then uses ``tau`` in
        ``[times[l, 0] - times[k, 1], times[l, 1] - times[k, 0]]`` (rounded
        outward), which holds the true ``t_l - t_k`` since each true time
        lies in its enclosure; pairs whose enclosure is not positive are not
        contracted.  None (default): the constant step ``t_s``.

    Returns
    -------
    ndarray of bool, shape (R,)
        Rows that no motion within ``a_max`` fits: a box became empty (or
        NaN), or two samples are farther apart in velocity than ``a_max``
        allows.  Their tubes are meaningless.

    Raises
    ------
    ValueError
        ``times`` is not ``(K, 2)``, not finite, or has an enclosure with
        ``lo > hi``.
    """
    R, K, n = x.shape[0], x.shape[1], x.shape[3]
    a = np.asarray(a_max, dtype=np.float64)
    empty = np.zeros(R, dtype=bool)
    if times is not None:
        times = _stamped_times(times, K)
    if compiled:
        from .compiled.motion_model import pair_kernel  # numba loaded on first use only
    with I.quiet_fp():
        for j in offsets:
            if not 0 < j < K:
                continue
            # cost: only the pairs whose velocity boxes are disjoint in some row (a choice of pairs, no bound);
            # elsewhere the square's lower bound is 0 and (*) is the plain trapezoid, which bought nothing
            gap = np.maximum(xd[:, j:, 0] - xd[:, :K - j, 1], xd[:, :K - j, 0] - xd[:, j:, 1])
            chosen = np.any(gap > 0.0, axis=(0, 2))
            if times is None:
                k = np.nonzero(chosen)[0]
                if not k.size:
                    continue
                tau, inv_tau2, e4, four_a = _constants_of(j, t_s, a)
            else:
                # (*) needs tau > 0: a pair whose enclosure is not positive is skipped, its boxes kept as they
                # are (sound, merely not contracted); NaN cannot reach here, the times are finite
                lo, hi = _taus(times, j)
                k = np.nonzero(chosen & (lo > 0.0))[0]
                if not k.size:
                    continue
                tau, inv_tau2, e4, four_a = _constants_of_tau((lo[k, None], hi[k, None]), a)
            if compiled:
                P = k.size
                if times is None:  # the same constants for every pair, remembered (their numpy cost is per call)
                    # for the power of two of pairs at or above K - j: a window growing sample by sample hits too
                    size = 1 << (K - j - 1).bit_length()
                    consts = _kernel_constants_remembered(int(j), float(t_s), a.shape, a.tobytes(), size, n)
                else:
                    consts = _kernel_constants(tau, inv_tau2, e4, four_a, P, n)
                pair_kernel(x, xd, k.astype(np.int64), j, *consts, np.empty((P, 8)), empty)
            else:
                neg = _pair(x, xd, k, k + j, tau, inv_tau2, e4, four_a)
                empty |= neg.any(axis=(1, 2))
        empty |= np.any(~(x[:, :, 0] <= x[:, :, 1]), axis=(1, 2)) | np.any(~(xd[:, :, 0] <= xd[:, :, 1]), axis=(1, 2))
    return empty
