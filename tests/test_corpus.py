"""The broken-config and broken-DBC corpus: every file gives exit 78 and one line naming the problem.

Each file under corpus/configs starts with `# expect: NEEDLE -- what is wrong`: NEEDLE is the key or
word the error message must contain (a `.expect` sidecar holds the line for files that cannot
carry a comment). corpus/dbc/README.md says what is wrong with each broken DBC; the configs that
use them name the expected error. All files go through the library; a subset through the CLI
(`check-config` and `replay`, as subprocesses) to keep the run short.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from frictiond.codec import validate_against_dbc
from frictiond.config import MAX_CONFIG_BYTES, ConfigError, load_config

from .conftest import REPO, write_config

CORPUS = Path(__file__).resolve().parent / "corpus"
FILES = sorted((CORPUS / "configs").glob("*.yaml"))
DBCS = sorted((CORPUS / "dbc").glob("*.dbc"))

# Corpus files that still crash instead of exiting 78 (none at present; an entry marks a strict xfail).
KNOWN_BUGS: dict[str, str] = {}


def header(path: Path) -> tuple[str, str]:
    """(needle, what is wrong) from the first line or the .expect sidecar."""
    side = path.with_suffix(".expect")
    if side.exists():
        line = side.read_text().strip()
    else:
        first = path.read_text(errors="replace").splitlines()[0]
        assert first.startswith("# expect: "), path
        line = first[len("# expect: "):].strip()
    needle, _, what = line.partition(" -- ")
    return needle.strip(), what.strip()


def expectation(path: Path) -> str:
    return header(path)[0]


def param(path: Path, **kw):
    marks = [pytest.mark.xfail(strict=True, reason=KNOWN_BUGS[path.stem])] if path.stem in KNOWN_BUGS else []
    return pytest.param(path, id=path.stem, marks=marks, **kw)


def test_corpus_is_large_and_described():
    assert len(FILES) >= 80 and len(DBCS) >= 12
    for path in FILES:
        needle, what = header(path)
        assert needle and what, f"{path.name}: first line must be '# expect: NEEDLE -- what is wrong'"
    readme = (CORPUS / "dbc" / "README.md").read_text()
    used = "\n".join(p.read_text(errors="replace") for p in FILES)
    for dbc in DBCS:
        assert f"`{dbc.name}`" in readme, f"{dbc.name} not described in corpus/dbc/README.md"
        assert f"../dbc/{dbc.name}" in used, f"{dbc.name} used by no corpus config"


@pytest.mark.parametrize("path", [param(p) for p in FILES])
def test_library_names_the_problem(path):
    needle = expectation(path)
    with pytest.raises(ConfigError) as info:
        validate_against_dbc(load_config(path))
    message = str(info.value)
    assert needle in message, message
    assert "\n" not in message and len(message) < 1000


# Every file through the CLI entry point in-process (fast); a subset as real subprocesses.
SUBPROCESS_FILES = sorted({*FILES[::9], *(p for p in FILES if p.stem in KNOWN_BUGS)})


def run_cli(tmp_path: Path, command: str, config: Path) -> subprocess.CompletedProcess:
    args = [command, str(config)] if command == "check-config" else [command, str(tmp_path / "x.log"), "--config", str(config)]
    return subprocess.run([sys.executable, "-m", "frictiond.cli.main", *args], capture_output=True, text=True,
                          timeout=60, cwd=tmp_path)


def assert_one_line_78(proc: subprocess.CompletedProcess, needle: str) -> None:
    assert "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert proc.returncode == 78, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], proc.stderr
    assert lines[0].startswith("frictiond: config error: ")


@pytest.mark.parametrize("path", [param(p) for p in FILES])
@pytest.mark.parametrize("command", ["check-config", "replay"])
def test_cli_main_exits_78_with_one_line(tmp_path, capsys, monkeypatch, path, command):
    from frictiond.cli.main import main

    monkeypatch.chdir(tmp_path)
    args = [command, str(path)] if command == "check-config" else [command, str(tmp_path / "x.log"), "--config", str(path)]
    try:
        code = main(args)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert_one_line_78(subprocess.CompletedProcess(args, code, "", err), expectation(path))


@pytest.mark.parametrize("path", [param(p) for p in SUBPROCESS_FILES])
@pytest.mark.parametrize("command", ["check-config", "replay"])
def test_cli_exits_78_with_one_line(tmp_path, path, command):
    proc = run_cli(tmp_path, command, path)
    assert_one_line_78(proc, expectation(path))
    assert not Path("/tmp/pwned").exists()       # yaml_python_object tries `touch /tmp/pwned`


# ------------------------------------------------------------------ unreadable and oversized files
def test_config_path_missing_or_a_directory(tmp_path):
    for path, needle in ((tmp_path / "nope.yaml", "no such config file"), (tmp_path, "is a directory")):
        with pytest.raises(ConfigError, match=needle):
            load_config(path)


def test_config_larger_than_limit_is_refused_before_parsing(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_text("# padding\n" * (MAX_CONFIG_BYTES // 10 + 10))
    with pytest.raises(ConfigError, match="larger than"):
        load_config(path)
    assert_one_line_78(run_cli(tmp_path, "check-config", path), "larger than")


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files whatever their mode")
def test_unreadable_config_and_dbc(tmp_path, config_dict):
    cfg = write_config(tmp_path, config_dict)
    cfg.chmod(0)
    with pytest.raises(ConfigError, match="cannot read config"):
        load_config(cfg)
    cfg.chmod(0o644)
    dbc = tmp_path / "in.dbc"
    dbc.write_bytes(Path(config_dict["can"]["dbc"]).read_bytes())
    dbc.chmod(0)
    config_dict["can"]["dbc"] = str(dbc)
    with pytest.raises(ConfigError, match="cannot read DBC"):
        validate_against_dbc(load_config(write_config(tmp_path, config_dict)))


def test_unreadable_file_behind_a_fifo_name_does_not_hang(tmp_path, config_dict):
    """A DBC path that is a FIFO (nothing will ever write) must be refused, not block start-up."""
    fifo = tmp_path / "in.dbc"
    os.mkfifo(fifo)
    config_dict["can"]["dbc"] = str(fifo)
    with pytest.raises(ConfigError, match="can.dbc"):
        load_config(write_config(tmp_path, config_dict))


def test_config_that_is_a_fifo_does_not_hang(tmp_path):
    fifo = tmp_path / "cfg.yaml"
    os.mkfifo(fifo)
    proc = subprocess.run([sys.executable, "-m", "frictiond.cli.main", "check-config", str(fifo)],
                          capture_output=True, text=True, timeout=8, cwd=tmp_path)
    assert_one_line_78(proc, "cfg.yaml")


# ------------------------------------------------------------------ generated hostile YAML
@pytest.mark.parametrize("text,needle", [
    pytest.param("a: " + "{b: " * 3000 + "1" + "}" * 3000, "nested too deeply", id="deep-mappings"),
    pytest.param("\n".join(f"k{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9 if i else ["x"] * 9) + "]" for i in range(12)),
                 "too large", id="wide-bomb"),
    pytest.param("can: !!binary aGVsbG8=\nvehicle: {}\nsignals: {}\n", "can: must be a mapping", id="binary-tag"),
    pytest.param("can: !!set {a, b}\nvehicle: {}\nsignals: {}\n", "can: must be a mapping", id="set-tag"),
    pytest.param("can: !!python/object/new:os.system [touch /tmp/pwned]\n", "invalid YAML", id="python-new"),
    pytest.param("%YAML 9.9\n---\na: 1\n", "invalid YAML", id="yaml-version"),
    pytest.param("\ufeffcan: 1\nvehicle: {}\nsignals: {}\n", "can: must be a mapping", id="bom"),
    pytest.param("can: \x00\x01\x02\n", "invalid YAML", id="control-chars"),
])
def test_generated_hostile_yaml(tmp_path, text, needle):
    path = tmp_path / "cfg.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert needle in str(info.value) and "\n" not in str(info.value)
    assert not Path("/tmp/pwned").exists()


def test_corpus_configs_are_otherwise_the_valid_default(config_dict):
    """Sanity of the corpus itself: the base every broken file starts from is a good config."""
    base = (CORPUS / "configs" / "negative_mass.yaml").read_text().replace("mass: -1500", "mass: 1500.0")
    data = yaml.safe_load(base)
    data["can"]["dbc"] = str(REPO / "dbc" / "frictiond.dbc")
    assert re.search(r"mass: 1500", base)
    from frictiond.config import parse_config
    validate_against_dbc(parse_config(data, None))
