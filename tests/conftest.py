from __future__ import annotations

import dataclasses

import copy
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest
import yaml

from frictiond.config import default_config_path, load_config

REPO = Path(__file__).resolve().parents[1]


def load_benchmark(name: str) -> ModuleType:
    """`benchmarks/<name>.py` as a module (the scripts are not a package), registered in
    `sys.modules` under `<name>_bench` (dataclasses look their module up there)."""
    spec = importlib.util.spec_from_file_location(f"{name}_bench", REPO / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def default_config():
    return load_config(default_config_path())


@pytest.fixture(scope="session")
def level_config(default_config):
    """The default config told that the roads are level (`FrontEndOptions.level_road`), as the
    built-in simulator's scenarios are unless given a grade: free rolling then teaches the
    accelerometer's own offset."""
    return dataclasses.replace(default_config, frontend=dataclasses.replace(default_config.frontend, level_road=True))


@pytest.fixture
def config_dict():
    """The default config as a plain dict, with the DBC path made absolute (for writing elsewhere)."""
    data = yaml.safe_load(default_config_path().read_text())
    data = copy.deepcopy(data)
    data["can"]["dbc"] = str(default_config_path().parent / "frictiond.dbc")
    return data


def write_config(tmp_path: Path, data, name: str = "cfg.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return path


def edited_dbc(tmp_path: Path, *edits: tuple[str, str]) -> Path:
    """The project's DBC with each (old, new) edit made at old's first place (old must be there),
    written under tmp_path: a vehicle's variant of the output messages."""
    text = (REPO / "dbc" / "frictiond.dbc").read_text()
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)
    path = tmp_path / "out.dbc"
    path.write_text(text)
    return path


def assert_each_refused(call, good: list, wrongs, errors=TypeError) -> None:
    """A compiled function's own argument checks (METH_FASTCALL): `call(*good)` with one argument
    at a time replaced, as (index, wrong value) in `wrongs`, raises one of `errors`; without its
    last argument, a TypeError that names the count."""
    with pytest.raises(TypeError, match=f"{len(good)} arguments"):
        call(*good[:-1])
    for k, wrong in wrongs:
        bad = list(good)
        bad[k] = wrong
        with pytest.raises(errors):
            call(*bad)
