"""docs/robots.md's example robot runs as written and validates (doc examples are tests)."""

import re
from pathlib import Path

DOC = Path(__file__).resolve().parents[1] / "docs" / "robots.md"


def test_the_example_robot_validates(capsys):
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    assert len(blocks) == 1
    namespace: dict = {}
    exec(compile(blocks[0], str(DOC), "exec"), namespace)
    assert namespace["report"].ok
    out = capsys.readouterr().out
    assert "mode-convention: passed" in out and "interval-containment: passed" in out
