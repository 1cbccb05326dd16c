"""What the estimator reports from a fit: the peaks, their spread, the status and the hold.

From the fitted parameters: each wheel's peak (μ, λ*) held within the slips the data support,
the road's μ_max as their load-weighted mean, its standard deviation by the delta method, the
peaks raised to the grip the wheels and the car measured; then the status (VALID, CONVERGING,
NOT_EXCITED) from the excitation, the confidence and the vetoes, and what is said at a cycle
without a fit (the last fit restated, a VALID held for `hold_s`). `EstimateReport` is a part of
`LugreTrustRegionEstimator` (its fit state and options are the estimator's);
`_peak_report_numpy` is the reference of the compiled `_fitcore.peak_report`.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from . import not_valid
from .samples import N_WHEELS, FrictionEstimate, Status
from .tyre_model import LugreParams, braking_mu_and_partials_few, peaks, supported_slip

_WHEEL_STD_KEYS = tuple(f"wheel_std_{i}" for i in range(N_WHEELS))


class EstimateReport:
    """A fit's numbers and status (`_report`, `_decided`), and what a cycle without a fit says
    (`_restate`, `_hold`)."""

    def _report(self, now_s: float, speed: float, residual_ss: float, normal: np.ndarray, weights: np.ndarray,
                w_sum: float, samples: int) -> FrictionEstimate:
        """The estimate from the fit just made: `residual_ss` is the weighted data residuals' sum
        of squares, `weights` the window samples' forgetting weights (None on the compiled path,
        where they stay in the window's scratch), `samples` their number."""
        o = self.options
        x = self._x
        x_list, theta_list, shared = self._floats_of_x()   # (shared: σ0, v_s, σ2 at 3, 5, 6)
        v_eval = max(speed, 1.0)
        wheel_mu, wheel_lam = self._fitted_peaks(v_eval, theta_list, shared)
        if self._due(0) or self._slip_support is None:
            self._slip_floor, self._slip_support = self._slip_range(weights)
            self._measured_peaks = self._data_peaks()
            self._band_ratio = self._band_ratio_of(wheel_mu, wheel_lam) if o.band_floor else 0.0
        # Variance factor from the data residuals (≥ 1: never more confident than assumed noise).
        dof = max(w_sum - len(x), 1.0)
        variance_factor = max(1.0, residual_ss / dof)
        # (μ_max's spread from the residuals' own size, for the confidence: on ice the assumed
        # noise floor is most of μ, and the fit is better than it)
        self._residual_scale = math.sqrt(min(residual_ss / dof, variance_factor) / variance_factor)
        if self._cov_unit is None or self._due(2):
            self._cov_unit = self._unit_covariance(x_list, normal)
        args = (wheel_mu, wheel_lam, self._slip_support, self._slip_floor,
                o.peak_extrapolation, o.extrapolation_max_slip, theta_list, v_eval)
        tail = (self._shared_scale, self._cov_unit, variance_factor, self._load_share)
        if self.core is not None:
            numbers = self.core.peak_report(*args, shared, *tail)
        else:
            numbers = _peak_report_numpy(*args, self._params(x), *tail)
        wheel_mu, wheel_lam, self._capped, mu_max, slip_star, mu_std, wheel_std = numbers
        fitted_mu = wheel_mu
        wheel_mu, mu_max = self._lifted_to_measured(now_s, wheel_mu, mu_max)
        # Excitation: how near the peak the data went, per wheel, from the newest samples.
        # Excitation moves on the time scale of ABS cycles (~0.1 s): evaluate it every few fits.
        if self._due(1) or self._excitation_cache is None:
            self._excitation_cache = self._excitation(weights, wheel_mu, wheel_lam, v_eval)
            self._data_above_fit = self._excess_over_fit(fitted_mu, wheel_mu, wheel_lam)
        excitation = self._excitation_cache
        wheel_mu, mu_max = self._lifted_to_bands(fitted_mu, wheel_mu, mu_max)
        longitudinal_mu = wheel_mu
        wheel_mu, mu_max = self._with_lateral_grip(wheel_mu, mu_max)
        confidence = self._confidence(now_s, mu_max, mu_std, excitation)
        theta_mean = sum(theta_list) / N_WHEELS
        detail = {"excitation": excitation, "variance_factor": variance_factor, "samples": float(samples),
                  "data_above_fit": self._data_above_fit, "spread_loss": self._peak_spread_loss,
                  "sigma0": float(shared[3]), "v_s": float(shared[5]), "sigma2": float(shared[6]),
                  "jumps": float(self._jumps)}
        detail.update(zip(_WHEEL_STD_KEYS, map(float, wheel_std)))
        if excitation > 0:
            self._balance_axles(now_s, longitudinal_mu)
        return self._decided(now_s, speed, excitation, confidence,
                             (mu_max, slip_star, theta_mean, wheel_mu, mu_std, detail))

    def _decided(self, now_s: float, speed: float, excitation: float, confidence: float,
                 numbers: tuple) -> FrictionEstimate:
        """The status of a fit's estimate (`numbers`: μ_max, λ*, mean θ, the wheels' μ_max, its
        spread, the detail), from its excitation and confidence, and the VALID kept from before."""
        o = self.options
        mu_max, slip_star, theta_mean, wheel_mu, mu_std, detail = numbers
        # Hysteresis: an estimate that was VALID last cycle (and not since invalidated by a jump)
        # stays VALID down to `keep_valid_confidence`. A one-cycle dip just under the threshold
        # (the drift term reacting to a 5 % correction when an ABS cycle adds samples nearer the
        # peak) would otherwise flip the status VALID → CONVERGING → VALID, which ABS/ESC
        # consumers see as flicker; a real change of road drops the confidence far lower.
        last = self._last_estimate
        kept = last is not None and last.status == Status.VALID and self._last_valid is not None
        threshold = o.keep_valid_confidence if kept else o.valid_confidence
        bar = self._barred_from_valid(now_s, mu_max, wheel_mu) if excitation > 0 else ""
        if bar:
            confidence = min(confidence, 0.5 * threshold)
        self._not_valid = bar or not_valid.LOW_CONFIDENCE
        if excitation > 0 and confidence >= threshold:
            status = Status.VALID
            self._last_excited_s = now_s
            self._not_valid = ""
        elif excitation > 0:
            status = Status.CONVERGING
        else:
            self._not_valid = not_valid.NOT_EXCITED
            if self._last_valid is None or now_s - self._last_excited_s > self._excitation_hold():
                # Braking goes on but the data no longer show the peak (a new road, or ABS
                # backing off): report the fit, not trusted, rather than an old VALID.
                return FrictionEstimate(now_s, Status.CONVERGING, mu_max, slip_star, theta_mean, 0.0,
                                        wheel_mu, mu_std, detail)
            return self._hold(now_s, speed)
        estimate = FrictionEstimate(now_s, status, mu_max, slip_star, theta_mean, confidence,
                                    wheel_mu, mu_std, detail)
        if status == Status.VALID:
            if not kept:
                self._valid_since_s = now_s
            self._last_valid = estimate
        return estimate

    def _excitation_hold(self) -> float:
        """How long braking without excitation keeps the standing VALID: one ABS cycle
        (`excitation_hold_s`) once it has stood a drift window, the span over which the confidence
        judges μ_max settled; a VALID younger than that (a confidence at the threshold, flickering)
        only that window. Held a cycle, such flickers carried a wrong μ_max on (averaged wheel
        speeds, a threshold ABS on dry cobblestone at 50 Hz: 28 outputs 22 % low to standstill)."""
        o = self.options
        if self._last_valid.time_s - self._valid_since_s >= o.drift_window_s:
            return o.excitation_hold_s
        return min(o.excitation_hold_s, o.drift_window_s)

    def _fitted_peaks(self, v_eval: float, theta_list: list[float], shared: tuple[float, ...]) -> tuple[list, list]:
        """Each wheel's fitted peak (μ, λ) at speed `v_eval`: searched near the last ones when
        the compiled fit can, else on the grid."""
        near = self._last_peak_slips
        found = None
        if self.core is not None and near is not None:
            found = self.core.peaks_near(v_eval, theta_list, near, shared)
            near = None   # (tried: what is left is the grid search)
        if found is None:
            grid_mu, grid_lam = peaks(v_eval, self._params(self._x), self._thetas(self._x), near=near)
            found = (grid_mu.tolist(), grid_lam.tolist())
        wheel_mu, wheel_lam = found
        self._last_peak_slips = wheel_lam
        return wheel_mu, wheel_lam

    def _unit_covariance(self, x_list: list[float], normal: np.ndarray) -> np.ndarray:
        """(JᵀWJ)⁻¹ over the free parameters. Parameters held at a bound are fixed there: the
        unconstrained Gauss–Newton covariance would count spread into the infeasible side. Like
        the excitation, it changes slowly: refreshed every few fits."""
        x = self._x
        if self.core is not None:
            # (the same test in floats: seven numbers do not need numpy's per-call cost)
            free_list = [v - lb > 1e-3 * (ub - lb) and ub - v > 1e-3 * (ub - lb)
                         for v, lb, ub in zip(x_list, self._lb_list, self._ub_list)]
            cov = np.empty((len(x), len(x)))
            if not self.core.inverse_free(normal, free_list, cov):
                cov[:] = np.inf
            return cov
        span = self._ub - self._lb
        free = (x - self._lb > 1e-3 * span) & (self._ub - x > 1e-3 * span)
        cov = np.zeros((len(x), len(x)))
        try:
            cov[np.ix_(free, free)] = np.linalg.inv(normal[np.ix_(free, free)])
        except np.linalg.LinAlgError:
            cov[:] = np.inf
        return cov

    def _lifted_to_measured(self, now_s: float, wheel_mu: tuple, mu_max: float) -> tuple[tuple, float]:
        """The wheels' peaks and μ_max raised to the grip measured: a wheel's own data, the car's
        deceleration."""
        o = self.options
        measured = self._measured_peaks
        if self._innovation_score <= o.jump_threshold and any(m > f for m, f in zip(measured, wheel_mu)):
            # A wheel's data rose above its fitted peak (a sharp peak the static model rounds
            # off): no tyre gives less than it was just measured to give. (Not while the newest
            # residuals say the road is changing: the grip measured may be the old road's.)
            wheel_mu = tuple(max(m, f) for m, f in zip(measured, wheel_mu))
            mu_max = sum(share * m for share, m in zip(self._load_share, wheel_mu))
        floor = self._body_floor(now_s)
        if mu_max < floor:
            # The fit's peak lies below the grip the car has just used (a sharp peak the static
            # model cannot follow, say): no road gives less than that. The wheels keep their split.
            lift = floor / max(mu_max, 1e-6)
            wheel_mu = tuple(m * lift for m in wheel_mu)
            mu_max = floor
        return wheel_mu, mu_max

    def _lifted_to_bands(self, fitted_mu: tuple, wheel_mu: tuple, mu_max: float) -> tuple[tuple, float]:
        """The wheels' peaks raised to the grip a band of their slips gave on average
        (`_band_ratio_of`). After the excitation and the data's excess over the curve have been
        read: the excess is the static curve's misfit, and a floor raised towards the data does not
        make the curve fit (the band's mean lies below a sharp peak), so it must not answer it."""
        ratio = self._band_ratio
        if ratio <= 1.0 or self._innovation_score > self.options.jump_threshold:
            return wheel_mu, mu_max
        wheel_mu = tuple(max(m, f * ratio) for m, f in zip(wheel_mu, fitted_mu))
        return wheel_mu, max(mu_max, sum(share * m for share, m in zip(self._load_share, wheel_mu)))

    def _with_lateral_grip(self, wheel_mu: tuple, mu_max: float) -> tuple[tuple, float]:
        """`_lateral_grip`'s peaks and μ_max; sets `_lateral_doubt` to its doubt."""
        wheel_mu, mu_max, self._lateral_doubt = self._lateral_grip(wheel_mu, mu_max)
        return wheel_mu, mu_max

    def _lateral_grip(self, wheel_mu: tuple, mu_max: float) -> tuple[tuple, float, float]:
        """The wheels' longitudinal peaks and μ_max as the road's grip: with the tyres carrying the
        lateral μ of a turn as well, √(μ_x² + μ_y²) each (the friction circle; a tyre whose
        lateral grip differs from its longitudinal one, an ellipse, is left to the model's
        mismatch); and the share of μ_max that adding a lateral μ smaller by
        `lateral_mu_tolerance` would not have added (all of what was added while the lateral μ is
        within that of nothing; 0 straight ahead, as before the turn)."""
        o = self.options
        lateral = self._lateral_mu
        if not o.lateral_grip or lateral <= 0.0 or mu_max <= 0.0:
            return wheel_mu, mu_max, 0.0
        share = self._load_share
        low = max(lateral - o.lateral_mu_tolerance, 0.0)
        mu_low = sum(s * math.hypot(m, low) for s, m in zip(share, wheel_mu))
        wheel_mu = tuple(math.hypot(m, lateral) for m in wheel_mu)
        mu_max = sum(s * m for s, m in zip(share, wheel_mu))
        return wheel_mu, mu_max, (mu_max - mu_low) / mu_max

    def _restate(self, last: FrictionEstimate, now_s: float, slipping: bool) -> FrictionEstimate:
        """The last (CONVERGING) fit again, at a cycle without usable samples.

        Its confidence is brought up to date when the excitation behind it is recent (within
        `excitation_window_s` of the fit) and the brakes still hold a wheel in slip (`slipping`):
        an ABS on ice releases every wheel together for a few tenths of a second, and a fit that
        was only waiting for the settling ramp and for its own drift to die down would otherwise
        stay CONVERGING until the next samples. Not while the driver lets go, every slip fallen
        below what the fit takes: waiting adds no evidence, and a fit made as the pressure fell
        went VALID 35 % low on a slip controller's held slip 60 ms later (new-seed stop 40965,
        70 % of its grip used).
        """
        o = self.options
        excitation = self._excitation_cache or 0.0
        if excitation <= 0.0 or now_s - self._last_fit_s > o.excitation_window_s or not slipping:
            self._not_valid = not_valid.NOT_EXCITED
            return dataclasses.replace(last, time_s=now_s)
        confidence = self._confidence(now_s, last.mu_max, last.mu_max_std, excitation)
        bar = self._barred_from_valid(now_s, last.mu_max, last.wheel_mu_max)
        if bar:
            confidence = min(confidence, 0.5 * o.valid_confidence)   # (as `_report` does)
        if confidence < o.valid_confidence:
            self._not_valid = bar or not_valid.LOW_CONFIDENCE
            return dataclasses.replace(last, time_s=now_s, confidence=confidence)
        self._not_valid = ""
        estimate = dataclasses.replace(last, time_s=now_s, status=Status.VALID, confidence=confidence)
        published = self._last_estimate
        if published is None or published.status != Status.VALID:
            self._valid_since_s = now_s
        self._last_valid = estimate
        self._last_excited_s = now_s
        return estimate

    def _hold(self, now_s: float, speed: float, fitted: tuple | None = None) -> FrictionEstimate:
        """No fresh excitation: keep a recent VALID for `hold_s`, then say NOT_EXCITED.

        Only a VALID still standing is kept: once an update at a speed where data can show a
        peak has published something else after it (the fit no longer backing it), it is not
        brought back, then or later. With every wheel deep in slip on a new road (wet to ice at
        110 km/h: no sample usable, the window aging out), it came back for a second at 7 times
        the ice's grip; a VALID withdrawn mid-stop came back at standstill two seconds later, 22 %
        below a road whose grip rises as the speed falls. As a stop ends (below
        `peak_evidence_min_speed`, where no slip is evidence), a VALID standing then is held as
        before, whatever the updates down there say: the road is the same."""
        o = self.options
        last = self._last_valid
        withdrawn = last is not None and self._withdrawn_moving_s > last.time_s
        if last is not None and not withdrawn and now_s - self._last_excited_s <= o.hold_s:
            return FrictionEstimate(now_s, Status.VALID, last.mu_max, last.slip_at_mu_max, last.theta,
                                    last.confidence, last.wheel_mu_max, last.mu_max_std, dict(last.detail))
        if last is not None:
            return FrictionEstimate(now_s, Status.NOT_EXCITED, last.mu_max, last.slip_at_mu_max, last.theta, 0.0,
                                    last.wheel_mu_max, math.inf)
        # Never excited: report the prior (contract: NOT_EXCITED carries the prior or the last
        # valid value), not a fit that has only seen the linear part of the curve.
        # The prior's peak at the speed rounded to 0.1 m/s, cached: this path runs every cycle of
        # every drive that has not braked hard yet, and the peak search is a grid search.
        key = (round(max(speed, 1.0), 1), self._prior.tobytes())
        if self._prior_peak is None or self._prior_peak[0] != key:
            p = self._params(self._prior)
            thetas = self._thetas(self._prior)
            wm, wl = peaks(key[0], p, thetas)
            self._prior_peak = (key, (float(np.mean(wm)), float(np.mean(wl)), float(np.mean(thetas)),
                                      tuple(map(float, wm))))
        mu_max, slip_star, theta, wheel_mu = self._prior_peak[1]
        return FrictionEstimate(now_s, Status.NOT_EXCITED, mu_max, slip_star, theta, 0.0, wheel_mu, math.inf)


def _peak_report_numpy(wheel_mu: list[float], wheel_lam: list[float], support: list[float], slip_floor: list[float],
                       peak_extrapolation: float, extrapolation_max_slip: float, thetas: list[float], v: float,
                       p: LugreParams, scales: tuple[float, float, float], cov_unit: np.ndarray,
                       variance_factor: float, share: list[float]) -> tuple:
    """The reported numbers from the wheels' peaks: (wheel μ_max, wheel λ*, capped, μ_max, λ*,
    std of μ_max, std of each wheel's μ_max). `_fitcore.peak_report` is the same, compiled.

    Each peak is held within the slips the data support (`support`: the high end of each wheel's
    recent slips; `slip_floor`: the low end): when the fitted curve keeps rising past
    `peak_extrapolation`× the slips seen (a monotone fit of a flat-topped road), μ_max is read at
    that slip instead of at a "peak" near lock; and data that only ever sit far past the fitted
    peak (a road whose μ keeps creeping up to high slip, an ABS that holds the wheels there) say
    nothing of a hump the model puts at small slips, so μ_max is read where the data begin.
    The road's μ_max is the wheels' peaks weighted by their normal loads (`share`): the body
    equation pins the total braking force (Σ μ_i·F_z,i), not its front/rear split (pad friction
    differs per axle), so the load-weighted mean is right when the plain mean is not. The
    standard deviations are the delta method's: ∂μ_max/∂x at each peak (envelope theorem).
    """
    wheel_mu, wheel_lam, support = np.array(wheel_mu), np.array(wheel_lam), np.array(support)
    thetas = np.array(thetas)
    if not np.isfinite(support).all() and np.isfinite(support).any():
        # A wheel without recent samples (held beyond max_slip, say) has seen no slips of its
        # own lately: it is bounded by the slips its car-mates have seen, not left to read
        # its peak at lock.
        support = np.where(np.isfinite(support), support, support[np.isfinite(support)].max())
    cap = supported_slip(support, peak_extrapolation, extrapolation_max_slip)
    beyond = wheel_lam > cap
    floor = np.array(slip_floor) / peak_extrapolation
    below = wheel_lam < floor
    capped = beyond | below
    if capped.any():
        limit = np.where(beyond, cap, floor)
        mu_cap, _ = braking_mu_and_partials_few(limit, v, thetas, p)
        wheel_mu = np.where(capped, np.minimum(mu_cap, wheel_mu), wheel_mu)
        wheel_lam = np.where(capped, limit, wheel_lam)
    _, jac = braking_mu_and_partials_few(wheel_lam, v, thetas, p)
    sc4, sc5, sc6 = scales
    G = np.array([[0.0] * i + [j[0] * th] + [0.0] * (N_WHEELS - 1 - i) + [j[1] * sc4, j[2] * sc5, j[3] * sc6]
                  for i, (j, th) in enumerate(zip(jac.tolist(), thetas.tolist()))])
    cov = cov_unit * variance_factor
    g_mean = np.dot(share, G)
    mu_max = sum(s * m for s, m in zip(share, wheel_mu.tolist()))
    slip_star = sum(s * lam for s, lam in zip(share, wheel_lam.tolist()))
    with np.errstate(invalid="ignore"):   # (a singular normal matrix left cov infinite: NaN std)
        mu_std = math.sqrt(max(float(g_mean @ cov @ g_mean), 0.0))
        wheel_std = [math.sqrt(max(v, 0.0)) if v == v else v for v in (np.dot(G, cov) * G).sum(axis=1).tolist()]
    return (tuple(wheel_mu.tolist()), tuple(wheel_lam.tolist()), tuple(capped.tolist()), mu_max, slip_star, mu_std,
            tuple(wheel_std))
