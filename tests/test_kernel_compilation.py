"""Each kernel is compiled once: no kernel passes a Python literal to another.

numba types a literal ``0`` or ``True`` in a call from compiled code as
``Literal[int](0)`` / ``Literal[bool](True)`` and compiles the callee once more
for that value, with its whole call tree: with Python literals the first run
compiled 88 copies of 69 kernels, 26 s instead of 18 s (measured side by side;
benchmarks/README.md's git history).  Constant arguments are numpy scalars instead
(:data:`verifier.compiled.contractors.I0`, ``YES``, ``NO``, ...), which numba
types as ``int64`` / ``bool``.  This test reads the source of
``verifier/compiled`` and fails on any call of a kernel with an int or bool
literal argument.  (A counter first bound to a literal and passed on before it
changes has the same effect; ``pose_solutions``' ``found`` starts at ``I0``
for that reason, which this syntactic check does not see.)
"""

from __future__ import annotations

import ast
import importlib
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

from numba.core.registry import CPUDispatcher

import crosscert.verifier.compiled as compiled_pkg

MODULES = ("interval", "tape", "linalg", "contractors", "step", "vectorized", "motion_model", "one_motion", "implicit")


def _literal(node) -> bool:
    """Whether ``node`` is an int or bool constant (``-1`` included); floats are never literal types."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        node = node.operand
    return isinstance(node, ast.Constant) and isinstance(node.value, (bool, int))


def _literal_kernel_calls(module_name: str) -> list[str]:
    mod = importlib.import_module(f"crosscert.verifier.compiled.{module_name}")
    kernels = {name for name, obj in vars(mod).items() if isinstance(obj, CPUDispatcher)}
    ops_kernels = {name for name, obj in vars(importlib.import_module("crosscert.verifier.compiled.interval")).items()
                   if isinstance(obj, CPUDispatcher)}
    tree = ast.parse(Path(mod.__file__).read_text())
    bad = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        is_kernel = (isinstance(f, ast.Name) and f.id in kernels) or (
            isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id == "ops"
            and f.attr in ops_kernels)
        if is_kernel and any(_literal(a) for a in node.args):
            bad.append(f"{module_name}.py:{node.lineno}: {ast.unparse(node)}")
    return bad


def test_no_kernel_passes_a_python_literal_to_a_kernel():
    assert Path(compiled_pkg.__file__).parent.name == "compiled"
    bad = [line for m in MODULES for line in _literal_kernel_calls(m)]
    assert not bad, "literal arguments compile the callee once more; use a numpy scalar:\n" + "\n".join(bad)


def test_the_check_sees_a_literal_argument(tmp_path, monkeypatch):
    # the check itself: a call with a literal 0 in a module of kernels is reported
    src = Path(importlib.import_module("crosscert.verifier.compiled.contractors").__file__).read_text()
    assert "copy_box(X_search, I0, stack, I0, n)" in src
    fake = tmp_path / "contractors.py"
    fake.write_text(src.replace("copy_box(X_search, I0, stack, I0, n)", "copy_box(X_search, 0, stack, I0, n)"))
    mod = importlib.import_module("crosscert.verifier.compiled.contractors")
    monkeypatch.setattr(mod, "__file__", str(fake))
    assert any("copy_box(X_search, 0, stack, I0, n)" in line for line in _literal_kernel_calls("contractors"))


def _reachable_kernels(fn) -> set[str]:
    """Names of the kernels a Python function or kernel calls, directly or through callees: its globals and
    closure cells that are kernels, followed through theirs."""
    seen, todo = set(), [getattr(fn, "py_func", fn)]
    while todo:
        f = todo.pop()
        refs = [f.__globals__.get(name) for name in f.__code__.co_names]
        refs += [cell.cell_contents for cell in (f.__closure__ or ())]
        for obj in refs:
            if isinstance(obj, CPUDispatcher) and obj.py_func.__name__ not in seen:
                seen.add(obj.py_func.__name__)
                todo.append(obj.py_func)
    return seen


def test_the_default_velocity_model_compiles_only_its_own_kernels():
    """The row step of the default model (``SOUND``) reaches neither the joint-acceleration bound nor the
    Gauss-Seidel contractor of the joint-rate models: numba compiles only what a call reaches, and these
    two cost 2 s of the first run (measured; benchmarks/README.md's git history)."""
    from crosscert.verifier.compiled import step as kernels
    from crosscert.verifier.constants import JOINT_FD, PAPER, SOUND

    def reach(code):
        hooks = kernels._HOOKS[type(kernels.velocity_strategy(code))]
        return set().union(_reachable_kernels(kernels.row_step), *(_reachable_kernels(h) for h in hooks))

    sound, paper, joint_fd = reach(SOUND), reach(PAPER), reach(JOINT_FD)
    assert "velocity_displacement" in sound and "split_prune" in sound
    assert not {"velocity_gs", "_qdd_over_step", "_joint_rates"} & sound
    assert "velocity_gs" in paper and "_qdd_over_step" not in paper and "velocity_displacement" not in paper
    assert {"velocity_gs", "_qdd_over_step"} <= joint_fd


def test_velocity_strategies_survive_the_on_disk_cache():
    """numba's on-disk cache finds a driver by its argument types, pickled in its index and compared after
    loading in the next process: the strategy's type must compare equal after a pickle round trip, by value.
    (The type of a kernel passed as an argument compares by object identity: a driver taking one was
    compiled again in every new process, numba 0.68; benchmarks/README.md.)"""
    import pickle

    import numba

    from crosscert.verifier.compiled import step as kernels
    from crosscert.verifier.constants import JOINT_FD, PAPER, SOUND

    types_ = {code: numba.typeof(kernels.velocity_strategy(code)) for code in (SOUND, PAPER, JOINT_FD)}
    for code, t in types_.items():
        assert pickle.loads(pickle.dumps(t)) == t, code
    assert len(set(types_.values())) == 3  # one driver per model, never a shared one


_SIGNATURES = textwrap.dedent("""
    import importlib, json, sys
    from numba.core.registry import CPUDispatcher
    from crosscert.verifier.compiled import step, warm
    step.run_slot.compile(warm.signature())
    mods = [importlib.import_module(f"crosscert.verifier.compiled.{name}") for name in sys.argv[1:]]
    many = {f"{mod.__name__}.{name}": [str(s) for s in obj.signatures]
            for mod in mods for name, obj in vars(mod).items()
            if isinstance(obj, CPUDispatcher) and len(obj.signatures) > 1}
    print(json.dumps({"compiled": len(step.run_slot.signatures), "many": many}))
""")


def test_the_driver_compiles_each_kernel_once(tmp_path):
    """What the syntactic check above cannot see: a variable first bound to a literal and passed on before it
    changes (``N = 1`` in ``split_prune`` compiled ``_settle`` and ``_hull_of_pieces`` twice, for
    ``Literal[int](1)`` and ``int64``).  The default driver compiled in a fresh process with an empty
    numba cache: every kernel it reaches has one signature."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    proc = subprocess.run([sys.executable, "-c", _SIGNATURES, *MODULES], capture_output=True, text=True, env=env,
                          timeout=900, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["compiled"] == 1
    assert got["many"] == {}, "a kernel compiled once per literal argument; pass a numpy scalar (I0, ONE, ...)"
