"""A robot's tapes in the kernels: forward interval evaluation and HC4Revise.

A robot's tapes (:meth:`verifier.tape.Tape.arrays`) are packed into one
:class:`Program` of flat arrays (:func:`verifier.compiled.straight.pack`).
The kernels call :func:`forward` and :func:`hc4`, which run the program's C
callback through its address (:data:`C_SIGNATURE`): the tapes written out as
straight-line code (:mod:`verifier.compiled.straight`), or, for long
programs, the interpreter of this module (:func:`interpret`,
:func:`interpret_hc4`, behind :mod:`verifier.compiled.interpreted`).  Either
way the kernels are robot-independent and compiled once.  Semantics are those
of :class:`verifier.tape.Tape`, operation for operation: the numpy reference,
the interpreter and the straight-line code compute the same floats (see
:mod:`verifier.compiled.interval`).

Kernels work on ONE scenario: node bounds in scratch arrays ``lo, hi`` of
length ``n_nodes``; inputs in a concatenated vector ``in_lo, in_hi``; the
program travels as one :class:`Program` argument.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ..tape import OPCODES
from . import interval as ops
from .interval import jit

__all__ = ["C_SIGNATURE", "HC4_TAPES", "Program", "TAPES", "forward", "hc4", "interpret", "interpret_hc4", "trig_memo"]

#: Order of the tapes in a :class:`Program` (attribute names of IntervalModel).
TAPES = ("tape_f", "tape_jx", "tape_jq", "tape_vel", "tape_jx_xd", "tape_accel_rhs", "tape_det")
# numpy integers, not Python ints: numba compiles a callee once per distinct literal int argument, and
# these index the tape of every forward / hc4 / output call (one compiled copy of each instead of seven)
T_F, T_JX, T_JQ, T_VEL, T_JX_XD, T_ACCEL, T_DET = (np.int64(i) for i in range(len(TAPES)))
#: The tapes HC4Revise contracts with (the others are only evaluated forward).
HC4_TAPES = (int(T_F),)
_NO_OUT = np.int64(0)

_INPUT = OPCODES["OP_INPUT"]
_CONST = OPCODES["OP_CONST"]
_ADD = OPCODES["OP_ADD"]
_SUB = OPCODES["OP_SUB"]
_MUL = OPCODES["OP_MUL"]
_DIV = OPCODES["OP_DIV"]
_NEG = OPCODES["OP_NEG"]
_SQ = OPCODES["OP_SQ"]
_SQRT = OPCODES["OP_SQRT"]
_SIN = OPCODES["OP_SIN"]
_COS = OPCODES["OP_COS"]
_TWICE = OPCODES["OP_TWICE"]
_FABS = OPCODES["OP_FABS"]
_INV = OPCODES["OP_INV"]
_ASSIGN = OPCODES["OP_ASSIGN"]
_CONSTPOW = OPCODES["OP_CONSTPOW"]


class Program(NamedTuple):
    """Every tape of one robot, concatenated.

    Attributes
    ----------
    code : int64 (N, 3)
        ``(opcode, a, b)`` per node, operand indices local to their tape.
    value : float64 (N,)
    outs : int64 (M,)
        Dense output entries (node index local to the tape, -1 = structural zero).
    meta : int64 (T, 3)
        Per tape (order :data:`TAPES`): first node, node count, first output entry.
    n_nodes : int
        Largest node count (size of the scratch arrays).
    fns : int64 (2, T)
        Machine-code addresses of the tapes' straight-line functions
        (:mod:`verifier.compiled.straight`): row 0 the forward sweeps, row 1
        HC4Revise (0 where a tape has none).  Set by :func:`link`.
    """

    code: np.ndarray
    value: np.ndarray
    outs: np.ndarray
    meta: np.ndarray
    n_nodes: int
    fns: np.ndarray

    def __reduce__(self):
        # machine-code addresses are this process's: a copy in another one carries none
        # (the kernels then raise instead of jumping to whatever lies there)
        return Program, (*self[:5], np.zeros_like(self.fns))


#: Entries of a thread's memo of sine and cosine bounds (a power of two).  Their
#: arguments are the joints' box and its hulls with the baselines' past boxes; the
#: joints are not contracted through sin and cos, so an argument comes back in every
#: tape and iteration, and often in the next sample: on the 1.458 m/s crossing a
#: row's sample asks for about 116 of them, of which 93 % hit.
MEMO_SIZE = 128
# the slot: multiplicative hashing (odd multipliers: the golden ratio's, splitmix64's,
# Murmur3's) and an xor-shift carry every bit of the key, the low mantissa bits where
# neighbouring arguments differ included, into the top 7 bits (MEMO_SIZE <= 128)
_H_LO = np.int64(-7046029254386353131)
_H_HI = np.int64(-4658895280553007687)
_H_TAG = np.int64(-49064778989728563)
_SLOT_SHIFT = np.int64(57)


def trig_memo(size=MEMO_SIZE):
    """An empty memo of :func:`trig`: keys ``(size, 3)`` int64 (opcode + 1,
    0 = empty; bit patterns of the lower and upper argument bound) and
    values ``(size, 2)`` float64.  ``size`` must be a power of two, at most 128."""
    if size < 1 or size > 128 or size & (size - 1):
        raise ValueError(f"trig memo size must be a power of two from 1 to 128, got {size}")
    return np.zeros((size, 3), np.int64), np.zeros((size, 2))


@jit
def trig(op, al, ah, mk, mv):
    """``sin([a])`` (``op`` = OP_SIN) or ``cos([a])`` (OP_COS), through the
    memo ``mk, mv`` (:func:`trig_memo`).

    Both are pure functions of the two bounds' bit patterns, so a hit returns
    the very floats a recomputation gives.  The key is the opcode and the
    bit patterns, not float equality: ``-0.0`` and ``0.0`` are distinct keys
    and a NaN bound matches itself only.  Direct-mapped: a colliding
    argument overwrites the slot (a miss, never a wrong hit)."""
    kl = ops._bits(al)
    kh = ops._bits(ah)
    tag = op + 1
    h = kl * _H_LO ^ kh * _H_HI ^ tag * _H_TAG
    s = (((h ^ (h >> 31)) * _H_LO) >> _SLOT_SHIFT) & (mk.shape[0] - 1)
    if mk[s, 0] == tag and mk[s, 1] == kl and mk[s, 2] == kh:
        return mv[s, 0], mv[s, 1]
    if op == _SIN:
        rl, rh = ops.sin(al, ah)
    else:
        rl, rh = ops.cos(al, ah)
    mk[s, 0] = tag
    mk[s, 1] = kl
    mk[s, 2] = kh
    mv[s, 0] = rl
    mv[s, 1] = rh
    return rl, rh


#: C signature of the callbacks behind :func:`verifier.compiled.tape.forward` and
#: :func:`~verifier.compiled.tape.hc4`: ``(sel, n_out, in_lo, in_hi, n_in, lo, hi,
#: n_nodes, memo keys, memo values, memo slots, code, code rows, value, outs,
#: n_outs, meta, tapes)``, each array as a pointer to its first element; ``sel``
#: is the tape for a forward sweep, the number of tapes plus the tape for
#: HC4Revise.  A straight-line callback (:mod:`verifier.compiled.straight`) ignores
#: the program's arrays (written out in it); the interpreter's
#: (:mod:`verifier.compiled.interpreted`) reads them.
_I, _F = types.int64, types.float64
_PI, _PF = types.CPointer(_I), types.CPointer(_F)
C_SIGNATURE = types.void(_I, _I, _PF, _PF, _I, _PF, _PF, _I, _PI, _PF, _I, _PI, _I, _PF, _PI, _I, _PI, _I)


@intrinsic
def _call(typingctx, addr, sel, n_out, in_lo, in_hi, lo, hi, mk, mv, code, value, outs, meta):
    """Call the callback at machine address ``addr`` (C signature
    :data:`C_SIGNATURE`): each array as the pointer
    to its first element followed by its length (the memo: its slots; the
    code and meta tables: their rows)."""
    f1 = types.Array(types.float64, 1, "C")
    i1 = types.Array(types.int64, 1, "C")
    i2 = types.Array(types.int64, 2, "C")
    i8 = types.int64
    if (addr, sel, n_out, in_lo, in_hi, lo, hi, mk, mv, code, value, outs, meta) != (
            i8, i8, i8, f1, f1, f1, f1, i2, types.Array(types.float64, 2, "C"), i2, f1, i1, i2):
        return None

    def codegen(context, builder, signature, args):
        def arr(k):
            return context.make_array(signature.args[k])(context, builder, args[k])

        def rows(a):
            return cgutils.unpack_tuple(builder, a.shape)[0]

        il, ih, nl, nh, mk_, mv_, code_, value_, outs_, meta_ = (arr(k) for k in range(3, 13))
        c_args = [args[1], args[2], il.data, ih.data, rows(il), nl.data, nh.data, rows(nl), mk_.data, mv_.data,
                  rows(mk_), code_.data, rows(code_), value_.data, outs_.data, rows(outs_), meta_.data, rows(meta_)]
        fnty = ir.FunctionType(ir.VoidType(), [v.type for v in c_args])
        builder.call(builder.inttoptr(args[0], fnty.as_pointer()), c_args)
        return context.get_dummy_value()

    return types.void(addr, sel, n_out, in_lo, in_hi, lo, hi, mk, mv, code, value, outs, meta), codegen


@jit
def forward(prog, t, in_lo, in_hi, lo, hi, mk, mv):
    """Evaluate tape ``t`` of the :class:`Program` ``prog`` over the input box;
    node bounds land in ``lo, hi`` (those of the output nodes at least);
    ``mk, mv`` is the calling thread's memo of sines and cosines (:func:`trig_memo`).
    Runs the tape's straight-line function (:func:`interpret` computes the same floats)."""
    addr = prog.fns[0, t]
    if addr == 0:
        raise ValueError("forward: a program without code addresses (unpickled from another process?): "
                         "link it in this process (verifier.compiled.straight.link, IntervalModel.program)")
    _call(addr, t, _NO_OUT, in_lo, in_hi, lo, hi, mk, mv, prog.code, prog.value, prog.outs, prog.meta)


@jit
def interpret(prog, t, in_lo, in_hi, lo, hi, mk, mv):
    """:func:`forward` by the interpreter of the program's arrays, node by node (the
    reference of the straight-line functions; every node's bounds land in ``lo, hi``)."""
    code = prog.code
    value = prog.value
    meta = prog.meta
    c0 = meta[t, 0]
    for i in range(meta[t, 1]):
        op = code[c0 + i, 0]
        a = code[c0 + i, 1]
        b = code[c0 + i, 2]
        if op == _INPUT:
            lo[i] = in_lo[a]
            hi[i] = in_hi[a]
        elif op == _CONST:
            lo[i] = value[c0 + i]
            hi[i] = value[c0 + i]
        elif op == _ADD:
            lo[i], hi[i] = ops.add(lo[a], hi[a], lo[b], hi[b])
        elif op == _SUB:
            lo[i], hi[i] = ops.sub(lo[a], hi[a], lo[b], hi[b])
        elif op == _MUL:
            lo[i], hi[i] = ops.mul(lo[a], hi[a], lo[b], hi[b])
        elif op == _DIV:
            lo[i], hi[i] = ops.div(lo[a], hi[a], lo[b], hi[b])
        elif op == _NEG:
            lo[i], hi[i] = ops.neg(lo[a], hi[a])
        elif op == _SQ:
            lo[i], hi[i] = ops.sqr(lo[a], hi[a])
        elif op == _SQRT:
            lo[i], hi[i] = ops.sqrt(lo[a], hi[a])
        elif op == _SIN or op == _COS:
            lo[i], hi[i] = trig(op, lo[a], hi[a], mk, mv)
        elif op == _TWICE:
            lo[i], hi[i] = ops.add(lo[a], hi[a], lo[a], hi[a])
        elif op == _FABS:
            lo[i], hi[i] = ops.absolute(lo[a], hi[a])
        elif op == _INV:
            lo[i], hi[i] = ops.div(1.0, 1.0, lo[a], hi[a])
        elif op == _ASSIGN:
            lo[i] = lo[a]
            hi[i] = hi[a]
        else:  # _CONSTPOW
            lo[i], hi[i] = ops.pown(lo[a], hi[a], int(value[c0 + i]))


@jit
def output(prog, t, e, lo, hi):
    """Bounds of dense output entry ``e`` of tape ``t`` after :func:`forward`."""
    node = prog.outs[prog.meta[t, 2] + e]
    if node < 0:
        return 0.0, 0.0
    return lo[node], hi[node]


@jit
def project_factor(al, ah, zl, zh, bl, bh):
    # [a] ∩ {a : a b in [z], b in [b]}; no contraction when 0 in [b] and 0 in [z]
    ql, qh = ops.div(zl, zh, bl, bh)
    if bl <= 0.0 and bh >= 0.0 and zl <= 0.0 and zh >= 0.0:
        ql = -np.inf
        qh = np.inf
    return ops.intersect(al, ah, ql, qh)


@jit
def project_square(al, ah, zl, zh):
    sl, sh = ops.sqrt(zl, zh)
    pl, ph = ops.intersect(al, ah, sl, sh)
    nl, nh = ops.intersect(al, ah, -sh, -sl)
    return ops.hull(pl, ph, nl, nh)


# HC4Revise's projections of one node ``z = a op b`` onto its operands, ``a`` first, then ``b``
# from the contracted ``a``; one call per node for the interpreter and the straight-line tapes
# (:mod:`verifier.compiled.straight`) alike.  When ``a`` and ``b`` are the same node the caller
# stores ``b``'s result last, as the node-by-node sweep does.
@jit
def back_add(zl, zh, al, ah, bl, bh):
    sl, sh = ops.sub(zl, zh, bl, bh)
    al, ah = ops.intersect(al, ah, sl, sh)
    sl, sh = ops.sub(zl, zh, al, ah)
    bl, bh = ops.intersect(bl, bh, sl, sh)
    return al, ah, bl, bh


@jit
def back_sub(zl, zh, al, ah, bl, bh):
    sl, sh = ops.add(zl, zh, bl, bh)
    al, ah = ops.intersect(al, ah, sl, sh)
    sl, sh = ops.sub(al, ah, zl, zh)
    bl, bh = ops.intersect(bl, bh, sl, sh)
    return al, ah, bl, bh


@jit
def back_mul(zl, zh, al, ah, bl, bh):
    al, ah = project_factor(al, ah, zl, zh, bl, bh)
    bl, bh = project_factor(bl, bh, zl, zh, al, ah)
    return al, ah, bl, bh


@jit
def back_div(zl, zh, al, ah, bl, bh):
    pl, ph = ops.mul(zl, zh, bl, bh)
    al, ah = ops.intersect(al, ah, pl, ph)
    bl, bh = project_factor(bl, bh, al, ah, zl, zh)
    return al, ah, bl, bh


@jit
def back_twice(zl, zh, al, ah):
    sl, sh = ops.scale(0.5, zl, zh)
    return ops.intersect(al, ah, sl, sh)


@jit
def back_sqrt(zl, zh, al, ah):
    zl0 = ops.maxn(zl, 0.0)
    sl, sh = ops.sqr(zl0, ops.maxn(zh, zl0))
    al, ah = ops.intersect(al, ah, sl, sh)
    if zh < 0.0:
        al = np.inf
    return al, ah


@jit
def hc4(prog, t, n_out, in_lo, in_hi, lo, hi, mk, mv):
    """HC4Revise: contract the input box in place with ``output_0(inputs) = 0``.

    ``n_out`` is the number of entries of output 0 (the constrained one);
    ``mk, mv`` as in :func:`forward`.  Runs the tape's straight-line
    function; tapes in :data:`HC4_TAPES` only.
    """
    addr = prog.fns[1, t]
    if addr == 0:
        raise ValueError("hc4: no code for this tape (tapes of verifier.compiled.tape.HC4_TAPES only), or a program "
                         "without code addresses (unpickled from another process?): link it in this process "
                         "(verifier.compiled.straight.link, IntervalModel.program)")
    _call(addr, prog.fns.shape[1] + t, n_out, in_lo, in_hi, lo, hi, mk, mv, prog.code, prog.value, prog.outs,
          prog.meta)


@jit
def interpret_hc4(prog, t, n_out, in_lo, in_hi, lo, hi, mk, mv):
    """:func:`hc4` by the interpreter (the reference of the straight-line functions)."""
    interpret(prog, t, in_lo, in_hi, lo, hi, mk, mv)
    code = prog.code
    value = prog.value
    outs = prog.outs
    meta = prog.meta
    o0 = meta[t, 2]
    for e in range(n_out):
        node = outs[o0 + e]
        if node >= 0:
            lo[node], hi[node] = ops.intersect(lo[node], hi[node], 0.0, 0.0)
    c0 = meta[t, 0]
    for i in range(meta[t, 1] - 1, -1, -1):
        op = code[c0 + i, 0]
        if op == _INPUT or op == _CONST:
            continue
        zl = lo[i]
        zh = hi[i]
        a = code[c0 + i, 1]
        b = code[c0 + i, 2]
        al = lo[a]
        ah = hi[a]
        if op == _ADD:
            lo[a], hi[a], lo[b], hi[b] = back_add(zl, zh, al, ah, lo[b], hi[b])
        elif op == _SUB:
            lo[a], hi[a], lo[b], hi[b] = back_sub(zl, zh, al, ah, lo[b], hi[b])
        elif op == _MUL:
            lo[a], hi[a], lo[b], hi[b] = back_mul(zl, zh, al, ah, lo[b], hi[b])
        elif op == _DIV:
            lo[a], hi[a], lo[b], hi[b] = back_div(zl, zh, al, ah, lo[b], hi[b])
        elif op == _NEG:
            lo[a], hi[a] = ops.intersect(al, ah, -zh, -zl)
        elif op == _TWICE:
            lo[a], hi[a] = back_twice(zl, zh, al, ah)
        elif op == _SQ or (op == _CONSTPOW and value[c0 + i] == 2.0):
            lo[a], hi[a] = project_square(al, ah, zl, zh)
        elif op == _SQRT:
            lo[a], hi[a] = back_sqrt(zl, zh, al, ah)
        elif op == _INV:
            lo[a], hi[a] = project_factor(al, ah, 1.0, 1.0, zl, zh)
        elif op == _ASSIGN:
            lo[a], hi[a] = ops.intersect(al, ah, zl, zh)
        # sin, cos, fabs, other powers: no projection (sound, only weaker)
    for i in range(meta[t, 1]):
        if code[c0 + i, 0] == _INPUT:
            s = code[c0 + i, 1]
            in_lo[s] = ops.maxn(in_lo[s], lo[i])
            in_hi[s] = ops.minn(in_hi[s], hi[i])
