"""Estimators on synthetic samples with known parameters (no CAN, no front end)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from frictiond import not_valid
from frictiond import tyre_model as tm
from frictiond.baseline_rls import BurckhardtRLSEstimator, burckhardt_peak
from frictiond.estimator import LugreTROptions, LugreTrustRegionEstimator
from frictiond.samples import FrictionEstimate, PhysicalSample, Status
from frictiond.wheel_verdicts import CONTRADICTED, REAR_CROSSING


def braking(curves, *, v0=25.0, slip_scale=1.0, noise=0.02, seed=0, duration=None, speed_floor=4.0,
            abs_flags=True):
    """ABS-like slip cycling around each wheel's own peak; curves[i](slip, v) -> μ, peaks[i](v) -> λ*.
    `abs_flags`: the samples say an ABS works every wheel, as the front end does from the pressures
    (slip cycling that never runs on to lock-up is an ABS's work, and its releases are the evidence)."""
    rng = np.random.default_rng(seed)
    t, v = 0.0, v0
    while v > speed_floor and (duration is None or t < duration):
        slips, mus = [], []
        for i in range(4):
            mu_fn, lam_fn = curves(t, i)
            lam = lam_fn(v) * slip_scale * (1.0 + 0.55 * math.sin(2 * math.pi * 3.0 * t + i))
            slips.append(float(lam))
            mus.append(float(mu_fn(lam, v)) + float(rng.normal(0, noise)))
        yield PhysicalSample(t, v, tuple(slips), tuple(mus), (4000.0,) * 4, (0.0,) * 4, (True,) * 4, True,
                             abs_active=(abs_flags,) * 4)
        v -= max(0.5, float(np.mean(mus))) * 9.81 * 0.01
        t += 0.01


def campaign_stop_estimates(seed, relaxation_compensation=True, family=None, **lugre_options):
    """One stop of the randomised campaign (its car, DBC and config; `family` as `draw_stop`'s;
    `lugre_options` replacing `LugreTROptions` fields) through the replay pipeline: (the simulated
    stop, lugre-tr's estimates). In still air, with the four wheel speeds in one message and the
    cycle times in the DBC, as the stops these tests tell of were found (the campaign's wind,
    split wheel messages and DBCs without cycle times came later), on level ground with the front
    end told so (`level_road`: the campaign's grades came later too)."""
    from dataclasses import replace

    from frictiond.campaign.draw import draw_stop
    from frictiond.campaign.simulate import simulate_stop
    from frictiond.replay import estimates_of

    spec = draw_stop(seed, family)
    stop = simulate_stop(replace(spec, wind_mps=0.0, grade=0.0, sensors=replace(spec.sensors, wheel_messages="one",
                                                                                cycle_times_in_dbc=True)))
    config = with_lugre_options(stop.config("lugre-tr"), **lugre_options)
    config = replace(config, frontend=replace(config.frontend, relaxation_compensation=relaxation_compensation,
                                              level_road=True))
    _pipeline, estimates = estimates_of(config, stop.frames)
    return stop, estimates


def with_lugre_options(config, **lugre_options):
    """`config` with `lugre_options` replacing its `LugreTROptions` fields."""
    estimator = config.estimator
    return dataclasses.replace(config, estimator=dataclasses.replace(
        estimator, lugre_tr=dataclasses.replace(estimator.lugre_tr, **lugre_options)))


def lugre_curve(p):
    return (lambda lam, v: tm.mu(lam, v, p)), (lambda v: tm.peak(v, p)[1])


def run(est, samples, truth):
    errors, statuses = [], []
    for s in samples:
        e = est.update(s)
        statuses.append(e.status)
        if e.status == Status.VALID and s.time_s > 0.5:
            errors.append(abs(e.mu_max - truth(s)))
    return e, np.array(errors), statuses


@pytest.mark.parametrize("theta", [1.0, 1.6, 3.5, 8.0])
def test_recovers_peak_of_its_own_model(theta):
    p = tm.LugreParams(theta=theta, sigma0=230.0, v_s=5.0, sigma2=0.002)
    curve = lugre_curve(p)
    est = LugreTrustRegionEstimator()
    last, errors, statuses = run(est, braking(lambda t, i: curve, seed=1), lambda s: tm.peak(s.speed_mps, p)[0])
    mu_true = tm.peak(5.0, p)[0]
    assert statuses.count(Status.VALID) > 0.6 * len(statuses)
    assert np.mean(errors) < 0.03 * mu_true + 0.005
    # θ trades off against σ2 and v_s (not separately identifiable); the peak is what must match.
    assert last.mu_max == pytest.approx(mu_true, rel=0.05)


@pytest.mark.parametrize("theta", [25.0, 60.0])
def test_recovers_an_ice_peak_far_from_the_prior(theta):
    # θ ≈ 25 (μ_max ≈ 0.05) is twenty times the nominal θ: a prior that held θ in absolute
    # terms stalled such fits at about twice the true μ_max. θ = 60 (μ_max ≈ 0.02, polished ice)
    # lies beyond where θ's bound once was (40): the fit sat on the bound, 20 % high, VALID.
    p = tm.LugreParams(theta=theta, sigma0=400.0, v_s=5.0, sigma2=0.0001)
    curve = lugre_curve(p)
    est = LugreTrustRegionEstimator()
    last, errors, statuses = run(est, braking(lambda t, i: curve, seed=3, noise=0.05 / theta, v0=15.0),
                                 lambda s: tm.peak(s.speed_mps, p)[0])
    mu_true = tm.peak(5.0, p)[0]
    assert statuses.count(Status.VALID) > 0.5 * len(statuses)
    assert np.mean(errors) < 0.1 * mu_true
    assert last.mu_max == pytest.approx(mu_true, rel=0.1)


def test_low_slip_braking_never_claims_a_wrong_peak():
    # Moderate braking at a fifth of the peak slip: at speed the curve is still near-linear there
    # and nothing may be VALID; at walking pace LuGre's flat top is already at ~90 % of μ_max,
    # where a VALID estimate is allowed — but only an accurate one.
    p = tm.LugreParams(theta=1.3)
    curve = lugre_curve(p)
    est = LugreTrustRegionEstimator()
    for s in braking(lambda t, i: curve, slip_scale=0.2, seed=2, abs_flags=False):
        e = est.update(s)
        if e.status == Status.VALID:
            assert s.speed_mps < 10.0
            assert e.mu_max == pytest.approx(tm.peak(s.speed_mps, p)[0], rel=0.1)


def test_split_mu_shows_per_wheel():
    high, low = tm.LugreParams(theta=1.1), tm.LugreParams(theta=4.0)
    curves = {0: lugre_curve(high), 2: lugre_curve(high), 1: lugre_curve(low), 3: lugre_curve(low)}
    est = LugreTrustRegionEstimator()
    last, _, _ = run(est, braking(lambda t, i: curves[i], seed=3), lambda s: 0.0)
    left, right = last.wheel_mu_max[0], last.wheel_mu_max[1]
    v = 5.0
    assert left == pytest.approx(tm.peak(v, high)[0], rel=0.08)
    assert right == pytest.approx(tm.peak(v, low)[0], rel=0.12)


def test_reconverges_after_a_mu_jump():
    dry, wet = tm.LugreParams(theta=1.0), tm.LugreParams(theta=1.8)
    jump_t = 1.5
    est = LugreTrustRegionEstimator()
    times = []
    for s in braking(lambda t, i: lugre_curve(dry if t < jump_t else wet), seed=4, v0=30.0):
        e = est.update(s)
        truth = tm.peak(s.speed_mps, dry if s.time_s < jump_t else wet)[0]
        if s.time_s > jump_t and e.status == Status.VALID:
            times.append((s.time_s, abs(e.mu_max - truth) / truth))
    settled = next(t for t, err in times if all(e2 < 0.1 for t2, e2 in times if t <= t2 <= t + 0.3))
    assert settled - jump_t < 0.5
    # and no VALID output far off after the jump has been absorbed
    assert max(err for t, err in times if t > jump_t + 0.5) < 0.1


def test_a_change_of_road_crossing_the_wheelbase_is_followed_to_the_rear_axle():
    """The front axle reaches ice 0.12 s before the rear (a wheelbase at ~20 m/s): two jumps, the
    second within the first's refractory time if that were longer than the crossing, and the fit
    on the ice soon after. (Whether it is VALID then is the confidence's matter: 0.02 of noise
    on a μ of 0.05, from half a second of samples, leaves it short of even odds within 10 %.)"""
    dry, ice = lugre_curve(tm.LugreParams(theta=1.0)), lugre_curve(tm.LugreParams(theta=25.0))
    front_t, rear_t = 1.5, 1.62
    truth = tm.peak(10.0, tm.LugreParams(theta=25.0))[0]
    est = LugreTrustRegionEstimator()
    first_right = None
    for s in braking(lambda t, i: ice if t >= (rear_t if i >= 2 else front_t) else dry, v0=25.0, seed=3):
        e = est.update(s)
        if first_right is None and s.time_s > rear_t and abs(e.mu_max - truth) < 0.1 * truth:
            first_right = s.time_s - rear_t
    assert est._jumps == 2
    assert first_right is not None and first_right < 0.45   # 0.56 s with a 0.3 s refractory time


def test_a_blind_stretch_after_a_change_of_road_does_not_bring_back_the_old_roads_fit():
    """The wheels' samples unusable from the moment a change of road (dry to ice) is detected:
    the stop's last fit described the old road, so the window's shortage gives the prior
    (NOT_EXCITED), not that fit restated as CONVERGING."""
    dry, ice = lugre_curve(tm.LugreParams(theta=1.0)), lugre_curve(tm.LugreParams(theta=25.0))
    est = LugreTrustRegionEstimator()
    after = []
    for s in braking(lambda t, i: ice if t >= 1.5 else dry, v0=25.0, seed=3, duration=2.2):
        if est._jumps == 0:
            est.update(s)
        else:
            after.append(est.update(dataclasses.replace(s, usable=(False,) * 4)))
    assert len(after) > 20
    assert all(e.status == Status.NOT_EXCITED for e in after)


def test_the_rear_wheels_show_no_peak_while_their_axle_crosses_a_change_of_road():
    """After a change of road is detected the rear axle meets it a wheelbase later (2.7 m here):
    till then, and till the rear wheels' newest excitation window lies past it, their data mix
    the two roads and show no peak; the front wheels' verdicts go on as before. A second change
    detected meanwhile is the rear axle meeting it: the samples kept after it are past the change."""
    dry, ice = lugre_curve(tm.LugreParams(theta=1.0)), lugre_curve(tm.LugreParams(theta=25.0))
    front_t, rear_t = 1.5, 1.62
    est = LugreTrustRegionEstimator()
    o, wheelbase = est.options, est.vehicle.wheelbase
    jump_times, crossing_whys, other_rear_whys, front_whys = [], [], [], []
    for s in braking(lambda t, i: ice if t >= (rear_t if i >= 2 else front_t) else dry, v0=25.0, seed=3):
        e = est.update(s)
        if est._jumps != len(jump_times):
            jump_times.append(s.time_s)
        if not jump_times:
            continue
        assert not (e.status == Status.VALID and s.time_s >= front_t
                    and abs(e.mu_max / tm.peak(s.speed_mps, tm.LugreParams(theta=25.0))[0] - 1.0) > 0.2)
        why = [w if isinstance(w, str) else w[0] for w in est._excitation_why]
        crossing_whys += [s.time_s for w in why[2:] if w == REAR_CROSSING]
        other_rear_whys += [s.time_s for w in why[2:] if w and w != REAR_CROSSING]
        front_whys += why[:2]
    first, second = jump_times   # (the front axle's change, then the rear axle's: 2.7 m at ~23 m/s later)
    assert second < first + wheelbase / 20.0 + o.excitation_window_s
    assert crossing_whys and min(crossing_whys) < first + 0.05
    # (the verdicts are refreshed every `excitation_every` fits: the last may stand a few samples)
    assert max(crossing_whys) <= second + 0.05
    assert any(t > second + 0.05 for t in other_rear_whys)
    assert REAR_CROSSING not in front_whys


def test_state_round_trip_is_used_as_prior():
    p = tm.LugreParams(theta=2.5)
    curve = lugre_curve(p)
    est = LugreTrustRegionEstimator()
    run(est, braking(lambda t, i: curve, seed=5), lambda s: 0.0)
    state = est.state()
    fresh = LugreTrustRegionEstimator()
    fresh.load_state(state)
    assert fresh.state()["parameters"]["theta_fl"] == pytest.approx(state["parameters"]["theta_fl"])
    with pytest.raises(ValueError):
        fresh.load_state({"kind": "lugre-tr", "parameters": {"theta_fl": "x"}})
    with pytest.raises(ValueError):
        fresh.load_state({"kind": "other"})


def test_options_are_validated():
    with pytest.raises(ValueError):
        LugreTrustRegionEstimator(LugreTROptions(prior_theta=500.0))
    with pytest.raises(ValueError):
        LugreTrustRegionEstimator(LugreTROptions(max_iterations=0))
    with pytest.raises(ValueError, match="prior_std_log_theta"):
        LugreTrustRegionEstimator(LugreTROptions(prior_std_log_theta=0.0))
    with pytest.raises(ValueError, match="rising_elasticity"):
        LugreTrustRegionEstimator(LugreTROptions(flat_elasticity=0.35, rising_elasticity=0.3))


def test_baseline_recovers_burckhardt_peak():
    c1, c2, c3 = 0.857, 33.822, 0.347
    mu_true, lam_true = burckhardt_peak(c1, c2, c3)
    curve = (lambda lam, v: c1 * (1 - np.exp(-c2 * lam)) - c3 * lam), (lambda v: lam_true)
    est = BurckhardtRLSEstimator()
    last, errors, statuses = run(est, braking(lambda t, i: curve, seed=6), lambda s: mu_true)
    assert statuses.count(Status.VALID) > 0.6 * len(statuses)
    assert np.mean(errors) < 0.05


def test_new_braking_event_needs_its_own_evidence():
    """A wet stop, free rolling, then braking on dry: the wet fit must not be VALID at the onset.

    The learned parameters stay as the warm start, but the excitation (and the VALID it allows)
    must come from the new event's samples. During the long free rolling the old VALID expires
    to NOT_EXCITED (which carries the last valid value, not to be trusted).
    """
    wet, dry = tm.LugreParams(theta=2.2), tm.LugreParams(theta=1.0)
    est = LugreTrustRegionEstimator()
    run(est, braking(lambda t, i: lugre_curve(wet), seed=7, duration=2.0), lambda s: 0.0)
    rolling = [est.update(PhysicalSample(2.0 + k * 0.01, 25.0, (0.0,) * 4, (0.0,) * 4, (0.0,) * 4, (0.0,) * 4,
                                         (True,) * 4, True)) for k in range(500)]
    assert rolling[-1].status == Status.NOT_EXCITED and rolling[-1].confidence == 0.0
    lam_star = tm.peak(25.0, dry)[1]
    t0, wrong, valid = 7.0, [], 0
    rng = np.random.default_rng(8)
    for k in range(60):     # brake onset: the slip ramps through the linear region to the peak
        t = t0 + k * 0.01
        lam = min(1.0, k / 25.0) * lam_star * (1.0 + (0.3 * math.sin(2 * math.pi * 3.0 * t) if k > 25 else 0.0))
        mu = float(tm.mu(lam, 25.0, dry))
        e = est.update(PhysicalSample(t, 25.0, (lam,) * 4, tuple(mu + float(rng.normal(0, 0.01)) for _ in range(4)),
                                      (4000.0,) * 4, (0.0,) * 4, (True,) * 4, True))
        truth = tm.peak(25.0, dry)[0]
        if e.status == Status.VALID:
            valid += 1
            if abs(e.mu_max - truth) > 0.2 * truth:
                wrong.append((round(t - t0, 3), round(e.mu_max, 3), round(truth, 3)))
    assert not wrong, wrong[:5]


def test_clock_step_back_does_not_extend_the_hold_of_valid():
    """The clock jumps back 1 h after a stop: a VALID is held `hold_s` as usual, not for an hour."""
    est = LugreTrustRegionEstimator()
    last, _, _ = run(est, braking(lambda t, i: lugre_curve(tm.LugreParams(theta=1.2)), seed=7, duration=2.0),
                     lambda s: 0.0)
    assert last.status == Status.VALID
    statuses = [est.update(PhysicalSample(2.0 - 3600.0 + k * 0.01, 25.0, (0.0,) * 4, (0.0,) * 4, (0.0,) * 4,
                                          (0.0,) * 4, (True,) * 4, True)).status for k in range(500)]
    assert statuses[0] == Status.VALID
    assert statuses[-1] == Status.NOT_EXCITED


def test_window_jacobian_matches_finite_differences():
    # The fit's analytic rows (∂μ/∂ln θ per wheel, ∂μ/∂σ0, v_s, σ2 scaled) and the normal
    # equations built from them, against central differences of the residuals.
    p = tm.LugreParams(theta=2.0, sigma0=230.0, v_s=5.0, sigma2=0.002)
    curve = lugre_curve(p)
    est = LugreTrustRegionEstimator()
    for s in braking(lambda t, i: curve, seed=4, duration=0.6):
        est.update(s)
    slip, speeds, mu, times, wheel = est._window.view()
    sw = np.sqrt(est._weights(float(times[-1]), times)) / est.options.measurement_std
    x = est._x + np.array([0.1, -0.2, 0.3, 0.05, 0.1, -0.1, 0.2])
    r, J = est._residuals(x, slip, speeds, mu, sw, wheel)
    cost, grad, normal, _ = est._normal(x, sw)
    assert cost == pytest.approx(0.5 * float(r @ r), rel=1e-10)
    np.testing.assert_allclose(grad, J.T @ r, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(normal, J.T @ J, rtol=1e-8, atol=1e-8)
    h = 1e-6
    for i in range(len(x)):
        d = np.zeros_like(x)
        d[i] = h
        numeric = (est._residuals(x + d, slip, speeds, mu, sw, wheel)[0]
                   - est._residuals(x - d, slip, speeds, mu, sw, wheel)[0]) / (2 * h)
        np.testing.assert_allclose(J[:, i], numeric, rtol=1e-5, atol=1e-6 * np.abs(J).max())


def test_a_cycle_without_usable_wheels_keeps_the_running_fit():
    # Wheels deep in slip (or a lost frame) give no usable sample for a while: the untrusted
    # fit stands, CONVERGING, while the brakes stay applied, also once its samples have left
    # the window, instead of the nominal prior's peak (NOT_EXCITED: no excursion seen yet).
    p = tm.LugreParams(theta=6.0)
    curve = lugre_curve(p)
    est = LugreTrustRegionEstimator()
    samples = list(braking(lambda t, i: curve, slip_scale=0.2, seed=5, duration=1.6, abs_flags=False))
    for s in samples[:50]:
        fitted = est.update(s)
    assert fitted.status == Status.CONVERGING
    held = [est.update(dataclasses.replace(s, usable=(False,) * 4)) for s in samples[50:]]
    assert held[-1].time_s - fitted.time_s > est.options.window_s   # (the window ran dry)
    assert all(e.status == Status.CONVERGING and e.mu_max == fitted.mu_max for e in held)
    # The brakes released: the fit stands for `window_s`, then the prior again; and a stop begun
    # after that does not bring the last stop's fit back.
    end = held[-1].time_s
    released = [est.update(dataclasses.replace(samples[-1], time_s=end + 0.01 * k, braking=False,
                                               usable=(False,) * 4)) for k in range(1, 121)]
    prior_from = next(e.time_s for e in released if e.status == Status.NOT_EXCITED)
    assert prior_from - end == pytest.approx(est.options.window_s, abs=0.02)
    assert released[-1].mu_max != fitted.mu_max
    again = est.update(dataclasses.replace(samples[-1], time_s=end + 1.3, usable=(False,) * 4))
    assert again.status == Status.NOT_EXCITED and again.mu_max == released[-1].mu_max


@pytest.mark.parametrize("every", [0, 1, 2, 3])
def test_slow_refreshes_run_at_any_excitation_cadence(every):
    # Slip range, excitation and covariance are refreshed every `excitation_every` fits (every fit
    # for 0 or 1); with 0 or 1 the slip range was once computed on the first fit only (too few
    # samples then: no extrapolation bound for the rest of the stop).
    p = tm.LugreParams(theta=1.3)
    curve = lugre_curve(p)
    est = LugreTrustRegionEstimator(LugreTROptions(excitation_every=every))
    for s in braking(lambda t, i: curve, seed=1, duration=1.5):
        est.update(s)
    assert np.isfinite(est._slip_support).all()


def test_quantile_pair_matches_numpy():
    from frictiond.peak_evidence import _quantile_pair
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 10, 11, 57, 300):
        for _ in range(20):
            values = rng.normal(size=n)
            low, high = _quantile_pair(values.copy(), 0.1, 0.9)
            assert (low, high) == pytest.approx(tuple(np.quantile(values, (0.1, 0.9))), abs=1e-12)


def test_a_settling_fit_becomes_valid_while_the_abs_releases_every_wheel():
    """Excited, CONVERGING only until its confidence ramp has run, then a cycle-long gap with no
    usable sample (ABS on ice releases all wheels together): the fit is restated with its
    confidence brought up to date: VALID, with the same μ_max."""
    p = tm.LugreParams(theta=1.6)
    curve = lugre_curve(p)
    est = LugreTrustRegionEstimator()
    last = None
    for s in braking(lambda t, i: curve, seed=4):
        last = est.update(s)
        if last.status == Status.CONVERGING and last.detail.get("excitation", 0.0) > 0:
            break
    assert last is not None and last.status == Status.CONVERGING
    t0, v = s.time_s, s.speed_mps
    statuses = []
    for k in range(1, 60):
        gap = PhysicalSample(t0 + 0.01 * k, v, s.slip, s.mu_used, (4000.0,) * 4, (0.0,) * 4, (False,) * 4, True)
        e = est.update(gap)
        statuses.append((0.01 * k, e.status, e.mu_max))
    valid = [t for t, status, _ in statuses if status == Status.VALID]
    assert valid and valid[0] <= 0.2
    assert all(mu == last.mu_max for _, status, mu in statuses if status == Status.VALID)


def test_valid_has_hysteresis_but_a_low_confidence_still_ends_it(monkeypatch):
    """Once VALID, a dip of the confidence to between `keep_valid_confidence` and
    `valid_confidence` keeps VALID (no one-cycle flicker); below it, CONVERGING; and from
    CONVERGING the full `valid_confidence` is needed again."""
    p = tm.LugreParams(theta=1.6)
    curve = lugre_curve(p)
    est = LugreTrustRegionEstimator()
    o = est.options
    samples = braking(lambda t, i: curve, seed=4)
    for s in samples:
        if est.update(s).status == Status.VALID:
            break
    else:
        pytest.fail("never VALID")
    between = 0.5 * (o.keep_valid_confidence + o.valid_confidence)
    script = iter([between, between, 0.5 * o.keep_valid_confidence, between, 0.9])
    monkeypatch.setattr(est, "_confidence", lambda *args: next(script))
    statuses = []
    for s in samples:
        e = est.update(s)
        if est._last_fit_s == s.time_s:      # a fitted update (each consumed one scripted value)
            statuses.append(e.status)
        if len(statuses) == 5:
            break
    assert statuses == [Status.VALID, Status.VALID, Status.CONVERGING, Status.CONVERGING, Status.VALID]


def test_keep_valid_confidence_cannot_exceed_valid_confidence():
    with pytest.raises(ValueError, match="keep_valid_confidence"):
        LugreTrustRegionEstimator(LugreTROptions(valid_confidence=0.5, keep_valid_confidence=0.6))


def test_a_one_cycle_dip_of_the_fit_is_not_counted_again_a_drift_window_later():
    """The drift term compares μ_max with the fits of `drift_window_s` ago: a fit that dipped 6 %
    for one cycle (an ABS release) lowers the confidence then, but not again when it becomes the
    oldest fit in the window (the median of the fits around then is the reference)."""
    est = LugreTrustRegionEstimator()
    o = est.options
    est._excited_since_s = 0.0
    dip_t = 0.3
    confidence = {}
    for k in range(80):
        t = round(0.01 * k, 2)
        mu = 0.094 if t == dip_t else 0.1
        confidence[t] = est._confidence(t, mu, 0.001, 1.0)
    settled = confidence[0.79]
    assert confidence[dip_t] < 0.9 * settled            # the dip itself costs confidence
    later = round(dip_t + o.drift_window_s, 2)
    assert min(confidence[round(later + d, 2)] for d in (-0.02, -0.01, 0.0, 0.01, 0.02)) > 0.95 * settled


def test_a_full_window_drops_its_oldest_quarter_and_keeps_taking_samples():
    # A long window_s at a high update rate fills the preallocated columns; appending must go on
    # (it failed with an IndexError once the columns were full).
    from frictiond.estimator import _Window

    w = _Window(capacity=16)
    for k in range(40):
        w.append(0.01 * (k + 1), 20.0, 0.5, 0.001 * k, k % 4)
        assert len(w) <= 16
    slip, _, _, times, wheel = w.view()
    assert len(w) >= 12 and times[-1] == pytest.approx(0.039) and wheel[-1] == 39 % 4
    assert list(times) == sorted(times) and slip[-1] == pytest.approx(0.40)


@pytest.mark.parametrize("window_s, period_s", [(0.8, 0.01), (20.0, 0.004), (60.0, 0.02)])
def test_the_window_has_room_for_window_s_of_four_wheels(window_s, period_s):
    est = LugreTrustRegionEstimator(dataclasses.replace(LugreTROptions(), window_s=window_s), sample_period_s=period_s)
    assert est._window.capacity >= 4 * window_s / period_s


def test_a_restated_fit_below_the_grip_the_car_used_or_with_the_brakes_let_go_is_not_made_valid():
    # A cycle without usable samples restates the last CONVERGING fit, and may promote it when
    # its evidence is recent and only its settling held it back; not when the car has used more
    # grip this stop than the fit claims (a bad last fit at walking pace, say), nor while the
    # driver lets go of the brakes, no wheel left in slip (waiting adds no evidence).
    def restated(highest, slipping=True):
        est = LugreTrustRegionEstimator()
        now = 5.0
        last = FrictionEstimate(now - 0.01, Status.CONVERGING, 0.22, 0.1, 1.0, 0.4, (0.22,) * 4, 0.002)
        est._excitation_cache = 1.0
        est._last_fit_s = now - 0.01
        est._excited_since_s = now - 1.0
        for k in range(30):
            est._mu_history.append((now - 0.3 + 0.01 * k, 0.22))
        est._body_mu.highest = highest
        return est._restate(last, now, slipping)

    assert restated(0.0).status == Status.VALID
    below = restated(0.45)
    assert below.status == Status.CONVERGING and below.confidence < 0.5
    released = restated(0.0, slipping=False)
    assert released.status == Status.CONVERGING and released.confidence == 0.4   # (the fit's own, as it was)


@pytest.mark.parametrize("after, confirmed", [
    ("stays", False),          # the linear region's transient (a relaxing tyre as the pedal goes down)
    ("locks", True),           # past the peak the slip runs on towards lock-up
    ("back", False),           # falls back: a released wheel, or a relaxing tyre's force catching up
])
def test_a_runaway_counts_once_the_wheel_runs_on_towards_lock_up(after, confirmed):
    est = LugreTrustRegionEstimator()
    est._last_sample_s = 1.0
    assert not est._runaway_confirmed(0, True, 0.10)        # a candidate, not yet evidence
    for k in range(1, 40):
        t = 1.0 + 0.005 * k
        slip = {"stays": 0.10, "locks": 0.10 + 0.01 * k, "back": max(0.03, 0.10 - 0.005 * k)}[after]
        est._follow_runaways(t, (slip, 0.0, 0.0, 0.0))
    est._last_sample_s = 1.2
    assert est._runaway_confirmed(0, False, 0.10) is confirmed


def _soft_magic_formula(b=6.5, c=1.47, d=0.32, e=0.3):
    """A snow-like Magic Formula curve, its peak far out at λ ≈ 0.33 (utilisation 0.7 at λ = 0.09)."""
    def mu(lam, v):
        x = b * lam
        return d * math.sin(c * math.atan(x - e * (x - math.atan(x))))
    grid = np.linspace(1e-4, 1.0, 100001)
    peak_slip = float(grid[np.argmax([mu(g, 0.0) for g in grid[::100]]) * 100])
    return mu, peak_slip, d


@pytest.mark.parametrize("at_peak", [False, True])
def test_an_abs_releasing_below_a_soft_peak_is_not_evidence_of_it(at_peak):
    # An ABS holding the slips at 0.04-0.14 on a snow curve whose peak lies at 0.33: the wheels
    # use at most 80 % of the grip, and the top of their slips still shows μ rising at ~0.6 of its
    # secant. The releases are the ABS's, not the tyre's: no excitation, nothing VALID. The same
    # ABS cycling around the peak itself is evidence, and its estimate is right.
    mu, peak_slip, peak_mu = _soft_magic_formula()
    curve = (mu, lambda v: peak_slip / 2.0 if at_peak else 0.09)
    est = LugreTrustRegionEstimator()
    valid, excited = [], []
    for s in braking(lambda t, i: curve, v0=20.0, noise=0.004, seed=5):
        e = est.update(s)
        excited.append(e.detail.get("excitation", 0.0) if e.detail else 0.0)
        if e.status == Status.VALID:
            valid.append(e.mu_max)
    if at_peak:
        assert len(valid) > 50
        assert np.median(valid) == pytest.approx(peak_mu, rel=0.1)
    else:
        assert max(excited) == 0.0 and valid == []


def test_a_deceleration_abs_releasing_below_a_soft_peak_gives_no_wrong_valid():
    # The campaign's development stop 40: a wheel-deceleration ABS on a split road, dry on one
    # side with a soft Magic Formula curve (B 4.3, C 2.2: its peak far out in slip), snow on the
    # other. The ABS releases the dry wheels at 45-75 % of their grip; their top slips show μ
    # still rising. Before the top-of-slips test, 299 of 461 VALID outputs were 20-40 % low.
    # The snow wheels do show their peak, but the published mean of the four would rest on the
    # dry wheels' extrapolation: excited, yet never VALID.
    from frictiond.campaign.score import estimator_scores

    # (The veto is tested on the samples as measured: the relaxation compensator, its σ pooled over
    # both sides' roads, reads a 0.1-0.2 m lag into this tyre, which has none, and the excitation
    # then never comes.)
    stop, estimates = campaign_stop_estimates(40, relaxation_compensation=False)
    scores = estimator_scores(estimates, stop.truth)
    assert scores["false_valid"] == 0
    assert any(e.detail and e.detail.get("excitation", 0.0) > 0 for e in estimates)


def test_a_withdrawn_valid_is_not_held_again_when_no_sample_is_usable():
    # The campaign's development stop 535: a slip-threshold ABS, wet Magic Formula road, then ice
    # at 110 km/h. On the ice every wheel runs deep into slip (none usable); the window aged out
    # of its last CONVERGING fit and the hold brought back the wet road's VALID 0.59 for a second,
    # 7 times the ice's 0.08 (59 of 74 VALID outputs).
    from frictiond.campaign.score import estimator_scores

    stop, estimates = campaign_stop_estimates(535)
    assert stop.spec.jump_kind == "to-ice"
    scores = estimator_scores(estimates, stop.truth)
    assert scores["false_valid"] == 0
    # ... and the statuses never go VALID → not VALID → VALID without a fit in between.
    for before, between, after in zip(estimates, estimates[1:], estimates[2:]):
        if before.status == Status.VALID and between.status != Status.VALID and after.status == Status.VALID:
            assert after.mu_max != before.mu_max


@pytest.mark.parametrize("first_s", [1.50, 1.51, 1.52, 1.53])
def test_a_brake_applied_again_after_a_pause_needs_new_evidence(first_s):
    # ABS on dry for `first_s` (each length leaves the excitation, evaluated every few fits, at
    # another phase), the brake released for 0.4 s (longer than `excitation_window_s`, shorter
    # than the window: the dry samples stay in it), then applied again on a wet road, its slip
    # ramping through the linear region. The excitation of the dry samples, no longer the
    # newest, must not make the first fits VALID: they still give the dry road's 1.02.
    dry, wet = tm.LugreParams(theta=1.0), tm.LugreParams(theta=2.2)
    est = LugreTrustRegionEstimator()
    run(est, braking(lambda t, i: lugre_curve(dry), seed=7, duration=first_s), lambda s: 0.0)
    t = round(first_s, 2)
    for _ in range(40):
        est.update(PhysicalSample(t, 20.0, (0.0,) * 4, (0.0,) * 4, (0.0,) * 4, (0.0,) * 4, (False,) * 4, True))
        t += 0.01
    lam_star, truth = tm.peak(20.0, wet)[1], tm.peak(20.0, wet)[0]
    rng = np.random.default_rng(8)
    wrong = []
    for k in range(30):
        lam = (k + 1) / 30.0 * 0.6 * lam_star
        mu = float(tm.mu(lam, 20.0, wet))
        e = est.update(PhysicalSample(t, 20.0, (lam,) * 4, tuple(mu + float(rng.normal(0, 0.01)) for _ in range(4)),
                                      (4000.0,) * 4, (0.0,) * 4, (True,) * 4, True))
        if e.status == Status.VALID and abs(e.mu_max - truth) > 0.2 * truth:
            wrong.append((round(t, 2), round(e.mu_max, 3)))
        t += 0.01
    assert not wrong, wrong[:5]


def test_a_valid_outlasts_the_gap_between_two_abs_cycles():
    # The data show the peak once per ABS cycle (`evidence_interval_s`): between two cycles that
    # each show it, the fit sees no excitation for most of a cycle. A VALID that has stood a drift
    # window stands through such a gap, and goes once a whole cycle has passed without evidence.
    # One that has only just entered (a confidence flickering at the threshold) is held no longer
    # than the drift window.
    def gap_status(valid_since_s: float, gap_s: float) -> FrictionEstimate:
        est = LugreTrustRegionEstimator()
        valid = FrictionEstimate(1.00, Status.VALID, 0.83, 0.12, 1.0, 0.8)
        est._last_valid, est._last_excited_s, est._last_estimate = valid, 1.00, valid
        est._valid_since_s = valid_since_s
        return est._decided(1.00 + gap_s, 20.0, 0.0, 0.0, (0.80, 0.12, 1.0, (0.80,) * 4, 0.01, {}))

    o = LugreTROptions()
    cycle, settled = o.evidence_interval_s, o.drift_window_s
    assert cycle > 1.5 * settled
    within = gap_status(1.00 - settled, 0.9 * cycle)
    assert within.status == Status.VALID and within.mu_max == 0.83
    after = gap_status(1.00 - settled, cycle + 0.05)
    assert after.status == Status.CONVERGING and after.mu_max == 0.80
    young = gap_status(1.00 - 0.5 * settled, 0.9 * cycle)
    assert young.status == Status.CONVERGING and young.mu_max == 0.80
    assert gap_status(1.00 - 0.5 * settled, 0.9 * settled).status == Status.VALID


def test_a_valid_withdrawn_mid_stop_is_not_brought_back_at_standstill():
    # Campaign development stop 427: one VALID at 1.70 s (15 % low), CONVERGING from the next
    # update on; at 3.70 s, the car at rest, the hold published that VALID again, 22 % below a
    # road whose grip had risen as the speed fell. A VALID still standing as the stop ends is
    # held (the road is the same), whatever the updates below the evidence speed said.
    est = LugreTrustRegionEstimator()
    slow = est.options.peak_evidence_min_speed - 1.0
    valid = FrictionEstimate(1.70, Status.VALID, 0.83, 0.2, 1.0, 0.55)
    est._last_valid, est._last_excited_s = valid, 3.69
    est._last_estimate = dataclasses.replace(valid, time_s=3.69, status=Status.CONVERGING)
    assert est._hold(3.70, slow).status == Status.VALID              # (not withdrawn while moving)
    est._withdrawn_moving_s = 1.71                                     # withdrawn at 1.71 s, moving
    held = est._hold(3.70, slow)
    assert held.status == Status.NOT_EXCITED and held.mu_max == 0.83
    est._last_valid = dataclasses.replace(valid, time_s=3.0)           # a VALID since: held again
    assert est._hold(3.70, slow).status == Status.VALID


def test_a_third_change_of_road_within_seconds_ends_valid_until_they_stop():
    # The road's residual bias flips every 0.7 s (a tyre the static model does not describe is
    # indistinguishable from this): the first two detections may be a road change and its rear
    # axle, the third says the model misfits. Nothing VALID while three lie within 4 s; VALID
    # again once the road has stayed the same that long.
    a, b = lugre_curve(tm.LugreParams(theta=1.0)), lugre_curve(tm.LugreParams(theta=2.2))
    flips_until = 2.3
    est = LugreTrustRegionEstimator()
    changes, valid_after_third, valid_late = [], [], []
    for s in braking(lambda t, i: (a if int(t / 0.7) % 2 == 0 or t > flips_until else b), v0=80.0, seed=6,
                     speed_floor=2.0):
        jumps = est._jumps
        e = est.update(s)
        if est._jumps > jumps:
            changes.append(s.time_s)
        if e.status == Status.VALID and len(changes) >= 3:
            recent = [c for c in changes if s.time_s - c <= est.options.misfit_window_s]
            (valid_after_third if len(recent) >= 3 else valid_late).append(s.time_s)
    assert len(changes) >= 3
    assert valid_after_third == []
    assert valid_late, "VALID must return once the detections are older than misfit_window_s"


@pytest.mark.parametrize("grippy_side_at_peak", [False, True])
def test_split_mu_is_valid_only_once_both_sides_show_their_peaks(grippy_side_at_peak):
    # Left wheels on ice cycle around their peak; the right ones, on a grippy road with a soft
    # curve (peak at λ ≈ 0.33), are held at slips of 0.04-0.14 by their ABS: utilisation ≤ 0.8,
    # μ still rising. The published mean of the four peaks would rest on the right wheels'
    # extrapolation: not VALID. Once the right wheels also cycle around their peak, it is.
    ice = lugre_curve(tm.LugreParams(theta=8.0))
    mu, peak_slip, peak_mu = _soft_magic_formula(d=1.0)
    grippy = (mu, lambda v: peak_slip / 2.0 if grippy_side_at_peak else 0.09)
    est = LugreTrustRegionEstimator()
    valid = []
    for s in braking(lambda t, i: ice if i in (0, 2) else grippy, v0=20.0, noise=0.004, seed=5):
        e = est.update(s)
        if e.status == Status.VALID:
            valid.append((e.mu_max, 0.5 * (tm.peak(s.speed_mps, tm.LugreParams(theta=8.0))[0] + peak_mu)))
    if grippy_side_at_peak:
        assert len(valid) > 50
        assert max(abs(m - truth) / truth for m, truth in valid[len(valid) // 2:]) < 0.15
    else:
        assert valid == []


def test_the_icy_sides_spin_up_after_a_split_mu_stop_is_not_the_cars_mu_max(monkeypatch):
    """The campaign's development stop 20994: split μ (wet cobblestone and ice), a car sending only
    its master-cylinder pressure. The pedal released, only the icy side's wheels spin back up from
    deep slip, and the window holds their samples alone; the fit couples the other side to them,
    so μ_max read the ice's for the whole car: ten VALID outputs 75 % low. Not VALID: a side of the
    car without samples."""
    from frictiond.campaign.draw import draw_stop
    from frictiond.campaign.score import estimator_scores
    from frictiond.campaign.simulate import simulate_stop
    from frictiond.estimate_confidence import EstimateConfidence
    from frictiond.pipeline import Pipeline

    stop = simulate_stop(draw_stop(20994))

    def run_stop():
        pipeline = Pipeline(stop.config("lugre-tr"))
        estimates, reasons = [], set()

        def keep(estimate, sample):
            estimates.append(estimate)
            reasons.add(pipeline.not_valid_reason)
        pipeline.on_estimate = keep
        for frame in stop.frames:
            pipeline.process(frame)
        return estimator_scores(estimates, stop.truth), reasons

    scores, reasons = run_stop()
    assert not_valid.UNSAMPLED_SIDE in reasons and scores["false_valid"] == 0
    monkeypatch.setattr(EstimateConfidence, "_a_side_unsampled", lambda self: False)
    assert run_stop()[0]["false_valid"] > 0


def test_a_slip_controller_holding_its_target_below_a_far_peak_gives_no_valid():
    # The campaign's development stop 581: a slip-control ABS holds every wheel at λ = 0.093
    # (±0.001) on dry cobblestone, whose peak lies near λ = 0.4: 53 % of the grip. Its releases
    # mark every wheel as worked by an ABS, but the slips do not spread: the shape tests saw
    # noise, passed at random, and 357 VALID outputs were 40-45 % low.
    from frictiond.campaign.score import estimator_scores

    stop, estimates = campaign_stop_estimates(581)
    assert estimator_scores(estimates, stop.truth)["valid"] == 0


def test_a_held_slip_is_past_the_peak_only_where_its_wheel_last_showed_the_peak():
    # Seed 2803 (outside the development seeds): a slip controller holds every wheel at λ = 0.10
    # on Magic Formula snow, 80 % of the grip. One early excitation check passed; every later one
    # with spread slips said "still rising". When the spread data left the window the fit moved
    # its peak under the held slip, and "held past the peak" made 84 outputs VALID, 19 % low.
    from frictiond.campaign.score import estimator_scores

    stop, estimates = campaign_stop_estimates(2803)
    assert estimator_scores(estimates, stop.truth)["valid"] == 0


def test_a_held_slip_past_the_fitted_peak_is_valid_only_while_the_spread_slips_are_in_the_window():
    # Development stop 923: the same kind of controller holds λ = 0.12 on a flat-topped snow curve
    # at 97 % of its grip (its peak at 0.155), after the wheels' spread slips came near the top.
    # The fit has since put its peak under the held slip. The carry is evidence while the samples
    # that showed the top are in the window; after that the held slip alone says nothing of what
    # lies beyond it (stop 40001 held the same way at 79 % of an ice curve's grip).
    from frictiond.campaign.score import estimator_scores

    stop, estimates = campaign_stop_estimates(923)
    scores = estimator_scores(estimates, stop.truth)
    assert scores["valid"] > 30 and scores["false_valid"] == 0 and scores["mae"] < 0.02
    valid_s = [e.time_s for e in estimates if e.status == Status.VALID]
    assert valid_s[-1] - valid_s[0] < LugreTROptions().window_s + LugreTROptions().hold_s


@pytest.mark.parametrize("coasting_s, spread_counts", [(0.1, True), (5.0, False)])
def test_a_slip_spread_the_speed_estimate_can_make_is_no_spread(coasting_s, spread_counts):
    # A slip controller holds every wheel, so nothing anchors the speed estimate: it coasts on
    # the accelerometer, and its error grows with the offset's. At 5 m/s, slowing 1 m/s over the
    # excitation window, an error of 0.12 m/s spreads a held slip by 0.005 (e·Δv/v²) and the
    # window's own drift by 0.001. Twice their sum on top of the ABS's 15 % of the slip, the
    # 0.018 of spread below is noise, not the curve's shape. Just after an anchor it counts.
    est = LugreTrustRegionEstimator()
    est._last_sample_s = 10.0
    # (Slowing by 1 m/s per 0.3 s; the brake released last at 10 − coasting_s.)
    for t in sorted((10.0 - coasting_s, 9.7, 10.0)):
        est._speed_error.follow(PhysicalSample(t, 5.1 + (10.0 - t) / 0.3, (0.08,) * 4, (0.3,) * 4, (4e3,) * 4,
                                               (1.2e3,) * 4, (True,) * 4, braking=t != 10.0 - coasting_s))
    stats = (30.0, 0.0673, 0.0853, 0.0673, 0.0853, 0.335, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    why, _, _ = est._wheel_verdict(0, stats, 0.34, 0.136, 0.335, False, 5.1, False, True)
    assert (why != "no slip spread") == spread_counts


def test_a_slip_controller_at_walking_pace_after_seconds_of_coasting_gives_no_valid():
    # Seed 9421 of the slip-controller / Magic Formula draws: every wheel held at λ = 0.114 on a
    # wet curve (71 % of the grip) for 6 s. The speed estimate coasted 0.2 m/s low; near 5 m/s
    # that spread the held slips by 0.014 with μ constant, which the shape tests read as a
    # plateau: 166 VALID outputs, all 24 % low.
    from frictiond.campaign.score import estimator_scores

    stop, estimates = campaign_stop_estimates(9421, family="c-slip/magic")
    assert estimator_scores(estimates, stop.truth)["valid"] == 0


@pytest.mark.parametrize("shown", [0.77, 1.0])
def test_a_held_slip_carries_no_more_than_its_wheel_last_showed(shown):
    # A slip controller holds λ = 0.108 (±0.5 %) and the fit has since moved its peak to 0.068,
    # under the held slip: the data did not move, so "past the peak" is only the wheel's last
    # verdict on spread slips carried on, at that verdict's strength. (Held-out stop 1000829:
    # a marginal 0.75 carried as 1.0 made 367 outputs VALID, 28 % low.)
    est = LugreTrustRegionEstimator()
    est._last_sample_s = 10.0
    est._shape_proximity[0] = shown
    est._shape_verdict_s[0] = 9.9
    stats = (50.0, 0.0, 0.0, 0.1075, 0.1085, 0.058, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    why, proximity, fresh = est._wheel_verdict(0, stats, 0.059, 0.068, 0.059, False, 30.0, True, True)
    assert why[0].startswith("past the peak") and not fresh
    assert proximity == shown


def test_a_slip_controller_holding_short_of_a_rising_ice_peak_keeps_no_lasting_valid():
    # Development stop 40001: a slip controller with its target capped holds λ = 0.11 on a Magic
    # Formula ice curve whose peak is at 0.23, at 79 % of the grip. The fit puts its peak under
    # the held slip; carried for the rest of the stop, one marginal verdict made 608 outputs
    # VALID, 21 % low. The carry ends with the samples that gave it.
    stop, estimates = campaign_stop_estimates(40001)
    valid_s = [e.time_s for e in estimates if e.status == Status.VALID]
    assert not valid_s or valid_s[-1] - valid_s[0] < LugreTROptions().window_s + LugreTROptions().hold_s


@pytest.mark.parametrize("verdict_age_s, carried", [(0.5, True), (0.9, False), (3.0, False)])
def test_a_held_slip_carries_its_wheel_last_verdict_only_while_that_verdict_samples_are_in_the_window(
        verdict_age_s, carried):
    # Once the samples whose spread showed the peak have left the window (0.8 s), the fit has
    # only the held slip: μ there bounds μ_max from below, and the peak's height is the prior
    # shape's guess. (Dev stop 40001: a slip controller held λ = 0.11 on ice whose peak is at
    # 0.23; one marginal verdict carried for 7 s made 608 outputs VALID, 21 % low.)
    est = LugreTrustRegionEstimator()
    est._last_sample_s = 10.0
    est._shape_proximity[0] = 1.0
    est._shape_verdict_s[0] = 10.0 - verdict_age_s
    stats = (50.0, 0.0, 0.0, 0.1075, 0.1085, 0.058, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    why, proximity, _fresh = est._wheel_verdict(0, stats, 0.059, 0.068, 0.059, False, 30.0, True, True)
    assert (proximity == 1.0) == carried
    assert (why == "no slip spread") != carried


@pytest.mark.parametrize("elasticity, fitted_peak_slip, contradicted", [
    (0.9, 0.10, True),    # μ rising at 0.9 of μ/λ at λ 0.2, twice past the fitted peak
    (0.5, 0.10, False),   # rising, but not clearly enough to contradict the fit
    (0.9, 0.25, False),   # rising below the fitted peak: the tyre is simply not there yet
])
def test_mu_rising_well_past_the_fitted_peak_contradicts_the_fit(elasticity, fitted_peak_slip, contradicted):
    est = LugreTrustRegionEstimator()
    est._top_elasticity = lambda wheel: (elasticity, 0.0, 0.0)
    est._bending = lambda *a: None     # (the data bend over: the verdict reaches the top-of-slips test)
    stats = (50.0, 0.05, 0.2, 0.05, 0.2, 0.5, -math.inf, 0.0, 0.0, 0.0, 0.0, 0.0)
    why, proximity, _fresh = est._wheel_verdict(0, stats, 0.55, fitted_peak_slip, 0.5, False, 20.0, False, True)
    assert (proximity == CONTRADICTED) == contradicted
    assert proximity <= 0.0    # (either way this wheel shows no peak)


@pytest.mark.parametrize("tops, flat", [
    ([(0.20, 0.05, 0.0)] * 4, True),                        # every wheel's top slope well under the threshold
    ([(0.30, 0.20, 0.0), None, None, None], True),          # near it, but clear of a curve at 80 % of its peak
    ([(0.30, 0.30, 0.0), None, None, None], False),         # as near, and within its noise of such a curve
    ([(0.30, 0.30, 0.0)] + [(0.25, 0.10, 0.0)] * 3, True),  # ... which the other wheels' slopes resolve
    ([(-1.2, 2.0, 0.0), None, None, None], False),          # "past the peak" by a slope that is all noise
])
def test_a_flat_top_must_be_clear_of_a_rising_curve_beyond_its_noise(tops, flat):
    # Dev stop 20941: a slip controller held λ ≈ 0.1 on a dry Magic Formula tyre at 82 % of
    # its peak, then the driver released; the held samples and the release's sweep below them
    # gave slopes of about zero ± several times the flat threshold over slips 0.095–0.105,
    # and 32 outputs went VALID 22 % low. The four wheels' slopes are pooled (one road, one
    # shape near the peak): on ice one wheel's is ±1.
    est = LugreTrustRegionEstimator()
    est._top_elasticity = lambda wheel: tops[wheel]
    est._bending = lambda *a: None
    stats = (50.0, 0.05, 0.2, 0.05, 0.2, 0.5, -math.inf, 0.0, 0.0, 0.0, 0.0, 0.0)
    why, proximity, _fresh = est._wheel_verdict(0, stats, 0.52, 0.2, 0.52, False, 20.0, False, True)
    assert (proximity >= est.options.excitation_slip_ratio) == flat
    assert (why[0].startswith("flat top not resolved")) == (not flat)


def test_a_release_sweeping_under_a_held_slip_is_no_flat_top(monkeypatch):
    # Dev stop 20941 (its story above): the top slips' slope is about zero, and noise. Without
    # the bound on it (`rising_elasticity` out of reach) the fit made as the driver let go
    # claimed the peak, and restated after the brakes were off it went VALID 22 % low. Either
    # guard keeps it out: the bound, or no VALID entered by a restate while the brakes let go.
    from frictiond.campaign.score import estimator_scores
    from frictiond.estimate_report import EstimateReport

    stop, estimates = campaign_stop_estimates(20941)
    assert estimator_scores(estimates, stop.truth)["false_valid"] == 0
    stop, unbounded = campaign_stop_estimates(20941, rising_elasticity=100.0)
    assert estimator_scores(unbounded, stop.truth)["false_valid"] == 0
    restate = EstimateReport._restate
    monkeypatch.setattr(EstimateReport, "_restate", lambda self, last, now_s, slipping: restate(self, last, now_s, True))
    stop, bounded = campaign_stop_estimates(20941)
    assert estimator_scores(bounded, stop.truth)["false_valid"] == 0
    stop, neither = campaign_stop_estimates(20941, rising_elasticity=100.0)
    assert estimator_scores(neither, stop.truth)["false_valid"] > 10


def test_one_wheel_contradicting_the_fit_leaves_no_excitation(monkeypatch):
    # Wheel 0 sits at its fitted peak; wheel 1's μ still rises well past its own: the fitted
    # curve is not the tyre's, so wheel 0's proximity to "its peak" proves nothing either.
    est = LugreTrustRegionEstimator()
    monkeypatch.setattr(est, "_wheel_stats", lambda weights: ((0.0,) * 12,) * 4)
    monkeypatch.setattr(est, "_fit_at_high_slip", lambda speed: np.zeros(4))
    for second in (0.0, CONTRADICTED):
        verdicts = {0: ("proximity", 1.0, True), 1: ("", second, True)}
        monkeypatch.setattr(est, "_wheel_verdict", lambda i, *a: verdicts.get(i, ("", 0.0, True)))
        excitation = est._excitation(None, np.full(4, 0.5), np.full(4, 0.1), 20.0)
        assert (excitation == 0.0) == (second == CONTRADICTED)


def test_the_confidence_counts_one_piece_of_evidence_per_abs_cycle():
    """The confidence is the probability of μ_max within 10 % of the road's. A delta-method spread
    of 2 % from samples 10 ms apart is 35 samples per ABS cycle that repeat one misfit: on the
    randomised campaign such outputs were within 10 % of the truth about 55 % of the time. The
    same spread from samples 20 ms apart rests on twice the cycles."""
    confidences = {}
    for period in (0.01, 0.02):
        est = LugreTrustRegionEstimator(sample_period_s=period)
        est._excited_since_s = 0.0
        for k in range(40):
            confidences[period] = est._confidence(0.01 * k, 0.5, 0.01, 1.0)
    assert 0.45 < confidences[0.01] < 0.6
    assert confidences[0.02] > confidences[0.01] + 0.05
    best = LugreTrustRegionEstimator()
    best._excited_since_s = 0.0
    settled = [best._confidence(0.01 * k, 0.5, 0.0, 1.0) for k in range(40)][-1]
    # The model-mismatch floor alone: the campaign's gated outputs with the least spread were within
    # 10 % of the truth 99–100 % of the time, and the floor keeps even those short of certain.
    assert 0.95 < settled < 0.99


def test_every_valid_output_makes_a_false_valid_unlikely():
    # The confidence is the probability of μ_max within 10 %; by the same error model a VALID kept
    # down to 0.63 has a 7 % chance of being more than 20 % off (16 % at 0.52). Dev stop 638 (a
    # threshold ABS on a Magic Formula tyre) leaves VALID eight times at a confidence of
    # 0.56-0.63, each of which a hysteresis down to 0.52 would have kept VALID. (The wheels' fit
    # alone: beside it, the car's total force covers some of those gaps, `body_curve_report`.)
    keep = LugreTROptions().keep_valid_confidence
    _stop, estimates = campaign_stop_estimates(638, body_curve_beside_wheels=False)
    valid = [e for e in estimates if e.status == Status.VALID]
    assert len(valid) > 300 and min(e.confidence for e in valid) >= keep
    left = [e for e, before in zip(estimates[1:], estimates) if before.status == Status.VALID != e.status]
    assert sum(0.52 <= e.confidence < keep for e in left) >= 3


def test_a_confidence_without_any_spread_is_certain_not_a_crash():
    # model_mismatch may be configured to 0; a fit with no spread and no drift then has σ = 0.
    est = LugreTrustRegionEstimator(dataclasses.replace(LugreTROptions(), model_mismatch=0.0, settle_s=0.0))
    est._excited_since_s = 0.0
    assert est._confidence(0.1, 0.5, 0.0, 1.0) == 1.0


def test_a_magic_formula_peak_swept_within_the_filter_is_no_confident_peak():
    # Campaign seed 2386: at each cycle a threshold ABS sweeps a snow Magic Formula tyre
    # (C = 1.76, E = 0.5) over its peak, within the 50 Hz derivative filter's window. Each
    # sample at the top is a mean over the slips swept, so the samples cannot show a top that
    # sharp. The fitted static LuGre curve is rounder there and put the peak low: 19 VALID
    # outputs were more than 20 % low. Counting the mean's shortfall at a real tyre's curvature
    # (twice the fitted curve's) keeps them out of VALID, and the stop stays VALID where it is right
    # (21 outputs 1-10 % low since each wheel-speed sample waits for its pressures, `trigger_hold`;
    # 58 outputs 2-17 % low before).
    stop, estimates = campaign_stop_estimates(2386)
    truth = {round(r["time_s"], 2): r["mu_max"] for r in stop.truth}
    valid = [e for e in estimates if e.status == Status.VALID]
    assert len(valid) > 15
    assert not [e for e in valid if abs(e.mu_max - truth[round(e.time_s, 2)]) > 0.2 * truth[round(e.time_s, 2)]]


def test_a_peak_first_shown_at_walking_pace_is_no_evidence():
    # Campaign seed 2594: a slip controller holds 66 % of a wet Magic Formula tyre's grip all
    # stop long; at its cut-out the wheels lock, and at 3.2 m/s a wheel's slips looked like a
    # peak. The published 0.47 (truth 0.69) was VALID to the stop; no peak was ever shown at a
    # speed where slip means something, so no VALID at all. (It is a turn: with the lateral
    # force's share, the tyres used at most 81 % of their grip.)
    stop, estimates = campaign_stop_estimates(2594)
    assert max(max(r[f"utilisation_{w}"] for w in ("fl", "fr", "rl", "rr")) for r in stop.truth
               if r["braking"] and r["speed_mps"] > 5.0) < 0.82
    assert estimates and not [e for e in estimates if e.status == Status.VALID]


def test_a_wheel_that_has_not_shown_its_peak_takes_the_peak_of_the_wheel_in_its_track():
    # Campaign seed 2995, split μ (dry left, snow right) under a deceleration-triggered ABS: the
    # front-left wheel stays at a third of its grip; its fit's peak (0.40) is near the mean of
    # the shown wheels (0.42, two of them on snow), so VALID was published at 0.39 against a
    # true mean of 0.57. The rear-left runs in the front-left's track: its peak is the one the
    # front-left's road has.
    est = LugreTrustRegionEstimator()
    now = 5.0
    est._wheel_shown_s = [-math.inf, now, now, now]             # FL not shown lately
    est._load_share = [0.3, 0.3, 0.2, 0.2]
    assert est._leans_on_unshown_wheels(now, [0.40, 0.20, 0.85, 0.20])     # split: the track says 0.85
    assert not est._leans_on_unshown_wheels(now, [0.80, 0.82, 0.78, 0.81])  # one road: no difference
    # Without a shown wheel in its track, the shown wheels' mean is the reference, as before.
    est._wheel_shown_s = [-math.inf, now, -math.inf, now]
    assert not est._leans_on_unshown_wheels(now, [0.22, 0.20, 0.21, 0.20])
    assert est._leans_on_unshown_wheels(now, [0.60, 0.20, 0.60, 0.20])


def test_a_peak_swept_within_the_derivative_filter_costs_confidence():
    """Campaign stop 2730: a threshold ABS on snow (Magic Formula, C 1.67, 25 % below its peak
    past it) with 50 Hz wheel speeds sweeps each wheel from 2 % to 60–100 % slip and back in
    0.2 s, across the peak in about one sample. μ read through the ±20 ms derivative filter is
    the tyre's mean over that sweep: 0.27–0.33 where the peak is 0.37. Fitted, those samples put
    the peak 20–27 % low with the confidence of data that agree cycle after cycle. What the
    filter's mean over those sweeps loses of the fitted curve (5 % at the top of the data: the
    static curve is rounder than the tyre) costs confidence: a third of those outputs go."""
    from frictiond.campaign.draw import draw_stop
    from frictiond.campaign.simulate import simulate_stop
    from frictiond.config import parse_config
    from frictiond.replay import estimates_of

    stop = simulate_stop(dataclasses.replace(draw_stop(2730), grade=0.0))   # (level, as it was found)
    times = np.array([r["time_s"] for r in stop.truth])

    def valid_errors(weight: float) -> list[float]:
        data = stop.config_data()
        data["frontend"] = {"level_road": True}
        # (at the VALID thresholds of then, 0.55 and 0.5, where the premise shows)
        data["estimator"]["lugre_tr"] = {"spread_loss_weight": weight, "valid_confidence": 0.55,
                                         "keep_valid_confidence": 0.5}
        _, estimates = estimates_of(parse_config(data, None), stop.frames)
        out = []
        for e in estimates:
            if e.status == Status.VALID:
                truth = stop.truth[min(int(times.searchsorted(e.time_s)), len(times) - 1)]["mu_max"]
                out.append((e.mu_max - truth) / truth)
        return out

    unaware = valid_errors(0.0)
    false_unaware = sum(x < -0.2 for x in unaware)
    assert false_unaware > 0.4 * len(unaware)
    aware = valid_errors(LugreTROptions().spread_loss_weight)
    assert sum(x < -0.2 for x in aware) < 0.8 * false_unaware


def test_a_change_of_road_under_the_front_axle_alone_costs_confidence(monkeypatch):
    """A threshold ABS on wet cobblestone meets a dry road (randomised campaign, jump family,
    seed 50431, 27 km/h): the front axle 0.4 s before the rear. Pooled with the rear wheels'
    residuals, still on the wet road, the front's bias failed the same-sign test, and the wet
    road's μ stayed VALID (confidence up to 0.64) while the car's grip was 42–44 % higher. The
    front axle's own residuals cost confidence; the last fit before the car crawls below the
    speed that slip can be measured at (from 1.85 s, where the rear axle meets the dry road
    unseen) is held at that confidence. Since the rear wheels show no peak for a wheelbase
    after a detected change (one at 1.43 s here), their wet-road data excite nothing either."""
    from frictiond import road_change, wheel_verdicts

    def confidences(front_test: bool, rear_crossing: bool) -> list[float]:
        with monkeypatch.context() as patch:
            if not front_test:
                patch.setattr(road_change.RoadChangeTest, "_front_score", lambda self, *bias: 0.0)
            if not rear_crossing:
                patch.setattr(wheel_verdicts.WheelVerdicts, "_rear_axle_crossing", lambda self: False)
            stop, estimates = campaign_stop_estimates(50431, family="*/*/jump")
        moving = [e.confidence for e in estimates if 1.5 <= e.time_s <= 1.85]
        assert moving
        return moving

    with_front = confidences(True, False)
    without = confidences(False, False)
    assert without[-1] >= 0.65          # (the premise: the pooled test alone sees nothing)
    # (The pressures' lag compensated by their rate at the sample's instant, the fit follows the
    # new road by 1.5 s and the front's residuals cost confidence only while the rear wheels'
    # still disagree: up to 0.07 around 1.6 s, 0.05 at 1.81 s, nothing by 1.85 s.)
    cost = [b - a for a, b in zip(with_front, without)]
    assert min(cost) >= 0.0 and max(cost) >= 0.04
    assert max(confidences(False, True)) < LugreTROptions().keep_valid_confidence


def test_a_brake_gain_the_body_equation_leaves_in_doubt_is_no_valid():
    # The same stop twice; the second time the front end says the brake gain (every wheel's μ with
    # it) may be off by up to 20 %: an accelerometer offset not yet learnt on a slippery road. That
    # alone is a σ of 11.5 %, more than VALID allows; the first stop is VALID.
    p = tm.LugreParams()
    mu_fn, lam_fn = lugre_curve(p)
    for doubt, valid_expected in ((0.0, True), (0.2, False)):
        est = LugreTrustRegionEstimator()
        statuses = [est.update(dataclasses.replace(s, brake_gain_doubt=doubt)).status
                    for s in braking(lambda t, i: (mu_fn, lam_fn), duration=2.0, noise=0.01)]
        assert (Status.VALID in statuses) == valid_expected, doubt


def test_an_accelerometer_offset_not_yet_learnt_lets_the_speed_estimate_drift_faster():
    # Coasting on the accelerometer, the speed estimate drifts at its offset's error: 0.02 m/s²
    # once free rolling has taught it, what the front end says is not yet known of it before.
    from frictiond.speed_error import SpeedErrorBound, SpeedErrorOptions

    spreads = {}
    for doubt in (0.0, 0.01, 0.1):
        bound = SpeedErrorBound(SpeedErrorOptions(0.05, 0.02, 0.02, 0.3))
        for k in range(200):     # 2 s of braking, every wheel held at 8 % slip, slowing 3 m/s²
            t = 0.01 * k
            bound.follow(PhysicalSample(t, 20.0 - 3.0 * t, (0.08,) * 4, (0.3,) * 4, (4e3,) * 4, (1.2e3,) * 4,
                                        (True,) * 4, braking=True, accel_offset_doubt_mps2=doubt))
        spreads[doubt] = bound.slip_spread(1.99, 20.0 - 3.0 * 1.99)
    assert spreads[0.01] == spreads[0.0] > 0.0          # (below the learnt offset's own 0.02)
    # (the error e = 0.05 + drift · 2 s, spreading a held slip by e·Δv/v² + drift·Δt/v)
    assert spreads[0.1] > 3.5 * spreads[0.0]


def test_a_turn_takes_the_lateral_grip_out_of_the_longitudinal_peak_and_it_is_added_back():
    # In a turn the tyres carry the car's lateral μ too: by the friction circle the longitudinal
    # curve the wheels show is √(1 − (μ_y/μ)²) of the road's. Reported as it is, μ_max reads that
    # much low (here 20 %: a_y = 0.6 μ g); with the lateral μ added back it is the road's.
    p = tm.LugreParams(theta=1.6, sigma0=230.0, v_s=5.0, sigma2=0.002)
    mu_fn, lam_fn = lugre_curve(p)
    road = tm.peak(10.0, p)[0]
    lateral = 0.6 * road
    left = math.sqrt(1.0 - 0.36)

    def last_valid(lateral_grip):
        est = LugreTrustRegionEstimator(LugreTROptions(lateral_grip=lateral_grip))
        valid = []
        for s in braking(lambda t, i: ((lambda lam, v: left * mu_fn(lam, v)), lam_fn), v0=14.0, noise=0.005,
                         speed_floor=10.0):
            e = est.update(dataclasses.replace(s, lateral_mu=lateral))
            if e.status == Status.VALID:
                valid.append(e.mu_max / tm.peak(s.speed_mps, p)[0])
        assert len(valid) > 20, lateral_grip
        return valid[-1]

    assert last_valid(False) == pytest.approx(left, rel=0.05)
    assert last_valid(True) == pytest.approx(1.0, rel=0.05)


def test_a_lateral_mu_within_its_tolerance_of_nothing_is_doubted_on_ice():
    # What a lateral μ adds to μ_max counts in the confidence as far as a lateral μ smaller by
    # its tolerance (0.03: an accelerometer's 0.3 m/s² offset) would not have added it. On dry
    # asphalt a lateral μ of 0.03 is a rounding; on ice it is a sixth of μ_max, all of it within
    # the tolerance: the confidence falls from 0.95 to below 0.8, and at 0.05 nothing is VALID.
    def run_with(theta, lateral):
        p = tm.LugreParams(theta=theta, sigma0=400.0, v_s=5.0, sigma2=0.0001)
        mu_fn, lam_fn = lugre_curve(p)
        est = LugreTrustRegionEstimator()
        return [est.update(dataclasses.replace(s, lateral_mu=lateral))
                for s in braking(lambda t, i: (mu_fn, lam_fn), v0=15.0, noise=0.05 / theta, duration=2.0)]

    def top(estimates):
        return max(e.confidence for e in estimates)

    assert top(run_with(1.0, 0.03)) == pytest.approx(top(run_with(1.0, 0.0)), abs=0.005)
    straight, turning = top(run_with(25.0, 0.0)), top(run_with(25.0, 0.03))
    assert straight > 0.9 and turning < 0.8
    assert not [e for e in run_with(25.0, 0.05) if e.status == Status.VALID]


def test_below_the_evidence_speed_only_a_wheel_that_showed_its_peak_above_it_shows_it_again():
    # On split μ one side's peak says nothing of the other's, and at walking pace the speed
    # estimate's error alone spreads a held slip into a seeming peak.
    est = LugreTrustRegionEstimator()
    slow = est.options.peak_evidence_min_speed - 1.0
    stats = (float(est._min_wheel_samples), 0.02, 0.12, 0.02, 0.12, 0.5, 1.0) + (1.0,) * 5
    est._wheel_shown_moving = [True, False, False, False]

    def verdict(wheel, peak_seen=True):
        return est._wheel_verdict(wheel, stats, 0.8, 0.1, 0.8, False, slow, peak_seen, True)[0]

    assert verdict(1) == "too slow to show a peak"
    assert verdict(0) != "too slow to show a peak"
    assert verdict(0, peak_seen=False) == "too slow to show a peak"


@pytest.mark.parametrize("smear, shown", [(1.0, True), (1.9, True), (2.5, False), (math.inf, False)])
def test_a_flat_top_within_the_filter_sweep_of_its_slips_shows_no_peak(smear, shown):
    # μ is a mean over the slips the wheel swept within the derivative filter's window: where
    # those sweeps are wide against the top slips' own spread, the slope across them is shrunk
    # towards zero, and a flat reading says nothing of the tyre.
    est = LugreTrustRegionEstimator()
    est._top_elasticity = lambda wheel: (0.2, 0.05, smear)
    est._bending = lambda *a: None
    stats = (50.0, 0.05, 0.2, 0.05, 0.2, 0.5, -math.inf, 0.0, 0.0, 0.0, 0.0, 0.0)
    why, proximity, _fresh = est._wheel_verdict(0, stats, 0.52, 0.2, 0.52, False, 20.0, False, True)
    assert (proximity >= est.options.excitation_slip_ratio) == shown
    assert why[0].startswith("top slips within the filter's sweep") == (not shown)


def test_a_soft_tyre_cycled_fast_below_its_peak_is_not_taken_for_a_flat_top():
    # Dev stop 245 with every stop split and the rear axle select-low: a deceleration ABS cycles
    # the dry-cobblestone front wheel (peak at slip 0.38) at slips 0.07–0.10, 60 % of its grip.
    # Each sample's μ is a mean over ±0.008 of slip, the top slips spread ±0.003: their slope
    # read 0.3 where the same samples' true slips and μ give 0.6–0.7, the wheel "showed" its
    # peak, and the four wheels' mean went VALID 21 % low.
    from frictiond.campaign.draw import Stress, draw_stop
    from frictiond.campaign.score import estimator_scores
    from frictiond.campaign.simulate import simulate_stop
    from frictiond.replay import estimates_of

    stop = simulate_stop(draw_stop(245, "*/*/split", Stress(rear_select_low=True)))
    false_valid = {}
    for max_smear in (LugreTROptions().max_top_smear, 1e9):
        config = with_lugre_options(stop.config("lugre-tr"), max_top_smear=max_smear)
        _pipeline, estimates = estimates_of(config, stop.frames)
        false_valid[max_smear] = estimator_scores(estimates, stop.truth)["false_valid"]
    assert false_valid[1e9] > 10
    assert false_valid[LugreTROptions().max_top_smear] == 0
