"""Each wheel's rolling radius learnt while the car rolls free (`frictiond.rolling_radius`)."""
from __future__ import annotations

import random

import pytest

from frictiond.campaign.draw import Stress, draw_stop
from frictiond.campaign.simulate import simulate_stop
from frictiond.evaluation import evaluate
from frictiond.input_names import PRESSURE_NAMES, WHEEL_SPEED_NAMES
from frictiond.pipeline import Pipeline

from .test_frontend import VEH, _without_speed_reference, make

# True rolling radius over the configured one: a worn front-left tyre, a soft rear-right one.
RADII = (0.98, 1.0, 1.005, 1.02)


def _drive(fe, radii=RADII, accel_lat=0.0, free_s=1.5, braked_s=1.0, slip=0.08, v0=20.0, decel=6.0,
           rest_bar=0.0, reference=False):
    """Rolls free for `free_s` (coasting at 0.3 m/s², the pressure sensors reading up to
    `rest_bar`, uniformly at random), then brakes with every tyre at `slip`: each wheel's ω is its ground
    speed over its own radius; with `reference`, a ground-speed sensor sends the car's speed 8 ms
    after the wheels. The samples, in order."""
    samples = []
    rng = random.Random(5)
    for k in range(int((free_s + braked_s) / 0.01)):
        t = k * 0.01
        braking = t >= free_s
        speed = v0 - 0.3 * min(t, free_s) - decel * max(t - free_s, 0.0)
        s = slip if braking else 0.0
        fe.push(t + 0.003, "ACCEL", {"accel_long": -decel if braking else -0.3, "accel_lat": accel_lat,
                                     "yaw_rate": accel_lat / speed})
        rest = rng.uniform(0.0, rest_bar)
        fe.push(t + 0.006, "PRESS", dict(zip(PRESSURE_NAMES, (60.0 if braking else rest,) * 4)))
        if reference:
            fe.push(t + 0.008, "REF", {"vehicle_speed_ref": speed})
        omegas = [speed * (1.0 - s) / (VEH.wheel_radius * f) for f in radii]
        r = fe.push(t, "WHEELS", dict(zip(WHEEL_SPEED_NAMES, omegas)))
        if r is not None and r.sample is not None:
            samples.append(r.sample)
    return samples


@pytest.mark.parametrize("compiled", [True, False])
def test_free_rolling_teaches_each_wheels_radius_and_the_braked_slips_agree(compiled):
    fe = _without_speed_reference(compiled)
    samples = _drive(fe)
    braked = [s for s in samples if s.braking and s.time_s > 1.7]
    assert braked
    for s in braked:
        # one slip on every tyre reads as one slip (uncorrected, they spread over 4 %)
        assert max(s.slip) - min(s.slip) < 3e-3
    mean = sum(RADII) / 4.0
    assert fe.rolling_radius_factors == pytest.approx([f / mean for f in RADII], abs=5e-4)
    assert fe.rolling_radius_note().startswith("FL -2.1 %, FR -0.1 %, RL +0.4 %, RR +1.9 % of the four's mean")
    # Braking teaches nothing: the factors are as free rolling left them.
    learnt = fe.rolling_radius_factors
    _drive(fe, free_s=0.0, braked_s=0.5)
    assert fe.rolling_radius_factors == learnt


@pytest.mark.parametrize("compiled", [True, False])
def test_the_radii_are_learnt_while_a_pressure_sensors_offset_flickers_above_the_brake_threshold(compiled):
    # Pressure sensors reading 0-2.4 bar at rest (their offset and noise) make the wheels
    # "braked" at some samples, and the tyres' differences read as 1-2 % slips: the
    # accelerometer's offset waits a second after each (`SETTLE_SLIP`). The radii do not wait
    # for that, and once they are learnt the slips are the tyres' no more.
    fe = _without_speed_reference(compiled)
    _drive(fe, braked_s=0.0, rest_bar=VEH.brake_pushout_pressure + 2.4)
    mean = sum(RADII) / 4.0
    assert fe.rolling_radius_factors == pytest.approx([f / mean for f in RADII], abs=1e-3)


@pytest.mark.parametrize("compiled", [True, False])
def test_turning_or_equal_tyres_teach_no_radius(compiled):
    # Turning at 3 m/s², the outer wheels' extra speed is the turn's (and the loads' shift), not
    # the tyres': nothing is learnt. Equal tyres going straight leave every factor at 1.
    fe = _without_speed_reference(compiled)
    _drive(fe, accel_lat=3.0, braked_s=0.0)
    assert fe.rolling_radius_factors == (1.0, 1.0, 1.0, 1.0)
    fe = _without_speed_reference(compiled)
    _drive(fe, radii=(1.0, 1.0, 1.0, 1.0), braked_s=0.0)
    assert fe.rolling_radius_factors == pytest.approx((1.0,) * 4, abs=1e-9)
    assert fe.rolling_radius_note() is None


def test_a_slip_controller_on_tyres_of_different_radii_shows_no_peak():
    # Campaign stop 20295 with tyres within ±2 % of the configured radius: a slip controller
    # meets dry cobblestone (its peak at slip ≈ 0.4) from wet asphalt, and holds every tyre at
    # slip 0.09, on the new road's rising branch. Read over one radius the four tyres show slips
    # 1-2 % apart at one μ, a flat top: 15 outputs VALID at 0.53 against a truth of 1.06. Each
    # wheel's radius learnt in the second of free rolling before the brakes, the slips agree
    # and no peak is shown.
    spec = draw_stop(20295, stress=Stress(tyre_radii=0.02))
    assert spec.abs_family == "c-slip" and max(spec.car.radius_factors) - min(spec.car.radius_factors) > 0.025
    stop = simulate_stop(spec)
    pipeline = Pipeline(stop.config("lugre-tr"))
    estimates = [pipeline.last_estimate for frame in stop.frames if pipeline.process(frame)]
    assert evaluate(estimates, stop.truth).false_valid_count == 0
    mean = sum(spec.car.radius_factors) / 4.0
    assert pipeline.front_end.rolling_radius_factors == pytest.approx(
        [f / mean for f in spec.car.radius_factors], abs=1e-3)


@pytest.mark.parametrize("compiled", [True, False])
def test_wheels_still_closing_a_stops_slip_teach_no_radius(compiled):
    # Braked at 8 % slip, then released: the front tyres close their slip more slowly than the
    # rear ones (1 % still open for 0.3 s), and the four roll free before they have. Read as
    # radii, that tail would make the front tyres 0.5 % larger; it is past within the wait
    # (`accel_bias_settle_s` after the four wheels' mean slip under the brakes last read real).
    fe = _without_speed_reference(compiled)
    for k in range(350):
        t = k * 0.01
        braking = 0.5 <= t < 1.0
        speed = 20.0 - 6.0 * min(max(t - 0.5, 0.0), 0.5)
        tail = 0.01 if 1.0 <= t < 1.3 else 0.0
        slips = (0.08,) * 4 if braking else (tail, tail, 0.0, 0.0)
        fe.push(t + 0.003, "ACCEL", {"accel_long": -6.0 if braking else -0.3, "accel_lat": 0.0, "yaw_rate": 0.0})
        fe.push(t + 0.006, "PRESS", dict(zip(PRESSURE_NAMES, (60.0 if braking else 0.0,) * 4)))
        fe.push(t, "WHEELS", dict(zip(WHEEL_SPEED_NAMES, [speed * (1.0 - s) / VEH.wheel_radius for s in slips])))
        if t < 1.9:
            assert fe.rolling_radius_factors == (1.0, 1.0, 1.0, 1.0)
        if t < 0.5:
            learnt_before = fe._radius_samples
    assert learnt_before > 20 and fe._radius_samples > learnt_before + 50
    assert fe.rolling_radius_factors == pytest.approx((1.0,) * 4, abs=1e-4)


def _braked_slips_with_reference(fe, scale):
    """`_drive` on a car with a ground-speed sensor, every tyre's radius `scale` times the
    configured one: the four slips of each braked sample after 1.7 s."""
    return [s.slip for s in _drive(fe, radii=(scale,) * 4, reference=True) if s.braking and s.time_s > 1.7]


@pytest.mark.parametrize("compiled", [True, False])
def test_a_radius_wrong_on_all_four_is_learnt_against_the_ground_speed_sensor(compiled):
    """Tyres 1.5 % larger than `vehicle.wheel_radius` on all four: against a ground-speed sensor
    every slip reads 1.5 % high (0.095 for 0.08), rolling free too. Learnt there, the braked slips
    are the tyres'; without a sensor the common radius is not learnt (nothing tells it)."""
    fe = make()
    if not compiled:
        fe.core = None
    braked = _braked_slips_with_reference(fe, 1.015)
    assert fe.rolling_radius_scale == pytest.approx(1.015, abs=1e-3)
    assert fe.rolling_radius_factors == pytest.approx((1.0,) * 4, abs=1e-4)
    # (as with tyres of the configured radius: the reference's 8 ms after the wheels add 0.2-0.3 %)
    right = make()
    if not compiled:
        right.core = None
    configured = _braked_slips_with_reference(right, 1.0)
    assert braked and len(braked) == len(configured)
    assert all(s == pytest.approx(c, abs=5e-4) for slips, ok in zip(braked, configured) for s, c in zip(slips, ok))
    assert "the four +1.5 % of vehicle.wheel_radius against the ground-speed sensor" in fe.rolling_radius_note()
    unlearnt = make()
    unlearnt._learn_rolling_radii = lambda sample, free_rolling: None
    off = _braked_slips_with_reference(unlearnt, 1.015)
    assert all(s > c + 0.012 for slips, ok in zip(off, configured) for s, c in zip(slips, ok))
    without = _without_speed_reference(compiled)
    _drive(without, radii=(1.015,) * 4)
    assert without.rolling_radius_scale == 1.0 and without.rolling_radius_note() is None
