"""The scripts in docs/examples run as documented.

``test_slow_sweep_bounds_quick`` runs ``docs/examples/sweep_bounds.py --quick``
in a subprocess (about a minute on 2 cores: four certifications at
tol 0.05 m/s): under the ``slow`` marker, run by ``pytest -m slow``.
"""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "docs" / "examples" / "sweep_bounds.py"

ROW = re.compile(r"^\|\s*([0-9.]+)\s*\|\s*([0-9.]+)\s*\|(.*)\|\s*$")


@pytest.mark.slow
def test_slow_sweep_bounds_quick(tmp_path):
    """docs/examples/sweep_bounds.py --quick end to end (about a minute on 2 cores: under the slow marker)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    env["MPLBACKEND"] = "Agg"
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), "--quick", "--out", str(tmp_path), "--workers", "2"],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr

    png = tmp_path / "sweep_bounds.png"
    assert png.exists() and png.stat().st_size > 10_000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # the table: header with the two width columns, one row per a_max of the quick mode
    lines = proc.stdout.splitlines()
    header = [ln for ln in lines if ln.startswith("| a_max")]
    assert len(header) == 1 and "x1 (m/s)" in header[0] and "x2 (m/s)" in header[0], proc.stdout
    rows = {}
    for ln in lines:
        m = ROW.match(ln)
        if m:
            rows[float(m.group(1))] = (float(m.group(2)), [c.strip() for c in m.group(3).split("|")])
    assert sorted(rows) == [65.0, 100.0], proc.stdout
    for a, (a_peak, cells) in rows.items():
        assert a_peak == min(60.0, a)
        assert len(cells) == 2
        for c in cells:
            assert c == "none" or 0.6 <= float(c) <= 2.0, proc.stdout
        # the paper's calibration box certifies the benchmark crossing at these bounds
        assert cells[0] != "none", proc.stdout

    data = json.loads((tmp_path / "sweep_bounds.json").read_text())
    assert len(data["cases"]) == 4 and not any(c["error"] for c in data["cases"])
    # a looser acceleration hypothesis costs speed (measured 2026-11-25: 1.187 -> 1.481 m/s)
    v = {c["a_max"]: c["v_min"] for c in data["cases"] if c["width"] == 1.0}
    assert v[100.0] >= v[65.0] - 0.05
