"""Property tests: hostile frames and samples never crash, never put NaN/inf on the bus."""
from __future__ import annotations

import math

import cantools
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from frictiond import faults
from frictiond.codec import DecodeFailure
from frictiond.config import parse_config
from frictiond.estimator import LugreTrustRegionEstimator
from frictiond.frames import Frame
from frictiond.pipeline import Pipeline
from frictiond.samples import PhysicalSample, Status
from frictiond.sim_frames import simulate_frames

from .conftest import REPO

DBC = cantools.database.load_file(str(REPO / "dbc" / "frictiond.dbc"))
INPUT_IDS = [0x0B0, 0x0C0, 0x0D0, 0x0E0, 0x0F0]
SETTINGS = settings(max_examples=150, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def truth_of(sim):
    rows = sim.truth.rows()
    t = np.array([r["time_s"] for r in rows])
    mu = np.array([r["mu_max"] for r in rows])
    return lambda time_s: float(mu[min(np.searchsorted(t, time_s), len(t) - 1)])


def recovered(outputs) -> bool:
    """Good data back, the estimator is too. `outputs`: (status, MuMax, the truth's μ_max) after
    the damage. VALID again; or, where the stop ends before the restarted fit's confidence regains
    VALID's threshold (a wheel's speeds lost for 0.5 s mid-stop: short of it two seconds later), the last
    outputs CONVERGING within 10 % of the truth, never held in FAULT or INPUT_STALE."""
    if any(status == Status.VALID for status, _, _ in outputs):
        return True
    last = outputs[-10:]
    return bool(last) and all(status == Status.CONVERGING and abs(mu - truth) <= 0.1 * truth
                              for status, mu, truth in last)


def check_outputs(frames):
    for f in frames:
        assert f.can_id in (0x3E0, 0x3E1) and len(f.data) == 8
        values = DBC.decode_message(f.can_id, f.data, decode_choices=False)
        assert all(math.isfinite(v) for v in values.values())
        if f.can_id == 0x3E0:
            assert 0 <= values["EstimatorStatus"] <= 5


payloads = st.binary(min_size=0, max_size=12)
markers = st.sampled_from([b"\xff" * 8, b"\x00" * 8, b"\xff\xff" * 4, b"\x7f\xff" * 4, b"\x80\x00" * 4])


@SETTINGS
@given(st.sampled_from(INPUT_IDS), st.one_of(payloads, markers))
def test_codec_decodes_or_refuses_with_a_reason(default_config, can_id, data):
    pipeline = Pipeline(default_config)
    try:
        decoded = pipeline.input_codec.decode(Frame(1.0, can_id, data))
    except DecodeFailure as exc:
        assert exc.reason in ("wrong length", "out of range", "undecodable", "not finite")
        return
    assert decoded is not None
    assert all(math.isfinite(v) for v in decoded.values.values())


frame_strategy = st.builds(
    Frame,
    time_s=st.one_of(st.floats(-1e6, 1e7, allow_nan=False), st.just(math.nan), st.just(math.inf)),
    can_id=st.one_of(st.sampled_from(INPUT_IDS), st.integers(0, 0x7FF), st.integers(0, 0x1FFFFFFF)),
    data=st.one_of(payloads, markers),
    is_extended=st.booleans(),
    is_error=st.booleans(),
    is_remote=st.booleans(),
)


@SETTINGS
@given(st.lists(frame_strategy, min_size=1, max_size=60))
def test_pipeline_survives_arbitrary_frames(default_config, frames):
    pipeline = Pipeline(default_config)
    for f in frames:
        check_outputs(pipeline.process(f))
    if all(math.isfinite(f.time_s) for f in frames):
        check_outputs(pipeline.tick(max(f.time_s for f in frames) + 1.0))


@settings(max_examples=15, deadline=None, derandomize=True, phases=[Phase.explicit, Phase.generate],
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.integers(0, 10_000), st.floats(-7200.0, 7200.0), st.integers(0, 2))
def test_real_drive_with_spliced_junk_and_time_jumps_recovers(default_config, seed, jump_s, mode):
    frames, sim = simulate_frames(default_config, "wet", seed=seed % 7)
    rng = np.random.default_rng(seed)
    cut = len(frames) // 3
    junk = []
    for _ in range(200):
        cid = int(rng.choice(INPUT_IDS))
        junk.append(Frame(frames[cut].time_s, cid, bytes(rng.integers(0, 256, int(rng.integers(0, 9))).tolist())))
    if mode == 0:   # time jumps (clock step), then continues
        tail = [f._replace(time_s=f.time_s + jump_s) for f in frames[cut:]]
    elif mode == 1:  # duplicated and reordered frames
        tail = list(frames[cut:])
        for k in range(0, len(tail) - 1, 17):
            tail[k], tail[k + 1] = tail[k + 1], tail[k]
        tail = [f for f in tail for _ in (0, 1)][: len(tail) + 300]
    else:           # a burst: the same frames again in one instant
        tail = [f._replace(time_s=frames[cut].time_s) for f in frames[cut:cut + 100]] + list(frames[cut:])
    pipeline = Pipeline(default_config)
    outputs = []
    truth = truth_of(sim)
    head = len(frames[:cut] + junk)
    for k, f in enumerate(frames[:cut] + junk + tail):
        out = pipeline.process(f)
        check_outputs(out)
        if out:
            e = pipeline.last_estimate
            t = e.time_s - jump_s if mode == 0 and k >= head else e.time_s
            outputs.append((e.status, e.mu_max, truth(t)))
            if e.status == Status.VALID:   # never a VALID estimate more than 20 % off
                assert abs(e.mu_max - truth(t)) <= 0.2 * truth(t), (e.time_s, e.mu_max, truth(t))
    statuses = [s for s, _, _ in outputs]
    assert Status.INIT in statuses or Status.NOT_EXCITED in statuses
    # good data returned after the damage: the estimator recovers by the end of the stop
    assert recovered(outputs[len(outputs) // 2:])


finite_or_not = st.one_of(st.floats(-1e9, 1e9, allow_nan=False), st.sampled_from([math.nan, math.inf, -math.inf]))
quad = st.tuples(finite_or_not, finite_or_not, finite_or_not, finite_or_not)


@SETTINGS
@given(st.lists(st.tuples(finite_or_not, quad, quad, st.tuples(*[st.booleans()] * 4)), min_size=1, max_size=40))
def test_estimator_never_reports_non_finite_numbers(rows):
    est = LugreTrustRegionEstimator()
    t = 0.0
    for speed, slip, mu, usable in rows:
        t += 0.01
        e = est.update(PhysicalSample(t, speed, slip, mu, (4000.0,) * 4, (0.0,) * 4, usable, True))
        assert e.status in Status.__members__.values()
        if e.status == Status.VALID:
            assert math.isfinite(e.mu_max) and math.isfinite(e.confidence)


# ------------------------------------------------------------------ signals at their raw extremes
_DRY: dict = {}


def dry_piece(config):
    """The first 2.8 s of a dry stop (braking starts inside): short enough for many examples,
    and long enough after the damage the tests put in it for an ABS stop's recovery (a wheel's
    speeds lost for 0.25 s: VALID again a second after them, within 10 % before that)."""
    if not _DRY:
        frames, sim = simulate_frames(config, "dry", seed=5)
        _DRY["frames"] = [f for f in frames if f.time_s < 2.8]
        _DRY["truth"] = truth_of(sim)
        _DRY["codec"] = Pipeline(config).input_codec
    return _DRY["frames"], _DRY["truth"], _DRY["codec"]


INPUT_NAMES = ["wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl", "wheel_speed_rr", "accel_long", "accel_lat",
               "brake_pressure_fl", "brake_pressure_fr", "brake_pressure_rl", "brake_pressure_rr", "yaw_rate",
               "vehicle_speed_ref"]


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.sampled_from(INPUT_NAMES), st.sampled_from(["all ones", "max", "min", "zero", "random"]),
       st.integers(0, 0xFFFF), st.floats(1.2, 2.2), st.floats(0.01, 0.5))
def test_signal_at_raw_extremes_and_invalid_markers(default_config, name, kind, rnd, start, length):
    frames, truth, codec = dry_piece(default_config)
    source = next(r for r in codec.resolved if r.name == name)
    signal = codec.db.get_message_by_name(source.message).get_signal_by_name(source.signal)
    low, high = (-(1 << (signal.length - 1)), (1 << (signal.length - 1)) - 1) if signal.is_signed \
        else (0, (1 << signal.length) - 1)
    raw = {"all ones": None, "max": high, "min": low, "zero": 0, "random": low + rnd % (high - low + 1)}[kind]
    damaged = faults.raw_signal(frames, codec, name, raw, start, start + length)
    pipeline, estimates, bad = faults.replay_on_bus(default_config, damaged)
    assert not bad
    for e in estimates:
        if e.status == Status.VALID:
            assert abs(e.mu_max - truth(e.time_s)) <= 0.2 * truth(e.time_s), (name, kind, e)
    # good data returns: the estimator recovers before the piece ends (when the damage ends early enough)
    if start + length < 2.2:
        assert recovered([(e.status, e.mu_max, truth(e.time_s)) for e in estimates if e.time_s > start + length + 0.25])


# ------------------------------------------------------------------ the front end, fed directly
hostile = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, -0.0, -1.0, -50.0, 1e308]))


@SETTINGS
@given(st.lists(st.tuples(st.sampled_from(["WHEEL_SPEEDS", "ACCELERATIONS", "BRAKE_PRESSURES", "VEHICLE_SPEED_REF",
                                           "WHEEL_DRIVE_TORQUE", "NO_SUCH"]),
                          st.floats(-1e4, 1e4, allow_nan=False), st.dictionaries(st.sampled_from(INPUT_NAMES), hostile,
                                                                                  max_size=6)),
                min_size=1, max_size=50))
def test_front_end_and_estimator_survive_any_values(default_config, pushes):
    """Values the codec would refuse (NaN, inf, negative speeds) reach the front end anyway: no
    exception, and whatever the estimator makes of them leaves the output codec finite."""
    pipeline = Pipeline(default_config)
    base = {n: 10.0 for n in INPUT_NAMES}
    t = 0.0
    for message, dt, values in pushes:
        t += dt * 1e-3
        result = pipeline.front_end.push(t, message, {**base, **values})
        if result is not None:
            check_outputs(pipeline._update(t, result))
    check_outputs(pipeline.tick(t + 1.0))


# ------------------------------------------------------------------ zero and reversed wheel speeds
@pytest.mark.parametrize("value", [0.0, -5.0, -60.0])
def test_zero_or_reversed_wheel_speeds_are_flagged_never_valid_wrong(default_config, value):
    """All four wheel speeds read `value` rad/s for 0.5 s while braking at ~20 m/s (negative:
    a reversing signal or a sign error)."""
    frames, sim = simulate_frames(default_config, "dry", seed=21)
    codec = Pipeline(default_config).input_codec
    raw = {}
    for r in codec.resolved:
        if r.name.startswith("wheel_speed"):
            sig = codec.db.get_message_by_name(r.message).get_signal_by_name(r.signal)
            raw[r.name] = round((value / r.factor - r.offset) / r.scale / sig.scale)
    damaged = frames
    for name, code in raw.items():
        if code < 0 and not codec.db.get_message_by_name("WHEEL_SPEEDS").get_signal_by_name(
                next(r.signal for r in codec.resolved if r.name == name)).is_signed:
            code = (1 << 16) + code        # the unsigned DBC signal: a reversed speed wraps to a huge code
        damaged = faults.raw_signal(damaged, codec, name, code, 2.0, 2.5)
    pipeline, estimates, bad = faults.replay_on_bus(default_config, damaged)
    assert not bad
    truth = truth_of(sim)
    assert all(abs(e.mu_max - truth(e.time_s)) <= 0.2 * truth(e.time_s) for e in estimates if e.status == Status.VALID)
    if value != 0.0:  # a negative (wrapped) code is out of range: FAULT while it lasts
        inside = [e.status for e in estimates if 2.05 <= e.time_s < 2.5]
        assert inside and all(s != Status.VALID for s in inside)
    assert recovered([(e.status, e.mu_max, truth(e.time_s)) for e in estimates if e.time_s > 3.0])


# ------------------------------------------------------------------ NaN/inf from scaling
def test_scaling_that_overflows_to_inf_is_refused_and_reported_stale(default_config, config_dict):
    """`scale: 1e308` passes the config check, but every decoded wheel speed overflows to inf:
    the codec refuses the frames ("not finite") and the status says INPUT_STALE."""
    config_dict["signals"]["wheel_speed_fl"] = {"message": "WHEEL_SPEEDS", "signal": "WheelSpeed_FL", "scale": 1e308}
    config = parse_config(config_dict, None)
    frames, _ = simulate_frames(default_config, "dry", seed=2)
    pipeline, estimates, bad = faults.replay_on_bus(config, frames)
    assert not bad
    assert pipeline.stats.undecodable["not finite"] > 0.9 * sum(f.can_id == 0x0B0 for f in frames)
    assert estimates and all(e.status in (Status.INPUT_STALE, Status.INIT) for e in estimates)
    assert sum(e.status == Status.INPUT_STALE for e in estimates) > 0.9 * len(estimates)


# ------------------------------------------------------------------ hostile frame streams, recovery
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.sampled_from(["dup", "reorder", "jump", "burst", "dlc"]), st.floats(1.3, 2.0), st.integers(0, 1000))
def test_hostile_streams_recover_accurately(default_config, kind, start, seed):
    frames, truth, codec = dry_piece(default_config)
    jump = 0.0
    if kind == "dup":
        damaged = faults.duplicate_frames(frames, 0.5, seed=seed, start_s=start, end_s=start + 0.3)
    elif kind == "reorder":
        damaged = faults.reorder_frames(frames, 0.5, seed=seed, start_s=start, end_s=start + 0.3)
    elif kind == "jump":
        jump = (-1) ** seed * 3600.0 * (1 + seed % 5)
        damaged = faults.time_jump(frames, start, jump)
    elif kind == "burst":
        damaged = faults.burst(frames, start, 50 + seed % 200)
    else:
        damaged = faults.wrong_dlc(frames, [0x0B0, 0x0C0, 0x0D0][seed % 3], seed % 9, start, start + 0.2)
    pipeline, estimates, bad = faults.replay_on_bus(default_config, damaged)
    assert not bad
    unshift = faults.FaultCase([], None, None, (start, jump) if jump else None).original_time
    for e in estimates:
        if e.status == Status.VALID:
            t = unshift(e.time_s)
            assert abs(e.mu_max - truth(t)) <= 0.2 * truth(t), (kind, e)
    assert recovered([(e.status, e.mu_max, truth(unshift(e.time_s))) for e in estimates if unshift(e.time_s) > 2.35])
