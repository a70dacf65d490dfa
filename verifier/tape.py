"""Interval evaluation and HC4Revise contraction of CasADi SX expressions.

A :class:`Tape` turns a CasADi ``SX`` function into a straight-line program in
static single assignment form (one node per instruction) by walking the
function's instruction list.  The same program is then

* evaluated forward in interval arithmetic (:mod:`verifier.interval`),
  batched over scenarios, giving a rigorous enclosure of every output; and
* run backward (HC4Revise, Benhamou et al. 1999): the output nodes are
  intersected with a target set (``[0, 0]`` for ``f(x, q, xi) = 0``) and each
  instruction projects its result's domain back onto its operands.

Every projection keeps all operand values compatible with the constraint, so
contraction never removes a solution: the soundness of HC4Revise only needs
each step to be an outward-rounded superset of the exact projection.
Operations without a projection here (sin, cos, fabs, pow) simply leave their
operands unchanged, which is sound.

Shapes: a batch of ``B`` scenarios evaluates input ``i`` given as a pair of
arrays of shape ``(B, size_i)`` (or ``(size_i,)``, broadcast to the batch);
output ``j`` comes back densely as ``(B, rows_j, cols_j)`` (or ``(B, rows_j)``
for a column vector).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import casadi as ca
import numpy as np

from . import interval as I
from crosscert.robots.errors import ModelError

__all__ = ["Tape", "TapeArrays", "OPCODES"]

#: Opcodes of :meth:`Tape.arrays` (the compiled interpreter's instruction set).
OPCODES = {name: i for i, name in enumerate((
    "OP_INPUT", "OP_CONST", "OP_ADD", "OP_SUB", "OP_MUL", "OP_DIV", "OP_NEG", "OP_SQ",
    "OP_SQRT", "OP_SIN", "OP_COS", "OP_TWICE", "OP_FABS", "OP_INV", "OP_ASSIGN", "OP_CONSTPOW",
))}


class TapeArrays(NamedTuple):
    """A tape as flat arrays, for the compiled interpreter (``verifier.compiled``).

    Attributes
    ----------
    code : int64 array (N, 3)
        Per node ``(opcode, a, b)``: operand node indices; for ``OP_INPUT``,
        ``a`` is the slot of the input in the concatenated input vector.
    value : float64 array (N,)
        Constant of ``OP_CONST``, integer exponent of ``OP_CONSTPOW``.
    out_nodes : int64 array (sum of rows_j cols_j,)
        Node of every dense output entry, outputs one after another, each
        row-major; -1 for a structural zero (exactly ``[0, 0]``).
    out_offsets : int64 array (n_out + 1,)
        Where output ``j`` starts in ``out_nodes``.
    in_offsets : int64 array (n_in + 1,)
        Where input ``i`` starts in the concatenated input vector.
    """

    code: np.ndarray
    value: np.ndarray
    out_nodes: np.ndarray
    out_offsets: np.ndarray
    in_offsets: np.ndarray

_OP = {name: getattr(ca, name) for name in dir(ca) if name.startswith("OP_")}
_NAME = {v: k for k, v in _OP.items()}

_UNARY = {"OP_NEG", "OP_SQ", "OP_SQRT", "OP_SIN", "OP_COS", "OP_TWICE", "OP_FABS", "OP_INV", "OP_ASSIGN"}
_BINARY = {"OP_ADD", "OP_SUB", "OP_MUL", "OP_DIV", "OP_CONSTPOW"}


@dataclass(frozen=True)
class _Instr:
    op: str
    out: int
    a: int = -1
    b: int = -1
    value: float = 0.0  # constant value, or integer exponent of OP_CONSTPOW


class Tape:
    """A CasADi SX function compiled for batched interval evaluation.

    Parameters
    ----------
    fun : casadi.Function
        An SX function (``casadi.Function`` built from ``SX`` expressions).
        Supported operations: ``+ - * /``, negation, square, ``sqrt``,
        ``sin``, ``cos``, ``fabs``, ``1/x`` and integer constant powers.
    """

    def __init__(self, fun: ca.Function):
        if not fun.is_a("SXFunction"):
            raise ModelError(f"{fun.name()}: interval evaluation needs an SX function, got {fun.class_name()}")
        self.name = fun.name()
        self.n_in = fun.n_in()
        self.n_out = fun.n_out()
        self.in_sizes = tuple(fun.nnz_in(i) for i in range(self.n_in))
        self.out_shapes = tuple(fun.size_out(j) for j in range(self.n_out))
        self._out_rc = []
        for j in range(self.n_out):
            rows, cols = fun.sparsity_out(j).get_triplet()
            self._out_rc.append((np.asarray(rows, dtype=int), np.asarray(cols, dtype=int)))

        instrs: list[_Instr] = []
        inputs: list[tuple[int, int, int]] = []  # (node, input index, nz)
        outputs: list[tuple[int, int, int]] = []  # (node, output index, nz)
        where: dict[int, int] = {}  # CasADi work slot -> current SSA node
        node = 0
        for k in range(fun.n_instructions()):
            name = _NAME.get(fun.instruction_id(k), str(fun.instruction_id(k)))
            ins = fun.instruction_input(k)
            outs = fun.instruction_output(k)
            if name == "OP_INPUT":
                inputs.append((node, ins[0], ins[1]))
                instrs.append(_Instr("OP_INPUT", node))
                where[outs[0]] = node
                node += 1
            elif name == "OP_OUTPUT":
                outputs.append((where[ins[0]], outs[0], outs[1]))
            elif name == "OP_CONST":
                instrs.append(_Instr("OP_CONST", node, value=float(fun.instruction_constant(k))))
                where[outs[0]] = node
                node += 1
            elif name in _UNARY:
                instrs.append(_Instr(name, node, where[ins[0]]))
                where[outs[0]] = node
                node += 1
            elif name in _BINARY:
                instrs.append(_Instr(name, node, where[ins[0]], where[ins[1]]))
                where[outs[0]] = node
                node += 1
            else:
                raise ModelError(
                    f"{self.name}: CasADi operation {name} has no interval implementation; "
                    "write the model with + - * / sq sqrt sin cos fabs and integer powers"
                )
        self.n_nodes = node
        self._instrs = tuple(instrs)
        self._inputs = tuple(inputs)
        self._outputs = tuple(outputs)
        # OP_CONSTPOW's exponent is a constant node: resolve it once.
        consts = {i.out: i.value for i in instrs if i.op == "OP_CONST"}
        fixed = []
        for ins in self._instrs:
            if ins.op == "OP_CONSTPOW":
                e = consts.get(ins.b)
                if e is None or e != int(e):
                    raise ModelError(f"{self.name}: only integer constant powers are supported (got {e})")
                ins = _Instr("OP_CONSTPOW", ins.out, ins.a, ins.b, float(e))
            fixed.append(ins)
        self._instrs = tuple(fixed)

    def arrays(self) -> TapeArrays:
        """The same program as flat arrays (see :class:`TapeArrays`); cached."""
        cached = getattr(self, "_arrays", None)
        if cached is not None:
            return cached
        in_off = np.concatenate([[0], np.cumsum(self.in_sizes)]).astype(np.int64)
        code = np.full((self.n_nodes, 3), -1, np.int64)
        value = np.zeros(self.n_nodes)
        slot = {node: in_off[i] + nz for node, i, nz in self._inputs}
        for ins in self._instrs:
            code[ins.out] = (OPCODES[ins.op], slot[ins.out] if ins.op == "OP_INPUT" else ins.a, ins.b)
            value[ins.out] = ins.value
        sizes = [r * c for r, c in self.out_shapes]
        out_off = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        out_nodes = np.full(int(out_off[-1]), -1, np.int64)
        for node, j, nz in self._outputs:
            r, c = self._out_rc[j][0][nz], self._out_rc[j][1][nz]
            out_nodes[out_off[j] + r * self.out_shapes[j][1] + c] = node
        self._arrays = TapeArrays(code, value, out_nodes, out_off, in_off)
        return self._arrays

    # ------------------------------------------------------------------ forward
    def _program(self):
        """The instructions as ``(kind, fn, out, a, b, value)`` tuples, dispatch resolved once."""
        prog = getattr(self, "_prog", None)
        if prog is not None:
            return prog
        binary = {"OP_ADD": I.add, "OP_SUB": I.sub, "OP_MUL": I.mul, "OP_DIV": I.div}
        unary = {
            "OP_SQ": I.sqr,
            "OP_NEG": I.neg,
            "OP_TWICE": lambda al, ah: I.add(al, ah, al, ah),
            "OP_SQRT": I.sqrt,
            "OP_SIN": I.sin,
            "OP_COS": I.cos,
            "OP_FABS": I.absolute,
            "OP_INV": lambda al, ah: I.div(1.0, 1.0, al, ah),
            "OP_ASSIGN": lambda al, ah: (al, ah),
        }
        prog = []
        for ins in self._instrs:
            if ins.op == "OP_INPUT":
                continue
            if ins.op == "OP_CONST":
                prog.append((0, None, ins.out, -1, -1, ins.value))
            elif ins.op == "OP_CONSTPOW":
                prog.append((3, I.pown, ins.out, ins.a, -1, int(ins.value)))
            elif ins.op in binary:
                prog.append((2, binary[ins.op], ins.out, ins.a, ins.b, 0.0))
            else:
                prog.append((1, unary[ins.op], ins.out, ins.a, -1, 0.0))
        self._prog = tuple(prog)
        return self._prog

    def _forward(self, inputs, batch_shape):
        lo = [None] * self.n_nodes
        hi = [None] * self.n_nodes
        for node, i, nz in self._inputs:
            lo[node] = np.broadcast_to(inputs[i][0][..., nz], batch_shape)
            hi[node] = np.broadcast_to(inputs[i][1][..., nz], batch_shape)
        for kind, fn, o, a, b, value in self._program():
            if kind == 2:
                lo[o], hi[o] = fn(lo[a], hi[a], lo[b], hi[b])
            elif kind == 1:
                lo[o], hi[o] = fn(lo[a], hi[a])
            elif kind == 0:
                lo[o] = np.full(batch_shape, value)
                hi[o] = lo[o]
            else:
                lo[o], hi[o] = fn(lo[a], hi[a], value)
        return lo, hi

    def _batch_shape(self, inputs):
        shapes = [np.shape(lo)[:-1] for lo, _ in inputs]
        return np.broadcast_shapes(*shapes) if shapes else ()

    def _collect(self, lo, hi, batch_shape):
        outs = []
        for j in range(self.n_out):
            rows, cols = self.out_shapes[j]
            olo = np.zeros(batch_shape + (rows, cols))
            ohi = np.zeros(batch_shape + (rows, cols))
            outs.append([olo, ohi])
        for node, j, nz in self._outputs:
            r, c = self._out_rc[j][0][nz], self._out_rc[j][1][nz]
            outs[j][0][..., r, c] = lo[node]
            outs[j][1][..., r, c] = hi[node]
        result = []
        for j, (olo, ohi) in enumerate(outs):
            if self.out_shapes[j][1] == 1:
                olo, ohi = olo[..., 0], ohi[..., 0]
            result.append((olo, ohi))
        return result

    def evaluate(self, inputs):
        """Enclose every output over the input boxes.

        Parameters
        ----------
        inputs : sequence of (lo, hi)
            One pair of arrays per function input, shape ``(B, size_i)`` or
            ``(size_i,)``.

        Returns
        -------
        list of (lo, hi)
            Per output, arrays of shape ``(B, rows, cols)`` (``(B, rows)`` for
            a column vector); structural zeros are exact ``[0, 0]``.
        """
        inputs = [(np.asarray(l, dtype=np.float64), np.asarray(h, dtype=np.float64)) for l, h in inputs]
        bs = self._batch_shape(inputs)
        lo, hi = self._forward(inputs, bs)
        return self._collect(lo, hi, bs)

    # ----------------------------------------------------------------- backward
    def contract(self, inputs, out_index: int = 0, target=(0.0, 0.0)):
        """HC4Revise: contract the input boxes with ``fun_j(inputs) in target``.

        Parameters
        ----------
        inputs : sequence of (lo, hi)
            As in :meth:`evaluate`, every input batched to shape ``(B, size_i)``.
        out_index : int
            Which output is constrained.
        target : (lo, hi)
            Bounds for every component of that output (broadcastable to
            ``(B, nnz)`` of the output), by default ``[0, 0]``.

        Returns
        -------
        list of (lo, hi)
            The contracted input boxes (same shapes as given, batched); a
            scenario whose box became empty has ``lo > hi`` somewhere.
        """
        inputs = [(np.asarray(l, dtype=np.float64), np.asarray(h, dtype=np.float64)) for l, h in inputs]
        bs = self._batch_shape(inputs)
        lo, hi = self._forward(inputs, bs)
        lo = [None if v is None else np.array(v, dtype=np.float64) for v in lo]
        hi = [None if v is None else np.array(v, dtype=np.float64) for v in hi]
        self._constrain_output(lo, hi, out_index, target, bs)
        for ins in reversed(self._instrs):
            _project_back(ins, lo, hi)
        return self._contracted_inputs(inputs, lo, hi, bs)

    def _constrain_output(self, lo, hi, out_index, target, bs):
        """Intersect the nodes of output ``out_index`` with ``target`` (broadcast to ``bs + (nnz,)``), in place."""
        tl = np.broadcast_to(np.asarray(target[0], dtype=np.float64), bs + (max(1, self._nnz_out(out_index)),))
        th = np.broadcast_to(np.asarray(target[1], dtype=np.float64), tl.shape)
        for node, j, nz in self._outputs:
            if j == out_index:
                lo[node], hi[node] = I.intersect(lo[node], hi[node], tl[..., nz], th[..., nz])

    def _contracted_inputs(self, inputs, lo, hi, bs):
        """The input boxes batched to ``bs`` and intersected with their nodes' contracted bounds ``lo, hi``."""
        result = []
        for il, ih in inputs:
            nl = np.array(np.broadcast_to(il, bs + il.shape[-1:]), dtype=np.float64)
            nh = np.array(np.broadcast_to(ih, bs + ih.shape[-1:]), dtype=np.float64)
            result.append([nl, nh])
        for node, i, nz in self._inputs:
            result[i][0][..., nz] = np.maximum(result[i][0][..., nz], lo[node])
            result[i][1][..., nz] = np.minimum(result[i][1][..., nz], hi[node])
        return [tuple(r) for r in result]

    def _nnz_out(self, j):
        return len(self._out_rc[j][0])


def _project_back(ins, lo, hi):
    """Project the bounds of the node ``ins.out`` onto its operands' bounds ``lo, hi``, in place (one
    HC4Revise step, :meth:`Tape.contract`); sin, cos, fabs and other powers are not projected (sound, just
    weaker)."""
    op = ins.op
    if op in ("OP_INPUT", "OP_CONST"):
        return
    zl, zh = lo[ins.out], hi[ins.out]
    a = ins.a
    al, ah = lo[a], hi[a]
    if op == "OP_ADD":
        b = ins.b
        bl, bh = lo[b], hi[b]
        lo[a], hi[a] = I.intersect(al, ah, *I.sub(zl, zh, bl, bh))
        lo[b], hi[b] = I.intersect(bl, bh, *I.sub(zl, zh, lo[a], hi[a]))
    elif op == "OP_SUB":
        b = ins.b
        bl, bh = lo[b], hi[b]
        lo[a], hi[a] = I.intersect(al, ah, *I.add(zl, zh, bl, bh))
        lo[b], hi[b] = I.intersect(bl, bh, *I.sub(lo[a], hi[a], zl, zh))
    elif op == "OP_MUL":
        b = ins.b
        bl, bh = lo[b], hi[b]
        lo[a], hi[a] = _project_factor(al, ah, zl, zh, bl, bh)
        lo[b], hi[b] = _project_factor(bl, bh, zl, zh, lo[a], hi[a])
    elif op == "OP_DIV":
        b = ins.b
        bl, bh = lo[b], hi[b]
        # z = a / b  =>  a = z * b  and  b = a / z
        lo[a], hi[a] = I.intersect(al, ah, *I.mul(zl, zh, bl, bh))
        lo[b], hi[b] = _project_factor(bl, bh, lo[a], hi[a], zl, zh)
    elif op == "OP_NEG":
        lo[a], hi[a] = I.intersect(al, ah, -zh, -zl)
    elif op == "OP_TWICE":
        lo[a], hi[a] = I.intersect(al, ah, *I.scale(0.5, zl, zh))
    elif op == "OP_SQ" or (op == "OP_CONSTPOW" and ins.value == 2.0):
        lo[a], hi[a] = _project_square(al, ah, zl, zh)
    elif op == "OP_SQRT":
        zl0 = np.maximum(zl, 0.0)
        lo[a], hi[a] = I.intersect(al, ah, *I.sqr(zl0, np.maximum(zh, zl0)))
        lo[a] = np.where(zh < 0.0, np.inf, lo[a])  # sqrt never negative
    elif op == "OP_INV":
        lo[a], hi[a] = _project_factor(al, ah, 1.0, 1.0, zl, zh)
    elif op == "OP_ASSIGN":
        lo[a], hi[a] = I.intersect(al, ah, zl, zh)
    # sin, cos, fabs, other powers: no projection (sound, just weaker)


def _project_factor(al, ah, zl, zh, bl, bh):
    """``[a] ∩ {a : a * b in [z] for some b in [b]}``.

    When both ``[b]`` and ``[z]`` contain 0, any ``a`` works (take ``b = 0``):
    no contraction.  Otherwise ``a in [z] / [b]`` (extended division).
    """
    ql, qh = I.div(zl, zh, bl, bh)
    free = (bl <= 0.0) & (bh >= 0.0) & (zl <= 0.0) & (zh >= 0.0)
    ql = np.where(free, -np.inf, ql)
    qh = np.where(free, np.inf, qh)
    return I.intersect(al, ah, ql, qh)


def _project_square(al, ah, zl, zh):
    """``[a] ∩ {a : a^2 in [z]}`` = ``[a] ∩ (-sqrt[z] ∪ sqrt[z])`` (hulled)."""
    sl, sh = I.sqrt(zl, zh)  # empty when z < 0
    pl, ph = I.intersect(al, ah, sl, sh)
    nl, nh = I.intersect(al, ah, -sh, -sl)
    return I.hull(pl, ph, nl, nh)
