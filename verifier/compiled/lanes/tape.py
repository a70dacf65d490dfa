"""A tape's forward sweep over lanes: one dispatch per instruction for every lane.

Node bounds live structure-of-arrays, ``lo[node, lane]``, inputs
``in_lo[input, lane]``.  Sums, differences and products run the select-form
operations of :mod:`.interval` (they vectorise); the other operations run
:mod:`verifier.compiled.interval`'s, lane by lane; sines and cosines go
through the thread's memo (:func:`verifier.compiled.tape.trig`, the same
floats hit or miss).  Node for node the floats of
:func:`verifier.compiled.tape.interpret` and of the straight-line code.
"""

from __future__ import annotations

from .. import interval as ops
from ..interval import jit
from ...tape import OPCODES
from ..tape import trig
from . import interval as lane

__all__ = ["forward"]

_INPUT, _CONST, _ADD, _SUB, _MUL, _DIV, _NEG, _SQ, _SQRT, _SIN, _COS, _TWICE, _FABS, _INV, _ASSIGN = (
    OPCODES[f"OP_{name}"] for name in ("INPUT", "CONST", "ADD", "SUB", "MUL", "DIV", "NEG", "SQ", "SQRT", "SIN", "COS",
                                      "TWICE", "FABS", "INV", "ASSIGN"))


@jit
def forward(prog, t, in_lo, in_hi, lo, hi, L, mk, mv, flag):
    """Evaluate tape ``t`` of the program ``prog`` on lanes ``0 .. L - 1``: inputs ``in_lo, in_hi``
    ``(inputs, >= L)``, every node's bounds into ``lo, hi`` ``(n_nodes, >= L)``; ``flag`` ``(>= L,)``
    bool scratch (the products' general-path lanes); ``mk, mv`` the thread's memo of sines and cosines."""
    code = prog.code
    value = prog.value
    c0 = prog.meta[t, 0]
    for i in range(prog.meta[t, 1]):
        op = code[c0 + i, 0]
        a = code[c0 + i, 1]
        b = code[c0 + i, 2]
        if op == _INPUT:
            for r in range(L):
                lo[i, r] = in_lo[a, r]
                hi[i, r] = in_hi[a, r]
        elif op == _CONST:
            v = value[c0 + i]
            for r in range(L):
                lo[i, r] = v
                hi[i, r] = v
        elif op == _ADD:
            for r in range(L):
                lo[i, r], hi[i, r] = lane.add(lo[a, r], hi[a, r], lo[b, r], hi[b, r])
        elif op == _SUB:
            for r in range(L):
                lo[i, r], hi[i, r] = lane.sub(lo[a, r], hi[a, r], lo[b, r], hi[b, r])
        elif op == _MUL:
            for r in range(L):
                lo[i, r], hi[i, r], flag[r] = lane.mul_fast(lo[a, r], hi[a, r], lo[b, r], hi[b, r])
            for r in range(L):
                if not flag[r]:
                    lo[i, r], hi[i, r] = ops._mul_general(lo[a, r], hi[a, r], lo[b, r], hi[b, r])
        elif op == _TWICE:
            for r in range(L):
                lo[i, r], hi[i, r] = lane.add(lo[a, r], hi[a, r], lo[a, r], hi[a, r])
        elif op == _DIV:
            for r in range(L):
                lo[i, r], hi[i, r] = ops.div(lo[a, r], hi[a, r], lo[b, r], hi[b, r])
        elif op == _NEG:
            for r in range(L):
                lo[i, r], hi[i, r] = ops.neg(lo[a, r], hi[a, r])
        elif op == _SQ:
            for r in range(L):
                lo[i, r], hi[i, r] = ops.sqr(lo[a, r], hi[a, r])
        elif op == _SQRT:
            for r in range(L):
                lo[i, r], hi[i, r] = ops.sqrt(lo[a, r], hi[a, r])
        elif op == _SIN or op == _COS:
            for r in range(L):
                lo[i, r], hi[i, r] = trig(op, lo[a, r], hi[a, r], mk, mv)
        elif op == _FABS:
            for r in range(L):
                lo[i, r], hi[i, r] = ops.absolute(lo[a, r], hi[a, r])
        elif op == _INV:
            for r in range(L):
                lo[i, r], hi[i, r] = ops.div(1.0, 1.0, lo[a, r], hi[a, r])
        elif op == _ASSIGN:
            for r in range(L):
                lo[i, r] = lo[a, r]
                hi[i, r] = hi[a, r]
        else:  # _CONSTPOW
            p = int(value[c0 + i])
            for r in range(L):
                lo[i, r], hi[i, r] = ops.pown(lo[a, r], hi[a, r], p)
