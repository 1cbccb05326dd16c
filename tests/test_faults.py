"""Fault-injection replays: each fault is flagged, and no VALID estimate is more than 20 % off.

Every fault of `frictiond.faults.standard_faults` is injected into simulated stops and replayed
the way the daemon drives the pipeline (`process` per frame, `tick` as time passes); the outputs
are judged as a receiver sees them, decoded off the bus.
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest

from frictiond import faults
from frictiond.daemon import RateGuard
from frictiond.frames import Frame
from frictiond.pipeline import Pipeline
from frictiond.replay import estimates_of
from frictiond.samples import Status
from frictiond.sim_frames import simulate_frames

SCENARIOS = ("dry", "wet")
DRIVES: dict = {}


def truth_lookup(sim):
    rows = sim.truth.rows()
    t = np.array([r["time_s"] for r in rows])
    mu = np.array([r["mu_max"] for r in rows])
    return lambda time_s: float(mu[min(np.searchsorted(t, time_s), len(t) - 1)])


def drive(config, scenario, seed=1):
    key = (scenario, seed)
    if key not in DRIVES:
        frames, sim = simulate_frames(config, scenario, seed=seed)
        codec = Pipeline(config).input_codec
        cases = faults.standard_faults(frames, codec, seed=seed,
                                       rate_guard=lambda: RateGuard(config.daemon.max_update_rate).allow)
        DRIVES[key] = (frames, sim, codec, cases)
    return DRIVES[key]


REPLAYS: dict = {}


def replayed(config, scenario, name):
    key = (scenario, name)
    if key not in REPLAYS:
        _, sim, _, cases = drive(config, scenario)
        REPLAYS[key] = (sim, cases[name], *faults.replay_on_bus(config, cases[name].frames))
    return REPLAYS[key]


def false_valid(estimates, truth, case=None):
    out = []
    for e in estimates:
        if e.status != Status.VALID:
            continue
        mu = truth(case.original_time(e.time_s) if case is not None else e.time_s)
        if abs(e.mu_max - mu) > 0.2 * mu:
            out.append((e.time_s, e.mu_max, mu))
    return out


def flagged_share(estimates, t0, t1):
    """Share of estimates in [t0, t1) whose status or confidence says the input is not right."""
    inside = [e for e in estimates if t0 <= e.time_s < t1]
    if not inside:
        return 0.0
    return sum(e.status != Status.VALID or e.confidence < 0.5 for e in inside) / len(inside)


DETECTED_ELSEWHERE = {
    # faults the estimate may tolerate; the pipeline's own counters must still have seen them
    # (each glitch is counted once, when it is confirmed and repaired: issue 21)
    "wheel-speed spikes 3 %": lambda p: p.stats.faults["wheel speed glitch"] >= 8,
    "duplicated frames 30 %": lambda p: p.front_end.skipped_triggers > 50,
    "reordered frames 10 %": lambda p: True,     # tolerated: neighbours swap, nothing to flag
    "burst of 200 frames": lambda p: True,
    "clock jumps back 3 h": lambda p: True,
    "clock jumps ahead 5 h": lambda p: True,
    # an offset is indistinguishable from road grade, so not a status; the front end learns it
    # (and removes it) while rolling free — a stop gives it ~1.5 s of its 3 s time constant
    "accelerometer offset +0.3": lambda p: p.front_end.accel_bias_mps2 > 0.08,
    "accelerometer offset -0.5": lambda p: p.front_end.accel_bias_mps2 < -0.1,
}

BUGS: dict[str, str] = {}

# The names of faults.standard_faults, in order (checked against it below).
CASE_NAMES = ["stuck wheel speed", "dead wheel speed (reads 0)", "wheel speed 0xFFFF marker", "pressures lost 1 s",
              "accelerations lost 1 s", "wheel speeds lost 1 s", "pressure stuck at zero", "pressure 0xFFFF marker",
              "accel 0x8000 marker", "accelerometer offset +0.3", "accelerometer offset -0.5",
              "wheel-speed spikes 3 %", "wheel speeds wrong DLC", "pressures wrong DLC", "duplicated frames 30 %",
              "reordered frames 10 %", "clock jumps back 3 h", "clock jumps ahead 5 h", "burst of 200 frames",
              "spoofing flood 10 kHz"]


def test_case_list_is_the_standard_set(default_config):
    _, _, _, cases = drive(default_config, "dry")
    assert list(cases) == CASE_NAMES


@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("name", CASE_NAMES)
def test_fault_never_crashes_never_lies(default_config, scenario, name):
    """No exception, every output finite, no VALID estimate more than 20 % off the truth."""
    sim, case, pipeline, estimates, bad = replayed(default_config, scenario, name)
    assert not bad
    assert not false_valid(estimates, truth_lookup(sim), case)[:5]
    # good data returns after the fault window: the estimate is trusted again (or, for a fault
    # that lasts to the end of the drive, keeps saying what is wrong)
    tail = [e.status for e in estimates if case.original_time(e.time_s) > 3.6]
    assert tail
    if name in ("stuck wheel speed", "pressure stuck at zero"):
        assert all(s == Status.FAULT for s in tail)
    elif name not in BUGS:
        assert Status.VALID in tail or Status.CONVERGING in tail, (name, tail[-5:])


@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=BUGS[n])) if n in BUGS
                                  else n for n in CASE_NAMES])
def test_fault_is_detected(default_config, scenario, name):
    sim, case, pipeline, estimates, _ = replayed(default_config, scenario, name)
    if case.flag_from is not None:
        share = flagged_share(estimates, case.flag_from, case.flag_until)
        assert share >= 0.95, f"{name}: only {share:.0%} of outputs in the fault window flag it"
    else:
        assert DETECTED_ELSEWHERE[name](pipeline), (name, pipeline.stats)


def test_dead_wheel_speed_estimate_is_still_accurate(default_config):
    """Even undetected (see the xfail above), a dead sensor must not produce a false VALID."""
    frames, sim, codec, _ = drive(default_config, "dry")
    damaged = faults.wheel_speed_zero(frames, codec, "FL", 0.3)
    _, estimates, bad = faults.replay_on_bus(default_config, damaged)
    assert not bad and not false_valid(estimates, truth_lookup(sim))


def test_statuses_name_the_fault(default_config):
    """A lost message is INPUT_STALE; implausible or out-of-range values are FAULT."""
    expect = {
        "pressures lost 1 s": Status.INPUT_STALE, "accelerations lost 1 s": Status.INPUT_STALE,
        "wheel speeds lost 1 s": Status.INPUT_STALE, "wheel speeds wrong DLC": Status.INPUT_STALE,
        "pressures wrong DLC": Status.INPUT_STALE, "pressure stuck at zero": Status.FAULT,
        "wheel speed 0xFFFF marker": Status.FAULT, "pressure 0xFFFF marker": Status.FAULT,
        "accel 0x8000 marker": Status.FAULT, "stuck wheel speed": Status.FAULT,
        "spoofing flood 10 kHz": Status.FAULT,
    }
    for name, status in expect.items():
        _, case, _, estimates, _ = replayed(default_config, "dry", name)
        inside = [e.status for e in estimates if case.flag_from <= e.time_s < case.flag_until]
        assert inside and inside.count(status) >= 0.9 * len(inside), (name, set(inside))


def test_wrong_dlc_is_counted_as_wrong_length(default_config):
    _, _, pipeline, _, _ = replayed(default_config, "dry", "pressures wrong DLC")
    assert pipeline.stats.undecodable["wrong length"] >= 90


@pytest.mark.parametrize("wheel", ["FL", "RR"])
def test_stuck_wheel_speed_in_every_scenario_position(default_config, wheel):
    frames, sim, codec, _ = drive(default_config, "wet")
    damaged = faults.stuck_wheel_speed(frames, codec, wheel, 1.5)
    pipeline, estimates = estimates_of(default_config, damaged)
    assert pipeline.stats.faults["wheel speed stuck"] > 20
    assert not false_valid(estimates, truth_lookup(sim))


def test_surface_change_between_stops_gives_no_false_valid(default_config):
    """Clean input, no fault at all: a wet stop, then a dry stop (the gap does not matter)."""
    wet, _ = simulate_frames(default_config, "wet", seed=1)
    dry, dry_sim = simulate_frames(default_config, "dry", seed=1)
    base = wet[-1].time_s + 20.0
    stream = list(wet) + [f._replace(time_s=f.time_s + base) for f in dry]
    _, estimates = estimates_of(default_config, stream)
    truth = truth_lookup(dry_sim)
    bad = [(e.time_s - base, e.mu_max, truth(e.time_s - base)) for e in estimates if e.time_s > base
           and e.status == Status.VALID and abs(e.mu_max - truth(e.time_s - base)) > 0.2 * truth(e.time_s - base)]
    assert not bad, bad[:3]


def test_stops_in_a_row_each_with_a_fault(default_config):
    """Several dry stops on one pipeline, 100 s apart, clock stepping between, a fault in each."""
    pipeline = Pipeline(default_config)
    injectors = ["stuck wheel speed", "pressures lost 1 s", "spoofing flood 10 kHz", "pressure stuck at zero",
                 "clock jumps back 3 h", "wheel speed 0xFFFF marker", "duplicated frames 30 %", "clock jumps ahead 5 h"]
    offset = 0.0
    wrong = valid = 0
    for k, name in enumerate(injectors):
        frames, sim, codec, cases = drive(default_config, "dry")
        case = cases[name]
        base = offset + 100.0
        stream = [f._replace(time_s=f.time_s + base) for f in case.frames]
        _, estimates, bad = faults.replay_on_bus(default_config, stream, pipeline=pipeline)
        assert not bad
        truth = truth_lookup(sim)
        for e in estimates:
            if e.status == Status.VALID:
                valid += 1
                mu = truth(case.original_time(e.time_s - base))
                wrong += abs(e.mu_max - mu) > 0.2 * mu
        offset = max(stream[-1].time_s, base + 10.0)
    assert wrong == 0
    assert valid > 300


# ------------------------------------------------------------------ flood: bounded update rate
def test_pipeline_alone_processes_every_trigger(default_config):
    """Without the daemon's guard the pipeline decodes every spoofed trigger frame (and flags it)."""
    frames, sim, codec, _ = drive(default_config, "dry")
    flood = faults.spoof_flood(frames, codec, 2.0, 2.5, rate_hz=10_000)
    triggers = sum(f.can_id == codec.trigger_id for f in flood)
    pipeline, estimates, bad = faults.replay_on_bus(default_config, flood)
    assert not bad
    assert pipeline.stats.input_frames == len(flood)
    assert pipeline.stats.updates + pipeline.front_end.skipped_triggers >= triggers - 5
    assert flagged_share(estimates, 2.1, 2.5) >= 0.95
    assert not false_valid(estimates, truth_lookup(sim))


@pytest.mark.parametrize("rate_hz", [10_000.0, 50_000.0])
def test_rate_guard_bounds_updates_whatever_the_flood(default_config, rate_hz):
    limit = default_config.daemon.max_update_rate
    guard = RateGuard(limit)
    n = int(rate_hz * 2.0)
    admitted = sum(guard.allow(100.0 + k / rate_hz) for k in range(n))
    assert admitted <= limit * 2.0 + guard.burst + 1
    assert guard.dropped == n - admitted


def test_rate_guard_cannot_be_refilled_by_clock_jumps():
    """A spoofer stamping frames hours ahead (or back) gains at most one burst per jump."""
    guard = RateGuard(250.0)
    admitted = 0
    t = 0.0
    for k in range(20_000):
        t += 1e-4
        jump = 3600.0 if k % 1000 == 0 else (-7200.0 if k % 1000 == 500 else 0.0)
        t += jump
        admitted += guard.allow(t)
    # 2 s of frame time (ignoring the jumps) at 250 Hz, plus one burst per jump (40 jumps)
    assert admitted <= 250.0 * 2.0 + 41 * guard.burst + 1


def test_rate_guard_ignores_nan_and_inf_time():
    guard = RateGuard(250.0)
    allowed = [guard.allow(t) for t in [0.0, math.nan, math.inf, -math.inf, 1.0] + [1.0] * 100]
    assert sum(allowed) <= 2 * guard.burst + 2


def test_flood_cpu_is_bounded_by_the_guard(default_config):
    """What the guard admits from a 10 kHz flood costs about as much as the normal traffic."""
    frames, sim, codec, _ = drive(default_config, "dry")
    start = time.process_time()
    estimates_of(default_config, frames)
    normal = time.process_time() - start
    flood = faults.spoof_flood(frames, codec, 0.0, frames[-1].time_s, rate_hz=10_000)
    guard = RateGuard(default_config.daemon.max_update_rate)
    admitted = [f for f in flood if f.can_id != codec.trigger_id or guard.allow(f.time_s)]
    triggers_in = sum(f.can_id == codec.trigger_id for f in admitted)
    triggers_normal = sum(f.can_id == codec.trigger_id for f in frames)
    assert triggers_in <= default_config.daemon.max_update_rate * frames[-1].time_s + guard.burst + 1
    start = time.process_time()
    estimates_of(default_config, admitted)
    guarded = time.process_time() - start
    assert guarded < 3.0 * normal * max(1.0, triggers_in / triggers_normal) + 0.5


@pytest.mark.parametrize("level", [True, False])
def test_long_stop_with_many_faults(default_config, level_config, level):
    """One long stop (snow, 8 s) with faults one after another, then recovery: VALID again where
    the front end knows the road is level (on snow the accelerometer's offset is otherwise a tenth
    of the brakes' torque it cannot tell from their gain, and the estimate stays CONVERGING)."""
    default_config = level_config if level else default_config
    frames, sim = simulate_frames(default_config, "snow", seed=3)
    codec = Pipeline(default_config).input_codec
    damaged = faults.drop_message(frames, 0x0D0, 1.0, 1.5)
    damaged = faults.spoof_flood(damaged, codec, 2.0, 2.3, rate_hz=10_000, seed=3)
    guard = RateGuard(default_config.daemon.max_update_rate)
    damaged = [f for f in damaged if f.can_id != codec.trigger_id or guard.allow(f.time_s)]
    damaged = faults.raw_signal(damaged, codec, "wheel_speed_rl", None, 3.0, 3.4)
    damaged = faults.duplicate_frames(damaged, 0.3, seed=3, start_s=3.5, end_s=4.5)
    damaged = faults.wrong_dlc(damaged, 0x0C0, 2, 4.6, 5.0)
    damaged = faults.reorder_frames(damaged, 0.2, seed=3, start_s=5.0, end_s=5.5)
    damaged = faults.time_jump(damaged, 5.6, -3 * 3600.0)
    pipeline, estimates, bad = faults.replay_on_bus(default_config, damaged)
    assert not bad
    truth = truth_lookup(sim)
    unshift = faults.FaultCase([], None, None, (5.6, -3 * 3600.0)).original_time
    assert not false_valid(estimates, lambda t: truth(unshift(t)))
    for t0, t1 in ((1.06, 1.45), (2.1, 2.3), (3.1, 3.4), (4.66, 4.95)):
        assert flagged_share(estimates, t0, t1) >= 0.9, (t0, t1)
    tail = [e.status for e in estimates if e.time_s < 0 and unshift(e.time_s) > 6.5]
    # (a third of it: after the clock step the window restarts, and its confidence regains
    # VALID's threshold a second later)
    assert tail and (tail.count(Status.VALID) > 0.25 * len(tail) or not level)


@pytest.mark.parametrize("level", [True, False])
@pytest.mark.parametrize("factor", [0.5, 2.5])
@pytest.mark.parametrize("scenario", ["dry", "snow", "ice"])
def test_brake_pressures_off_by_a_factor_are_a_fault_not_an_estimate(default_config, level_config, scenario, factor,
                                                                     level):
    # The brake-gain check cannot absorb a factor of 2: the body equation disagrees with the
    # pressures for most of the braking, which must show as FAULT, never as a VALID μ. Except
    # halved pressures on ice: at 0.4 m/s² the brakes give ~160 N·m, and the gain limits with
    # the accelerometer's and the pressures' offsets and a 5 m/s wind's drag explain up to about
    # a factor of 2 there. The disagreement is seen only while the ABS's cycles carry it further
    # out, too briefly for a FAULT, and the estimate stays short of VALID. Where the roads are not
    # known to be level, an accelerometer offset within the sensor's tolerance (0.3 m/s²) is not
    # known either, and on snow and ice that explains the factor too: no FAULT is owed there, but
    # still no VALID.
    default_config = level_config if level else default_config
    frames, sim = simulate_frames(default_config, scenario, seed=2)
    pipeline = Pipeline(default_config)
    _, estimates, bad = faults.replay_on_bus(default_config, faults.pressure_scaled(frames, pipeline.input_codec, factor),
                                             pipeline=pipeline)
    assert not bad
    assert not [e for e in estimates if e.status == Status.VALID]
    if not level and scenario != "dry":
        return
    least = 10 if (scenario, factor) == ("ice", 0.5) else 100
    assert pipeline.stats.faults["brake pressure disagrees with deceleration"] > least
    if (scenario, factor) != ("ice", 0.5):
        assert Status.FAULT in {e.status for e in estimates}


def test_a_head_wind_on_ice_is_weather_not_a_pressure_fault():
    # Campaign stop 360 with its sensors made ideal: a slip-controlled stop from 139 km/h, snow
    # then ice, brakes 13-15 % stronger than configured, a 5 m/s head wind the config knows
    # nothing of. On the ice the wind's drag is a large share of the tyres' force, and the body
    # equation needed more torque than the pressures gave, beyond the gain limits: FAULT for
    # 58 outputs of a normal emergency stop.
    from frictiond.campaign.draw import draw_stop
    from frictiond.campaign.simulate import simulate_stop

    # (on level ground, with the front end told so, as it was found: the grades came later)
    spec = dataclasses.replace(draw_stop(360, None, clean_sensors=True), grade=0.0)
    assert spec.wind_mps > 4.5 and spec.surfaces[-1].label == "ice"
    stop = simulate_stop(spec)
    config = stop.config("lugre-tr")
    pipeline = Pipeline(dataclasses.replace(config, frontend=dataclasses.replace(config.frontend, level_road=True)))
    statuses = [pipeline.last_estimate.status for frame in stop.frames if pipeline.process(frame)]
    assert Status.FAULT not in statuses and statuses.count(Status.VALID) > 300
