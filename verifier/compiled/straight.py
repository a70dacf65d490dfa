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
import threading
import time
import uuid
from pathlib import Path

import numba
import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.errors import ModelError

from ..tape import OPCODES
from .tape import HC4_TAPES, TAPES, Program

__all__ = ["MAX_STRAIGHT_NODES", "UNUSED_DAYS", "cache_dir", "link", "load", "module_source", "pack", "program_key",
           "prune"]

_NAMES = {v: k for k, v in OPCODES.items()}
_INPUT = OPCODES["OP_INPUT"]
_CONST = OPCODES["OP_CONST"]
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
            out.append(f"{A} = project_square({A}, {z})")
        elif name == "OP_SQRT":
            out.append(f"{A} = back_sqrt({z}, {A})")
        elif name == "OP_INV":
            out.append(f"{A} = project_factor({A}, 1.0, 1.0, {z})")
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


def _shared(a):
    """``a`` with repeated instructions (same opcode, operands and constant)
    evaluated once: CasADi's derivatives repeat subexpressions (the velocity
    tape computes each sine twice).  Forward evaluation gives the same floats;
    HC4Revise would not (a shared node collects both projections), so the
    contracted tape ``f`` is kept as written."""
    new_of = np.empty(len(a.code), np.int64)
    seen = {}
    code, value = [], []
    for i, (op, x, y) in enumerate(a.code):
        if op != _INPUT and op != _CONST:  # an input's ``a`` is a slot; a constant has no operand
            x = new_of[x]
            y = new_of[y] if y >= 0 else y
        key = (int(op), int(x), int(y), float(a.value[i]))
        if key not in seen:
            seen[key] = len(code)
            code.append((op, x, y))
            value.append(a.value[i])
        new_of[i] = seen[key]
    outs = np.where(a.out_nodes >= 0, new_of[np.maximum(a.out_nodes, 0)], -1)
    return a._replace(code=np.array(code, np.int64).reshape(-1, 3), value=np.array(value), out_nodes=outs)


def pack(model) -> Program:
    """Concatenate the tapes of an :class:`verifier.model.IntervalModel` and
    link their straight-line functions (:func:`link`)."""
    return link([getattr(model, name).arrays() for name in TAPES])


def link(arrs) -> Program:
    """The :class:`Program` of the tapes ``arrs`` (:class:`verifier.tape.TapeArrays`,
    in the order :data:`TAPES`), with the addresses of their straight-line
    functions, generated, compiled or found in the cache
    (:func:`load`)."""
    arrs = [a if name == "tape_f" else _shared(a) for name, a in zip(TAPES, arrs)]
    meta = np.zeros((len(arrs), 3), np.int64)
    c0 = o0 = 0
    for t, a in enumerate(arrs):
        meta[t] = (c0, len(a.code), o0)
        c0 += len(a.code)
        o0 += len(a.out_nodes)
    prog = Program(
        code=np.ascontiguousarray(np.concatenate([a.code for a in arrs])),
        value=np.concatenate([a.value for a in arrs]),
        outs=np.concatenate([a.out_nodes for a in arrs]),
        meta=meta,
        n_nodes=int(max(len(a.code) for a in arrs)),
        fns=np.zeros((2, len(arrs)), np.int64),
    )
    prog.fns[:] = load(prog)
    return prog


def module_source(prog) -> str:
    """Python source of the module of ``prog``'s straight-line code: one C
    callback ``tapes`` of :data:`verifier.compiled.tape.C_SIGNATURE` whose branch ``sel = t`` is tape
    ``t``'s forward sweep and ``sel = T + t`` its HC4Revise (tapes of
    :data:`verifier.compiled.tape.HC4_TAPES`); ``ADDRESSES`` (2, T) holds the
    callback's address where a branch exists, else 0.  One function: numba
    compiles the interval operations it calls once."""
    n_tapes = len(prog.meta)
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
        "from crosscert.verifier.compiled import interval as ops",
        "from crosscert.verifier.compiled.tape import (",
        "    C_SIGNATURE, project_factor, project_square, back_add, back_div, back_mul, back_sqrt, back_sub, back_twice,",
        "    trig)",
        "",
        f"_SIN = np.int64({OPCODES['OP_SIN']})",
        f"_COS = np.int64({OPCODES['OP_COS']})",
        f"_K = np.array({bits}, dtype=np.int64).view(np.float64)",
        "",
        "",
        "@cfunc(C_SIGNATURE, cache=True)",
        "def tapes(sel, n_out, in_lo_p, in_hi_p, n_in, lo_p, hi_p, n_nodes, mk_p, mv_p, slots,",
        "          code_p, n_code, value_p, outs_p, n_outs, meta_p, n_tapes):",
        "    # the caller's arrays (the program's own arrays are written out below)",
        "    in_lo = carray(in_lo_p, (n_in,))",
        "    in_hi = carray(in_hi_p, (n_in,))",
        "    lo = carray(lo_p, (n_nodes,))",
        "    hi = carray(hi_p, (n_nodes,))",
        "    mk = carray(mk_p, (slots, 3))",
        "    mv = carray(mv_p, (slots, 2))",
    ]
    for k, (sel, what, body) in enumerate(branches):
        lines += [f"    {'if' if k == 0 else 'elif'} sel == {sel}:  # {what}"] + ["        " + b for b in body]
    lines += ["", "", f"ADDRESSES = np.where(np.array({has.tolist()}), tapes.address, 0).astype(np.int64)", ""]
    return "\n".join(lines)


#: Programs with more nodes than this run in the interpreter's callback: the
#: compilation of straight-line code grows faster than its length (on the
#: robots of the registry, first run: 3 s of CPU for 307 nodes, 9 s for 649,
#: 181 s for 4014; benchmarks/README.md).
MAX_STRAIGHT_NODES = 1000

#: A generated module not loaded for this many days is deleted (with its numba
#: cache files) the next time a new module is written to the same directory:
#: every edit of the package names new modules (:func:`program_key`), and
#: several installed versions may share the directory.
UNUSED_DAYS = 30


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
    """Write ``text`` to ``path`` through a new file in the same directory (the
    user's default permissions) and :func:`os.replace`; refuses to replace
    anything but a regular file."""
    if os.path.lexists(path) and not stat.S_ISREG(os.lstat(path).st_mode):
        raise ModelError(f"{path} exists and is not a regular file; remove it or set CROSSCERT_CACHE_DIR "
                         "to another directory")
    tmp = path.with_name(f"{path.name}.{os.getpid()}.{uuid.uuid4().hex}.tmp")
    try:
        with open(tmp, "x") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


_LOAD_LOCK = threading.Lock()


def load(prog) -> np.ndarray:
    """Addresses (2, T) of ``prog``'s straight-line functions (see
    :attr:`verifier.compiled.tape.Program.fns`).

    The module of ``prog`` is generated once per machine into :func:`cache_dir`
    as ``tapes_<key>.py`` (:func:`program_key`), and numba caches its machine
    code next to it, so a later process compiles nothing; a process imports it
    once (``sys.modules``, which also keeps the callbacks alive).  An
    unwritable cache directory falls back to a private temporary one."""
    if len(prog.code) > MAX_STRAIGHT_NODES:
        from .interpreted import interpreter

        return np.full((2, len(prog.meta)), interpreter.address, np.int64)
    key = program_key(prog)
    name = f"crosscert_tapes_{key}"
    with _LOAD_LOCK:  # a module half run is in sys.modules: one thread at a time
        return _import(name, key, prog).ADDRESSES


def _import(name, key, prog):
    """The generated module ``name`` of ``prog``, imported once per process."""
    mod = sys.modules.get(name)
    if mod is None:
        src = module_source(prog)
        for attempt in (0, 1):
            path = _module_path(key, src)
            spec = importlib.util.spec_from_file_location(name, path)
            mod = importlib.util.module_from_spec(spec)
            sys.modules[name] = mod  # before running it: numba's cache refers to the module by name
            try:
                spec.loader.exec_module(mod)
                break
            except FileNotFoundError:
                del sys.modules[name]
                if attempt:
                    raise
                # another process pruned it between writing and reading it: write it again
            except BaseException:
                del sys.modules[name]
                raise
    return mod


def _module_path(key: str, src: str) -> Path:
    """Where the module ``src`` of key ``key`` is: :func:`cache_dir`, or a new
    private temporary directory when that one cannot be written."""
    try:
        return _place(cache_dir(), key, src)
    except OSError:
        return _place(Path(tempfile.mkdtemp(prefix="crosscert-tapes-")), key, src)


def _place(directory: Path, key: str, src: str) -> Path:
    """``directory/tapes_<key>.py`` holding ``src`` (written when missing or different), its use recorded;
    writing one prunes the directory (:func:`prune`)."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"tapes_{key}.py"
    _mark_used(directory, key)
    try:
        same = path.read_text() == src
    except (OSError, UnicodeDecodeError):
        same = False
    if not same:
        _write_atomically(path, src)
        prune(directory)
    return path


def _mark_used(directory: Path, key: str) -> None:
    """Record that the module ``key`` is loaded now: the time of ``tapes_<key>.used`` (an empty file), not
    the module's own, which numba's cache index may stamp (by time and size in some numba versions)."""
    used = directory / f"tapes_{key}.used"
    with contextlib.suppress(OSError):
        if os.path.lexists(used) and not stat.S_ISREG(os.lstat(used).st_mode):
            return
        used.touch()


def prune(directory: Path | None = None, *, max_age_days: float = UNUSED_DAYS, now: float | None = None) -> list:
    """Delete the generated modules of ``directory`` (default :func:`cache_dir`) not loaded for
    ``max_age_days`` days, with their use records and numba cache files.

    Only regular files named as this module names them are deleted (links,
    directories and other files are left alone); a module without a use record
    counts from its own time.  Errors (a file another process deletes first, a
    read-only directory) are ignored: pruning is housekeeping.

    Returns
    -------
    list of str
        The keys of the modules deleted.

    Raises
    ------
    InputError
        If ``max_age_days`` is not a positive number.
    """
    max_age_days = V.positive("max_age_days", max_age_days)
    directory = cache_dir() if directory is None else Path(directory)
    limit = (time.time() if now is None else now) - 86400.0 * max_age_days
    gone = []
    try:
        modules = [p for p in directory.iterdir() if p.name.startswith("tapes_") and p.name.endswith(".py")]
    except OSError:
        return gone
    for path in modules:
        key = path.name[len("tapes_"):-len(".py")]
        try:
            if not _regular(path):
                continue
            used = directory / f"tapes_{key}.used"
            last = max(os.lstat(path).st_mtime, os.lstat(used).st_mtime if _regular(used) else 0.0)
            if last >= limit:
                continue
            cached = list((directory / "__pycache__").glob(f"tapes_{key}.*"))
        except OSError:
            continue
        for p in [path, directory / f"tapes_{key}.used", *cached]:
            with contextlib.suppress(OSError):
                if _regular(p):
                    os.unlink(p)
        gone.append(key)
    return gone


def _regular(path: Path) -> bool:
    """``path`` exists and is a regular file (not followed if a link)."""
    try:
        return stat.S_ISREG(os.lstat(path).st_mode)
    except OSError:
        return False
