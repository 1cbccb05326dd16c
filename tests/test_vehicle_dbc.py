"""Bring your own car: a production-style DBC through the config alone (issue 6)."""
from __future__ import annotations

import dataclasses
import random
import subprocess
import sys

import numpy as np
import pytest

from frictiond.codec import validate_against_dbc
from frictiond.config import ConfigError, load_config
from frictiond.evaluation import evaluate
from frictiond.frames import Frame
from frictiond.pipeline import Pipeline
from frictiond.replay import ReplayRecorder, replay_frames
from frictiond.samples import Status
from frictiond.sim_frames import background_traffic, frames_per_second_for_load, merge_frames, simulate_frames

from .conftest import REPO, write_config

EXAMPLE = REPO / "config" / "examples" / "saloon_x.yaml"
MASTER = REPO / "config" / "examples" / "saloon_x_master_cylinder.yaml"
DEFAULT = REPO / "config" / "frictiond.yaml"


def replay(config, frames):
    recorder = ReplayRecorder()
    pipeline = Pipeline(config)
    summary = replay_frames(pipeline, frames, None, recorder)
    return pipeline, summary, recorder


@pytest.mark.parametrize("scenario", ["dry", "wet", "snow"])
def test_example_car_is_as_accurate_as_the_default_layout(scenario):
    results = {}
    for path in (EXAMPLE, DEFAULT):
        config = load_config(path)
        frames, sim = simulate_frames(config, scenario, seed=4)
        ids = {f.can_id for f in frames}
        other = background_traffic(0.0, frames[-1].time_s, frames_per_second_for_load(0.5), ids | {0x3E0, 0x3E1}, seed=1)
        pipeline, summary, recorder = replay(config, list(merge_frames(frames, other)))
        assert summary.stats.undecodable_total == 0
        report = evaluate(recorder.estimates, sim.truth.rows())
        results[path] = report
        truth = {round(r["time_s"], 2): r["mu_max"] for r in sim.truth.rows()}
        for e in recorder.estimates:
            if e.status == Status.VALID:
                t = min(truth, key=lambda k: abs(k - e.time_s)) if round(e.time_s, 2) not in truth else round(e.time_s, 2)
                assert abs(e.mu_max - truth[t]) < 0.1
    ex, de = results[EXAMPLE], results[DEFAULT]
    assert ex.valid_share >= 0.8
    # Wheel pressures at 50 Hz (multiplexed) instead of 100 Hz cost a little: within 0.05.
    assert ex.mae <= 0.08 and abs(ex.mae - de.mae) < 0.05, (ex.mae, de.mae)


def test_example_input_counters_are_checked():
    config = load_config(EXAMPLE)
    frames, _ = simulate_frames(config, "dry", seed=1)
    pipeline, _, _ = replay(config, frames)
    assert pipeline.input_codec.counter_jumps == 0
    # Lose two wheel-speed frames and repeat one: the alive counter shows it.
    trigger = pipeline.input_codec.trigger_id
    idx = [i for i, f in enumerate(frames) if f.can_id == trigger]
    damaged = [f for i, f in enumerate(frames) if i not in (idx[100], idx[101])]
    damaged.insert(idx[200], frames[idx[200]])
    pipeline, _, _ = replay(config, damaged)
    assert pipeline.input_codec.counter_jumps >= 2


def test_check_config_names_every_mapping():
    proc = subprocess.run([sys.executable, "-m", "frictiond.cli.main", "check-config", str(EXAMPLE)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    for text in ("ESP_21", "WhlSpd_FL", "km/h", "ESP_LongDecel", "×-1", "ESP_LatAccel", "×9.80665",
                 "WhlPress_RR mux [3]", "deg/s", "100 Hz", "vehicle_speed_ref", "absent: optional", "OK"):
        assert text in out, text


def test_master_cylinder_split_by_axle_factors():
    config = load_config(MASTER)
    codec, _ = validate_against_dbc(config)
    db_msg = codec.db.get_message_by_name("BRK_01")
    data = db_msg.encode({"BRK_01_Chksum": 0, "BRK_01_Counter": 1, "MasterCylPressure": 800, "BrakePedalSwitch": 1})
    values = codec.decode(Frame(0.0, db_msg.frame_id, data)).values
    assert values["brake_pressure_fl"] == pytest.approx(80.0)
    assert values["brake_pressure_rr"] == pytest.approx(56.0)


def test_lenient_dbc_and_several_files(tmp_path, config_dict):
    # An overlapping signal: cantools refuses it strictly, accepts it with strict=False.
    extra = tmp_path / "extra.dbc"
    extra.write_text(
        'VERSION ""\n\nNS_ :\n\nBS_:\n\nBU_: X\n\n'
        "BO_ 1536 ODD: 2 X\n SG_ A : 0|12@1+ (1,0) [0|4095] \"\" X\n SG_ B : 8|8@1+ (1,0) [0|255] \"\" X\n\n")
    config_dict["can"]["dbc"] = [config_dict["can"]["dbc"], str(extra)]
    config_dict["can"]["dbc_strict"] = True
    with pytest.raises(ConfigError, match="extra.dbc"):
        validate_against_dbc(load_config(write_config(tmp_path, config_dict)))
    config_dict["can"]["dbc_strict"] = False
    config = load_config(write_config(tmp_path, config_dict))
    codec, _ = validate_against_dbc(config)
    assert "ODD" in {m.name for m in codec.db.messages}


def test_capture_with_glitches_and_junk_never_gives_a_false_valid():
    config = load_config(EXAMPLE)
    frames, sim = simulate_frames(config, "wet", seed=9)
    rng = random.Random(3)
    trigger = next(m.frame_id for m in Pipeline(config).input_codec.input_messages() if m.name == "ESP_21")
    noisy = []
    for f in frames:
        if f.can_id == trigger and rng.random() < 0.02:
            # single-sample spike on one wheel: flip high bits of a wheel-speed field
            data = bytearray(f.data)
            data[rng.randrange(1, 8)] ^= 0x40
            f = f._replace(data=bytes(data))
        noisy.append(f)
        r = rng.random()
        if r < 0.01:
            noisy.append(Frame(f.time_s, trigger, bytes(rng.randrange(0, 7))))          # wrong length
        elif r < 0.02:
            noisy.append(Frame(f.time_s, 0x1FFFF0A0, bytes(8), is_extended=True))    # extended ID
        elif r < 0.025:
            noisy.append(Frame(f.time_s, 0x20000004, bytes(8), is_error=True))        # error frame
        elif r < 0.03:
            noisy.append(Frame(f.time_s, 0x101, b"", is_remote=True))                 # remote frame
    other = background_traffic(0.0, frames[-1].time_s, 20000, {trigger, 0x101, 0x106, 0x1B5, 0x3E0, 0x3E1}, seed=2)
    capture = list(merge_frames(noisy, other))
    assert len(capture) > 50_000
    pipeline, summary, recorder = replay(config, capture)
    stats = summary.stats
    assert stats.undecodable_total > 0 and stats.error_frames > 0 and stats.ignored_frames > 50_000
    text = summary.format()
    assert "undecodable" in text and "wrong length" in text
    rows = sim.truth.rows()
    t_truth = np.array([r["time_s"] for r in rows])
    mu_truth = np.array([r["mu_max"] for r in rows])
    for e in recorder.estimates:
        if e.status == Status.VALID:
            truth = mu_truth[min(np.searchsorted(t_truth, e.time_s), len(t_truth) - 1)]
            assert abs(e.mu_max - truth) <= 0.2 * truth
    assert sum(e.status == Status.VALID for e in recorder.estimates) > 100
