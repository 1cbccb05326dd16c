"""Fault-injection replays: each fault is flagged, and no VALID estimate is more than 20 % off."""
from __future__ import annotations

import numpy as np
import pytest

from frictiond import faults
from frictiond.daemon import RateGuard
from frictiond.pipeline import Pipeline
from frictiond.replay import estimates_of
from frictiond.samples import Status
from frictiond.sim_frames import simulate_frames


def run(config, frames):
    return estimates_of(config, frames)


def truth_lookup(sim):
    rows = sim.truth.rows()
    t = np.array([r["time_s"] for r in rows])
    mu = np.array([r["mu_max"] for r in rows])
    return lambda time_s: mu[min(np.searchsorted(t, time_s), len(t) - 1)]


def assert_no_false_valid(estimates, truth):
    bad = [(e.time_s, e.mu_max, truth(e.time_s)) for e in estimates
           if e.status == Status.VALID and abs(e.mu_max - truth(e.time_s)) > 0.2 * truth(e.time_s)]
    assert not bad, bad[:5]


@pytest.fixture(scope="module")
def dry(default_config):
    frames, sim = simulate_frames(default_config, "dry", seed=21)
    pipeline = Pipeline(default_config)
    return frames, sim, pipeline.input_codec


def flagged(estimates, t0, t1):
    """Inside [t0, t1): the status says something is wrong or the estimate is not trusted."""
    inside = [e for e in estimates if t0 <= e.time_s < t1]
    return inside and all(e.status != Status.VALID or e.confidence < 0.5 for e in inside[len(inside) // 4:])


@pytest.mark.parametrize("scenario", ["dry", "wet"])
def test_stuck_wheel_speed_sensor(default_config, scenario):
    frames, sim = simulate_frames(default_config, scenario, seed=1)
    codec = Pipeline(default_config).input_codec
    damaged = faults.stuck_wheel_speed(frames, codec, "FL", 2.0)
    pipeline, estimates = run(default_config, damaged)
    assert pipeline.stats.faults["wheel speed stuck"] > 20
    assert flagged(estimates, 2.3, 3.5)
    assert_no_false_valid(estimates, truth_lookup(sim))


def test_pressure_message_lost_for_a_second_is_input_stale(default_config, dry):
    frames, sim, codec = dry
    damaged = faults.drop_message(frames, 0x0D0, 2.0, 3.0)
    _, estimates = run(default_config, damaged)
    inside = [e.status for e in estimates if 2.06 <= e.time_s < 2.95]
    assert inside and all(s == Status.INPUT_STALE for s in inside)
    after = [e.status for e in estimates if e.time_s >= 3.3]
    assert Status.VALID in after or Status.CONVERGING in after   # recovers when it returns
    assert_no_false_valid(estimates, truth_lookup(sim))


def test_wheel_speeds_lost_is_input_stale_via_tick(default_config, dry):
    frames, sim, codec = dry
    pipeline = Pipeline(default_config)
    for f in frames:
        if f.time_s > 2.0:
            break
        pipeline.process(f)
    ticked = pipeline.tick(2.04)
    assert ticked and pipeline.last_estimate is not None
    out = pipeline.output_codec.decode_output(ticked[0])
    assert out["EstimatorStatus"] == "INPUT_STALE"


def test_pressure_stuck_at_zero_while_braking(default_config, dry):
    frames, sim, codec = dry
    damaged = faults.pressure_stuck_at_zero(frames, codec, 2.0)
    pipeline, estimates = run(default_config, damaged)
    inside = [e.status for e in estimates if 2.2 <= e.time_s < 3.5]
    assert inside and all(s == Status.FAULT for s in inside)
    assert pipeline.stats.faults["brake pressure implausible"] > 50
    assert_no_false_valid(estimates, truth_lookup(sim))


@pytest.mark.parametrize("offset", [-0.2, 0.2])
def test_accelerometer_offset(default_config, dry, offset):
    frames, sim, codec = dry
    damaged = faults.accel_offset(frames, codec, offset)
    _, estimates = run(default_config, damaged)
    assert_no_false_valid(estimates, truth_lookup(sim))
    assert sum(e.status == Status.VALID for e in estimates) > 50


def test_wheel_speed_spikes_are_faults_not_estimates(default_config, dry):
    frames, sim, codec = dry
    damaged = faults.wheel_speed_spikes(frames, codec, 0.03, seed=4)
    pipeline, estimates = run(default_config, damaged)
    assert pipeline.stats.faults["wheel speed glitch"] > 5
    assert_no_false_valid(estimates, truth_lookup(sim))


def test_spoofing_flood_is_bounded_and_flagged(default_config, dry):
    frames, sim, codec = dry
    damaged = faults.spoof_flood(frames, codec, 2.0, 2.5, rate_hz=10_000)
    # the daemon's guard admits at most max_update_rate trigger frames per second
    guard = RateGuard(default_config.daemon.max_update_rate)
    admitted = [f for f in damaged if f.can_id != codec.trigger_id or guard.allow(f.time_s)]
    triggers = [f for f in admitted if f.can_id == codec.trigger_id and 2.0 <= f.time_s < 2.5]
    assert len(triggers) <= default_config.daemon.max_update_rate * 0.5 + 20
    _, estimates = run(default_config, admitted)
    assert flagged(estimates, 2.1, 2.5)
    assert_no_false_valid(estimates, truth_lookup(sim))
