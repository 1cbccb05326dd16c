"""Wheel-speed inputs held until the pressures and acceleration have caught up (`trigger_hold`)."""
from __future__ import annotations

import dataclasses

import numpy as np

from frictiond.codec import DecodedInput
from frictiond.trigger_hold import TriggerHold


def wheel(t: float) -> DecodedInput:
    return DecodedInput(t, "WHEEL_SPEEDS", {"wheel_speed_fl": 50.0}, True)


def pressure(t: float) -> DecodedInput:
    return DecodedInput(t, "BRAKE_PRESSURES", {"brake_pressure_fl": 20.0}, False)


def accel(t: float) -> DecodedInput:
    return DecodedInput(t, "ACCELERATIONS", {"accel_long": -5.0}, False)


def times(items: list[DecodedInput]) -> list[tuple[str, float]]:
    return [(i.message[0], i.time_s) for i in items]


def test_a_wheel_speed_input_waits_until_every_partner_has_reached_its_time():
    hold = TriggerHold("WHEEL_SPEEDS", ["BRAKE_PRESSURES", "ACCELERATIONS"], max_wait_s=0.04)
    assert times(hold.push(pressure(0.000))) == [("B", 0.0)]
    assert times(hold.push(accel(0.001))) == [("A", 0.001)]
    assert hold.push(wheel(0.010)) == [] and hold.waiting == 1
    # the acceleration passes it, the pressures not yet
    assert times(hold.push(accel(0.012))) == [("A", 0.012)] and hold.waiting == 1
    assert times(hold.push(wheel(0.020))) == [] and hold.waiting == 2
    # the pressures pass both: the first goes on after them, in order; the second still waits
    # for the acceleration
    assert times(hold.push(pressure(0.020))) == [("B", 0.020), ("W", 0.010)]
    assert times(hold.push(accel(0.022))) == [("A", 0.022), ("W", 0.020)]
    assert hold.waiting == 0
    # (a partner's frame a little older than a waiting wheel input is no clock step)
    hold.push(wheel(0.030))
    assert times(hold.push(accel(0.028))) == [("A", 0.028)] and hold.waiting == 1


def test_a_partner_gone_silent_is_waited_for_no_longer_than_the_limit():
    hold = TriggerHold("WHEEL_SPEEDS", ["BRAKE_PRESSURES", "ACCELERATIONS"], max_wait_s=0.04)
    hold.push(pressure(0.0))
    hold.push(accel(0.0))
    assert hold.push(wheel(0.01)) == []
    assert hold.push(wheel(0.02)) == []
    assert times(hold.push(wheel(0.05))) == [("W", 0.01)]      # 0.04 after the first
    assert hold.due(0.059) == [] and times(hold.due(0.06)) == [("W", 0.02)]   # (the bus gone quiet)
    assert times(hold.flush()) == [("W", 0.05)] and hold.waiting == 0


def test_time_going_back_releases_what_waits_first():
    hold = TriggerHold("WHEEL_SPEEDS", ["BRAKE_PRESSURES"], max_wait_s=0.04)
    hold.push(pressure(10.0))
    hold.push(wheel(10.01))
    # a clock stepped back: the old time line's wheel input goes on before the new frame
    assert times(hold.push(pressure(2.0))) == [("W", 10.01), ("B", 2.0)]
    assert hold.push(wheel(2.01)) == []
    assert times(hold.push(pressure(2.02))) == [("B", 2.02), ("W", 2.01)]


def test_without_partners_or_a_wait_every_input_passes_at_once():
    for hold in (TriggerHold("WHEEL_SPEEDS", [], 0.04), TriggerHold("WHEEL_SPEEDS", ["BRAKE_PRESSURES"], 0.0)):
        assert times(hold.push(wheel(0.01))) == [("W", 0.01)]
        assert times(hold.push(pressure(0.0))) == [("B", 0.0)]
        assert hold.waiting == 0


def test_the_wheels_mu_is_read_against_the_pressures_of_the_window_s_end():
    # Campaign stop 22: wheel speeds at 100 Hz, pressures at 50 Hz lagging 36 ms, a threshold ABS.
    # Read at each wheel frame's arrival, the window's newest brake torques were the last pressure
    # frame's, up to 20 ms old: the wheels' μ against the truth's (the same window's mean) was off
    # by 0.037 rms. Waiting for the pressures to pass the frame's time takes a third of that off.
    from frictiond.campaign.draw import draw_stop
    from frictiond.campaign.simulate import simulate_stop
    from frictiond.pipeline import Pipeline

    spec = draw_stop(22)
    assert (spec.sensors.wheel_hz, spec.sensors.pressure_hz, spec.sensors.master_only) == (100, 50, False)
    stop = simulate_stop(spec, keep_trace=True)
    trace = stop.trace
    angle = np.vstack([np.zeros((1, 4)), np.cumsum(0.5 * (trace.fx[1:] + trace.fx[:-1])
                                                   * np.diff(trace.t)[:, None], axis=0)])

    def rms_error(wait_periods: float) -> float:
        config = stop.config("lugre-tr")
        config = dataclasses.replace(config, frontend=dataclasses.replace(config.frontend,
                                                                          input_wait_periods=wait_periods))
        pipeline = Pipeline(config)
        samples = []
        pipeline.on_estimate = lambda _e, s: samples.append(s) if s is not None and s.braking else None
        for frame in stop.frames:
            pipeline.process(frame)
        pipeline.flush()
        half = 2.0 / spec.sensors.wheel_hz     # (the derivative filter's half-span: 5 samples)
        errors = []
        for s in samples:
            for i in range(4):
                if not s.usable[i]:
                    continue
                mean_fx = (np.interp(s.time_s + half, trace.t, angle[:, i])
                           - np.interp(s.time_s - half, trace.t, angle[:, i])) / (2 * half)
                errors.append((s.tyre_force_n[i] - mean_fx) / s.normal_force_n[i])
        assert len(errors) > 1000
        return float(np.sqrt(np.mean(np.square(errors))))

    at_arrival, held = rms_error(0.0), rms_error(2.0)
    assert held < 0.75 * at_arrival, (held, at_arrival)


def test_a_negative_wait_is_refused_by_the_config():
    import pytest

    from frictiond.frontend import FrontEndOptions

    with pytest.raises(ValueError, match="input_wait_periods"):
        FrontEndOptions(input_wait_periods=-1.0).validate()
