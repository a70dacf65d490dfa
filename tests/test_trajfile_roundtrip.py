"""Trajectory files round-trip exactly (seeded random data).

``write_trajectory`` writes ``repr(float)``, the shortest string that reads
back as the same double, so ``read_trajectory`` must return the very same
``t, q, qd, x``: equal bits, sign of zero included, for values from the
smallest subnormal to the largest double.
"""

from __future__ import annotations

import numpy as np
import pytest

from crosscert.verifier.trajfile import read_trajectory, write_trajectory

#: values a float64 column may hold that decimal printing gets wrong most easily
SPECIAL = np.array([0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 2.225073858507201e-308,
                    1.7976931348623157e308, -1.7976931348623157e308, 0.1, 1 / 3, -2 / 3, 1e-5, 1e22, 1e23,
                    9007199254740993.0, np.pi, np.nextafter(1.0, 2.0), np.nextafter(1.0, 0.0)])


def _values(rng, shape):
    """Random doubles of every magnitude and sign, exact zeros of both signs and the specials mixed in."""
    mant = rng.uniform(1.0, 10.0, shape) * rng.choice([-1.0, 1.0], shape)
    v = mant * 10.0 ** rng.integers(-323, 308, shape).astype(float)  # subnormals and overflow-free huge ones
    info = np.iinfo(np.int64)
    raw = rng.integers(info.min, info.max, shape, dtype=np.int64).view(np.float64)  # random bit patterns
    pick = rng.random(shape)
    v = np.where(pick < 0.3, raw, v)
    v = np.where((pick > 0.9) & (pick < 0.95), rng.choice(SPECIAL, shape), v)
    return np.where(np.isfinite(v), v, 1.0)  # a random pattern may be inf or NaN


def _times(rng, K):
    """Times with a constant step from 1e-300 to 1e300 s (the reader checks the step)."""
    t_s = 10.0 ** rng.uniform(-300, 300)
    t0 = t_s * rng.integers(-1000, 1000)
    return t0 + t_s * np.arange(K)


def _same_bits(a, b):
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


@pytest.mark.parametrize("seed", range(12))
def test_write_then_read_returns_the_same_bits(tmp_path, seed):
    """write_trajectory then read_trajectory: t, q, qd, x equal bit for bit (and as repr strings)."""
    rng = np.random.default_rng(seed)
    n = int(rng.choice([1, 2, 3, 6]))
    K = int(rng.integers(2, 60))
    t = _times(rng, K)
    q = _values(rng, (K, n))
    qd = _values(rng, (K, n)) if seed % 3 else None  # every third file without qd
    x = _values(rng, (K, n)) if seed % 4 else None  # every fourth without x
    path = tmp_path / "traj.csv"
    write_trajectory(path, t, q, qd=qd, x=x)
    got = read_trajectory(path, n)
    for name, want in (("t", t), ("q", q), ("qd", qd), ("x", x)):
        have = getattr(got, name)
        if want is None:
            assert have is None, name
            continue
        assert _same_bits(have, want), (name, have, want)
        assert [repr(float(v)) for v in np.ravel(have)] == [repr(float(v)) for v in np.ravel(want)], name
    assert len(got) == K and got.n == n


def test_values_cover_the_range():
    """The generator really produces subnormals, huge values and negative zeros (the test above is not vacuous)."""
    v = np.concatenate([_values(np.random.default_rng(s), (60, 6)).ravel() for s in range(12)])
    a = np.abs(v[v != 0])
    assert a.min() < 2.2250738585072014e-308 and a.max() > 1e300
    assert np.any((v == 0) & np.signbit(v))
