"""The README's examples run as written (doc examples are tests).

Python blocks run in order in one namespace; the shell block of "Checking a
recorded trajectory" runs in a scratch folder with ``crosscert`` standing for
``python -m crosscert`` of this interpreter.
"""

import re
import subprocess
import sys
from pathlib import Path

from problems import DEFAULT_CERTIFICATION, check_certified_speed

README = Path(__file__).resolve().parents[1] / "README.md"


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README.read_text(), flags=re.S)


def test_the_python_examples_run(capsys):
    blocks = _blocks("python")
    assert len(blocks) >= 3
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(README), "exec"), namespace)
    out = capsys.readouterr().out
    assert "mode-changed" in out
    cert = namespace["cert"]
    expected = DEFAULT_CERTIFICATION["dextar"]
    check_certified_speed(cert.v_min, expected)
    assert abs(cert.refutation_bound - expected.refutation_bound) < 1e-3


def test_the_recording_commands_run(tmp_path):
    section = README.read_text().split("## Checking a recorded trajectory", 1)[1]
    block = re.search(r"```sh\n(.*?)```", section, flags=re.S).group(1)
    cli = f"{sys.executable} -m crosscert"
    for line in block.strip().splitlines():
        command = re.sub(r"\bcrosscert\b", cli, line.split("  #")[0].strip())
        done = subprocess.run(command, shell=True, cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, (line, done.stderr)
    assert (tmp_path / "crossing.csv").is_file() and (tmp_path / "boxes.png").is_file()
