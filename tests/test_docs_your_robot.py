"""docs/your-robot.md runs as written: its Python block, then its shell block through the real command line
(``planner.cli.main`` in this process), in a folder holding the example robot file as ``five_bar.py``."""

import re
import shlex
import shutil
from pathlib import Path

from crosscert.planner.cli import main

DOCS = Path(__file__).resolve().parents[1] / "docs"
PAGE = DOCS / "your-robot.md"


def test_the_page_runs_from_the_robot_file(tmp_path, monkeypatch, capsys):
    shutil.copy(DOCS / "examples" / "five_bar.py", tmp_path / "five_bar.py")
    monkeypatch.chdir(tmp_path)
    text = PAGE.read_text()
    (python,) = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    namespace: dict = {}
    exec(compile(python, str(PAGE), "exec"), namespace)
    out = capsys.readouterr().out
    assert out.startswith(f"file {tmp_path / 'five_bar.py'}:FIVE_BAR\n")
    assert "[0.         0.10897247] [ 0. -1.]" in out

    (shell,) = re.findall(r"```sh\n(.*?)```", text, flags=re.S)
    outputs = []
    for line in shell.strip().splitlines():
        program, *argv = shlex.split(line.split("  #")[0])
        assert program == "crosscert"
        assert main(argv) == 0, (line, capsys.readouterr().err)
        outputs.append(capsys.readouterr().out)
    assert "five-bar-250: every check passed" in outputs[0]
    assert "(singular sample 366; start 50.0 mm before the locus)" in outputs[1]  # as the page says
    assert outputs[2].startswith("verdict: mode-changed\n")
    assert (tmp_path / "five-bar-quick" / "certificate.json").is_file()
