"""The relaxation compensator: σ learnt from the loops a lagging tyre draws, the lag inverted."""
from __future__ import annotations

import math

import numpy as np
import pytest

from frictiond import relaxation as relaxation_module
from frictiond.relaxation import RelaxationCompensator
from frictiond.samples import PhysicalSample, Status

SPEED = 15.0
LOAD = 4000.0


def _static_mu(slip: np.ndarray) -> np.ndarray:
    """A Burckhardt-like dry curve (not the estimator's LuGre), peak near 0.17."""
    return 1.2 * (1.0 - np.exp(-20.0 * slip)) - 0.35 * slip


def _abs_samples(sigma_m: float, noise: float = 0.005, seed: int = 3, rate_hz: float = 100.0,
                 seconds: float = 3.0) -> tuple[list[PhysicalSample], np.ndarray]:
    """ABS-like slip cycles (6 Hz, 2–30 % slip) at constant speed; the force integrated with the
    lag σ/v at 1 kHz and sampled at `rate_hz` with noise. Returns the samples and the static μ of
    each sample's slip."""
    rng = np.random.default_rng(seed)
    dt = 1e-3
    t = np.arange(0.0, seconds, dt)
    slip = 0.02 + 0.28 * (0.5 + 0.5 * np.sin(2 * math.pi * 6.0 * t)) ** 2
    target = _static_mu(slip)
    mu = np.empty_like(target)
    mu[0] = target[0]
    lag = sigma_m / SPEED
    for k in range(1, len(t)):
        mu[k] = mu[k - 1] + (target[k] - mu[k - 1]) * (dt / lag if lag > 0 else 1.0)
    step = int(round(1.0 / (rate_hz * dt)))
    samples = []
    for k in range(0, len(t), step):
        m = float(mu[k] + rng.normal(0.0, noise))
        lam = float(slip[k])
        samples.append(PhysicalSample(float(t[k]), SPEED, (lam,) * 4, (m,) * 4, (LOAD,) * 4, (m * LOAD,) * 4,
                                      (True,) * 4, True))
    return samples, target[::step]


def _run(comp: RelaxationCompensator, samples: list[PhysicalSample]) -> list[PhysicalSample]:
    out = [comp.push(s) for s in samples]
    return [s for s in out if s is not None]


def test_a_lagging_tyre_is_learnt_and_its_loops_close():
    samples, static = _abs_samples(sigma_m=0.4)
    comp = RelaxationCompensator()
    out = _run(comp, samples)
    # The differenced μ's noise shrinks σ towards 0, never beyond the tyre's.
    assert 0.2 < comp.sigma_m <= 0.45
    raw = np.array([s.mu_used[0] for s in samples[:-1]])
    fixed = np.array([s.mu_used[0] for s in out])
    half = len(raw) // 2          # (once σ is learnt)
    raw_err = np.sqrt(np.mean((raw[half:] - static[half:len(raw)]) ** 2))
    fixed_err = np.sqrt(np.mean((fixed[half:] - static[half:len(raw)]) ** 2))
    assert fixed_err < 0.6 * raw_err
    # The top of the cycle, which the lag kept under the peak, comes back up to it.
    peak = float(_static_mu(np.linspace(0, 0.3, 3001)).max())
    assert fixed[half:].max() > raw[half:].max() + 0.02
    assert fixed[half:].max() > 0.97 * peak


def test_a_tyre_without_lag_passes_nearly_unchanged():
    samples, _ = _abs_samples(sigma_m=0.0, noise=0.01)
    comp = RelaxationCompensator()
    out = _run(comp, samples)
    assert comp.sigma_m < 0.05
    raw = np.array([s.mu_used[0] for s in samples[:-1]])
    fixed = np.array([s.mu_used[0] for s in out])
    assert np.sqrt(np.mean((fixed - raw) ** 2)) < 0.01


def test_each_sample_passes_once_one_late_and_gaps_pass_uncorrected():
    samples, _ = _abs_samples(sigma_m=0.4, seconds=2.0)
    # A lost stretch: 0.3 s without samples after the 150th.
    samples = samples[:150] + [
        PhysicalSample(s.time_s + 0.3, s.speed_mps, s.slip, s.mu_used, s.normal_force_n, s.tyre_force_n,
                       s.usable, s.braking) for s in samples[150:]]
    # One wheel not usable in one sample: its neighbours give that wheel no derivative.
    s = samples[100]
    samples[100] = PhysicalSample(s.time_s, s.speed_mps, s.slip, s.mu_used, s.normal_force_n, s.tyre_force_n,
                                  (True, False, True, True), s.braking)
    comp = RelaxationCompensator()
    assert comp.push(samples[0]) is None
    out = [comp.push(s) for s in samples[1:]]
    assert [o.time_s for o in out] == [s.time_s for s in samples[:-1]]
    assert comp.sigma_m > 0.1
    for k in (149, 150):          # either side of the gap
        assert out[k].mu_used == samples[k].mu_used
    for k in (99, 100, 101):      # the unusable sample and its neighbours, on that wheel
        assert out[k].mu_used[1] == samples[k].mu_used[1]
    assert out[100].mu_used[0] != samples[100].mu_used[0]
    assert out[100].tyre_force_n[0] == pytest.approx(out[100].mu_used[0] * LOAD)


@pytest.mark.skipif(relaxation_module.compiled_front is None,
                    reason="not built (test_frontcore's test_the_compiled_front_end_is_built fails instead)")
def test_the_compiled_wheels_say_what_the_python_ones_say_to_the_last_bit():
    """`_frontcore.relaxation_step` and `relaxation_sigma` against `_corrected`'s Python loop and
    `_fitted_sigma`: every sample, σ and the regression's sums equal, over a stop whose speed falls
    below `MIN_SPEED_MPS` (learning stops), with a gap, unusable wheels and a NaN μ."""
    samples, _ = _abs_samples(sigma_m=0.35, seconds=3.0, seed=11)
    rng = np.random.default_rng(5)
    varied = []
    for k, s in enumerate(samples):
        speed = 25.0 - 7.5 * s.time_s                               # 25 → 2.5 m/s
        mu = tuple(m * f for m, f in zip(s.mu_used, (1.0, 0.93, 1.05, 0.88)))
        slip = tuple(x * f for x, f in zip(s.slip, (1.0, 1.1, 0.9, 1.2)))
        usable = tuple(bool(u) for u in rng.random(4) > 0.03)
        if k == 77:
            mu = (math.nan,) + mu[1:]
        time_s = s.time_s + (0.2 if k >= 200 else 0.0)
        varied.append(PhysicalSample(time_s, speed, slip, mu, s.normal_force_n,
                                     tuple(m * LOAD for m in mu), usable, True))
    compiled, floats = RelaxationCompensator(), RelaxationCompensator()
    floats.core = None
    corrected = 0
    for s in varied:
        a, b = compiled.push(s), floats.push(s)
        assert (a is None) == (b is None)
        if a is not None:
            assert a.time_s == b.time_s
            assert np.array_equal(a.mu_used, b.mu_used, equal_nan=True)
            assert np.array_equal(a.tyre_force_n, b.tyre_force_n, equal_nan=True)
            corrected += a.mu_used != s.mu_used
        assert compiled.sigma_m == floats.sigma_m
        assert np.array_equal(compiled._sums, floats._sums, equal_nan=True)
    # The lag was learnt and inverted, the NaN μ notwithstanding (in the sums it would end the learning).
    assert compiled.sigma_m > 0.1 and corrected > 100


@pytest.mark.skipif(relaxation_module.compiled_front is None, reason="not built")
def test_the_compiled_step_refuses_sums_of_the_wrong_shape():
    core = relaxation_module.compiled_front
    four = (0.1, 0.1, 0.1, 0.1)
    with pytest.raises(ValueError, match="rows of 9"):
        core.relaxation_step(np.zeros((5, 9)), relaxation_module.SLIP_BANDS, 3.0, 1.0, math.nan, True, 0.01,
                             0.02, 10.0, four, four, four, four, (True,) * 4, (True,) * 4, (True,) * 4, four, four)
    with pytest.raises(TypeError, match="float64"):
        core.relaxation_sigma(np.zeros((32, 9), dtype=np.float32), 6, 200, 1.0)


def test_disabled_passes_every_sample_at_once():
    samples, _ = _abs_samples(sigma_m=0.4, seconds=1.0)
    comp = RelaxationCompensator(enabled=False)
    assert all(comp.push(s) is s for s in samples)
    assert comp.sigma_m == 0.0


def test_a_relaxing_tyre_under_abs_is_not_valid_low():
    """Campaign seed 427 (development seeds): a slip-threshold ABS on dry cobblestone, a tyre with a
    0.27 m relaxation length, wheel speeds at 83 Hz. Read as a static tyre, the lagging force put
    the peak 27 % low, VALID (34 of 35 VALID outputs more than 20 % off)."""
    from frictiond.campaign.draw import draw_stop
    from frictiond.campaign.simulate import simulate_stop
    from frictiond.replay import estimates_of

    spec = draw_stop(427)
    assert spec.relaxation_m > 0.2
    stop = simulate_stop(spec)
    pipeline, estimates = estimates_of(stop.config("lugre-tr"), stop.frames)
    t = np.array([r["time_s"] for r in stop.truth])
    mu = np.array([r["mu_max"] for r in stop.truth])
    valid = [e for e in estimates if e.status == Status.VALID]
    truth = [mu[min(int(np.searchsorted(t, e.time_s)), len(t) - 1)] for e in valid]
    off = sum(abs(e.mu_max - m) > 0.2 * m for e, m in zip(valid, truth))
    assert off <= 0.01 * max(len(valid), 1)
    assert pipeline.relaxation.sigma_m > 0.1
    # The replay summary says what was learnt.
    from frictiond.pipeline import Pipeline
    from frictiond.replay import replay_frames

    summary = replay_frames(Pipeline(stop.config("lugre-tr")), stop.frames).format()
    assert f"relaxation length {pipeline.relaxation.sigma_m:.2f} m" in summary
