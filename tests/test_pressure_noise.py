"""A pressure sensor's noise measured from its own frames, and the ABS releases it lets count."""
from __future__ import annotations

import numpy as np
import pytest

from frictiond.abs_activity import AbsActivity
from frictiond.config import default_config_path, load_config
from frictiond.frontend import PRESSURE_NAMES, WHEEL_SPEED_NAMES, FrontEnd, FrontEndOptions
from frictiond.pipeline import Pipeline
from frictiond.pressure_noise import NOISE_FIRST, PressureNoise
from frictiond.replay import replay_frames
from frictiond.sim_frames import simulate_frames

from .conftest import load_benchmark
from frictiond.vehicle import VehicleParams

NO_FLAGS = (None, None, None, None)


def _frames(true_bar, sigma: float, seconds: float, hz: float = 50.0, jitter_s: float = 0.002, seed: int = 3,
            repeat: int = 1):
    """(time, four readings) of sensors reading `true_bar(t)` with Gaussian noise `sigma`, cut at
    0; each reading sent `repeat` times (a 100 Hz message carrying a 50 Hz sensor)."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(int(seconds * hz)):
        t = k / hz + float(rng.uniform(-jitter_s, jitter_s))
        readings = tuple(max(0.0, true_bar(t) + float(rng.normal(0.0, sigma))) for _ in range(4))
        for r in range(repeat):
            out.append((t + r / (hz * repeat), readings))
    return out


def _measured(frames) -> float | None:
    noise = PressureNoise(PRESSURE_NAMES)
    for t, readings in frames:
        noise.push(t, dict(zip(PRESSURE_NAMES, readings)))
    return noise.sigma()


@pytest.mark.parametrize("sigma", [0.1, 0.3, 0.6])
def test_a_steady_pressure_gives_its_sensors_noise(sigma):
    measured = _measured(_frames(lambda t: 12.0, sigma, 4.0))
    assert measured == pytest.approx(sigma, rel=0.3)


def test_a_sender_repeating_each_reading_does_not_read_as_a_quieter_sensor():
    once = _measured(_frames(lambda t: 12.0, 0.4, 4.0))
    twice = _measured(_frames(lambda t: 12.0, 0.4, 4.0, repeat=2))
    assert twice == pytest.approx(0.4, rel=0.3) and twice >= 0.8 * once


def test_abs_cycles_read_as_a_little_more_noise_and_never_less():
    # A slip-threshold ABS on ice at 4 Hz: 1.5 bar re-applied to 6 bar along a ramp, then dumped.
    sawtooth = lambda t: 1.5 + 4.5 * ((t * 4.0) % 1.0)  # noqa: E731
    assert 0.15 * 0.8 < _measured(_frames(sawtooth, 0.15, 4.0, hz=100.0)) < 0.15 * 1.5
    # Re-applied in 0.75 bar steps every 20 ms: a step at every other reading is more noise.
    steps = lambda t: 1.5 + 4.5 * min(1.0, round((t * 6.0) % 1.0 * 8) / 6)  # noqa: E731
    assert _measured(_frames(steps, 0.15, 4.0, hz=100.0)) > 0.15 * 0.8


def test_a_noiseless_sensor_under_an_abs_that_holds_reads_as_quiet():
    # A deceleration ABS read by a sensor without noise at 50 Hz: dumped by 12 bar in one frame,
    # held for three frames, re-applied along a ramp for three. The holds are the sensor's
    # proof of quiet; without them only the corners' residuals would be left to measure.
    cycle = [50.0, 50.0, 50.0, 54.0, 58.0, 62.0]
    readings = [(k * 0.02, (cycle[k % 6],) * 4) for k in range(400)]
    measured = _measured(readings)
    assert measured is not None and measured < 0.6      # (8 σ below the fixed 5 bar)


def test_readings_cut_at_zero_say_nothing_and_too_few_say_nothing():
    # Free rolling with a sensor reading 0.4 bar low: its noise is cut at 0 nearly always.
    assert _measured(_frames(lambda t: 0.0, 0.2, 3.0, seed=5)) is None
    # A steady pressure, but fewer residuals than a median needs.
    assert _measured(_frames(lambda t: 12.0, 0.2, NOISE_FIRST / 50.0)) is None


def test_the_noisiest_sensor_speaks_for_all():
    rng = np.random.default_rng(8)
    noise = PressureNoise(PRESSURE_NAMES)
    for k in range(200):
        noise.push(k * 0.02, {n: 12.0 + float(rng.normal(0.0, s)) for n, s in zip(PRESSURE_NAMES, (0.1, 0.1, 0.1, 0.5))})
    assert noise.sigma() == pytest.approx(0.5, rel=0.3)


def _marks(activity: AbsActivity, frames) -> list[tuple[float, tuple[bool, ...]]]:
    return [(t, activity.update(t, readings, None, None, NO_FLAGS)) for t, readings in frames]


def test_a_release_of_a_few_bar_counts_unless_the_sensor_is_that_noisy():
    # The front left dumps from 20 to 14 bar at 0.3 s while the others hold 20 bar.
    def pressures(t: float) -> tuple[float, ...]:
        return (20.0 if t < 0.3 else 14.0, 20.0, 20.0, 20.0)

    frames = [(k * 0.01, pressures(k * 0.01)) for k in range(60)]
    for sigma in (None, 0.1, 0.6):   # not known, quiet, the noise the fixed 5 bar is 8 σ of
        activity = AbsActivity()
        activity.set_noise(sigma)
        marks = _marks(activity, frames)
        assert not any(any(m) for t, m in marks if t < 0.295)
        assert all(m == (True, False, False, False) for t, m in marks if 0.305 < t < 0.55)
    noisy = AbsActivity()
    noisy.set_noise(1.0)                                 # 8 σ = 8 bar: the same 6 bar could be noise
    assert not any(any(m) for _, m in _marks(noisy, frames))


@pytest.mark.parametrize("sigma, hz", [(0.6, 100.0), (1.2, 50.0)])
def test_noise_alone_is_never_a_release_at_the_noise_it_measured(sigma, hz):
    # A minute of steady braking at 20 bar (a moderate stop, no ABS), each wheel's sensor noisy:
    # the release threshold comes from the noise measured on the same readings. Without it a
    # sensor as noisy as 1.2 bar reads as releases.
    frames = _frames(lambda t: 20.0, sigma, 60.0, hz=hz, seed=11)
    noise, activity, fixed = PressureNoise(PRESSURE_NAMES), AbsActivity(), AbsActivity()
    marked = marked_fixed = 0
    for t, readings in frames:
        if noise.push(t, dict(zip(PRESSURE_NAMES, readings))):
            activity.set_noise(noise.sigma())
        marked += any(activity.update(t, readings, None, None, NO_FLAGS))
        marked_fixed += any(fixed.update(t, readings, None, None, NO_FLAGS))
    assert noise.sigma() == pytest.approx(sigma, rel=0.3)
    assert marked == 0
    assert (marked_fixed > 0) == (sigma > 1.0)


def test_the_front_end_learns_the_noise_from_pressure_frames_and_a_restart_forgets_it():
    veh = VehicleParams()
    messages = {"WHEELS": WHEEL_SPEED_NAMES, "ACCEL": ("accel_long", "accel_lat"), "PRESS": PRESSURE_NAMES}

    def run(sigma: float, fe: FrontEnd | None = None, dump_s: float = 1.2) -> tuple[FrontEnd, list]:
        fe = fe or FrontEnd(veh, FrontEndOptions(), messages, {m: 0.01 for m in messages}, "WHEELS")
        rng = np.random.default_rng(6)
        samples = []
        for k in range(150):
            t = k * 0.01
            v = 20.0 - 4.0 * t
            fe.push(t + 0.003, "ACCEL", {"accel_long": -4.0, "accel_lat": 0.0})
            # 30 bar on every wheel, the front left dumped to 23 bar from `dump_s`
            true = (30.0 if t < dump_s else 23.0, 30.0, 30.0, 30.0)
            fe.push(t + 0.006, "PRESS", {n: p + float(rng.normal(0.0, sigma)) for n, p in zip(PRESSURE_NAMES, true)})
            r = fe.push(t, "WHEELS", dict(zip(WHEEL_SPEED_NAMES, (v * 0.97 / veh.wheel_radius,) * 4)))
            if r is not None and r.sample is not None:
                samples.append(r.sample)
        return fe, samples

    _, quiet = run(0.1)
    assert any(s.abs_active[0] for s in quiet if s.time_s > 1.25)
    assert not any(any(s.abs_active) for s in quiet if s.time_s < 1.15)
    fe, noisy = run(1.5)                             # 8 σ = 12 bar: a 7 bar dip is not told from noise
    assert not any(any(s.abs_active) for s in noisy)
    # Restarted (another car's sensors, for all it knows): the dump comes before the quiet
    # sensors have told their noise, and the old noise must not stand for it.
    fe.reset()
    _, after = run(0.1, fe, dump_s=0.3)
    assert any(s.abs_active[0] for s in after if 0.32 < s.time_s < 0.42)


def test_replay_says_when_the_pressure_sensors_were_too_noisy_for_the_usual_threshold():
    # The simulator's "noisy" scenario reads pressures with 1.2 bar of noise (4 × 0.3 bar);
    # "wet" with 0.3 bar, within what 5 bar is 8 σ of.
    config = load_config(default_config_path())
    texts = {}
    for scenario in ("noisy", "wet"):
        frames, _ = simulate_frames(config, scenario, seed=2)
        pipeline = Pipeline(config)
        texts[scenario] = replay_frames(pipeline, frames).format()
        # (the ABS's valve steps and the largest of four sensors: more than the noise, never less)
        true = 1.2 if scenario == "noisy" else 0.3
        assert 0.9 * true < pipeline.front_end.pressure_noise_bar < 1.5 * true
    line = next(x for x in texts["noisy"].splitlines() if x.startswith("pressure noise"))
    drop = float(line.split(" bar drop")[0].rsplit(" ", 1)[1])
    assert 8 * 1.2 * 0.9 < drop < 8 * 1.2 * 1.5
    assert "pressure noise" not in texts["wet"]


def test_a_stop_without_abs_read_through_noisy_pressure_sensors_is_not_taken_for_one_at_the_limit():
    # Campaign stop 65 (no ABS, moderate braking) with 1.2 bar of pressure noise, twice the
    # campaign's most: with the release threshold held at 5 bar its noise reads as ABS releases
    # and every VALID output is more than 20 % off; with the noise measured, none is VALID. (On
    # level ground with the front end told so, as it was found: where the road may have a grade
    # the accelerometer's offset keeps the snow's gain in doubt, and neither variant is VALID.)
    bench = load_benchmark("pressure_noise")
    seed, family, valid, false, measured_share = bench.run_stop(65, 1.2, "measured", level=True)
    assert family == "d-none" and valid == 0 and 0.8 < measured_share < 1.5
    _, _, valid_fixed, false_fixed, _ = bench.run_stop(65, 1.2, "fixed 5 bar", level=True)
    assert valid_fixed > 100 and false_fixed == valid_fixed
