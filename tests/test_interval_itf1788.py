"""Optional IEEE 1788 conformance check of the interval cores (ITF1788).

The ITF1788 test vectors (``*.itl`` files of the "Interval Test Framework for
IEEE 1788") are *not* vendored: they are read from
``<repo>/../shared/conformance/itf1788`` or from the folder named by the
environment variable ``CROSSCERT_ITF1788_DIR``; the module is skipped when
neither exists.

For every bare (undecorated) test case of an operation we implement, the
result computed by each core (the ``core`` fixture: the numpy reference
:mod:`verifier.interval` and the compiled operations through
:mod:`verifier.compiled.vectorized`) must *contain* the tightest result
stated by the vector (soundness).  Being tightest is not required (we round
outward by one ulp even for exact results, and sin/cos carry a margin): the
number of cases that are not tightest is reported, not failed.

Literals are parsed exactly (:class:`fractions.Fraction`) and an interval
literal ``[a, b]`` denotes the tightest float64 interval containing the real
set ``[a, b]``, as IEEE 1788 prescribes for ``b-textToInterval``.
"""

from __future__ import annotations

import math
import os
import re
from collections import Counter, defaultdict
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from crosscert.verifier import interval as I
from crosscert.verifier.compiled import vectorized as V


def _itf_dir() -> Path:
    env = os.environ.get("CROSSCERT_ITF1788_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2] / "shared" / "conformance" / "itf1788"


ITF_DIR = _itf_dir()
if not ITF_DIR.is_dir() or not any(ITF_DIR.glob("*.itl")):
    pytest.skip(f"ITF1788 test vectors not found in {ITF_DIR}", allow_module_level=True)


@pytest.fixture(scope="module", params=["numpy", "compiled"])
def core(request):
    """The interval core under test."""
    return {"numpy": I, "compiled": V}[request.param]


# ---------------------------------------------------------------------------
# exact literal parsing
# ---------------------------------------------------------------------------

_MAX = Fraction(np.finfo(np.float64).max)
_HEX = re.compile(r"([+-]?)0x([0-9a-f]*)(?:\.([0-9a-f]*))?p([+-]?[0-9]+)", re.I)
_DEC = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:e[+-]?[0-9]+)?", re.I)


def parse_number(tok: str) -> Fraction | float:
    """Exact value of an ITL number literal (a Fraction, or +-inf)."""
    t = tok.strip()
    low = t.lower()
    if low in ("infinity", "+infinity", "inf", "+inf"):
        return math.inf
    if low in ("-infinity", "-inf"):
        return -math.inf
    m = _HEX.fullmatch(t)
    if m:
        sign, ip, fp, ex = m.groups()
        fp = fp or ""
        if not (ip or fp):
            raise ValueError(f"bad hex literal {tok!r}")
        v = Fraction(int((ip or "0") + fp, 16), 16 ** len(fp)) * Fraction(2) ** int(ex)
        return -v if sign == "-" else v
    if _DEC.fullmatch(t):
        return Fraction(t)  # exact: Fraction parses decimal strings exactly
    raise ValueError(f"unsupported number literal {tok!r}")


def round_down(v: Fraction | float) -> float:
    """Largest float64 <= v (v exact)."""
    if isinstance(v, float):
        return v
    if v > _MAX:
        return float(np.finfo(np.float64).max)
    if v < -_MAX:
        return -math.inf
    f = float(v)  # int / int true division: correctly rounded
    return math.nextafter(f, -math.inf) if Fraction(f) > v else f


def round_up(v: Fraction | float) -> float:
    """Smallest float64 >= v (v exact)."""
    if isinstance(v, float):
        return v
    if v > _MAX:
        return math.inf
    if v < -_MAX:
        return -float(np.finfo(np.float64).max)
    f = float(v)
    return math.nextafter(f, math.inf) if Fraction(f) < v else f


EMPTY = (math.inf, -math.inf)


class Skip(Exception):
    """A literal we do not handle (decorated interval, NaI, ...)."""


def parse_interval(tok: str) -> tuple[float, float]:
    """Tightest float64 enclosure of a bare ITL interval literal."""
    t = tok.strip()
    if not (t.startswith("[") and t.endswith("]")):
        raise Skip(tok)  # decorated ("[..]_com") or not an interval
    body = t[1:-1].strip().lower()
    if body == "empty":
        return EMPTY
    if body == "entire":
        return (-math.inf, math.inf)
    if body == "nai" or not body:
        raise Skip(tok)
    parts = [p.strip() for p in body.split(",")]
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2:
        raise Skip(tok)
    a, b = (parse_number(p) for p in parts)
    if a > b or a == math.inf or b == -math.inf:
        raise Skip(tok)  # not a valid interval literal
    return round_down(a), round_up(b)


# ---------------------------------------------------------------------------
# ITL file parsing
# ---------------------------------------------------------------------------

# ITL op name -> (our name, arity: interval operands, has integer exponent)
OPS = {
    "add": ("add", 2, False),
    "sub": ("sub", 2, False),
    "neg": ("neg", 1, False),
    "mul": ("mul", 2, False),
    "div": ("div", 2, False),
    "sqr": ("sqr", 1, False),
    "pown": ("pown", 1, True),
    "sqrt": ("sqrt", 1, False),
    "abs": ("absolute", 1, False),
    "sin": ("sin", 1, False),
    "cos": ("cos", 1, False),
    "intersection": ("intersect", 2, False),
    "convexHull": ("hull", 2, False),
}

_TOKEN = re.compile(r"\[[^\]]*\](?:_\w+)?|\S+")


@dataclass(frozen=True)
class Case:
    where: str  # file:line testcase
    text: str
    op: str
    args: tuple  # intervals (lo, hi) and possibly the int exponent
    expected: tuple[float, float]


def _strip_comments(txt: str) -> str:
    # keep newlines so that line numbers stay right
    txt = re.sub(r"/\*.*?\*/", lambda m: "\n" * m.group(0).count("\n"), txt, flags=re.S)
    return re.sub(r"//[^\n]*", "", txt)


def parse_itl(path: Path) -> tuple[list[Case], Counter]:
    """All bare cases of our operations in one file, and a counter of skips."""
    cases: list[Case] = []
    skipped: Counter = Counter()
    txt = _strip_comments(path.read_text())
    for block in re.finditer(r"testcase\s+(\S+)\s*\{(.*?)\}", txt, flags=re.S):
        name = block.group(1)
        for stm in re.finditer(r"\s*([^;]+);", block.group(2)):
            text = " ".join(stm.group(1).split())
            if not text or text.split()[0] not in OPS:
                continue
            op = text.split()[0]
            line = txt.count("\n", 0, block.start(2) + stm.start(1)) + 1
            where = f"{path.name}:{line} {name}"
            if " signal " in f" {text} " or text.count("=") != 1:
                skipped[op, "signal/extra"] += 1
                continue
            lhs, rhs = (s.strip() for s in text.split("="))
            rtoks = _TOKEN.findall(rhs)
            if len(rtoks) != 1:
                skipped[op, "extra outputs"] += 1  # e.g. mulRevToPair-like results
                continue
            toks = _TOKEN.findall(lhs)[1:]
            _, arity, has_int = OPS[op]
            if len(toks) != arity + has_int:
                skipped[op, "arity"] += 1
                continue
            try:
                ivs = [parse_interval(t) for t in toks[:arity]]
                expected = parse_interval(rtoks[0])
            except Skip:
                skipped[op, "decorated/nai"] += 1
                continue
            args = tuple(ivs) + ((int(toks[arity]),) if has_int else ())
            cases.append(Case(where, text, op, args, expected))
    return cases, skipped


def _load():
    by_op: dict[str, list[Case]] = defaultdict(list)
    skipped: Counter = Counter()
    for path in sorted(ITF_DIR.glob("*.itl")):
        cases, sk = parse_itl(path)
        skipped += sk
        for c in cases:
            by_op[c.op].append(c)
    return by_op, skipped


CASES, SKIPPED = _load()

# Minimum bare cases per operation (libieeep1788_elem/set, mpfi, fi_lib and
# c-xsc of the ITF1788 release this was written against); fewer means the parser
# silently lost vectors.
EXPECTED_MIN = {
    "add": 100, "sub": 130, "neg": 20, "mul": 270, "div": 490, "sqr": 55,
    "pown": 160, "sqrt": 50, "abs": 24, "sin": 210, "cos": 125,
    "intersection": 35, "convexHull": 45,
}  # 1742 bare cases in total (71 decorated/NaI ones are skipped)


# ---------------------------------------------------------------------------
# evaluation
# ---------------------------------------------------------------------------


def _is_empty(iv) -> bool:
    return not (iv[0] <= iv[1])


def evaluate(core, op: str, args) -> tuple[float, float]:
    """The result of ``core`` for one case; empty inputs are handled here.

    The arithmetic of the cores assumes non-empty operands (the
    tracker tests emptiness after each intersection), so an empty operand of an
    arithmetic operation short-circuits to empty, as IEEE 1788 prescribes.
    The set operations accept empties and get them as they are.
    """
    name, arity, _ = OPS[op]
    ivs = args[:arity]
    fun = getattr(core, name)
    if name not in ("intersect", "hull") and any(_is_empty(iv) for iv in ivs):
        return EMPTY
    flat = [np.float64(b) for iv in ivs for b in iv]
    lo, hi = fun(*flat, *args[arity:])
    assert np.shape(lo) == () and np.shape(hi) == ()
    return float(lo), float(hi)


def check(case: Case, got) -> tuple[bool, bool]:
    """(sound, tightest) for one result."""
    el, eh = case.expected
    gl, gh = got
    if math.isnan(gl) or math.isnan(gh):
        return False, False
    if _is_empty(case.expected):
        return True, _is_empty(got)
    if _is_empty(got):
        return False, False
    sound = gl <= el and eh <= gh
    return sound, sound and gl == el and gh == eh


@pytest.fixture(scope="module")
def tightness_report(request):
    """Collects per-op counts; prints one summary table after the module."""
    report: dict[tuple[str, str], tuple[int, int]] = {}  # (core, op) -> counts
    yield report
    lines = []
    for name in sorted({c for c, _ in report}):
        rows = {op: v for (c, op), v in report.items() if c == name}
        lines.append(f"ITF1788 conformance of {name} (op: run / not tightest)")
        lines += [f"  {op:<13s} {n:5d} / {nt:4d}" for op, (n, nt) in sorted(rows.items())]
        tot = sum(n for n, _ in rows.values())
        lines.append(f"  {'total':<13s} {tot:5d} / {sum(nt for _, nt in rows.values()):4d}")
    tr = request.config.pluginmanager.getplugin("terminalreporter")
    cap = request.config.pluginmanager.getplugin("capturemanager")
    if tr is None or cap is None:
        print("\n".join(lines))
        return
    with cap.global_and_fixture_disabled():
        tr.write_line("")
        for ln in lines:
            tr.write_line(ln)


@pytest.mark.parametrize("op", sorted(OPS))
def test_itf1788_containment(core, op, tightness_report):
    cases = CASES.get(op, [])
    assert len(cases) >= EXPECTED_MIN[op], (
        f"only {len(cases)} ITF1788 cases of {op!r} found in {ITF_DIR} "
        f"(skipped: {dict((k, v) for k, v in SKIPPED.items() if k[0] == op)})"
    )
    unsound, loose = [], []
    for case in cases:
        got = evaluate(core, op, case.args)
        sound, tight = check(case, got)
        if not sound:
            unsound.append(f"{case.where}: {case.text}  -> got [{got[0]!r}, {got[1]!r}]")
        elif not tight:
            loose.append(case)
    tightness_report[core.__name__, op] = (len(cases), len(loose))
    print(f"{op}: {len(cases)} cases, {len(loose)} not tightest")
    assert not unsound, f"{len(unsound)} unsound results:\n" + "\n".join(unsound[:30])


@pytest.mark.parametrize("op", sorted(OPS))
def test_itf1788_batched_equals_scalar(core, op):
    """One vectorised call over all cases gives the per-case answers."""
    name, arity, has_int = OPS[op]
    groups: dict[tuple, list[Case]] = defaultdict(list)
    for c in CASES.get(op, []):
        if name in ("intersect", "hull") or not any(_is_empty(iv) for iv in c.args[:arity]):
            groups[c.args[arity:]].append(c)
    assert groups
    for extra, cases in groups.items():
        cols = [np.array([c.args[k][j] for c in cases]) for k in range(arity) for j in (0, 1)]
        lo, hi = getattr(core, name)(*cols, *extra)
        for c, l, h in zip(cases, lo, hi):
            want = evaluate(core, op, c.args)
            assert (l, h) == want or (np.isnan(l) and np.isnan(want[0])), c.where


def test_itf1788_literal_parser():
    assert parse_interval("[0X1.FFFFFFFFFFFFFP1023, infinity]") == (np.finfo(float).max, math.inf)
    assert parse_interval("[-0x1p-1074,+0x1P-1074]") == (-5e-324, 5e-324)
    # float(0.1) > 0.1 and float(0.3) < 0.3: the enclosure has the float on one side
    assert parse_interval("[0.1, 0.1]") == (math.nextafter(0.1, 0.0), 0.1)
    assert parse_interval("[0.3, 0.3]") == (0.3, math.nextafter(0.3, 1.0))
    assert parse_interval("[0.1, 0.3]") == (math.nextafter(0.1, 0.0), math.nextafter(0.3, 1.0))
    assert parse_interval("[1e400, infinity]") == (np.finfo(float).max, math.inf)
    assert parse_interval("[-1e-400, 1e-400]") == (-5e-324, 5e-324)
    assert parse_interval("[-0.0, +7]") == (0.0, 7.0)
    assert parse_interval("[0x123456789abcdef1p0,0x123456789abcdef1p0]") == (
        float.fromhex("0x123456789abcde00p0"), float.fromhex("0x123456789abcdf00p0"))
    assert parse_interval("[empty]") == EMPTY
    assert parse_interval("[entire]") == (-math.inf, math.inf)
    for bad in ("[nai]", "[1.0, 2.0]_com", "[empty]_trv"):
        with pytest.raises(Skip):
            parse_interval(bad)


def test_itf1788_total_count():
    total = sum(len(v) for v in CASES.values())
    assert total >= sum(EXPECTED_MIN.values())
