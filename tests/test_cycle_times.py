"""Cycle times the DBC does not give: measured from the first frames, the front end rebuilt with
them (`frictiond.cycle_times`), as accurate as with the DBC's own."""
from __future__ import annotations

import random
import re

import pytest
import yaml

from frictiond.busio import LogWriter
from frictiond.config import load_config
from frictiond.cycle_times import FRAMES_TO_MEASURE, CycleTimeProbe
from frictiond.evaluation import evaluate
from frictiond.pipeline import Pipeline
from frictiond.replay import estimates_of, replay_log
from frictiond.sim_frames import simulate_frames

from .conftest import REPO

DEFAULT = REPO / "config" / "frictiond.yaml"


def test_the_probe_measures_each_message_seen_and_waits_for_none_unseen():
    probe = CycleTimeProbe({"WHEELS": 0.01, "ACCEL": 0.01, "SPEED_REF": 0.01})
    jitter = random.Random(3)
    result = None
    for k in range(FRAMES_TO_MEASURE):
        assert result is None
        probe.see("ACCEL", 0.003 + 0.01 * k)                  # as assumed
        result = probe.see("WHEELS", 0.02 * k + jitter.uniform(-0.001, 0.001))   # 20 ms, jittered
    assert result == {"WHEELS": 0.02}                          # SPEED_REF never came: not waited for


def _config(tmp_path, cycle_ms: int | None):
    """The project's config and DBC with the three main inputs at `cycle_ms` (None: no
    GenMsgCycleTime for any input)."""
    dbc = (REPO / "dbc" / "frictiond.dbc").read_text()
    for frame_id in (176, 192, 208, 224, 240):
        line = f'BA_ "GenMsgCycleTime" BO_ {frame_id} 10;\n'
        assert line in dbc
        keep = cycle_ms is not None and (frame_id > 208 or cycle_ms == 10)
        new = line if keep else (f'BA_ "GenMsgCycleTime" BO_ {frame_id} {cycle_ms};\n' if cycle_ms else "")
        dbc = dbc.replace(line, new)
    name = f"car{cycle_ms}"
    (tmp_path / f"{name}.dbc").write_text(dbc)
    data = yaml.safe_load(DEFAULT.read_text())
    data["can"]["dbc"] = f"{name}.dbc"
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_config(path)


@pytest.mark.parametrize("scenario", ["dry", "wet"])
def test_a_dbc_without_cycle_times_at_50_hz_is_as_accurate_as_one_that_gives_them(tmp_path, scenario):
    declared, silent = _config(tmp_path, 20), _config(tmp_path, None)
    frames, sim = simulate_frames(declared, scenario, seed=3)
    reports = {}
    for config in (declared, silent):
        pipeline, estimates = estimates_of(config, frames)
        reports[config is silent] = evaluate(estimates, sim.truth.rows()), pipeline
    (one, p_declared), (two, p_silent) = reports[False], reports[True]
    assert p_declared.measured_cycle_times == {}
    assert p_silent.measured_cycle_times == {"WHEEL_SPEEDS": 0.02, "ACCELERATIONS": 0.02, "BRAKE_PRESSURES": 0.02}
    assert p_silent.front_end.sample_period_s == pytest.approx(0.02)
    assert two.valid_share >= one.valid_share - 0.03 and abs(two.mae - one.mae) < 0.003, (one, two)


def test_at_the_assumed_rate_nothing_is_rebuilt_and_the_summary_says_what_was_measured(tmp_path):
    silent = _config(tmp_path, None)
    frames, _ = simulate_frames(load_config(DEFAULT), "dry", seed=1)    # 100 Hz, as assumed
    pipeline = Pipeline(silent)
    front_end = pipeline.front_end
    for f in frames:
        pipeline.process(f)
    assert pipeline.measured_cycle_times == {} and pipeline.front_end is front_end
    frames, _ = simulate_frames(_config(tmp_path, 20), "dry", seed=1)
    log = tmp_path / "fifty.log"
    with LogWriter(log) as writer:
        writer.write_all(frames)
    text = replay_log(Pipeline(silent), log).format()
    assert re.search(r"cycle times .*ACCELERATIONS 20 ms, BRAKE_PRESSURES 20 ms, WHEEL_SPEEDS 20 ms", text)


def test_frames_of_messages_with_a_cycle_time_do_not_count_and_never_break_the_probe():
    probe = CycleTimeProbe({"ACCEL": 0.01})
    assert probe.see("WHEELS", 0.0) is None          # (first: a message the DBC gives a cycle for)
    for k in range(FRAMES_TO_MEASURE):
        result = probe.see("ACCEL", 0.02 * k)
    assert result == {"ACCEL": 0.02}


def test_the_front_end_rebuilt_at_the_measured_cycle_keeps_what_coasting_showed(tmp_path):
    # The accelerometer's offset coasting shows (`BodyEquation._learn_rolling_offset`) is the
    # sensor's, whatever period its samples were first taken at: the rebuild after the first
    # frames carries it over, and at the brakes both configs know it from the same coasting.
    declared, silent = _config(tmp_path, 20), _config(tmp_path, None)
    frames, _ = simulate_frames(declared, "wet", seed=3)
    at_brakes = {}
    for config in (declared, silent):
        pipeline = Pipeline(config)
        for f in frames:
            pipeline.process(f)
            if pipeline.last_sample is not None and pipeline.last_sample.braking:
                break
        fe = pipeline.front_end
        at_brakes[config is silent] = (fe._rolling_offset_samples, fe.rolling_offset_prior())
    assert pipeline.measured_cycle_times          # (the silent config's front end was rebuilt)
    (n_declared, (mean_declared, _)), (n_silent, (mean_silent, _)) = at_brakes[False], at_brakes[True]
    # (a few are lost while the rebuilt front end fills its derivative window; without the carry, 16 more)
    assert n_declared > 20 and n_declared - 10 <= n_silent <= n_declared
    assert mean_silent == pytest.approx(mean_declared, abs=0.01)
