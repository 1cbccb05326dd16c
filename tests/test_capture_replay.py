"""`frictiond replay` on real-bus-like captures: tens of thousands of frames, mostly unrelated IDs,
single-sample wheel-speed spikes, wrong lengths, extended IDs, error and remote frames (issue 6).

It must never crash, never report VALID from a glitch, and say what it skipped."""
from __future__ import annotations

import random
import subprocess
import sys

import can
import cantools
import numpy as np
import pytest

from frictiond.busio import LogWriter
from frictiond.config import load_config
from frictiond.frames import Frame
from frictiond.pipeline import Pipeline
from frictiond.replay import ReplayRecorder, replay_frames, replay_log
from frictiond.samples import Status
from frictiond.sim_frames import background_traffic, merge_frames, simulate_frames

from .conftest import REPO

EXAMPLE = REPO / "config" / "examples" / "saloon_x.yaml"
VEHICLE_DB = cantools.database.load_file(str(REPO / "dbc" / "examples" / "saloon_x.dbc"))
OUTPUT_DB = cantools.database.load_file(str(REPO / "dbc" / "frictiond.dbc"))
ESP_21 = VEHICLE_DB.get_message_by_name("ESP_21")
INPUT_IDS = {m.frame_id for m in VEHICLE_DB.messages if m.name in ("ESP_21", "ESP_02", "ESP_WhlPress")}


def spike(frame: Frame, rng: random.Random) -> Frame:
    """One wheel speed jumps for one sample; counter and the other fields stay as sent."""
    values = ESP_21.decode(frame.data, decode_choices=False)
    wheel = rng.choice(["WhlSpd_FL", "WhlSpd_FR", "WhlSpd_RL", "WhlSpd_RR"])
    if rng.random() < 0.2:
        values[wheel] = 327.67                       # the DBC's "invalid" code 0x7FFF
    else:
        values[wheel] = min(max(values[wheel] + rng.choice((-1, 1)) * rng.uniform(15.0, 80.0), 0.0), 327.0)
    return frame._replace(data=ESP_21.encode(values, strict=False))


def junk(t: float, rng: random.Random) -> Frame | None:
    r = rng.random()
    if r < 0.004:
        return Frame(t, rng.choice(sorted(INPUT_IDS)), rng.randbytes(rng.choice((0, 1, 3, 5, 7))))  # wrong length
    if r < 0.03:
        return Frame(t, rng.randrange(0x800, 1 << 29), rng.randbytes(8), is_extended=True)
    if r < 0.035:
        return Frame(t, 0x20000004, bytes(8), is_error=True)
    if r < 0.04:
        return Frame(t, rng.choice(sorted(INPUT_IDS) + [0x280]), b"", is_remote=True)
    return None


def capture(glitches: bool, seed: int = 9):
    """The same simulated drive with the same junk; with or without wheel-speed spikes."""
    config = load_config(EXAMPLE)
    frames, sim = simulate_frames(config, "wet", seed=seed)
    rng_junk, rng_spike = random.Random(3), random.Random(4)
    out = []
    for f in frames:
        spiked = rng_spike.random() < 0.02 and f.can_id == ESP_21.frame_id
        out.append(spike(f, rng_spike) if spiked and glitches else f)
        extra = junk(f.time_s, rng_junk)
        if extra is not None:
            out.append(extra)
    other = background_traffic(0.0, frames[-1].time_s, 8000, INPUT_IDS | {0x3E0, 0x3E1}, seed=2, n_ids=120)
    return list(merge_frames(out, other)), sim


def cli_replay(log, out):
    proc = subprocess.run([sys.executable, "-m", "frictiond.cli.main", "replay", str(log), "--config", str(EXAMPLE),
                           "--output", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    return proc.stdout


def valid_outputs(path):
    return [(m.timestamp, OUTPUT_DB.decode_message(0x3E0, m.data)["MuMax"]) for m in can.LogReader(str(path))
            if m.arbitration_id == 0x3E0 and OUTPUT_DB.decode_message(0x3E0, m.data, decode_choices=False)[
                "EstimatorStatus"] == int(Status.VALID)]


def errors_against_truth(valid, sim):
    rows = sim.truth.rows()
    t_truth = np.array([r["time_s"] for r in rows])
    mu_truth = np.array([r["mu_max"] for r in rows])
    idx = np.minimum(np.searchsorted(t_truth, [t for t, _ in valid]), len(t_truth) - 1)
    return np.abs(np.array([mu for _, mu in valid]) - mu_truth[idx]), mu_truth[idx]


def summary_count(summary: str, key: str) -> int:
    return int(next(line for line in summary.splitlines() if line.startswith(key))[len(key):].split()[0])


def test_capture_with_spikes_and_junk_through_the_cli(tmp_path):
    results = {}
    for glitches in (False, True):
        frames, sim = capture(glitches)
        log = tmp_path / f"capture_{glitches}.log"
        with LogWriter(log) as writer:
            writer.write_all(frames)
        summary = cli_replay(log, tmp_path / f"out_{glitches}.log")
        valid = valid_outputs(tmp_path / f"out_{glitches}.log")
        results[glitches] = (len(frames), summary, valid, sim)

    n, summary, valid, sim = results[True]
    assert n > 40_000
    assert summary_count(summary, "frames read") == n
    # What was skipped, by reason.
    assert summary_count(summary, "ignored frames") > 30_000
    ignored = next(line for line in summary.splitlines() if line.startswith("ignored frames"))
    assert "unrelated IDs" in ignored and "extended IDs" in ignored and "remote frames" in ignored
    assert summary_count(summary, "error frames") > 0
    undecodable = next(line for line in summary.splitlines() if line.startswith("undecodable"))
    assert "wrong length" in undecodable and "out of range" in undecodable
    assert summary_count(summary, "counter jumps") == 0     # spikes keep the alive counter
    assert "faults" in summary and "wheel speed glitch" in summary

    # Never VALID from a glitch: no VALID output more than 20 % off the truth.
    errors, truth = errors_against_truth(valid, sim)
    assert np.all(errors <= 0.2 * truth), float(np.max(errors / truth))
    # And the spikes cost little: most of the clean capture's VALID outputs remain.
    _, clean_summary, clean_valid, clean_sim = results[False]
    clean_errors, _ = errors_against_truth(clean_valid, clean_sim)
    assert len(clean_valid) > 200 and float(np.max(clean_errors)) < 0.1
    assert len(valid) >= 0.5 * len(clean_valid), (len(valid), len(clean_valid))
    # The same junk in both; only the spiked capture has invalid (0x7FFF) wheel speeds.
    clean_undecodable = next(line for line in clean_summary.splitlines() if line.startswith("undecodable"))
    assert "wrong length" in clean_undecodable and "out of range" not in clean_undecodable


class ListSink(list):
    write = list.append


@pytest.mark.parametrize("suffix", [".log", ".asc"])
def test_replaying_a_log_skips_unrelated_ids_unread_and_counts_them_the_same(tmp_path, suffix):
    frames, _ = capture(True)
    frames.insert(0, Frame(frames[0].time_s - 0.5, 0x456, b"\x01"))    # span from unrelated frames
    frames.append(Frame(frames[-1].time_s + 0.5, 0x457, b"\x02"))
    log = tmp_path / f"capture{suffix}"
    with LogWriter(log) as writer:
        writer.write_all(frames)
    config = load_config(EXAMPLE)
    every, every_out = Pipeline(config), ListSink()
    from frictiond.busio import read_log

    reference = replay_frames(every, read_log(log), every_out)
    pipeline, out = Pipeline(config), ListSink()
    summary = replay_log(pipeline, log, out)
    assert summary.stats == reference.stats and summary.stats.frames_read == len(frames)
    assert summary.stats.ignored["unrelated IDs"] > 30_000
    assert summary.format() == reference.format()
    assert (summary.first_time_s, summary.last_time_s) == (reference.first_time_s, reference.last_time_s)
    assert summary.last_time_s - summary.first_time_s == pytest.approx(frames[-1].time_s - frames[0].time_s, abs=1e-5)
    assert out == every_out and len(out) > 1000


def test_bit_flips_in_wheel_speed_frames_never_give_a_false_valid():
    config = load_config(EXAMPLE)
    frames, sim = simulate_frames(config, "snow", seed=9)
    rng = random.Random(3)
    noisy = []
    for f in frames:
        if f.can_id == ESP_21.frame_id and rng.random() < 0.02:
            data = bytearray(f.data)
            data[rng.randrange(1, 8)] ^= 1 << rng.randrange(0, 8)   # a corrupted bit the CRC missed
            f = f._replace(data=bytes(data))
        noisy.append(f)
    recorder = ReplayRecorder()
    summary = replay_frames(Pipeline(config), noisy, None, recorder)
    valid = [(e.time_s, e.mu_max) for e in recorder.estimates if e.status == Status.VALID]
    errors, truth = errors_against_truth(valid, sim)
    assert len(valid) > 100 and np.all(errors <= 0.2 * truth), float(np.max(errors / truth))
    assert summary.stats.frames_read == len(noisy)


@pytest.mark.parametrize("seed", [0, 1])
def test_random_garbage_on_every_id_never_crashes(seed):
    config = load_config(EXAMPLE)
    rng = random.Random(seed)
    ids = sorted(INPUT_IDS) + [0x3E0, 0x3E1, 0x000, 0x7FF]
    garbage = []
    for i in range(20_000):
        kind = rng.random()
        garbage.append(Frame(i * 1e-4, rng.choice(ids) if kind < 0.7 else rng.randrange(0, 1 << 29),
                             rng.randbytes(rng.randrange(0, 9)), is_extended=kind >= 0.7,
                             is_error=rng.random() < 0.01, is_remote=rng.random() < 0.01))
    recorder = ReplayRecorder()
    summary = replay_frames(Pipeline(config), garbage, None, recorder)
    assert summary.stats.frames_read == len(garbage)
    assert not any(e.status == Status.VALID for e in recorder.estimates)
    assert "undecodable" in summary.format()


@pytest.mark.parametrize("period_s", [0.025, 0.01])
def test_replay_summary_names_a_cycle_time_the_dbc_gets_wrong(default_config, period_s):
    from .vcan.synth import braking_frames

    frames = list(braking_frames(default_config, duration_s=3.0, period_s=period_s))
    summary = replay_frames(Pipeline(default_config), frames)
    assert summary.measured_trigger_period_s == pytest.approx(period_s, rel=0.02)
    text = summary.format()
    assert ("every 25.0 ms, the DBC says 10.0 ms" in text) == (period_s == 0.025)
    # time in status counts the frames as they came
    assert sum(summary.status_seconds().values()) == pytest.approx(summary.stats.updates * period_s, rel=0.02)
