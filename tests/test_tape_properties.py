"""Interval tapes on random expression graphs (seeded).

A graph is a random DAG over three symbols and two constants built from
``+ - * /``, square, ``sqrt``, ``sin``, ``cos`` (and the negation, doubling,
inverse and ``fabs`` CasADi also emits); its :class:`~verifier.tape.Tape` is
evaluated on random boxes, from point boxes to boxes of width 2.

* containment: the interval of every output holds CasADi's float value of the
  same function at every sampled point of the box (interior points, the two
  extreme corners, a random vertex), which by the rounding argument of
  docs/soundness.md it must, sin/cos within the TRIG_ULPS margin (E2);
* agreement: the tape's flat program (:meth:`Tape.arrays`), run with the
  compiled scalar kernels through :mod:`verifier.compiled.vectorized` and by
  the compiled interpreter itself (:func:`verifier.compiled.tape.interpret`),
  gives the numpy tape's bounds bit for bit (sign of zero included).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from crosscert.verifier import interval as I
from crosscert.verifier.compiled import vectorized as V
from crosscert.verifier.compiled.tape import Program, interpret, output, trig_memo
from crosscert.verifier.tape import OPCODES, Tape

N_SYM = 3
N_GRAPHS = 120
N_BOXES = 24  # per graph
N_POINTS = 12  # random interior points per box, besides the corners

# numpy may use its own SIMD sin/cos where the compiled kernels call libm (see test_backends.py)
_probe = np.random.default_rng(5).uniform(-7.0, 7.0, 20000)
TRIG_SAME = bool(np.all(np.sin(_probe) == [math.sin(v) for v in _probe])
                 and np.all(np.cos(_probe) == [math.cos(v) for v in _probe]))

# unbounded intermediates (a division by an interval holding 0) make numpy warn about inf - inf
pytestmark = pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")

_UNARY = ("sq", "sqrt", "sin", "cos", "neg", "twice", "inv", "fabs")
_BINARY = ("add", "sub", "mul", "div")


def random_graph(rng, n_ops=24, n_out=3):
    """A casadi.Function ``x (3,) -> (n_out,)``: ``n_ops`` random operations on earlier nodes
    (the first operand mostly one of the last four, so the graphs grow deep)."""
    x = ca.SX.sym("x", N_SYM)
    pool = [x[i] for i in range(N_SYM)] + [ca.SX(float(c)) for c in np.round(rng.uniform(-2, 2, 2), 3)]
    used = set()

    def pick(recent):
        lo = max(0, len(pool) - 4) if recent and rng.random() < 0.7 else 0
        return pool[int(rng.integers(lo, len(pool)))]

    for _ in range(n_ops):
        op = str(rng.choice(_BINARY + _UNARY))
        a = pick(True)
        if op in _BINARY:
            b = pick(False)
            e = {"add": a + b, "sub": a - b, "mul": a * b, "div": a / b}[op]
        else:
            e = {"sq": a * a, "sqrt": ca.sqrt(a), "sin": ca.sin(a), "cos": ca.cos(a), "neg": -a,
                 "twice": 2 * a, "inv": 1 / a, "fabs": ca.fabs(a)}[op]
        used.add(op)
        pool.append(e)
    outs = pool[-n_out + 1:] + [pool[int(rng.integers(N_SYM, len(pool)))]]
    return ca.Function("g", [x], [ca.vertcat(*outs)]), used


def random_boxes(rng, count):
    """Boxes ``(count, 3)``: centres in [-2, 2], half-widths from 0 (point boxes) to 1."""
    c = rng.uniform(-2, 2, (count, N_SYM))
    r = 10.0 ** rng.uniform(-9, 0, (count, N_SYM))
    r[rng.random((count, N_SYM)) < 0.15] = 0.0
    return c - r, c + r


def points_in(rng, lo, hi):
    """Per box: ``N_POINTS`` interior points, the corners ``lo`` and ``hi`` and one random vertex: (B, P, 3)."""
    u = rng.random((len(lo), N_POINTS, N_SYM))
    inner = lo[:, None] + (hi - lo)[:, None] * u
    vertex = np.where(rng.random(lo.shape) < 0.5, lo, hi)
    return np.concatenate([inner, lo[:, None], hi[:, None], vertex[:, None]], axis=1)


def _graphs(seed):
    rng = np.random.default_rng(seed)
    for g in range(N_GRAPHS):
        fun, used = random_graph(rng)
        yield g, rng, fun, used


def test_tape_encloses_casadi_values_on_random_graphs():
    """Every output interval holds the CasADi float value at every sampled point of its box."""
    checked = total = 0
    for g, rng, fun, _used in _graphs(2024):
        tape = Tape(fun)
        lo, hi = random_boxes(rng, N_BOXES)
        olo, ohi = tape.evaluate([(lo, hi)])[0]  # (B, n_out)
        pts = points_in(rng, lo, hi)  # (B, P, 3)
        B, P, _ = pts.shape
        vals = np.array(fun.map(B * P)(pts.reshape(-1, N_SYM).T)).T.reshape(B, P, -1)
        ok = np.isfinite(vals)  # sqrt of a negative, division by 0: no value to enclose
        inside = (olo[:, None] <= vals) & (vals <= ohi[:, None])
        bad = np.argwhere(ok & ~inside)
        if bad.size:
            b, p, j = bad[0]
            pytest.fail(f"graph {g}, output {j} = {fun.sx_out(0)[j]}: box {lo[b]} .. {hi[b]}, point "
                        f"{pts[b, p].tolist()}: CasADi {vals[b, p, j]!r} outside [{olo[b, j]!r}, {ohi[b, j]!r}]")
        checked += int(ok.sum())
        total += ok.size
    assert checked > 0.5 * total, (checked, total)  # not vacuous: most points have a value


# ----------------------------------------------------------- compiled agreement
def _run_flat(ops, arrays, lo_in, hi_in):
    """Run :meth:`Tape.arrays` with an interval module ``ops`` (names of verifier.interval), batched."""
    code, value, out_nodes = arrays.code, arrays.value, arrays.out_nodes
    B = lo_in.shape[0]
    lo = [None] * len(code)
    hi = [None] * len(code)
    op_of = {v: k for k, v in OPCODES.items()}
    for i, (op, a, b) in enumerate(code):
        name = op_of[int(op)]
        if name == "OP_INPUT":
            lo[i], hi[i] = lo_in[:, a], hi_in[:, a]
        elif name == "OP_CONST":
            lo[i] = hi[i] = np.full(B, value[i])
        elif name in ("OP_ADD", "OP_SUB", "OP_MUL", "OP_DIV"):
            fn = {"OP_ADD": ops.add, "OP_SUB": ops.sub, "OP_MUL": ops.mul, "OP_DIV": ops.div}[name]
            lo[i], hi[i] = fn(lo[a], hi[a], lo[b], hi[b])
        elif name == "OP_TWICE":
            lo[i], hi[i] = ops.add(lo[a], hi[a], lo[a], hi[a])
        elif name == "OP_INV":
            lo[i], hi[i] = ops.div(1.0, 1.0, lo[a], hi[a])
        elif name == "OP_ASSIGN":
            lo[i], hi[i] = lo[a], hi[a]
        elif name == "OP_CONSTPOW":
            lo[i], hi[i] = ops.pown(lo[a], hi[a], int(value[i]))
        else:
            fn = {"OP_NEG": ops.neg, "OP_SQ": ops.sqr, "OP_SQRT": ops.sqrt, "OP_SIN": ops.sin, "OP_COS": ops.cos,
                  "OP_FABS": ops.absolute}[name]
            lo[i], hi[i] = fn(lo[a], hi[a])
    zero = np.zeros(B)
    olo = np.stack([zero if n < 0 else np.broadcast_to(lo[n], (B,)) for n in out_nodes], axis=1)
    ohi = np.stack([zero if n < 0 else np.broadcast_to(hi[n], (B,)) for n in out_nodes], axis=1)
    return olo, ohi


def _run_kernel(arrays, lo_in, hi_in):
    """The compiled interpreter (verifier.compiled.tape.interpret), one scenario at a time."""
    N = len(arrays.code)
    meta = np.array([[0, N, 0]], np.int64)
    code = np.ascontiguousarray(arrays.code, dtype=np.int64)
    outs = np.ascontiguousarray(arrays.out_nodes, dtype=np.int64)
    B, n_out = lo_in.shape[0], len(outs)
    olo, ohi = np.empty((B, n_out)), np.empty((B, n_out))
    lo, hi = np.empty(N), np.empty(N)
    mk, mv = trig_memo()
    prog = Program(code, np.ascontiguousarray(arrays.value, dtype=np.float64), outs, meta, N, np.zeros((2, 1), np.int64))
    for s in range(B):
        interpret(prog, 0, np.ascontiguousarray(lo_in[s]), np.ascontiguousarray(hi_in[s]), lo, hi, mk, mv)
        for e in range(n_out):
            olo[s, e], ohi[s, e] = output(prog, 0, e, lo, hi)
    return olo, ohi


def _same_bits(u, v):
    """Equal floats with equal signs (so -0.0 != 0.0); NaN matches NaN."""
    u, v = np.asarray(u), np.asarray(v)
    return ((u == v) & (np.signbit(u) == np.signbit(v))) | (np.isnan(u) & np.isnan(v))


@pytest.mark.parametrize("runner", ["vectorized", "kernel"])
def test_compiled_tape_agrees_with_numpy_tape_bit_for_bit(runner):
    """The compiled arithmetic on the tape's flat program gives the numpy tape's bounds, bit for bit."""
    for g, rng, fun, used in _graphs(77):
        tape = Tape(fun)
        lo, hi = random_boxes(rng, N_BOXES)
        want = tape.evaluate([(lo, hi)])[0]
        arrays = tape.arrays()
        got = _run_flat(V, arrays, lo, hi) if runner == "vectorized" else _run_kernel(arrays, lo, hi)
        exact = TRIG_SAME or not ({"sin", "cos"} & used)
        for w, v, side in ((want[0], got[0], "lo"), (want[1], got[1], "hi")):
            if exact:
                same = _same_bits(w, v)
                assert same.all(), (g, side, fun.sx_out(0), w[~same], v[~same])
            else:  # numpy's and libm's sin/cos differ on this machine: a few ulp
                assert np.allclose(w, v, rtol=1e-9, atol=1e-15, equal_nan=True), (g, side)


def test_flat_program_is_the_tape():
    """``Tape.arrays`` run with the numpy interval operations reproduces ``Tape.evaluate`` exactly."""
    for g, rng, fun, _used in _graphs(5):
        tape = Tape(fun)
        lo, hi = random_boxes(rng, N_BOXES)
        want = tape.evaluate([(lo, hi)])[0]
        got = _run_flat(I, tape.arrays(), lo, hi)
        assert _same_bits(want[0], got[0]).all() and _same_bits(want[1], got[1]).all(), g
