"""The compiled derivative filter (`frictiond._frontcore`) against the float code it replaces."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from frictiond import frontend as frontend_module
from frictiond import input_alignment
from frictiond.config import default_config_path, load_config
from frictiond.pipeline import Pipeline
from frictiond.sim_frames import simulate_frames

from .conftest import assert_each_refused

core = frontend_module.compiled_front
needs_core = pytest.mark.skipif(core is None, reason="not built (test_the_compiled_front_end_is_built fails instead)")


def test_the_compiled_front_end_is_built():
    assert core is not None, "frictiond._frontcore did not build: see the pip install output (gcc, python3-dev)"


@needs_core
@pytest.mark.parametrize("scenario, seed, spike_threshold", [("dry", 1, None), ("snow", 2, None), ("noisy", 3, 0.5)])
def test_the_front_end_says_the_same_on_both_paths(scenario, seed, spike_threshold):
    config = load_config(default_config_path())
    if spike_threshold is not None:   # (a tight threshold: glitches flagged on both paths alike)
        config = dataclasses.replace(config, frontend=dataclasses.replace(config.frontend, spike_threshold=spike_threshold))
    frames, _ = simulate_frames(config, scenario, seed=seed)
    compiled, floats = Pipeline(config), Pipeline(config)
    floats.front_end.core = None
    samples = 0
    for frame in frames:
        out_c, out_f = compiled.process(frame), floats.process(frame)
        assert len(out_c) == len(out_f)
        a, b = compiled.last_result, floats.last_result
        if a is None or not out_c:
            continue
        assert (a.sample is None) == (b.sample is None) and a.fault == b.fault and a.dead_wheels == b.dead_wheels
        if a.sample is not None:
            samples += 1
            for field in ("time_s", "speed_mps", "slip", "mu_used", "normal_force_n", "tyre_force_n", "brake_gain_doubt",
                          "accel_offset_doubt_mps2"):
                np.testing.assert_allclose(getattr(a.sample, field), getattr(b.sample, field), rtol=1e-9, atol=1e-12)
            assert a.sample.usable == b.sample.usable and a.sample.abs_active == b.sample.abs_active
            assert (a.sample.slip_spread is None) == (b.sample.slip_spread is None)
            if a.sample.slip_spread is not None:
                np.testing.assert_allclose(a.sample.slip_spread, b.sample.slip_spread, rtol=1e-9, atol=1e-12)
                np.testing.assert_allclose(a.sample.slip_spread_weights, b.sample.slip_spread_weights, rtol=1e-9, atol=1e-12)
    assert samples > 300
    assert compiled.last_estimate.status == floats.last_estimate.status
    assert compiled.last_estimate.mu_max == pytest.approx(floats.last_estimate.mu_max, abs=1e-6)


@needs_core
def test_the_window_checks_compiled_equal_the_python_ones():
    """`_frontcore.newest_suspect` and `slip_spread` against `_newest_suspect` and
    `_attach_slip_spread` on the same windows: random speeds with single-sample jumps (suspect
    and not), uneven and repeated times, slips outside [0, 1), slow wheels, no accelerometer."""
    from frictiond.samples import PhysicalSample
    rng = np.random.default_rng(21)
    fe = Pipeline(load_config(default_config_path())).front_end
    n = fe._wheel_times.maxlen
    suspect = spread = 0
    for trial in range(2000):
        times = list(np.cumsum(rng.uniform(0.005, 0.015, n)))
        if trial % 50 == 0:
            times[-2] = times[-3]                      # (a repeated time: neither path judges it)
        speeds = [tuple(30.0 + 5.0 * t + rng.normal(0.0, 0.02, 4)) for t in times]
        if trial % 3 == 0:                             # a jump in one wheel's newest or next samples
            k, i = n - 1 - int(rng.integers(0, 2)), int(rng.integers(0, 4))
            row = list(speeds[k])
            row[i] += float(rng.choice((-1.0, 1.0)) * rng.uniform(0.5, 20.0))
            speeds[k] = tuple(row)
        if trial % 7 == 0:
            speeds = [(0.3,) + row[1:] for row in speeds]   # (a wheel too slow for a spread)
        fe._wheel_times.clear()
        fe._wheel_speeds.clear()
        fe._wheel_times.extend(times)
        fe._wheel_speeds.extend(speeds)
        weights = rng.uniform(0.0, 1.0, n) * (rng.random(n) > 0.2)
        fe._torque_weights = list(weights / max(weights.sum(), 1e-9))
        fe._sample_accel = None if trial % 11 == 0 else float(rng.normal(-5.0, 2.0))
        slips = tuple(float(x) for x in rng.uniform(-0.1, 1.1, 4))
        made = []
        for core in (fe.core, None):
            fe.core = core
            made.append(fe._newest_suspect())
            sample = PhysicalSample(times[n // 2], float(rng.uniform(0.5, 40.0)) if core else sample.speed_mps,
                                    slips, (0.5,) * 4, (4000.0,) * 4, (2000.0,) * 4, (True,) * 4, True)
            fe._attach_slip_spread(sample)
            made.append((sample.slip_spread, sample.slip_spread_weights))
        fe.core = frontend_module.compiled_front
        assert made[0] == made[2], trial
        assert np.array_equal(np.array(made[1][0], dtype=float), np.array(made[3][0], dtype=float)) if made[1][0] \
            else made[1][0] == made[3][0], trial
        assert made[1][1] == made[3][1], trial
        suspect += made[0]
        spread += made[1][0] is not None
    assert 300 < suspect < 1900 and spread > 500   # (both verdicts and both outcomes were compared)
    with pytest.raises(ValueError, match="a weight per time"):
        fe.core.slip_spread([0.5], fe._wheel_times, fe._wheel_speeds, 10.0, slips, 0.0)
    with pytest.raises(TypeError, match="speeds"):
        fe.core.newest_suspect([0.0, 0.01, 0.02, 0.03], [(1.0, 2.0)] * 4, 80_000.0)


@needs_core
@pytest.mark.parametrize("torque_window", [3, 5])
def test_fit_wheels_matches_the_float_fit_and_refuses_bad_input(torque_window):
    rng = np.random.default_rng(4)
    fe = Pipeline(load_config(default_config_path())).front_end
    fe.torque_window = torque_window
    for n in (3, 5, 7, 13):
        times = list(np.cumsum(rng.uniform(0.008, 0.012, n)))
        speeds = [tuple(rng.uniform(20, 80, 4)) for _ in range(n)]
        fe._wheel_times.clear()
        fe._wheel_speeds.clear()
        fe._wheel_times.extend(times)
        fe._wheel_speeds.extend(speeds)
        fe.core = None
        expected = fe._fit_window()   # (the fit alone: `_fit_wheels` also repairs a glitch)
        weights, torque_omega_dot = fe._torque_weights, fe._torque_omega_dot
        got = core.fit_wheels(list(fe._wheel_times), list(fe._wheel_speeds), fe.glitch_threshold, torque_window)
        assert got[0] == expected[0]
        np.testing.assert_allclose(got[1], expected[1], rtol=1e-12)
        np.testing.assert_allclose(got[2], expected[2], rtol=1e-9, atol=1e-9)
        assert got[3] == expected[3]
        np.testing.assert_allclose(got[4], weights, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(got[5], torque_omega_dot, rtol=1e-9, atol=1e-9)
        assert sum(got[4]) == pytest.approx(1.0)
        # Over fewer samples than the window, the torques' weights lie on the central ones only.
        n = len(fe._wheel_times)   # (the filter's window keeps the newest 5)
        outside = (n - min(torque_window, n)) // 2
        assert not any(got[4][:outside]) and not any(got[4][n - outside:])
        assert (got[5] == got[2]) == (torque_window >= n)
    # All timestamps equal: the closed form cannot be used (the caller falls back to lstsq).
    assert core.fit_wheels([1.0] * 5, [(1.0, 1.0, 1.0, 1.0)] * 5, 1.0, 5) is None
    with pytest.raises(ValueError, match="four"):
        core.fit_wheels([0.0, 0.01, 0.02], [(1.0, 1.0, 1.0)] * 3, 1.0, 5)
    with pytest.raises(ValueError, match="per time"):
        core.fit_wheels([0.0, 0.01, 0.02], [(1.0, 1.0, 1.0, 1.0)] * 2, 1.0, 5)
    with pytest.raises(TypeError):
        core.fit_wheels([0.0, "x", 0.02], [(1.0, 1.0, 1.0, 1.0)] * 3, 1.0, 5)


@needs_core
@pytest.mark.parametrize("floor", [None, 0.0, 2.5])
def test_matched_sum_is_the_interpolation_plan(floor):
    from frictiond.input_alignment import interpolation_plan

    rng = np.random.default_rng(7)
    for _ in range(200):
        ts = list(np.sort(rng.uniform(0.0, 0.12, int(rng.integers(1, 16)))))
        if len(ts) > 3:
            ts[2] = ts[1]                                  # a repeated timestamp
        vs = list(rng.uniform(-1.0, 10.0, len(ts)))
        times = list(np.sort(rng.uniform(-0.02, 0.14, 7)))  # before, inside and after the series
        weights = list(rng.normal(size=7))
        plan = interpolation_plan(ts, times, weights)
        if floor is None:
            expected = sum(a * vs[j] for j, a in plan)
        else:
            expected = sum(a * (vs[j] - floor) for j, a in plan if vs[j] > floor)
        assert core.matched(ts, vs, times, weights, floor) == pytest.approx(expected, rel=1e-12, abs=1e-12)
    with pytest.raises(ValueError, match="matched"):
        core.matched([], [], [0.0], [1.0], None)


@needs_core
def test_values_at_is_value_at_for_every_signal():
    rng = np.random.default_rng(21)
    history = input_alignment.MessageHistory(0.01)
    for step in range(60):
        t = 0.01 * step + float(rng.uniform(-0.004, 0.004))
        if step % 7 == 3:
            t = 0.01 * (step - 1)   # a repeated time stamp (t1 == t0 in the interpolation)
        values = {"a": float(rng.normal()), "b": float(rng.uniform(0, 200))}
        if step % 3 == 0:
            values["c"] = float(rng.normal())   # a signal on every third frame only
        history.push(t, values)
        lookups = ((history.series, "a"), (history.series, "b"), (history.series, "c"), (history.series, "absent"),
                   None)
        for probe in (t + 0.02, t, t - 0.003, t - 0.05, -1.0, float(rng.uniform(0, t + 0.01))):
            expected = tuple(history.value_at(probe, n) for n in ("a", "b", "c", "absent")) + (None,)
            assert core.values_at(lookups, probe) == expected
    with pytest.raises(TypeError):
        core.values_at(((history.series,),), 0.1)


@needs_core
def test_matched_many_is_matched_for_each_signal():
    rng = np.random.default_rng(22)
    history = input_alignment.MessageHistory(0.01)
    for step in range(30):
        history.push(0.01 * step + float(rng.uniform(-0.003, 0.003)),
                     {"p": float(rng.uniform(0, 80)), "a": float(rng.normal())})
    times = sorted(float(t) for t in rng.uniform(0.1, 0.32, 7))
    weights = [float(w) for w in rng.normal(size=7)]
    lookups = ((history.series, "p", 2.5), (history.series, "a", None), (history.series, "absent", 1.0), None,
               (history.series, "p", float("nan")))
    expected = (core.matched(*history.series["p"], times, weights, 2.5),
                core.matched(*history.series["a"], times, weights, None), None, None,
                core.matched(*history.series["p"], times, weights, float("nan")))
    assert core.matched_many(lookups, times, weights) == expected
    assert expected[4] == 0.0   # (a NaN floor: no value exceeds it, as in the float code)
    with pytest.raises(ValueError):
        core.matched_many(lookups, times, weights[:-1])


@needs_core
def test_history_push_is_the_same_on_both_paths():
    rng = np.random.default_rng(23)
    compiled, floats = input_alignment.MessageHistory(0.01), input_alignment.MessageHistory(0.01)
    t = 0.0
    for step in range(80):
        t += float(rng.choice([0.01, 0.01, 0.01, -0.05]))   # now and then back in time: cleared
        names = ["a", "b"] + (["c"] if step > 20 else []) + (["d"] if step % 5 == 0 else [])
        values = {name: float(rng.normal()) for name in names}
        compiled.push(t, values, core)
        floats.push(t, values, None)
        assert compiled.merged == floats.merged and compiled.last_arrival_s == floats.last_arrival_s
        assert {n: (list(ts), list(vs)) for n, (ts, vs) in compiled.series.items()} == \
               {n: (list(ts), list(vs)) for n, (ts, vs) in floats.series.items()}
    assert all(ts.maxlen == 16 for ts, _ in compiled.series.values())
    # push_values converts its arguments itself (METH_FASTCALL): wrong ones are refused.
    good = [compiled.series, compiled.merged, t + 1.0, {"a": 1.0}, input_alignment.new_series]
    assert_each_refused(core.push_values, good, ((0, []), (1, None), (2, 1), (3, [("a", 1.0)])))
    assert core.push_values(*good) is None and compiled.merged["a"] == 1.0


# The state `_frontcore.sample_physics` carries between samples (on the FrontEnd's attributes).
PHYSICS_STATE = ("_repeats", "_dead", "_low_since_s", "_low_unbraked_s", "_braked_time_s", "_last_sample_time_s", "_accel_bias_mps2",
                 "_accel_bias_samples", "_accel_bias_m2", "_unexplained_s", "_speed_time_s", "_speed_estimate_mps",
                 "_ref_disagreements", "_gain_sum_tt", "_gain_sum_tn", "_gain_sum_t", "_gain_sum_n", "_gain_sum_w",
                 "_sensor_offset_mps2", "_sensor_offset_doubt_mps2", "_recent_weight_nm", "_recent_lag_nm", "_last_brake_nm", "_recent_needed_nm",
                 "_recent_brake_nm", "_brake_released", "_brake_gain_factor", "_brake_gain_doubt", "_brake_model_holds",
                 "_unjudged_s", "_lag_state", "_slipping_time_s", "_rolling_offset_mps2", "_rolling_offset_samples",
                 "_rolling_offset_m2", "_rolling_air_doubt_mps2")


def _physics_stream(seed: int, steps: int):
    """Randomised inputs that visit every branch of `_compute_sample`: braking and free rolling,
    drive torque, a curve, a dead and a stuck wheel, a reference speed that glitches or goes
    silent, pressures that vanish under deceleration or leave their range, NaN inputs, gaps."""
    from frictiond.frontend import DRIVE_TORQUE_NAMES, PRESSURE_NAMES, WHEEL_SPEED_NAMES

    rng = np.random.default_rng(seed)
    t, v = 0.0, 25.0
    for k in range(steps):
        phase = (k // 60) % 6          # 0.6 s of each regime in turn
        t += 0.01 if rng.random() > 0.01 else 0.4   # now and then a gap beyond max_gap
        decel = {0: 0.0, 1: 6.0, 2: 2.0, 3: -1.5, 4: 8.0, 5: 0.5}[phase]
        if phase == 1:      # brakes swinging at 3 Hz, their pressure sensor 20 ms late (the lag's branch)
            decel += 2.5 * math.sin(6 * math.pi * t)
        v = max(v - decel * 0.01, 0.0) if v > 4 else 25.0
        slips = rng.uniform(0.0, 0.25, 4) if phase in (1, 4) else rng.uniform(-0.01, 0.02, 4)
        omega = [max(v * (1 - s), 0.0) / 0.31 + float(rng.normal(0, 0.05)) for s in slips]
        if phase == 2 and k % 60 > 20:
            omega[1] = 0.0                                        # a dead sensor
        if phase == 5 and k % 60 > 10:
            omega[3] = 55.0                                       # a stuck one
        pressures = [float(rng.uniform(20, 90)) if phase in (1, 4) else float(rng.uniform(0, 0.5))] * 4
        if phase == 1:
            pressures = [55.0 + 23.0 * math.sin(6 * math.pi * (t - 0.02))] * 4
        if phase == 4 and k % 60 > 40:
            pressures = [0.0] * 4                                 # gone while the car decelerates
        if rng.random() < 0.01:
            pressures[int(rng.integers(4))] = float(rng.choice([400.0, -5.0, math.nan]))
        accel = {"accel_long": -decel + float(rng.normal(0, 0.1)), "accel_lat": float(rng.normal(0, 2.0)),
                 "yaw_rate": float(rng.normal(0, 0.1)) if rng.random() > 0.05 else math.nan}
        if rng.random() < 0.005:
            accel["accel_long"] = 40.0
        drive = {n: (300.0 if phase == 3 else 0.0) + float(rng.normal(0, 5)) for n in DRIVE_TORQUE_NAMES}
        yield t + 0.001, "ACCEL", accel
        yield t + 0.002, "PRESS", dict(zip(PRESSURE_NAMES, pressures))
        yield t + 0.003, "DRIVE", drive
        if phase != 0 or k % 60 < 30:                           # the reference falls silent at times
            ref = v + (float(rng.choice([0.0, 0.0, 0.0, 8.0])))    # ... and glitches
            yield t + 0.004, "REF", {"vehicle_speed_ref": ref}
        yield t + 0.009, "WHEELS", dict(zip(WHEEL_SPEED_NAMES, omega))


@needs_core
@pytest.mark.parametrize(("seed", "level_road"), [(11, False), (12, False), (13, True)])
def test_sample_physics_is_compute_sample_on_every_branch(seed, level_road):
    from frictiond.frontend import DRIVE_TORQUE_NAMES, PRESSURE_NAMES, WHEEL_SPEED_NAMES, FrontEnd, FrontEndOptions
    from frictiond.vehicle import VehicleParams

    messages = {"WHEELS": WHEEL_SPEED_NAMES, "ACCEL": ("accel_long", "accel_lat", "yaw_rate"),
                "PRESS": PRESSURE_NAMES, "REF": ("vehicle_speed_ref",), "DRIVE": DRIVE_TORQUE_NAMES}
    vehicle = VehicleParams(brake_pushout_pressure=0.3, rolling_resistance=5.0)

    def make() -> FrontEnd:
        fe = FrontEnd(vehicle, FrontEndOptions(level_road=level_road), messages, {m: 0.01 for m in messages}, "WHEELS")
        # The input gate (plausibility.py) would keep the out-of-range values away from the
        # physics; its branches for them stay as a second line and are compared here too.
        fe.gate.admit = lambda *args: None
        fe.gate.repair_spike = lambda *args: None
        return fe

    compiled, floats = make(), make()
    floats.core = None
    faults, samples, from_ref, dead, lag, doubted = set(), 0, 0, 0, 0.0, 0
    for t, message, values in _physics_stream(seed, 3000):
        a, b = compiled.push(t, message, values), floats.push(t, message, values)
        assert (a is None) == (b is None)
        if a is None:
            continue
        assert (a.fault, a.dead_wheels, a.stale_messages) == (b.fault, b.dead_wheels, b.stale_messages)
        assert (a.sample is None) == (b.sample is None)
        if a.sample is not None:
            samples += 1
            from_ref += a.sample.speed_from_reference
            dead += bool(a.dead_wheels)
            doubted += a.sample.brake_gain_doubt > 0.0
            for field in ("time_s", "speed_mps", "slip", "mu_used", "normal_force_n", "tyre_force_n", "brake_gain_doubt",
                          "accel_offset_doubt_mps2"):
                np.testing.assert_allclose(getattr(a.sample, field), getattr(b.sample, field), rtol=1e-12, atol=1e-12)
            assert (a.sample.usable, a.sample.braking, a.sample.speed_from_reference) == \
                   (b.sample.usable, b.sample.braking, b.sample.speed_from_reference)
        faults.add(a.fault)
        lag = max(lag, compiled.pressure_lag_s)
        for name in PHYSICS_STATE:
            x, y = getattr(compiled, name), getattr(floats, name)
            assert type(x) is type(y), name
            np.testing.assert_allclose(np.array(x, dtype=float), np.array(y, dtype=float), rtol=1e-12, atol=1e-12,
                                       err_msg=name)
    # Every way out of the compiled code was taken.
    assert {"acceleration out of range", "brake pressure out of range", "brake pressure implausible",
            "wheel speed stuck", "wheel speed glitch", None} <= faults, faults
    assert samples > 1000 and 0 < from_ref < samples and dead > 5
    assert 0 < doubted < samples    # (braking before the accelerometer's offset was learnt, and after)
    assert lag > 0.002    # (the pressure-lag compensation was at work, not only its zero)
    # (coasting taught the offset's prior, unless the roads are level)
    assert (compiled._rolling_offset_samples > 10) != level_road


@needs_core
def test_sample_physics_refuses_what_it_cannot_read():
    fe = Pipeline(load_config(default_config_path())).front_end
    args = [fe, fe._physics_constants, frontend_module._PHYSICS_TYPES, 1.0, [80.0] * 4, [0.0] * 4, False,
            (0.0,) * len(fe._sample_inputs), (), fe._matched_lookups, [1.0], None, None, False, None]
    assert core.sample_physics(*args).sample is not None
    assert core.sample_physics(*args[:14], [0.5] * 4).sample is not None
    with pytest.raises(ValueError, match="four"):
        core.sample_physics(*args[:14], [0.5] * 3)
    with pytest.raises(ValueError, match="constants"):
        core.sample_physics(*args[:1], args[1][:-1], *args[2:])
    with pytest.raises(ValueError, match="inputs"):
        core.sample_physics(*args[:7], (0.0,) * 3, *args[8:])
    with pytest.raises(ValueError, match="four"):
        core.sample_physics(*args[:4], [80.0] * 3, *args[5:])
    # Its arguments are converted by hand (METH_FASTCALL): each wrong one is refused.
    assert_each_refused(core.sample_physics, args,
                        ((1, list(args[1])), (2, None), (3, "1.0"), (7, list(args[7])), (9, list(args[9]))))
    assert core.sample_physics(*args[:6], 1, *args[7:13], "yes", None).sample is not None   # ("p": any truth value)
    fe._dead = [False] * 3
    with pytest.raises(TypeError, match="_dead"):
        core.sample_physics(*args)
