"""A campaign stop as files: the candump log, its DBC, the frictiond YAML config of each
estimator, the truth CSV and the draw; what `frictiond replay` needs to reproduce it."""
from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import yaml

from ..busio import LogWriter
from .score import ESTIMATORS
from .simulate import CampaignStop, config_data

DBC_NAME = "campaign.dbc"


def write_stop_files(stop: CampaignStop, directory: Path | str) -> dict[str, Path]:
    """Writes stop.log, campaign.dbc, frictiond-<kind>.yaml per estimator, truth.csv and
    spec.json into `directory` (created); returns the paths by role."""
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {"log": folder / "stop.log", "dbc": folder / DBC_NAME, "truth": folder / "truth.csv",
                              "spec": folder / "spec.json"}
    paths["dbc"].write_text(stop.dbc_path.read_text())
    for kind in ESTIMATORS.values():
        path = folder / f"frictiond-{kind}.yaml"
        header = (f"# campaign stop {stop.spec.seed} ({stop.spec.family}), the car as configured;\n"
                  f"# the truth differs (brake gains, payload): see spec.json\n")
        path.write_text(header + yaml.safe_dump(config_data(stop.spec, DBC_NAME, kind), sort_keys=False))
        paths[kind] = path
    with LogWriter(paths["log"]) as writer:
        writer.write_all(stop.frames)
    with open(paths["truth"], "w", newline="") as fh:
        writer_csv = csv.DictWriter(fh, fieldnames=list(stop.truth[0]))
        writer_csv.writeheader()
        writer_csv.writerows({k: f"{v:.6g}" for k, v in row.items()} for row in stop.truth)
    paths["spec"].write_text(json.dumps(dataclasses.asdict(stop.spec), indent=1, default=float) + "\n")
    return paths


def replay_commands(paths: dict[str, Path]) -> list[str]:
    return [f"frictiond replay {paths['log']} --config {paths[kind]} --truth {paths['truth']}"
            for kind in ESTIMATORS.values()]
