"""The memo of sine and cosine bounds in the compiled interpreter
(:func:`verifier.compiled.tape.trig`).

A hit must return the very floats a recomputation gives.  The key is the
opcode and the bounds' bit patterns: a memo of one slot makes every query
collide with the previous one, so a key that ignored the upper bound, the
lower bound or the opcode would hand back a stale entry here.  End to end,
tests/test_backends.py compares the tracker, which runs through the memo,
with the numpy reference bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from crosscert.verifier.compiled import interval as ops
from crosscert.verifier.compiled.tape import MEMO_SIZE, trig, trig_memo
from crosscert.verifier.tape import OPCODES

SIN = np.int64(OPCODES["OP_SIN"])
COS = np.int64(OPCODES["OP_COS"])
NAN = math.nan
INF = math.inf
# NaN with another payload than numpy's
NAN2 = np.frombuffer(np.array([0x7FF8000000000123], np.int64).tobytes(), np.float64)[0]

ARGS = [(0.5, 1.0), (0.5, 2.0), (0.4, 1.0), (0.0, 0.0), (-0.0, 0.0), (-0.0, -0.0), (0.0, 1e-300),
        (-0.0, 1e-300), (-5e-324, 5e-324), (NAN, 1.0), (NAN2, 1.0), (0.0, NAN), (NAN, NAN), (-INF, 0.3),
        (1.0, INF), (3.0, 2.0), (1.8311521086160842, 1.8353369081839432), (-1e300, 1e300),
        (math.pi / 2, math.pi / 2), (-7.0, 7.0)]


def _bits(lo, hi):
    return np.array([lo, hi]).view(np.int64).tolist()


def _direct(op, lo, hi):
    return ops.sin(lo, hi) if op == SIN else ops.cos(lo, hi)


@pytest.mark.parametrize("size", [1, 2, MEMO_SIZE])
def test_a_memo_gives_the_floats_of_a_recomputation(size):
    """Every query, twice over in shuffled orders, matches ``ops.sin``/``ops.cos`` bit for bit
    (-0.0, NaN payloads and empty arguments included), whatever the collisions."""
    mk, mv = trig_memo(size)
    rng = np.random.default_rng(17)
    queries = [(op, lo, hi) for op in (SIN, COS) for lo, hi in ARGS]
    hits = 0
    for _ in range(3):
        for j in rng.permutation(len(queries)):
            op, lo, hi = queries[j]
            before = mk.copy()
            got = trig(op, lo, hi, mk, mv)
            assert _bits(*got) == _bits(*_direct(op, lo, hi)), (op, lo, hi)
            hits += np.array_equal(before, mk) and before[:, 0].any()
    if size == MEMO_SIZE:
        assert hits > len(queries)  # a large memo answers most repeated queries from its entries


@pytest.mark.parametrize("first, second", [
    ((SIN, 0.5, 1.0), (SIN, 0.5, 2.0)),  # same lower bound
    ((SIN, 0.5, 1.0), (SIN, 0.4, 1.0)),  # same upper bound
    ((SIN, 0.5, 1.0), (COS, 0.5, 1.0)),  # same argument, the other function
    ((COS, 0.0, 0.1), (COS, -0.0, 0.1)),  # equal as floats, not as bits
])
def test_a_colliding_query_is_recomputed(first, second):
    """With one slot, the second query lands on the first one's entry: it must not be taken for a hit."""
    mk, mv = trig_memo(1)
    trig(*first, mk, mv)
    mv[0] = (-0.25, 0.25)  # mark the entry: a wrong hit would return this
    got = trig(*second, mk, mv)
    assert _bits(*got) == _bits(*_direct(*second))
    assert _bits(*trig(*second, mk, mv)) == _bits(*got)  # and the entry now holds the second query


def test_the_key_is_the_bit_pattern():
    """An entry answers its own bit pattern only: the marked value comes back for the same
    argument (a NaN bound included, which float equality would never match), not for -0.0 when
    0.0 was stored."""
    for lo, hi in [(0.5, 1.0), (NAN2, 1.0)]:
        mk, mv = trig_memo(1)
        trig(SIN, lo, hi, mk, mv)
        mv[0] = (-0.25, 0.25)
        assert trig(SIN, lo, hi, mk, mv) == (-0.25, 0.25)
    mk, mv = trig_memo(1)
    trig(COS, 0.0, 0.1, mk, mv)
    mv[0] = (-0.25, 0.25)
    assert trig(COS, -0.0, 0.1, mk, mv) != (-0.25, 0.25)


@pytest.mark.parametrize("size", [0, 3, 256])
def test_memo_size_is_a_power_of_two_up_to_128(size):
    with pytest.raises(ValueError, match="power of two"):
        trig_memo(size)
