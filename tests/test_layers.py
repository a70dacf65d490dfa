"""The import contract of the house: layers, no cycles, no private names across modules, robots named once.

``robots`` (bottom) -> ``verifier`` -> ``planner`` -> ``planner.cli``, all
under the ``crosscert`` namespace (``crosscert.robots`` ...; the folders keep
their top-level names).  Read from the source with :mod:`ast`, imports inside
functions included (an import hidden in a function is still a dependency).
Module names below drop the ``crosscert.`` prefix.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("robots", "verifier", "planner")
#: What each layer may import from the project (itself included).
ALLOWED = {"robots": {"robots"}, "verifier": {"robots", "verifier"}, "planner": {"robots", "verifier", "planner"}}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> list[tuple[str, tuple[str, ...], int]]:
    """``(module imported, names taken from it, line)`` for every import of ``name``, relative ones resolved."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(a.name, (), node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            names = tuple(a.name for a in node.names)
            # `from pkg import module` imports a module, not a name
            subs = [n for n in names if f"{base}.{n}" in MODULES]
            out += [(f"{base}.{n}", (), node.lineno) for n in subs]
            out.append((base, tuple(n for n in names if n not in subs), node.lineno))
    return [(m.removeprefix("crosscert."), n, line) for m, n, line in out
            if m.split(".")[0] in PACKAGES or m.startswith("crosscert.")]


IMPORTS = {name: _imports(name, path) for name, path in MODULES.items()}


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_upward_import(name):
    layer = name.split(".")[0]
    for target, _, line in IMPORTS[name]:
        assert target.split(".")[0] in ALLOWED[layer], f"{name}:{line} imports {target}, above its layer"
        if not name.startswith("planner.cli"):
            assert not target.startswith("planner.cli"), f"{name}:{line} imports the command line {target}"


#: Planner modules that certification builds on: they may not import ``planner.certify`` back (a room below
#: reaching up into the one that uses it).
BELOW_CERTIFY = ("planner.montecarlo", "planner.execution", "planner.execution_proof", "planner.task",
                 "planner.plan", "planner.refute", "planner.simulate", "planner.generate", "planner.timescale")


@pytest.mark.parametrize("name", sorted(n for n in MODULES if n.startswith(BELOW_CERTIFY)))
def test_certification_is_not_imported_from_below(name):
    for target, _, line in IMPORTS[name]:
        assert not target.startswith("planner.certify"), f"{name}:{line} imports {target}, which builds on it"


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_private_name_across_modules(name):
    for target, names, line in IMPORTS[name]:
        private = [n for n in names if n.startswith("_") and not n.startswith("__")]
        assert target == name or not private, f"{name}:{line} imports private {private} from {target}"
        assert not any(part.startswith("_") and part != "__init__" for part in target.split(".")), \
            f"{name}:{line} imports the private module {target}"


def test_no_import_cycle():
    graph = {name: {t for t, _, _ in IMPORTS[name] if t in MODULES and t != name} for name in MODULES}
    # a package's __init__ re-exporting its submodules is not a cycle of the submodules among themselves
    edges = {n: {t for t in ts if not n.startswith(t + ".")} for n, ts in graph.items()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n):
        state[n] = 1
        stack.append(n)
        for t in edges[n]:
            if state.get(t) == 1:
                cycle = stack[stack.index(t):] + [t]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if t not in state:
                visit(t)
        stack.pop()
        state[n] = 2

    for n in sorted(edges):
        if n not in state:
            visit(n)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_imports_through_the_namespace(name):
    """Absolute imports of the project go through ``crosscert.`` (a bare ``import verifier`` may pick up another project)."""
    tree = ast.parse(MODULES[name].read_text())
    for node in ast.walk(tree):
        bare = ([a.name for a in node.names] if isinstance(node, ast.Import)
                else [node.module] if isinstance(node, ast.ImportFrom) and not node.level and node.module else [])
        for mod in bare:
            assert mod.split(".")[0] not in PACKAGES, f"{name}:{node.lineno} imports {mod} outside the crosscert namespace"


def test_every_package_is_installed():
    """pyproject.toml's package list names every package folder (a missing one would not install)."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {"crosscert"} | {".".join(("crosscert",) + p.parent.relative_to(ROOT).parts)
                             for pkg in PACKAGES for p in (ROOT / pkg).rglob("__init__.py")}
    assert listed == found


def test_only_robots_names_a_robot():
    from crosscert.robots import available_robots

    for name, path in MODULES.items():
        if name.split(".")[0] == "robots":
            continue
        text = path.read_text().lower()
        for robot in available_robots():
            assert robot not in text, f"{path.relative_to(ROOT)} names the robot {robot!r}"


def test_the_contract_sees_a_violation(tmp_path):
    """The parser finds relative, hidden and private imports (so the tests above can fail)."""
    bad = tmp_path / "mod.py"
    bad.write_text("def f():\n    from ..planner.simulate import _vec\n    from crosscert.planner.cli import main\n")
    found = _imports("verifier.mod", bad)
    assert ("planner.simulate", ("_vec",), 2) in found
    assert ("planner.cli", ("main",), 3) in found


def test_the_contract_resolves_imports_inside_a_sub_package(tmp_path):
    """In a sub-package (``verifier.window``), a sibling's private name is still across modules, and ``..``
    reaches the parent package: a private helper shared by sibling modules must be made public."""
    bad = tmp_path / "mod.py"
    bad.write_text("from .hypotheses import _decide\nfrom ..step import advance\nfrom . import passes\n")
    found = _imports("verifier.window.mod", bad)
    assert ("verifier.window.hypotheses", ("_decide",), 1) in found
    assert ("verifier.step", ("advance",), 2) in found
    assert ("verifier.window.passes", (), 3) in found  # a sibling module, not a name


# ------------------------------------------------------------------ one owner of the assumptions
#: The bounds robots.assumptions owns; only it decides whether a value of one is admissible.
BOUNDS = {"eps_q", "t_s", "a_max", "xd0", "v_max", "v0_max", "eps_q_fast", "drift_rate"}
ASSUMPTIONS_OWNER = "robots.assumptions"
#: Argument checkers a bound may not be run through outside the owner (robots.arguments).
_CHECKERS = {"positive", "number", "vector", "floats"}


def _bound_name(node) -> str | None:
    while isinstance(node, ast.Subscript):
        node = node.value
    name = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else None
    return name if name in BOUNDS else None


def _revalidations(tree) -> list[tuple[int, str]]:
    """``(line, bound)`` of each sign check of a bound: ``bound < 0``-like comparisons with 0, and
    ``positive("bound", ...)``-like calls of the argument checkers (a rule of its own)."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare) and all(isinstance(op, (ast.Lt, ast.LtE, ast.Gt, ast.GtE)) for op in node.ops):
            sides = [node.left, *node.comparators]
            zero = any(isinstance(s, ast.Constant) and type(s.value) in (int, float) and s.value == 0 for s in sides)
            names = [n for n in map(_bound_name, sides) if n]
            if zero and names:
                out.append((node.lineno, names[0]))
        elif isinstance(node, ast.Call) and node.args:
            f = node.func
            fname = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
            first = node.args[0]
            signed = fname in ("positive", "number") or any(
                k.arg in ("positive", "nonneg") and not (isinstance(k.value, ast.Constant) and not k.value.value)
                for k in node.keywords)
            if (fname in _CHECKERS and signed and isinstance(first, ast.Constant) and first.value in BOUNDS):
                out.append((node.lineno, first.value))
    return sorted(out)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_only_the_owner_checks_a_bound(name):
    """eps_q, t_s, a_max ... are checked by the rule of robots.assumptions, once: no module re-validates one."""
    if name == ASSUMPTIONS_OWNER:
        return
    found = _revalidations(ast.parse(MODULES[name].read_text()))
    assert not found, (f"{MODULES[name].relative_to(ROOT)} checks {', '.join(f'{b} (line {k})' for k, b in found)}"
                       f" itself: use robots.assumptions (Assumptions, check_bound)")


def test_the_owner_check_sees_a_revalidation():
    """The finder sees each form (so the test above can fail), and not a bound compared with another value."""
    code = ("if eps_q <= 0: pass\nif not self.t_s > 0.0: pass\nif 0 < s.a_max[0]: pass\n"
            "V.positive('t_s', x)\nvector('a_max', v, n, positive=True)\nif t_s > t_min: pass\n"
            "vector('a_max', v, n)\n")
    assert [b for _, b in _revalidations(ast.parse(code))] == ["eps_q", "t_s", "a_max", "t_s", "a_max"]


def test_the_layers_import_only_under_the_crosscert_namespace(tmp_path):
    """From outside the checkout: ``crosscert.verifier`` imports, a bare ``verifier`` (or robots, planner) does not."""
    import subprocess
    import sys

    code = ("import importlib.util, crosscert.verifier, crosscert.planner, crosscert.robots\n"
            "assert [importlib.util.find_spec(m) for m in ('verifier', 'planner', 'robots')] == [None] * 3\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


def test_the_namespace_imports_from_the_checkout_root_too():
    """Run from the checkout, where its ``crosscert/`` folder shadows the installed package: the layers still import."""
    import subprocess
    import sys

    code = "import crosscert.verifier, crosscert.planner.cli, crosscert.robots; print(crosscert.planner.cli.__name__)"
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "crosscert.planner.cli", done.stderr


def test_every_name_of_the_top_level_api_resolves():
    """``import crosscert`` promises each name of ``__all__``: each one loads, from its defining module."""
    import crosscert

    for name in crosscert.__all__:
        value = getattr(crosscert, name)
        assert getattr(value, "__name__", name) == name, name
