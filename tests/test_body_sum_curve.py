"""The free curve of the car's total tyre force (`body_sum_curve`), where the wheels run deep past
their peaks, and the estimate the body sum gives from it. The truths are Magic Formula and
Burckhardt curves, not a piecewise-linear curve nor the estimator's LuGre."""
import dataclasses
import math

import numpy as np
import pytest

from frictiond.body_sum_curve import AT_EDGE, DRIFTING, FEW_ROWS, NO_FALL, NOT_IN_BOTH_HALVES, fit_curve_sum
from frictiond.body_sum_fit import CURVE_LOST, BodySumResult
from frictiond.estimator import LugreTROptions, LugreTrustRegionEstimator
from frictiond.samples import FrictionEstimate, PhysicalSample, Status

RATE_HZ = 100
LOADS = np.array([4800.0, 4800.0, 3200.0, 3200.0])
SHARES = LOADS / LOADS.sum()


def magic_formula(slip, b=10.0, c=2.2, d=0.9, e=0.3):
    """A sharp Magic Formula peak: 0.9 at slip ≈ 0.1, about 35 % lower at lock."""
    x = b * np.asarray(slip, dtype=float)
    return d * np.sin(c * np.arctan(x - e * (x - np.arctan(x))))


def burckhardt_dry(slip):
    slip = np.asarray(slip, dtype=float)
    return 1.2801 * (1.0 - np.exp(-23.99 * slip)) - 0.52 * slip


def peak_of(curve):
    grid = np.linspace(0.0, 1.0, 100_001)
    values = curve(grid)
    return float(values.max()), float(grid[values.argmax()])


def threshold_abs_slips(t, low=0.02, high=0.9, period=0.25):
    """A threshold ABS's cycles with a slow dump: each wheel swept from `low` to deep slip `high`
    and back, the four out of phase (the wheels of a master-cylinder-only car)."""
    phases = np.array([0.0, 0.3, 0.55, 0.8])
    swing = 0.5 * (1.0 - np.cos(2.0 * np.pi * (t / period + phases)))
    return low + (high - low) * swing ** 2


def rows(curve, slips_of, seconds=1.0, noise=0.01, seed=11, start=0.0):
    rng = np.random.default_rng(seed)
    times = start + np.arange(int(seconds * RATE_HZ)) / RATE_HZ
    slips = np.array([slips_of(t) for t in times])
    body = (SHARES * curve(slips)).sum(axis=1) + noise * rng.standard_normal(len(times))
    return times, slips, np.tile(SHARES, (len(times), 1)), body


@pytest.mark.parametrize("curve", [magic_formula, burckhardt_dry], ids=["magic-formula C 2.2", "burckhardt dry"])
def test_wheels_swept_deep_past_the_peak_give_it(curve):
    peak, _ = peak_of(curve)
    _, slips, shares, body = rows(curve, threshold_abs_slips)
    fit = fit_curve_sum(slips, shares, body)
    assert fit.verdict == ""
    assert fit.mu_max == pytest.approx(peak, rel=0.06)
    # (the sliding level, read at the deepest knot, lies where the tyre's does, not where a shape puts it)
    assert fit.values[-1] == pytest.approx(float(curve(1.0)), abs=0.06)


@pytest.mark.parametrize("share", [0.7, 0.95])
def test_slips_held_short_of_the_peak_show_nothing(share):
    _, peak_slip = peak_of(burckhardt_dry)
    _, slips, shares, body = rows(burckhardt_dry, lambda t: threshold_abs_slips(t, 0.1 * peak_slip, share * peak_slip))
    fit = fit_curve_sum(slips, shares, body)
    assert fit.verdict in (FEW_ROWS, AT_EDGE, NO_FALL)


def test_noise_that_hides_the_fall_past_the_peak_shows_nothing():
    """A flat-topped Burckhardt curve falls 9 % from its peak to lock; with rows as noisy as an
    accelerometer on a rough road (0.15 of μ) the fall is within the knots' errors."""
    _, slips, shares, body = rows(burckhardt_dry, threshold_abs_slips, noise=0.15)
    fit = fit_curve_sum(slips, shares, body)
    assert fit.verdict == NO_FALL


def test_a_road_changing_within_the_window_shows_nothing():
    """Dry for the window's first half, wet (70 % of the grip) for its second: the rows do not
    lie on one curve, whatever the curve."""
    t1, s1, sh1, b1 = rows(magic_formula, threshold_abs_slips, seconds=0.5)
    t2, s2, sh2, b2 = rows(lambda s: 0.7 * magic_formula(s), threshold_abs_slips, seconds=0.5, start=0.5, seed=12)
    fit = fit_curve_sum(np.vstack((s1, s2)), np.vstack((sh1, sh2)), np.concatenate((b1, b2)))
    assert fit.verdict == DRIFTING
    same_road = fit_curve_sum(np.vstack((s1, s2)), np.vstack((sh1, sh2)),
                              np.concatenate((b1, (SHARES * magic_formula(s2)).sum(axis=1))))
    assert same_road.verdict == ""


def test_two_roads_met_at_different_slips_draw_no_peak():
    """Dry asphalt while the wheels' slips stay small, then a wet road where the ABS runs them deep
    (campaign stop 172 with clean sensors): the rows trace the dry curve's rise, then the wet
    one's low tail, a "peak" no tyre had, and one curve fits them both. Its top holds rows only in
    the window's older half."""
    def wet(slip):
        return 0.35 * magic_formula(slip) / 0.9

    _, s1, sh1, b1 = rows(burckhardt_dry, lambda t: np.full(4, 0.02 + 0.06 * (t % 0.25) / 0.25), seconds=0.5)
    _, s2, sh2, b2 = rows(wet, lambda t: threshold_abs_slips(t, 0.25, 0.9), seconds=0.5, start=0.5, seed=12)
    fit = fit_curve_sum(np.vstack((s1, s2)), np.vstack((sh1, sh2)), np.concatenate((b1, b2)))
    assert fit.verdict == NOT_IN_BOTH_HALVES
    assert fit.mu_max > 1.5 * 0.35   # (the "peak" it would have drawn: the dry road's)


def body_samples(curve, slips_of, seconds=2.5, start_speed=25.0, noise=0.01, seed=5, lateral_of=lambda t: 0.0):
    """Samples of a car sending its master cylinder's pressure alone, its ABS working every wheel:
    no wheel's μ measured (`usable` all False), the body's μ from the accelerometer."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(int(seconds * RATE_HZ)):
        t = k / RATE_HZ
        slips = slips_of(t)
        body = float((SHARES * curve(slips)).sum() + noise * rng.standard_normal())
        out.append(PhysicalSample(time_s=t, speed_mps=start_speed - 5.0 * t, slip=tuple(slips.tolist()),
                                  mu_used=(math.nan,) * 4, normal_force_n=tuple(LOADS.tolist()),
                                  tyre_force_n=(0.0,) * 4, usable=(False,) * 4, braking=True,
                                  lateral_mu=lateral_of(t), body_force_mu=body, wheel_torques_unknown=True))
    return out


def test_the_estimator_publishes_the_free_curve_where_the_wheels_run_deep():
    peak, _ = peak_of(magic_formula)
    samples = body_samples(magic_formula, threshold_abs_slips)
    estimator = LugreTrustRegionEstimator()
    estimates = [estimator.update(s) for s in samples]
    valid = [e for e in estimates if e.status == Status.VALID]
    assert len(valid) > 0.3 * len(estimates)
    assert all(abs(e.mu_max / peak - 1.0) < 0.1 for e in valid)
    assert all(e.detail["body_sum_curve_se"] > 0.0 for e in valid)
    # Without the free curve the body sum leaves the deep rows out and shows nothing.
    static_only = LugreTrustRegionEstimator(LugreTROptions(body_sum_curve=False))
    without = [static_only.update(s) for s in samples]
    assert Status.VALID not in {e.status for e in without}
    assert static_only.not_valid_reason.endswith("(wheels deep past the peak)")


def test_a_valid_from_the_curve_goes_at_once_when_the_curve_stops_showing_the_peak():
    """Deep ABS cycles, then the car steered hard into a turn (lateral μ 0.6, past half the peak
    the sum shows: the friction circle no longer gives the road's back). A VALID between two ABS
    cycles is held for one (`excitation_hold_s`); one from the free curve, whose window spans
    several cycles, goes at the first fit that no longer shows its peak."""
    samples = body_samples(magic_formula, threshold_abs_slips, seconds=3.0, lateral_of=lambda t: 0.6 * (t >= 2.0))
    estimator = LugreTrustRegionEstimator()
    estimates, reasons = [], []
    for sample in samples:
        estimates.append(estimator.update(sample))
        reasons.append(estimator.not_valid_reason)
    assert estimates[199].status == Status.VALID
    after = [i for i in range(200, len(estimates)) if estimates[i].status != Status.VALID]
    assert after and after[0] <= 200 + 6   # (the next fit, every 0.05 s)
    assert CURVE_LOST in reasons[after[0]]



def test_grip_used_on_a_road_before_the_curves_window_does_not_hold_its_peak_from_valid():
    """A dry road's grip used early in the stop (its μ 0.95, while the brakes' torques were still
    known), then a wet road under a threshold ABS (peak 0.4). The stop's floor would bar the wet
    curve's peak (it is far below what the car used); the free curve's top is in its own rows, so
    only what the car used within its window bounds it."""
    wet = lambda slip: magic_formula(slip, d=0.4)   # noqa: E731
    peak, _ = peak_of(wet)
    dry_braking = [PhysicalSample(time_s=k / RATE_HZ, speed_mps=30.0, slip=(0.05,) * 4, mu_used=(math.nan,) * 4,
                                  normal_force_n=tuple(LOADS.tolist()), tyre_force_n=(0.0,) * 4,
                                  usable=(False,) * 4, braking=True, body_mu=0.95, body_force_mu=0.95,
                                  wheel_torques_unknown=False)
                   for k in range(50)]
    wet_abs = [dataclasses.replace(s, time_s=s.time_s + 0.5) for s in body_samples(wet, threshold_abs_slips)]
    estimator = LugreTrustRegionEstimator()
    estimates = [estimator.update(s) for s in dry_braking + wet_abs]
    assert estimator._stop_floor() > 1.5 * peak   # (the dry road's grip, less its tolerance)
    valid = [e for e in estimates if e.status == Status.VALID]
    assert len(valid) > 0.3 * len(wet_abs)
    assert all(abs(e.mu_max / peak - 1.0) < 0.1 for e in valid)


def test_a_free_curve_under_what_the_car_used_within_its_window_is_below_the_floor():
    """The floor a body fit must reach: the stop's for the static curve, the window's own
    utilisation, less the accelerometer's and the drag's doubt it is given, the accelerometer's
    margins and the tolerance, for the free curve."""
    estimator = LugreTrustRegionEstimator()
    o = estimator.options
    static = BodySumResult(0.5, 0.1, (0.1,) * 4, 1.0, 0.0, 0.0, (True,) * 4, 0.0, 100, "")
    curve = dataclasses.replace(static, curve_se_share=0.02, window_utilisation=0.6)
    for k in range(10):
        estimator._body_mu.push(0.01 * k, 0.9)
    assert estimator._body_fit_floor(static, 0.04) == estimator._stop_floor() > 0.6
    for doubt in (0.0, 0.04):
        used = (0.6 - doubt) * (1.0 - o.body_floor_relative_margin) - o.body_floor_margin
        assert estimator._body_fit_floor(curve, doubt) == pytest.approx(used * (1.0 - o.stop_floor_tolerance))



def test_in_a_turn_the_friction_circle_gives_the_roads_peak_back():
    """A turn at lateral μ 0.35 on a road of peak 0.9: each tyre has √(1 − (0.35/0.9)²) of its
    longitudinal curve left, the sum's peak 8 % under the road's. The report adds the lateral μ
    back; with `lateral_grip` off the sum in a turn shows nothing."""
    peak, _ = peak_of(magic_formula)
    lateral = 0.35
    left = math.sqrt(1.0 - (lateral / peak) ** 2)
    samples = body_samples(lambda slip: left * magic_formula(slip), threshold_abs_slips, lateral_of=lambda t: lateral)
    estimator = LugreTrustRegionEstimator()
    estimates = [estimator.update(s) for s in samples]
    valid = [e for e in estimates if e.status == Status.VALID]
    assert len(valid) > 0.3 * len(estimates)
    assert all(abs(e.mu_max / peak - 1.0) < 0.05 for e in valid)
    straight_only = LugreTrustRegionEstimator(LugreTROptions(lateral_grip=False))
    without = [straight_only.update(s) for s in samples]
    assert Status.VALID not in {e.status for e in without}
    assert straight_only.not_valid_reason.endswith("(turning)")


def wheel_and_body_samples(curve, slips_of, wheel_scale=1.0, wheel_noise=0.12, seconds=3.0, seed=7, lateral=0.0):
    """A car whose wheels' torques are known: each wheel's μ as its torque balance reads it (times
    `wheel_scale`, with `wheel_noise`: a derivative filter's noise under ABS, enough to keep the
    wheels' fit from VALID), and the body's μ from the accelerometer; in a turn at `lateral` μ,
    what the friction circle leaves of the curve."""
    peak, _ = peak_of(curve)
    curve = (lambda c, left: lambda slip: left * c(slip))(curve, math.sqrt(1.0 - (lateral / peak) ** 2))
    rng = np.random.default_rng(seed)
    out = []
    for k in range(int(seconds * RATE_HZ)):
        t = k / RATE_HZ
        slips = slips_of(t)
        mus = wheel_scale * curve(slips) + wheel_noise * rng.standard_normal(4)
        body = float((SHARES * curve(slips)).sum() + 0.01 * rng.standard_normal())
        out.append(PhysicalSample(time_s=t, speed_mps=25.0 - 5.0 * t, slip=tuple(slips.tolist()),
                                  mu_used=tuple(mus.tolist()), normal_force_n=tuple(LOADS.tolist()),
                                  tyre_force_n=tuple((mus * LOADS).tolist()), usable=(True,) * 4, braking=True,
                                  lateral_mu=lateral, body_force_mu=body, wheel_torques_unknown=False))
    return out


def statuses_and_sources(estimator, samples):
    out = []
    for sample in samples:
        e = estimator.update(sample)
        out.append((e.status, bool(e.detail and e.detail.get("body_curve")), e.mu_max))
    return out


def curve_valids_near_the_peak(samples, within):
    """The free curve's VALID outputs beside the wheels' fit over `samples` (more than 30, each
    within `within` of the Magic Formula tyre's peak)."""
    peak, _ = peak_of(magic_formula)
    beside = statuses_and_sources(LugreTrustRegionEstimator(), samples)
    from_curve = [mu for status, curve, mu in beside if status == Status.VALID and curve]
    assert len(from_curve) > 30
    assert all(abs(mu / peak - 1.0) < within for mu in from_curve)
    return from_curve


def test_beside_a_wheels_fit_that_agrees_the_free_curve_gives_the_valid():
    """Threshold-ABS cycles on a sharp Magic Formula tyre, the wheels' μ too noisy for their fit
    to be VALID: the car's total force shows the peak, and where the wheels' fit puts it within
    15 %, the curve's estimate is VALID. Off, or with the wheels reading 35 % low (a fit that
    disagrees), it is not."""
    samples = wheel_and_body_samples(magic_formula, threshold_abs_slips)
    from_curve = curve_valids_near_the_peak(samples, within=0.1)
    alone = statuses_and_sources(LugreTrustRegionEstimator(LugreTROptions(body_curve_beside_wheels=False)), samples)
    assert not any(curve for _, curve, _ in alone)
    assert sum(status == Status.VALID for status, _, _ in alone) < len(from_curve)
    low_wheels = wheel_and_body_samples(magic_formula, threshold_abs_slips, wheel_scale=0.65)
    assert not any(curve for _, curve, _ in statuses_and_sources(LugreTrustRegionEstimator(), low_wheels))


def test_beside_a_wheels_fit_in_a_turn_the_curve_is_read_by_the_friction_circle():
    """The same in a turn at lateral μ 0.35: both sources read the longitudinal curve 8 % under the
    road's, and both add the lateral μ back, so the curve's VALID is the road's peak. With
    `lateral_grip` off the curve says "turning" and gives none."""
    samples = wheel_and_body_samples(magic_formula, threshold_abs_slips, lateral=0.35)
    curve_valids_near_the_peak(samples, within=0.05)
    straight_only = statuses_and_sources(LugreTrustRegionEstimator(LugreTROptions(lateral_grip=False)), samples)
    assert not any(curve for _, curve, _ in straight_only)


@pytest.mark.parametrize("used_in_window, doubt, valid", [(0.45, 0.0, True), (0.7, 0.0, False), (0.62, 0.02, True),
                                                           (0.62, 0.0, False)])
def test_beside_a_wheels_fit_the_curve_is_held_to_the_grip_used_within_its_window(used_in_window, doubt, valid):
    """The same rule beside the wheels' fit: the car used 0.9 earlier in the stop (another road,
    the change unseen by the wheels' fit), the free curve shows a peak of 0.5, the wheels' fit
    agrees (CONVERGING at 0.52). The stop's floor would bar it; what bounds it is the grip used
    among the curve's own rows, less this sample's accelerometer and drag doubt (not a doubt
    left from a stop the body sum read: 0.1 here)."""
    estimator = LugreTrustRegionEstimator()
    estimator._body_force_doubt = 0.1
    for k in range(10):
        estimator._body_mu.push(0.01 * k, 0.9)
    assert estimator._stop_floor() > 0.6
    fit = BodySumResult(0.5, 0.1, (0.1,) * 4, 1.0, 0.01, 0.0, (True,) * 4, 0.0, 100, "",
                        curve_se_share=0.01, window_utilisation=used_in_window)
    estimator._body_curve.result = lambda now_s, speed: fit
    wheels = FrictionEstimate(1.0, Status.CONVERGING, 0.52, 0.1, 1.0, 0.3)
    sample = PhysicalSample(time_s=1.0, speed_mps=20.0, slip=(0.1,) * 4, mu_used=(0.5,) * 4,
                            normal_force_n=tuple(LOADS.tolist()), tyre_force_n=(0.0,) * 4, usable=(True,) * 4,
                            braking=True, body_force_mu=0.5, wheel_torques_unknown=False, body_force_doubt=doubt)
    out = estimator._beside_body_curve(wheels, sample)
    assert (out.status == Status.VALID) is valid
    assert out.mu_max == (0.5 if valid else 0.52)
