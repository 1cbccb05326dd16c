from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

from frictiond.config import default_config_path, load_config

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def default_config():
    return load_config(default_config_path())


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
