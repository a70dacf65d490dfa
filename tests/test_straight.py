"""Straight-line tapes (:mod:`verifier.compiled.straight`): the same floats as
the interpreter, and their cache on disk.

The kernels run each robot's tapes as generated straight-line code; the
interpreter (:func:`verifier.compiled.tape.interpret`), checked against the
numpy tapes and Arb elsewhere (tests/test_tape_properties.py,
tests/test_rounding_guard.py), is the reference here: every output of every
tape and every box HC4Revise contracts must be the interpreter's, bit for bit
(a NaN matching any NaN), on a seeded batch of boxes with signed zeros,
infinities, NaN, subnormal and huge bounds and empty boxes.

Removal checks (2026-12-02) in the generator: without the projections of
products, with the backward sweep run forward, with the outputs intersected
with 0 after the backward sweep instead of before, or with the quotients
dropped from the forward sweep, ``test_straight_line_code_is_the_interpreter``
fails.  Without the sources' digest in the module's key,
``test_the_key_names_the_program_and_the_sources`` fails; without the check for
a regular file, ``test_the_cache_writes_regular_files_only``; with the module
put in ``sys.modules`` after running it, ``test_a_second_process_compiles_nothing``
(numba's cache cannot name the module); without ``Program.__reduce__``,
``test_a_program_pickles_without_its_addresses``.  Without the check for a
regular file in :func:`straight.prune`, ``test_prune_deletes_old_unused_modules_only``
fails (a link named like a module, or among its numba files, is removed);
with the module's own time refreshed on load instead of its use record,
``test_writing_a_module_prunes_and_loading_one_records_its_use``.
"""

from __future__ import annotations

import os
import pickle
import shutil
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from crosscert.robots import available_robots, get_robot
from crosscert.robots.errors import InputError, ModelError
from crosscert.verifier.compiled import straight
from crosscert.verifier.compiled.tape import HC4_TAPES, TAPES, forward, hc4, interpret, interpret_hc4, output, trig_memo
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.tape import OPCODES

SPECIAL = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 5e-324, -5e-324, 2.2250738585072014e-308, 1e300, -1e300])


def _boxes(rng, n_in, count):
    """``count`` input boxes: ordinary ones, then bounds replaced by special values
    (either bound, so some boxes are empty, infinite or NaN), and point boxes."""
    mid = rng.uniform(-2.0, 2.0, (count, n_in))
    rad = rng.exponential(0.05, (count, n_in))
    lo, hi = mid - rad, mid + rad
    k = count // 3
    lo[2 * k:] = hi[2 * k:] = mid[2 * k:]  # points
    for b in (lo, hi):
        mask = rng.random((count, n_in)) < 0.15
        mask[:k] = False  # the first third ordinary
        b[mask] = rng.choice(SPECIAL, mask.sum())
    return lo, hi


def _entries(prog, t):
    o1 = prog.meta[t + 1, 2] if t + 1 < len(prog.meta) else len(prog.outs)
    return int(o1 - prog.meta[t, 2])


def _same(u, v):
    """The same floats: equal bit patterns (so -0.0 != 0.0), any NaN matching any NaN
    (IEEE 754 leaves a NaN's sign and payload to the machine code: ``a * b`` and ``b * a``
    return different NaNs, and no kernel reads them)."""
    u, v = np.array(u, np.float64), np.array(v, np.float64)
    return bool(((u.view(np.int64) == v.view(np.int64)) | (np.isnan(u) & np.isnan(v))).all())


@pytest.mark.parametrize("name", available_robots())
def test_straight_line_code_is_the_interpreter(name):
    """Outputs of every tape and HC4Revise's boxes agree bit for bit with the interpreter."""
    prog = IntervalModel(get_robot(name)).program
    n_in = int(max(prog.code[i, 1] for i in range(len(prog.code)) if prog.code[i, 0] == OPCODES["OP_INPUT"])) + 1
    rng = np.random.default_rng(1788)
    lo_in, hi_in = _boxes(rng, n_in, 150)
    a_lo, a_hi, b_lo, b_hi = (np.empty(prog.n_nodes) for _ in range(4))
    memo_a, memo_b = trig_memo(), trig_memo()
    for s in range(len(lo_in)):
        for t in range(len(TAPES)):
            forward(prog, t, lo_in[s].copy(), hi_in[s].copy(), a_lo, a_hi, *memo_a)
            interpret(prog, t, lo_in[s].copy(), hi_in[s].copy(), b_lo, b_hi, *memo_b)
            for e in range(_entries(prog, t)):
                got, want = output(prog, t, e, a_lo, a_hi), output(prog, t, e, b_lo, b_hi)
                assert _same(got, want), (name, TAPES[t], e, s, got, want)
        for t in HC4_TAPES:
            n_out = s % (_entries(prog, t) + 1)  # every count of constrained entries, 0 included
            u = [lo_in[s].copy(), hi_in[s].copy()]
            v = [lo_in[s].copy(), hi_in[s].copy()]
            hc4(prog, t, n_out, u[0], u[1], a_lo, a_hi, *memo_a)
            interpret_hc4(prog, t, n_out, v[0], v[1], b_lo, b_hi, *memo_b)
            assert _same(u, v), (name, TAPES[t], n_out, s)


def test_only_short_programs_are_written_out():
    """The registry's longest program runs the interpreter's callback, the default robot's its own code."""
    from crosscert.verifier.compiled.interpreted import interpreter

    sizes = {}
    for name in available_robots():
        prog = IntervalModel(get_robot(name)).program
        sizes[name] = len(prog.code)
        long = len(prog.code) > straight.MAX_STRAIGHT_NODES
        assert (prog.fns[0] == interpreter.address).all() == long
        assert (prog.fns[1] != 0).all() == long  # the straight-line code contracts with tape f only
    assert min(sizes.values()) <= straight.MAX_STRAIGHT_NODES < max(sizes.values())


def test_hc4_refuses_a_tape_without_code():
    prog = IntervalModel(get_robot("dextar")).program
    t = next(t for t in range(len(TAPES)) if t not in HC4_TAPES)
    x = np.zeros(prog.n_nodes)
    with pytest.raises(ValueError, match="HC4_TAPES"):
        hc4(prog, t, 1, x.copy(), x.copy(), x.copy(), x.copy(), *trig_memo())


def test_a_program_pickles_without_its_addresses():
    """Addresses are the linking process's; a copy elsewhere makes the kernels raise, not jump."""
    prog = IntervalModel(get_robot("dextar")).program
    copy = pickle.loads(pickle.dumps(prog))
    assert (copy.fns == 0).all() and all(np.array_equal(a, b) for a, b in zip(copy[:4], prog[:4]))
    x = np.zeros(prog.n_nodes)
    with pytest.raises(ValueError, match="link it in this process"):
        forward(copy, 0, x.copy(), x.copy(), x.copy(), x.copy(), *trig_memo())
    with pytest.raises(ValueError, match="link it in this process"):
        hc4(copy, 0, 1, x.copy(), x.copy(), x.copy(), x.copy(), *trig_memo())


def test_the_key_names_the_program_and_the_sources(monkeypatch):
    prog = IntervalModel(get_robot("dextar")).program
    key = straight.program_key(prog)
    assert straight.program_key(prog) == key
    value = prog.value.copy()
    value[np.flatnonzero(prog.code[:, 0] == OPCODES["OP_CONST"])[0]] *= -1.0
    assert straight.program_key(prog._replace(value=value)) != key
    monkeypatch.setattr("crosscert.verifier.compiled.sources_digest", lambda: "edited")
    assert straight.program_key(prog) != key


def test_the_cache_writes_regular_files_only(tmp_path):
    target = tmp_path / "tapes_x.py"
    straight._write_atomically(target, "A = 1\n")
    umask = os.umask(0)
    os.umask(umask)
    assert target.read_text() == "A = 1\n" and (target.stat().st_mode & 0o777) == (0o666 & ~umask)
    straight._write_atomically(target, "A = 2\n")
    assert target.read_text() == "A = 2\n"
    (tmp_path / "d.py").mkdir()
    (tmp_path / "s.py").symlink_to(target)
    for bad in (tmp_path / "d.py", tmp_path / "s.py"):
        with pytest.raises(ModelError, match="not a regular file"):
            straight._write_atomically(bad, "A = 3\n")
    assert target.read_text() == "A = 2\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.py", "s.py", "tapes_x.py"]  # no temporary left


def test_an_unusable_cache_directory_falls_back_to_a_private_one(tmp_path, monkeypatch):
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("CROSSCERT_CACHE_DIR", str(tmp_path / "file"))  # a file: no directory below it
    path = straight._module_path("k", "A = 1\n")
    assert path.read_text() == "A = 1\n" and not path.is_relative_to(tmp_path)
    shutil.rmtree(path.parent)
    monkeypatch.setenv("CROSSCERT_CACHE_DIR", str(tmp_path / "c"))
    assert straight._module_path("k", "A = 1\n") == tmp_path / "c" / "tapes" / "tapes_k.py"
    (tmp_path / "c" / "tapes" / "tapes_j.py").mkdir()
    with pytest.raises(ModelError, match="not a regular file"):  # an error, not a fallback
        straight._module_path("j", "A = 1\n")


def _old(*paths, days=40.0):
    """Set the times of ``paths`` (links themselves) ``days`` days back."""
    t = time.time() - 86400.0 * days
    for p in paths:
        os.utime(p, (t, t), follow_symlinks=False)


def _module(directory, key, *, used=None, days=40.0):
    """A generated module ``key`` in ``directory``, ``days`` old, with numba cache files; its use record
    ``used`` days old (None: no record)."""
    (directory / "__pycache__").mkdir(exist_ok=True)
    files = [directory / f"tapes_{key}.py", directory / "__pycache__" / f"tapes_{key}.tapes-14.py311.nbi",
             directory / "__pycache__" / f"tapes_{key}.tapes-14.py311.1.nbc"]
    for f in files:
        f.write_text("A = 1\n")
    _old(*files, days=days)
    if used is not None:
        (directory / f"tapes_{key}.used").touch()
        _old(directory / f"tapes_{key}.used", days=used)
    return files


def test_prune_deletes_old_unused_modules_only(tmp_path):
    """Modules unused for UNUSED_DAYS go with their numba files; recent ones, recently used ones, links,
    directories and other files stay."""
    old = _module(tmp_path, "aa", used=35.0)
    bare = _module(tmp_path, "bb")  # no use record: its own time counts
    kept = _module(tmp_path, "cc", used=1.0)  # old module, loaded yesterday
    fresh = _module(tmp_path, "dd", days=2.0)
    target = tmp_path / "elsewhere.txt"
    target.write_text("keep")
    link = tmp_path / "tapes_ee.py"
    link.symlink_to(target)
    (tmp_path / "tapes_ff.py").mkdir()
    stray = tmp_path / "__pycache__" / "tapes_aa.link.nbc"  # a link among the old module's numba files
    stray.symlink_to(target)
    (tmp_path / "notes.txt").write_text("")
    _old(target, link, stray, tmp_path / "tapes_ff.py", tmp_path / "notes.txt")
    assert sorted(straight.prune(tmp_path)) == ["aa", "bb"]
    assert not any(p.exists() for p in old + bare + [tmp_path / "tapes_aa.used"])
    assert all(p.exists() for p in kept + fresh + [tmp_path / "tapes_cc.used"])
    assert link.is_symlink() and stray.is_symlink() and target.read_text() == "keep"
    assert (tmp_path / "tapes_ff.py").is_dir() and (tmp_path / "notes.txt").exists()
    assert straight.prune(tmp_path / "missing") == []
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(InputError, match="max_age_days"):  # never "delete everything"
            straight.prune(tmp_path, max_age_days=bad)
    assert all(p.exists() for p in kept + fresh)


def test_writing_a_module_prunes_and_loading_one_records_its_use(tmp_path):
    """A new module prunes the directory; placing an existing one refreshes its use record, not its own time
    (which numba's cache index may stamp)."""
    old = _module(tmp_path, "aa")
    kept = _module(tmp_path, "bb", used=50.0)
    path = tmp_path / "tapes_bb.py"
    t_module = os.stat(path).st_mtime
    assert straight._place(tmp_path, "bb", "A = 1\n") == path  # the same source: not written, nothing pruned
    assert os.stat(path).st_mtime == t_module and time.time() - os.stat(tmp_path / "tapes_bb.used").st_mtime < 60
    assert all(p.exists() for p in old + kept)
    straight._place(tmp_path, "new", "A = 2\n")
    assert not any(p.exists() for p in old) and all(p.exists() for p in kept)
    assert (tmp_path / "tapes_new.py").read_text() == "A = 2\n" and (tmp_path / "tapes_new.used").exists()


_CHILD = textwrap.dedent("""
    import sys
    import casadi as ca
    from crosscert.verifier.compiled import straight
    from crosscert.verifier.compiled.tape import TAPES
    from crosscert.verifier.tape import Tape
    x, q, xi = ca.SX.sym("x", 2), ca.SX.sym("q", 2), ca.SX.sym("xi", 1)
    f = ca.vertcat(x[0] ** 2 + x[1] ** 2 - q[0] ** 2 + 0 * xi[0], x[0] * ca.sin(x[1]) - q[1])
    tape = Tape(ca.Function("f", [x, q, xi], [f]))
    prog = straight.link([tape.arrays()] * len(TAPES))
    mod = sys.modules["crosscert_tapes_" + straight.program_key(prog)]
    print(mod.tapes.cache_hits, mod.__file__)
""")


def test_a_second_process_compiles_nothing(tmp_path):
    """The generated module and numba's machine code of it are found on disk by the next process."""
    env = dict(os.environ, CROSSCERT_CACHE_DIR=str(tmp_path))
    runs = [subprocess.run([sys.executable, "-c", _CHILD], env=env, capture_output=True, text=True, check=True)
            for _ in range(2)]
    (hits0, path0), (hits1, path1) = (r.stdout.split() for r in runs)
    assert (hits0, hits1) == ("0", "1") and path0 == path1
    assert path0.startswith(str(tmp_path / "tapes"))
