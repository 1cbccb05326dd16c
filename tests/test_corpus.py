"""The broken-config and broken-DBC corpus: every file gives exit 78 and one line naming the problem."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from frictiond.codec import validate_against_dbc
from frictiond.config import ConfigError, load_config

CORPUS = Path(__file__).resolve().parent / "corpus" / "configs"
FILES = sorted(CORPUS.glob("*.yaml"))


def expectation(path: Path) -> str:
    side = path.with_suffix(".expect")
    if side.exists():
        return side.read_text().strip()
    first = path.read_text(errors="replace").splitlines()[0]
    assert first.startswith("# expect: "), path
    return first[len("# expect: "):].strip()


def test_corpus_is_large():
    assert len(FILES) >= 40


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_library_names_the_problem(path):
    needle = expectation(path)
    with pytest.raises(ConfigError) as info:
        validate_against_dbc(load_config(path))
    message = str(info.value)
    assert needle in message, message
    assert "\n" not in message


@pytest.mark.parametrize("path", FILES[::5], ids=lambda p: p.stem)
@pytest.mark.parametrize("command", ["check-config", "replay"])
def test_cli_exits_78_with_one_line(tmp_path, path, command):
    args = [command, str(path)] if command == "check-config" else [command, str(tmp_path / "x.log"), "--config", str(path)]
    proc = subprocess.run([sys.executable, "-m", "frictiond.cli.main", *args], capture_output=True, text=True,
                          timeout=60, cwd=tmp_path)
    assert proc.returncode == 78, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and expectation(path) in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert not Path("/tmp/pwned").exists()
