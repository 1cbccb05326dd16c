"""μ_max is never published below the grip that was measured: the car's deceleration and a
wheel's own μ–slip data bound it from below where the static model rounds a sharp peak off."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from frictiond import tyre_model as tm
from frictiond.estimator import LugreTROptions, LugreTrustRegionEstimator
from frictiond.samples import PhysicalSample, Status


def magic_formula(lam: float, B: float = 12.0, C: float = 2.4, D: float = 1.0, E: float = -0.5) -> float:
    x = B * lam
    return D * math.sin(C * math.atan(x - E * (x - math.atan(x))))


def sharp_peak() -> tuple[float, float]:
    lams = np.linspace(0.001, 0.6, 6000)
    values = np.array([magic_formula(float(x)) for x in lams])
    return float(values.max()), float(lams[values.argmax()])


def overshooting_abs(options: LugreTROptions, seed: int = 2):
    """Four wheels cycled out of phase from 0.3 to 2.5 × the peak slip (an ABS that overshoots)
    on a Magic Formula tyre whose force falls 30 % past its peak (C = 2.4)."""
    rng = np.random.default_rng(seed)
    mu_peak, lam_peak = sharp_peak()
    est = LugreTrustRegionEstimator(options)
    v, t = 30.0, 0.0
    while v > 5.0:
        phases = [(3.0 * t + 0.25 * i) % 1.0 for i in range(4)]
        slips = [lam_peak * (0.3 + 2.2 * (p / 0.6 if p < 0.6 else (1 - p) / 0.4)) for p in phases]
        mus = [magic_formula(s) + float(rng.normal(0, 0.02)) for s in slips]
        e = est.update(PhysicalSample(t, v, tuple(slips), tuple(mus), (4000.0,) * 4, (0.0,) * 4, (True,) * 4, True))
        yield t, e, mu_peak
        v -= float(np.mean(mus)) * 9.81 * 0.01
        t += 0.01


def test_a_sharp_peak_is_not_published_far_below_what_the_wheels_measured():
    def errors(options, statuses=(Status.VALID,)):
        return [(e.mu_max - peak) / peak for t, e, peak in overshooting_abs(options)
                if e.status in statuses and t > 0.6]

    bound_off = dataclasses.replace(LugreTROptions(), peak_group_samples=1, band_floor=False)
    rounded = errors(bound_off, (Status.VALID, Status.CONVERGING))
    assert np.mean(rounded) < -0.15          # the static model alone: ~20 % low ...
    assert not [x for x in errors(bound_off) if x < -0.2]   # ... and, with the data above its curve, not VALID
    bounded = errors(LugreTROptions(), (Status.VALID, Status.CONVERGING))
    assert np.mean(bounded) > -0.12 and max(bounded) < 0.02   # lifted towards the data, never above the peak


def test_a_band_of_slips_around_the_peak_lifts_it_but_does_not_answer_the_misfit():
    # Over several ABS cycles the samples within 0.75–2 × the fitted peak slip average above the
    # rounded fit's peak: no tyre gives less than that. The band's mean lies below a sharp peak,
    # so the data's excess over the curve still costs confidence as without the lift.
    def run(options):
        return [(e, peak) for t, e, peak in overshooting_abs(options) if t > 0.6
                and e.status in (Status.VALID, Status.CONVERGING)]

    no_floor = dataclasses.replace(LugreTROptions(), peak_group_samples=1, band_floor=False)
    band_only = dataclasses.replace(no_floor, band_floor=True)
    rounded, lifted = run(no_floor), run(band_only)
    errors = [(e.mu_max - peak) / peak for e, peak in lifted]
    assert np.mean([(e.mu_max - peak) / peak for e, peak in rounded]) < -0.15
    assert np.mean(errors) > -0.05 and max(errors) < 0.01
    excess = [e.detail["data_above_fit"] for e, _ in lifted if e.detail]
    assert np.median(excess) > 0.15
    assert np.median(excess) == pytest.approx(np.median([e.detail["data_above_fit"] for e, _ in rounded if e.detail]),
                                              abs=0.01)
    assert not [e for e, _ in lifted if e.status == Status.VALID]


def test_data_above_the_fitted_curve_cost_confidence():
    # The same overshooting ABS: the data rise above the rounded fit in the slips around the peak.
    def run(options):
        return [e for t, e, _ in overshooting_abs(options, seed=4) if t > 1.0 and e.detail]

    measured = run(LugreTROptions())
    ignored = run(dataclasses.replace(LugreTROptions(), misfit_peak_ratio=0.0))
    assert np.median([e.detail["data_above_fit"] for e in measured]) > 0.03
    assert (np.mean([e.confidence for e in measured]) < np.mean([e.confidence for e in ignored]) - 0.05)


def test_the_cars_deceleration_bounds_the_peak_from_below():
    # The wheels' data say a peak of ~0.76; the accelerometer says the car used 0.9 of its weight.
    p = tm.LugreParams(theta=1.45, sigma0=230.0, v_s=5.0, sigma2=0.002)
    rng = np.random.default_rng(5)
    est = LugreTrustRegionEstimator()
    o = est.options
    v, t, published = 25.0, 0.0, []
    while v > 6.0:
        lam_star = tm.peak(v, p)[1]
        slips = [lam_star * (1.0 + 0.55 * math.sin(2 * math.pi * 3.0 * t + i)) for i in range(4)]
        mus = [float(tm.mu(s, v, p)) + float(rng.normal(0, 0.01)) for s in slips]
        e = est.update(PhysicalSample(t, v, tuple(slips), tuple(mus), (4000.0,) * 4, (0.0,) * 4, (True,) * 4,
                                      True, body_mu=0.9))
        if t > 0.2 and e.status in (Status.VALID, Status.CONVERGING):
            published.append(e.mu_max)
        v -= 0.9 * 9.81 * 0.01
        t += 0.01
    floor = 0.9 * (1 - o.body_floor_relative_margin) - o.body_floor_margin
    assert tm.peak(10.0, p)[0] < floor - 0.02       # (the fit alone would be below the bound)
    assert published and min(published) >= floor - 1e-9
