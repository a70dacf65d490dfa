"""benchmarks/figures.py rewrites only its block of benchmarks/README.md (no timing is measured here)."""

import stat
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import figures  # noqa: E402


def test_the_block_is_replaced_and_the_rest_and_the_mode_kept(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(f"# head\n\n{figures.BEGIN}\nold figures\n{figures.END}\n\n## tail\n")
    readme.chmod(0o640)
    info = {"date": "2026-12-07", "cpu": "AMD EPYC", "cores": 2, "commit": "abc1234", "python": "3.11",
            "numba": "0.68"}
    text = figures.render([("a figure", "1.0 s", "`reproduce`")], info, (0.1, 0.2), 60.0)
    figures.write_block(text, readme)
    new = readme.read_text()
    assert new.startswith("# head\n\n") and new.endswith("\n\n## tail\n") and "old figures" not in new
    assert "| a figure | 1.0 s | `reproduce` |" in new and "AMD EPYC, 2 cores" in new and "commit abc1234" in new
    assert stat.S_IMODE(readme.stat().st_mode) == 0o640


def test_a_file_without_markers_or_not_regular_is_refused(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("no markers\n")
    with pytest.raises(SystemExit, match="markers"):
        figures.write_block("x", readme)
    link = tmp_path / "link.md"
    link.symlink_to(readme)
    with pytest.raises(SystemExit, match="not a regular file"):
        figures.write_block("x", link)
    assert readme.read_text() == "no markers\n"
