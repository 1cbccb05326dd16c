"""Wheel speeds sent in more than one message: joined at the trigger's instants, never with an old
speed (`frictiond.wheel_speed_join`), through the pipeline as accurate as from one message."""
from __future__ import annotations

import subprocess
import sys
from types import SimpleNamespace

import pytest
import yaml

from frictiond.codec import DecodedInput, InputMessage
from frictiond.config import ConfigError, load_config
from frictiond.evaluation import evaluate
from frictiond.frames import Frame
from frictiond.pipeline import Pipeline
from frictiond.replay import estimates_of
from frictiond.samples import Status
from frictiond.sim_frames import simulate_frames
from frictiond.wheel_speed_join import GAP_PERIODS, WheelSpeedJoin

from .conftest import REPO

REAR = ("wheel_speed_rl", "wheel_speed_rr")


def trigger(t: float, v: float = 30.0) -> DecodedInput:
    return DecodedInput(t, "FRONT", {"wheel_speed_fl": v, "wheel_speed_fr": v}, True)


def rear(t: float, v: float, **other: float) -> DecodedInput:
    return DecodedInput(t, "REAR", {"wheel_speed_rl": v, "wheel_speed_rr": v + 1.0, **other}, False)


def join(period_s: float = 0.01) -> WheelSpeedJoin:
    return WheelSpeedJoin("FRONT", {"REAR": REAR}, {"REAR": period_s})


def test_a_trigger_waits_for_the_partners_next_frame_and_gets_its_speeds_interpolated():
    j = join()
    assert j.push(rear(0.006, 10.0)) == []
    assert j.push(trigger(0.010)) == []          # the rear's speed at 0.010 is not known yet
    out = j.push(rear(0.016, 20.0))
    assert len(out) == 1 and out[0].is_trigger and out[0].time_s == 0.010 and out[0].message == "FRONT"
    assert out[0].values["wheel_speed_rl"] == pytest.approx(14.0)
    assert out[0].values["wheel_speed_rr"] == pytest.approx(15.0)
    assert out[0].values["wheel_speed_fl"] == 30.0
    # A partner frame at the trigger's own instant is taken as it is, at once.
    assert j.push(trigger(0.016))[0].values["wheel_speed_rl"] == 20.0


def test_other_messages_pass_at_once_and_a_partners_other_signals_without_its_wheels():
    j = join()
    accel = DecodedInput(0.001, "ACCEL", {"accel_long": -3.0}, False)
    assert j.push(accel) == [accel]
    out = j.push(rear(0.002, 10.0, yaw_rate=0.1))
    assert out == [DecodedInput(0.002, "REAR", {"yaw_rate": 0.1}, False)]


def test_a_silent_partner_stops_the_updates_and_none_gets_an_old_speed():
    j = join()
    speed = lambda t: 10.0 + 100.0 * t   # noqa: E731  (linear: interpolation is exact)
    rears = [0.002 + 0.01 * k for k in range(20) if not 0.045 < 0.002 + 0.01 * k < 0.15]   # silent 42-152 ms
    triggers = [0.005 + 0.01 * k for k in range(20)]
    events = sorted([(t, rear(t, speed(t))) for t in rears] + [(t, trigger(t)) for t in triggers], key=lambda e: e[0])
    released = [d for _, e in events for d in j.push(e)]
    times = [round(d.time_s, 3) for d in released]
    assert times == [0.005, 0.015, 0.025, 0.035] + [round(t, 3) for t in triggers if 0.15 < t < 0.192]
    assert j.dropped == 11   # 45 ... 145 ms: their rear neighbours are 110 ms apart
    for d in released:
        assert d.values["wheel_speed_rl"] == pytest.approx(speed(d.time_s))
    # A partner silent for good: the held triggers are dropped as the other inputs go on.
    for k in range(1, 40):
        assert j.push(trigger(0.2 + 0.01 * k)) == []
    assert j.dropped > 11 + 30


def test_a_partner_frame_out_of_order_goes_to_its_place():
    j = join()
    j.push(rear(0.000, 10.0))
    j.push(rear(0.020, 30.0))
    assert j.push(trigger(0.015))[0].values["wheel_speed_rl"] == pytest.approx(25.0)
    assert j.push(rear(0.010, 40.0)) == []   # late: it belongs between the two
    assert j.push(trigger(0.005))[0].values["wheel_speed_rl"] == pytest.approx(25.0)   # (10 + 40) / 2


def test_the_join_waits_no_longer_than_the_gap_allows():
    j = join(period_s=0.02)
    j.push(rear(0.000, 10.0))
    assert j.push(trigger(0.010)) == []
    # Other inputs go on; within 2.5 periods of the trigger it still waits for the rear frame ...
    assert j.push(DecodedInput(0.010 + GAP_PERIODS * 0.02 - 0.001, "ACCEL", {"accel_long": 0.0}, False))
    assert j.dropped == 0
    # ... past that, the rear is silent around it: dropped.
    j.push(DecodedInput(0.010 + GAP_PERIODS * 0.02 + 0.001, "ACCEL", {"accel_long": 0.0}, False))
    j.push(trigger(0.070))
    assert j.dropped == 1


def test_the_front_end_sees_one_wheel_message():
    messages = [InputMessage("FRONT", 1, 0.01, ("wheel_speed_fl", "wheel_speed_fr"), 8, False),
                InputMessage("REAR", 2, 0.01, ("wheel_speed_rl",), 8, False),
                InputMessage("MIXED", 3, 0.02, ("wheel_speed_rr", "yaw_rate"), 8, False)]
    seen = WheelSpeedJoin.front_end_messages(messages, "FRONT", {"REAR": ("wheel_speed_rl",), "MIXED": ("wheel_speed_rr",)})
    assert [(m.name, m.signals) for m in seen] == [
        ("FRONT", ("wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl", "wheel_speed_rr")), ("MIXED", ("yaw_rate",))]


# A car that sends its rear wheel speeds in a message of their own (big-endian, 4 bytes), at the
# same rate with its own phase: the project's DBC and config with WHEEL_SPEEDS split in two.
_REAR_SIGNALS = ''' SG_ WheelSpeed_RL : 32|16@1+ (0.01,0) [0|655.35] "rad/s" FRICTIOND
 SG_ WheelSpeed_RR : 48|16@1+ (0.01,0) [0|655.35] "rad/s" FRICTIOND
'''
_REAR_MESSAGE = '''
BO_ 177 WHEEL_SPEEDS_REAR: 4 VEHICLE
 SG_ WheelSpeed_RL : 7|16@0+ (0.01,0) [0|655.35] "rad/s" FRICTIOND
 SG_ WheelSpeed_RR : 23|16@0+ (0.01,0) [0|655.35] "rad/s" FRICTIOND
'''
DEFAULT = REPO / "config" / "frictiond.yaml"


@pytest.fixture(scope="module")
def split_config(tmp_path_factory):
    folder = tmp_path_factory.mktemp("split")
    dbc = (REPO / "dbc" / "frictiond.dbc").read_text()
    assert _REAR_SIGNALS in dbc
    dbc = dbc.replace(_REAR_SIGNALS, _REAR_MESSAGE).replace(
        'BA_ "GenMsgCycleTime" BO_ 176 10;', 'BA_ "GenMsgCycleTime" BO_ 176 10;\nBA_ "GenMsgCycleTime" BO_ 177 10;')
    (folder / "split.dbc").write_text(dbc)
    data = yaml.safe_load(DEFAULT.read_text())
    data["can"]["dbc"] = "split.dbc"
    for name in REAR:
        data["signals"][name]["message"] = "WHEEL_SPEEDS_REAR"
    path = folder / "split.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize("scenario", ["dry", "snow"])
def test_rear_wheel_speeds_apart_are_as_accurate_as_in_the_trigger(split_config, scenario):
    reports = {}
    for path in (DEFAULT, split_config):
        config = load_config(path)
        frames, sim = simulate_frames(config, scenario, seed=4)
        pipeline, estimates = estimates_of(config, frames)
        reports[path] = (evaluate(estimates, sim.truth.rows()), len(estimates), pipeline)
    (one, n_one, _), (two, n_two, pipeline) = reports[DEFAULT], reports[split_config]
    assert pipeline.wheel_join is not None and pipeline.wheel_join.dropped <= 1
    assert abs(n_two - n_one) <= 0.01 * n_one          # an update per wheel-speed frame, each recorded
    assert two.valid_share >= 0.95 and abs(two.mae - one.mae) < 0.005, (one.mae, two.mae)
    assert two.false_valid_count == 0


def test_a_silent_rear_message_stops_the_updates_and_the_tick_says_stale(split_config):
    config = load_config(split_config)
    frames, _ = simulate_frames(config, "dry", seed=2)
    rear_id = 177
    kept = [f for f in frames if not (f.can_id == rear_id and 2.0 <= f.time_s <= 2.5)]
    pipeline = Pipeline(config)
    times, stale = [], []
    pipeline.on_estimate = lambda e, _s: times.append(e.time_s)
    for f in kept:
        pipeline.process(f)
        if 2.2 <= f.time_s <= 2.21:
            pipeline.tick(f.time_s)
            stale.append(pipeline.last_estimate.status)
    # No update from a wheel-speed frame whose rear speeds are not known (none held at an old value).
    assert not [t for t in times if 2.0 + 0.01 * 2.5 < t < 2.5]
    assert stale and stale[-1] == Status.INPUT_STALE
    assert pipeline.wheel_join.dropped >= 45
    assert [t for t in times if t > 2.6], "updates resume with the rear message"


def test_check_config_names_where_the_rear_wheel_speeds_come_from(split_config):
    out = subprocess.run([sys.executable, "-m", "frictiond.cli.main", "check-config", str(split_config)],
                         capture_output=True, text=True, check=True).stdout
    assert "wheel_speed_rl, wheel_speed_rr from WHEEL_SPEEDS_REAR: interpolated" in out


def test_a_multiplexed_partner_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="multiplexed"):
        Pipeline(load_config(REPO / "tests" / "corpus" / "configs" / "wheel_speeds_partner_multiplexed.yaml"))


def test_the_replay_summary_and_the_daemon_status_name_the_silent_message(split_config, tmp_path):
    from frictiond.busio import LogWriter
    from frictiond.replay import replay_log

    config = load_config(split_config)
    frames, _ = simulate_frames(config, "dry", seed=2)
    log = tmp_path / "rear_silent.log"
    with LogWriter(log) as writer:
        writer.write_all(f for f in frames if not (f.can_id == 177 and 2.0 <= f.time_s <= 2.5))
    pipeline = Pipeline(config)
    summary = replay_log(pipeline, log)
    line = next(l for l in summary.format().splitlines() if l.startswith("unjoined"))
    assert f"{pipeline.wheel_join.dropped} wheel-speed frames gave no update" in line
    assert "WHEEL_SPEEDS_REAR silent around" in line and pipeline.wheel_join.dropped >= 45
    from frictiond.daemon_status import DaemonStatus

    status = SimpleNamespace(pipeline=pipeline, _fps=0.0, bus_down=False, bus=object(), bus_off=False,
                             stats=SimpleNamespace(flood_dropped=0, tx_dropped=0))
    assert "wheel-speed frames without WHEEL_SPEEDS_REAR" in DaemonStatus.status_text(status)


def test_a_corrupt_time_on_one_frame_holds_no_update_behind_it(split_config):
    """One frame stamped far in the future (any message, the rear one too), one stamped NaN: the
    join must not wait for the rear's frame 'after' the bogus one, nor take 'now' from it."""
    config = load_config(split_config)
    frames, _ = simulate_frames(config, "dry", seed=2)
    rears = [i for i, f in enumerate(frames) if f.can_id == 177]
    accels = [i for i, f in enumerate(frames) if f.can_id == 0xC0]
    corrupt = list(frames)
    for t, index in zip((1e12, float("nan"), 1e12, -1.0), (rears[50], rears[51], accels[300], rears[400])):
        corrupt[index] = corrupt[index]._replace(time_s=t)
    counts = {}
    for name, stream in (("clean", frames), ("corrupt", corrupt)):
        pipeline = Pipeline(config)
        for f in stream:
            pipeline.process(f)
        counts[name] = pipeline.stats.updates
    assert counts["corrupt"] >= counts["clean"] - 10, counts
