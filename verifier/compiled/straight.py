"""Straight-line tape functions: a robot's tapes written out as Python source.

:mod:`verifier.compiled.tape` interprets a :class:`~verifier.compiled.tape.Program`
node by node (opcode load, dispatch, operand loads and stores through the
scratch arrays).  Here the same node sequence is written out, per tape, as the
body of a function on local variables: the same ``ops.*`` calls with the same
arguments in the same order, so the same floats bit for bit.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import os
import stat
import sys
import tempfile
from pathlib import Path

import numba
import numpy as np

from crosscert.robots.errors import ModelError

from ..tape import OPCODES

__all__ = ["C_SIGNATURE", "cache_dir", "load", "module_source", "program_key"]

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


def _tape_bodies(prog, t, consts, with_hc4):
    """Statements of tape ``t``'s forward sweep and (when ``with_hc4``, else
    None) of its HC4Revise; constants are appended to ``consts``."""
    code, value, outs = _tape_parts(prog, t)
    fwd = _forward_lines(code, value, consts)
    # the output nodes only: :func:`verifier.compiled.tape.output` reads nothing else
    kept = sorted({int(v) for v in outs if v >= 0})
    store = [f"lo[{i}] = l{i}" for i in kept] + [f"hi[{i}] = h{i}" for i in kept]
    if not with_hc4:
        return fwd + store, None
    body = list(fwd)
    for e, node in enumerate(outs):
        if node >= 0:  # output 0's entries: the first n_out
            body += [f"if n_out > {e}:", f"    l{node}, h{node} = ops.intersect(l{node}, h{node}, 0.0, 0.0)"]
    body += _backward_lines(code, value)
    for i, (op, a, _) in enumerate(code):
        if _NAMES[int(op)] == "OP_INPUT":
            body += [f"in_lo[{a}] = ops.maxn(in_lo[{a}], l{i})", f"in_hi[{a}] = ops.minn(in_hi[{a}], h{i})"]
    return fwd + store, body


def module_source(prog) -> str:
    """Python source of the module of ``prog``'s straight-line code: one C
    callback ``tapes`` of :data:`C_SIGNATURE` whose branch ``sel = t`` is tape
    ``t``'s forward sweep and ``sel = T + t`` its HC4Revise (tapes of
    :data:`verifier.compiled.tape.HC4_TAPES`); ``ADDRESSES`` (2, T) holds the
    callback's address where a branch exists, else 0.  One function: numba
    compiles the interval operations it calls once."""
    from .tape import HC4_TAPES

    n_tapes = len(prog.meta)
    n_in = max([int(a) + 1 for op, a, _ in prog.code if _NAMES[int(op)] == "OP_INPUT"] + [1])
    consts, branches = [], []
    has = np.zeros((2, n_tapes), bool)
    for t in range(n_tapes):
        fwd, hc4 = _tape_bodies(prog, t, consts, t in HC4_TAPES)
        branches.append((t, f"forward sweep of tape {t}", fwd))
        has[0, t] = True
        if hc4 is not None:
            branches.append((n_tapes + t, f"HC4Revise on tape {t}", hc4))
            has[1, t] = True
    bits = np.asarray(consts, np.float64).view(np.int64).tolist()
    lines = [
        '"""Generated by crosscert.verifier.compiled.straight from one robot\'s tapes: do not edit."""',
        "import numpy as np",
        "from numba import carray, cfunc",
        "from crosscert.verifier.compiled import ops",
        "from crosscert.verifier.compiled.straight import C_SIGNATURE",
        "from crosscert.verifier.compiled.tape import (",
        "    trig, back_add, back_sub, back_mul, back_div, back_twice, back_sqrt, _project_factor, _project_square)",
        "",
        f"_SIN = np.int64({OPCODES['OP_SIN']})",
        f"_COS = np.int64({OPCODES['OP_COS']})",
        f"_K = np.array({bits}, dtype=np.int64).view(np.float64)",
        "",
        "",
        "@cfunc(C_SIGNATURE, cache=True)",
        "def tapes(sel, n_out, in_lo_p, in_hi_p, lo_p, hi_p, mk_p, mv_p, slots):",
        "    # the caller's arrays (sizes: the program's inputs and nodes, the memo's slots)",
        f"    in_lo = carray(in_lo_p, ({n_in},))",
        f"    in_hi = carray(in_hi_p, ({n_in},))",
        f"    lo = carray(lo_p, ({prog.n_nodes},))",
        f"    hi = carray(hi_p, ({prog.n_nodes},))",
        "    mk = carray(mk_p, (slots, 3))",
        "    mv = carray(mv_p, (slots, 2))",
    ]
    for k, (sel, what, body) in enumerate(branches):
        lines += [f"    {'if' if k == 0 else 'elif'} sel == {sel}:  # {what}"] + ["        " + b for b in body]
    lines += ["", "", f"ADDRESSES = np.where(np.array({has.tolist()}), tapes.address, 0).astype(np.int64)", ""]
    return "\n".join(lines)


#: C signature of a program's straight-line callback: ``(sel, n_out, in_lo, in_hi,
#: lo, hi, memo keys, memo values, memo slots)``, pointers to the arrays' first
#: elements; ``sel`` is the tape for a forward sweep, the number of tapes plus
#: the tape for HC4Revise.
_P = numba.types.CPointer
C_SIGNATURE = numba.types.void(numba.types.int64, numba.types.int64, *[_P(numba.types.float64)] * 4,
                               _P(numba.types.int64), _P(numba.types.float64), numba.types.int64)


def cache_dir() -> Path:
    """Where generated modules are written: ``$CROSSCERT_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/crosscert``, else ``~/.cache/crosscert``; then ``tapes``."""
    root = os.environ.get("CROSSCERT_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "crosscert")
    return Path(root) / "tapes"


def program_key(prog) -> str:
    """Hash naming ``prog``'s generated module: its arrays, the sources of the
    kernels and of this generator (:func:`verifier.compiled.sources_digest`)
    and numba's version, so that an edit of any of them names a new module
    (numba's own cache of a module checks that module's file only)."""
    from . import sources_digest

    h = hashlib.sha256()
    for part in (sources_digest(), numba.__version__, str(prog.n_nodes)):
        h.update(part.encode())
    for a in (prog.code, prog.value, prog.outs, prog.meta):
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:32]


def _write_atomically(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same directory
    and :func:`os.replace`; refuses to replace anything but a regular file."""
    if os.path.lexists(path) and not stat.S_ISREG(os.lstat(path).st_mode):
        raise ModelError(f"{path} exists and is not a regular file; remove it or set CROSSCERT_CACHE_DIR "
                           "to another directory")
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def load(prog) -> np.ndarray:
    """Addresses (2, T) of ``prog``'s straight-line functions (see
    :attr:`verifier.compiled.tape.Program.fns`).

    The module of ``prog`` is generated once per machine into :func:`cache_dir`
    as ``tapes_<key>.py`` (:func:`program_key`), and numba caches its machine
    code next to it, so a later process compiles nothing; a process imports it
    once (``sys.modules``, which also keeps the callbacks alive).  An
    unwritable cache directory falls back to a private temporary one."""
    key = program_key(prog)
    name = f"crosscert_tapes_{key}"
    mod = sys.modules.get(name)
    if mod is None:
        src = module_source(prog)
        try:
            path = _place(cache_dir(), key, src)
        except OSError:
            path = _place(Path(tempfile.mkdtemp(prefix="crosscert-tapes-")), key, src)
        spec = importlib.util.spec_from_file_location(name, path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod  # before running it: numba's cache refers to the module by name
        try:
            spec.loader.exec_module(mod)
        except BaseException:
            del sys.modules[name]
            raise
    return mod.ADDRESSES


def _place(directory: Path, key: str, src: str) -> Path:
    """``directory/tapes_<key>.py`` holding ``src`` (written when missing or different)."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"tapes_{key}.py"
    try:
        same = path.read_text() == src
    except (OSError, UnicodeDecodeError):
        same = False
    if not same:
        _write_atomically(path, src)
    return path
