"""Straight-line tape functions: a robot's tapes written out as Python source.

:mod:`verifier.compiled.tape` interprets a :class:`~verifier.compiled.tape.Program`
node by node (opcode load, dispatch, operand loads and stores through the
scratch arrays).  Here the same node sequence is written out, per tape, as the
body of a function on local variables: the same ``ops.*`` calls with the same
arguments in the same order, so the same floats bit for bit.
"""

from __future__ import annotations

import numpy as np

from ..tape import OPCODES

__all__ = ["module_source"]

_NAMES = {v: k for k, v in OPCODES.items()}
_BINARY = {"OP_ADD": "ops.add", "OP_SUB": "ops.sub", "OP_MUL": "ops.mul", "OP_DIV": "ops.div"}
_UNARY = {"OP_NEG": "ops.neg", "OP_SQ": "ops.sqr", "OP_SQRT": "ops.sqrt", "OP_FABS": "ops.absolute"}


def _tape_parts(prog, t):
    """Code rows, constants and output nodes of tape ``t`` of ``prog``."""
    c0, n, o0 = (int(v) for v in prog.meta[t])
    o1 = int(prog.meta[t + 1, 2]) if t + 1 < len(prog.meta) else len(prog.outs)
    return prog.code[c0:c0 + n], prog.value[c0:c0 + n], prog.outs[o0:o1]


def _forward_lines(code, value, consts):
    """Statements of the forward sweep on locals ``l{i}, h{i}``; constants are
    appended to ``consts`` (read from a global array: every bit pattern kept)."""
    out = []
    for i, (op, a, b) in enumerate(code):
        name = _NAMES[int(op)]
        d = f"l{i}, h{i}"
        if name == "OP_INPUT":
            out.append(f"l{i} = in_lo[{a}]")
            out.append(f"h{i} = in_hi[{a}]")
        elif name == "OP_CONST":
            consts.append(value[i])
            out.append(f"l{i} = _K[{len(consts) - 1}]  # {float(value[i])!r}")
            out.append(f"h{i} = l{i}")
        elif name in _BINARY:
            out.append(f"{d} = {_BINARY[name]}(l{a}, h{a}, l{b}, h{b})")
        elif name in _UNARY:
            out.append(f"{d} = {_UNARY[name]}(l{a}, h{a})")
        elif name == "OP_SIN" or name == "OP_COS":
            out.append(f"{d} = trig(_{name[3:]}, l{a}, h{a}, mk, mv)")
        elif name == "OP_TWICE":
            out.append(f"{d} = ops.add(l{a}, h{a}, l{a}, h{a})")
        elif name == "OP_INV":
            out.append(f"{d} = ops.div(1.0, 1.0, l{a}, h{a})")
        elif name == "OP_ASSIGN":
            out.append(f"l{i} = l{a}")
            out.append(f"h{i} = h{a}")
        elif name == "OP_CONSTPOW":
            out.append(f"{d} = ops.pown(l{a}, h{a}, np.int64({int(value[i])}))")
        else:  # pragma: no cover - OPCODES and this table change together
            raise AssertionError(f"opcode {name} has no straight-line form")
    return out


def _backward_lines(code, value):
    """HC4Revise's backward sweep (:func:`verifier.compiled.tape.hc4`), node by node in reverse."""
    out = []
    for i in range(len(code) - 1, -1, -1):
        op, a, b = (int(v) for v in code[i])
        name = _NAMES[op]
        z = f"l{i}, h{i}"
        A, B = f"l{a}, h{a}", f"l{b}, h{b}"
        back = {"OP_ADD": "back_add", "OP_SUB": "back_sub", "OP_MUL": "back_mul", "OP_DIV": "back_div"}
        if name in back:
            # ``b`` assigned last: when a = b the sweep keeps b's projection
            out.append(f"{A}, {B} = {back[name]}({z}, {A}, {B})")
        elif name == "OP_NEG":
            out.append(f"{A} = ops.intersect({A}, -h{i}, -l{i})")
        elif name == "OP_TWICE":
            out.append(f"{A} = back_twice({z}, {A})")
        elif name == "OP_SQ" or (name == "OP_CONSTPOW" and value[i] == 2.0):
            out.append(f"{A} = _project_square({A}, {z})")
        elif name == "OP_SQRT":
            out.append(f"{A} = back_sqrt({z}, {A})")
        elif name == "OP_INV":
            out.append(f"{A} = _project_factor({A}, 1.0, 1.0, {z})")
        elif name == "OP_ASSIGN":
            out.append(f"{A} = ops.intersect({A}, {z})")
        # input, constant, sin, cos, fabs, other powers: no projection (as the interpreter)
    return out


def _function_source(prog, t, tag, consts):
    """Source of ``fwd_{tag}`` and ``hc4_{tag}`` for tape ``t`` (constants appended to ``consts``)."""
    code, value, outs = _tape_parts(prog, t)
    n = len(code)
    fwd = _forward_lines(code, value, consts)
    # the output nodes only: :func:`verifier.compiled.tape.output` reads nothing else
    kept = sorted({int(v) for v in outs if v >= 0})
    store = [f"lo[{i}] = l{i}" for i in kept] + [f"hi[{i}] = h{i}" for i in kept]
    src = [f"@jit\ndef fwd_{tag}(in_lo, in_hi, lo, hi, mk, mv):"]
    src += ["    " + s for s in fwd + store]
    src.append("")
    src.append(f"@jit\ndef hc4_{tag}(n_out, in_lo, in_hi, lo, hi, mk, mv):")
    body = list(fwd)
    for e, node in enumerate(outs):
        if node >= 0:
            body += [f"if n_out > {e}:", f"    l{node}, h{node} = ops.intersect(l{node}, h{node}, 0.0, 0.0)"]
    body += _backward_lines(code, value)
    for i, (op, a, _) in enumerate(code):
        if _NAMES[int(op)] == "OP_INPUT":
            body += [f"in_lo[{a}] = ops.maxn(in_lo[{a}], l{i})", f"in_hi[{a}] = ops.minn(in_hi[{a}], h{i})"]
    src += ["    " + s for s in body]
    return "\n".join(src) + "\n"


def module_source(prog, tapes):
    """Python source of a module defining ``fwd_{tag}`` / ``hc4_{tag}`` for
    each ``(t, tag)`` of ``tapes`` (tape index in ``prog``, name suffix)."""
    head = [
        '"""Generated by verifier.compiled.straight: do not edit."""',
        "import numpy as np",
        "from crosscert.verifier.compiled import ops",
        "from crosscert.verifier.compiled.ops import jit",
        "from crosscert.verifier.compiled.tape import (\n    trig, back_add, back_sub, back_mul, back_div, back_twice, back_sqrt, _project_factor, _project_square)",
        f"_SIN = np.int64({OPCODES['OP_SIN']})",
        f"_COS = np.int64({OPCODES['OP_COS']})",
    ]
    consts = []
    bodies = [_function_source(prog, t, tag, consts) for t, tag in tapes]
    bits = np.asarray(consts, np.float64).view(np.int64).tolist()
    head.append(f"_K = np.array({bits}, dtype=np.int64).view(np.float64)")
    return "\n".join(head) + "\n\n\n" + "\n\n".join(bodies)


def _hack_module():  # STEP-1 HACK: the default robot's generated tapes, imported from /tmp
    import importlib.util
    import sys

    from crosscert.robots import DEXTAR
    from ..model import IntervalModel
    from .tape import pack

    path = "/tmp/g17_straight_dextar.py"
    src = module_source(pack(IntervalModel(DEXTAR)), [(0, "f"), (3, "vel")])
    try:
        old = open(path).read()
    except OSError:
        old = None
    if old != src:
        with open(path, "w") as f:
            f.write(src)
    spec = importlib.util.spec_from_file_location("g17_straight_dextar", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["g17_straight_dextar"] = mod
    spec.loader.exec_module(mod)
    return mod
