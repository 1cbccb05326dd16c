"""simulate → log file → replay → output log → decode with dbc/frictiond.dbc, through the CLI."""
from __future__ import annotations

import subprocess
import sys

import cantools
import can
import numpy as np
import pytest

from frictiond.e2e import e2e_crc
from frictiond.replay import read_truth_csv

from .conftest import REPO

DBC = cantools.database.load_file(str(REPO / "dbc" / "frictiond.dbc"))


def cli(*args, cwd):
    proc = subprocess.run([sys.executable, "-m", "frictiond.cli.main", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def decode_estimates(path):
    out = []
    for msg in can.LogReader(str(path)):
        if msg.arbitration_id == 0x3E0:
            out.append((msg.timestamp, bytes(msg.data), DBC.decode_message(0x3E0, msg.data, decode_choices=False)))
    return out


@pytest.mark.parametrize("scenario,suffix", [("dry", ".log"), ("wet", ".blf"), ("snow", ".asc")])
def test_simulate_replay_decode_is_valid_and_accurate(tmp_path, scenario, suffix):
    log = tmp_path / f"in{suffix}"
    out = tmp_path / f"out{suffix}"
    truth = tmp_path / "truth.csv"
    cli("simulate", "--scenario", scenario, "--output", str(log), "--truth", str(truth), "--seed", "11", cwd=tmp_path)
    summary = cli("replay", str(log), "--output", str(out), cwd=tmp_path)
    assert "updates" in summary and "final estimate" in summary
    frames = decode_estimates(out)
    assert len(frames) > 200
    counters = [d["Counter"] for _, _, d in frames]
    assert all((b - a) % 16 == 1 for a, b in zip(counters, counters[1:]))
    assert all(d["Crc"] == e2e_crc(0x3E0, data) for _, data, d in frames)
    rows = read_truth_csv(truth)
    t_truth = np.array([r["time_s"] for r in rows])
    mu_truth = np.array([r["mu_max"] for r in rows])
    valid = [(t, d["MuMax"]) for t, _, d in frames if d["EstimatorStatus"] == 3]
    assert len(valid) > 100, f"only {len(valid)} VALID outputs"
    errors = [abs(mu - mu_truth[min(np.searchsorted(t_truth, t), len(t_truth) - 1)]) for t, mu in valid]
    # Every VALID estimate lies within 0.1 of the simulator's truth.
    assert max(errors) < 0.1, f"max error {max(errors):.3f}"


def test_replay_ignores_foreign_frames_and_counts_bad_ones(tmp_path):
    log = tmp_path / "in.log"
    cli("simulate", "--scenario", "dry", "--output", str(log), "--seed", "3", "--background-load", "0.3", cwd=tmp_path)
    # Append damaged input frames: short wheel-speed frames and a wrong-length pressure frame.
    with open(log, "a") as fh:
        fh.write("(99.000000) can0 0B0#0102\n(99.001000) can0 0D0#01020304\n(99.002000) can0 0B0#\n")
    summary = cli("replay", str(log), "--output", str(tmp_path / "out.log"), cwd=tmp_path)
    assert "undecodable       3" in summary
    ignored = int(next(line for line in summary.splitlines() if line.startswith("ignored")).split()[2])
    assert ignored > 1000
