"""The compiled derivative filter (`frictiond._frontcore`) against the float code it replaces."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from frictiond import frontend as frontend_module
from frictiond.config import default_config_path, load_config
from frictiond.pipeline import Pipeline
from frictiond.sim_frames import simulate_frames

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
            for field in ("time_s", "speed_mps", "slip", "mu_used", "normal_force_n", "tyre_force_n"):
                np.testing.assert_allclose(getattr(a.sample, field), getattr(b.sample, field), rtol=1e-9, atol=1e-12)
            assert a.sample.usable == b.sample.usable
    assert samples > 300
    assert compiled.last_estimate.status == floats.last_estimate.status
    assert compiled.last_estimate.mu_max == pytest.approx(floats.last_estimate.mu_max, abs=1e-6)


@needs_core
def test_fit_wheels_matches_the_float_fit_and_refuses_bad_input():
    rng = np.random.default_rng(4)
    fe = Pipeline(load_config(default_config_path())).front_end
    for n in (3, 5, 7, 13):   # (the filter's window keeps the newest 7)
        times = list(np.cumsum(rng.uniform(0.008, 0.012, n)))
        speeds = [tuple(rng.uniform(20, 80, 4)) for _ in range(n)]
        fe._wheel_times.clear()
        fe._wheel_speeds.clear()
        fe._wheel_times.extend(times)
        fe._wheel_speeds.extend(speeds)
        fe.core = None
        expected = fe._fit_wheels()
        weights = fe._torque_weights
        got = core.fit_wheels(list(fe._wheel_times), list(fe._wheel_speeds), fe.options.spike_threshold)
        assert got[0] == expected[0]
        np.testing.assert_allclose(got[1], expected[1], rtol=1e-12)
        np.testing.assert_allclose(got[2], expected[2], rtol=1e-9, atol=1e-9)
        assert got[3] == expected[3]
        np.testing.assert_allclose(got[4], weights, rtol=1e-9, atol=1e-12)
        assert sum(got[4]) == pytest.approx(1.0)
    # All timestamps equal: the closed form cannot be used (the caller falls back to lstsq).
    assert core.fit_wheels([1.0] * 5, [(1.0, 1.0, 1.0, 1.0)] * 5, 1.0) is None
    with pytest.raises(ValueError, match="four"):
        core.fit_wheels([0.0, 0.01, 0.02], [(1.0, 1.0, 1.0)] * 3, 1.0)
    with pytest.raises(ValueError, match="per time"):
        core.fit_wheels([0.0, 0.01, 0.02], [(1.0, 1.0, 1.0, 1.0)] * 2, 1.0)
    with pytest.raises(TypeError):
        core.fit_wheels([0.0, "x", 0.02], [(1.0, 1.0, 1.0, 1.0)] * 3, 1.0)


@needs_core
@pytest.mark.parametrize("floor", [None, 0.0, 2.5])
def test_matched_sum_is_the_interpolation_plan(floor):
    from frictiond.frontend import _interpolation_plan

    rng = np.random.default_rng(7)
    for _ in range(200):
        ts = list(np.sort(rng.uniform(0.0, 0.12, int(rng.integers(1, 16)))))
        if len(ts) > 3:
            ts[2] = ts[1]                                  # a repeated timestamp
        vs = list(rng.uniform(-1.0, 10.0, len(ts)))
        times = list(np.sort(rng.uniform(-0.02, 0.14, 7)))  # before, inside and after the series
        weights = list(rng.normal(size=7))
        plan = _interpolation_plan(ts, times, weights)
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
    history = frontend_module._MessageHistory(0.01)
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
    history = frontend_module._MessageHistory(0.01)
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
    compiled, floats = frontend_module._MessageHistory(0.01), frontend_module._MessageHistory(0.01)
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
