"""The estimate from the car's total tyre force, where no wheel's brake torque is known.

`BodySumReport` is a part of `LugreTrustRegionEstimator`: while the front end says no wheel's
brake torque is known (`PhysicalSample.wheel_torques_unknown`: one master-cylinder pressure, an
ABS releasing wheels), no wheel's μ enters the window, and μ_max comes from the fit of the
sides' θ to the body's force (`body_sum_fit`) instead. Its confidence is the probability of μ_max within
`confidence_band` under a normal error of σ² = the fit's measured mismatch
(`body_sum_mismatch`)² + its drift² + the accelerometer's and the drag's doubt²/3 + the rise of its
residuals towards deep slips² (`BodySumResult.rise_share`, counted `misfit_peak_ratio` times as the
wheels' fit counts the data above its curve: the peak lies beyond the fit by about that much).
"""
from __future__ import annotations

import dataclasses
import math
from collections import deque

from . import input_quality, not_valid
from .body_sum_fit import CURVE_LOST, MISFIT, ROAD_CHANGE, BodySumFit, BodySumOptions, BodySumResult
from .samples import N_WHEELS, FrictionEstimate, PhysicalSample, Status
from .tyre_model import LugreParams

# The body-sum fits μ_max's drift is read over: the largest change within this long.
DRIFT_WINDOW_S = 0.3


class BodySumReport:
    """Rows of the body's force in, an estimate out (`_body_sum_estimate`)."""

    def _init_body_sum(self) -> None:
        o = self.options
        self._body_sum = self._new_body_fit(BodySumOptions(peak_extrapolation=o.peak_extrapolation,
                                                           extrapolation_max_slip=o.extrapolation_max_slip,
                                                           deep_curve=o.body_sum_curve))
        self._body_sum_history: deque[tuple[float, float]] = deque()
        self._body_force_doubt = 0.0   # the newest row's (`PhysicalSample.body_force_doubt`)

    def _new_body_fit(self, fit_options: BodySumOptions) -> BodySumFit:
        """A fit of the car's total force on the estimator's priors: the static curve's shape, θ
        and its bounds, the sides' coupling; read in a turn up to `body_sum_lateral_share` of its
        peak where the reports add the lateral μ back (`lateral_grip`)."""
        o = self.options
        fit_options = dataclasses.replace(fit_options,
                                          max_lateral_share=o.body_sum_lateral_share if o.lateral_grip else 0.0)
        shape = LugreParams(sigma0=o.prior_sigma0, sigma2=o.prior_sigma2, mu_c=o.mu_c, mu_s=o.mu_s, v_s=o.prior_v_s,
                            alpha=o.alpha, patch_length=o.patch_length)
        return BodySumFit(shape, o.prior_theta, o.prior_std_log_theta, (o.theta_min, o.theta_max),
                          o.left_right_coupling, fit_options)

    @staticmethod
    def _body_drift(history: deque[tuple[float, float]], now_s: float, mu_max: float) -> float:
        """`mu_max` into `history` (its last `DRIFT_WINDOW_S` kept), and how far the fits' μ_max
        moved over that: the largest change, as a share of μ_max."""
        history.append((now_s, mu_max))
        while history and history[0][0] < now_s - DRIFT_WINDOW_S:
            history.popleft()
        return (max(m for _, m in history) - min(m for _, m in history)) / max(mu_max, 0.05)

    def _body_confidence(self, mu_max: float, drift: float, fit: BodySumResult, doubt: float,
                         lateral_doubt: float = 0.0) -> tuple[float, float]:
        """(confidence, σ²) of a body fit's `mu_max`: the probability of μ_max within
        `confidence_band` under a normal error of σ² = `body_sum_mismatch`² + `drift`² + (the
        accelerometer's and the drag's `doubt` over μ_max)²/3 + (`misfit_peak_ratio` × the
        residuals' rise, if positive)² + (`body_sum_curve_error_ratio` × the free curve's standard
        error)² + `lateral_doubt`²/3 (as the wheels' fit counts it, `_with_lateral_grip`), less
        what corrupted input costs."""
        o = self.options
        rise = o.misfit_peak_ratio * max(fit.rise_share, 0.0)
        curve = o.body_sum_curve_error_ratio * fit.curve_se_share
        spread2 = (o.body_sum_mismatch ** 2 + drift ** 2 + (doubt / max(mu_max, 0.05)) ** 2 / 3.0 + rise ** 2
                   + curve ** 2 + lateral_doubt ** 2 / 3.0)
        confidence = math.erf(o.confidence_band / math.sqrt(2.0 * spread2)) if spread2 > 0.0 else 1.0
        return confidence * input_quality.confidence_factor(self._input_share), spread2

    def _body_fit_floor(self, fit: BodySumResult, doubt: float) -> float:
        """The least μ_max VALID allows a body fit, here and beside the wheels' fit
        (`body_curve_report`): the stop's floor (`_stop_floor`), or for the free curve the same rule
        on the utilisation within its own window, less `doubt` (the accelerometer's and the drag's
        for the newest row, `PhysicalSample.body_force_doubt`). The stop's floor guards against a
        fit that has forgotten the peak the car used, its wheels held deep in slip since; a free
        curve that shows the peak has its top read in both halves of its window (`body_sum_curve`),
        so that peak is in its rows, and what the car used before them may have been another road's
        (dev stops 172 and 490: the grip used on a dry road held a wet road's curve, within 2 % of
        the truth, from VALID for the rest of the stop; 40703 beside the wheels' fit, whose test
        missed the change from snow to ice, an ice curve within 1 %)."""
        if fit.curve_se_share <= 0.0:
            return self._stop_floor()
        used = self._less_accelerometer_margins(fit.window_utilisation - doubt)
        return used * (1.0 - self.options.stop_floor_tolerance)

    def _clear_body_sum(self) -> None:
        self._body_sum.clear()
        self._body_sum_history.clear()

    def _take_in_body_sum(self, sample: PhysicalSample) -> None:
        """The sample's row of the body's force, while that is all there is to fit."""
        if self.options.body_sum and sample.wheel_torques_unknown and sample.braking:
            self._body_sum.push(sample.time_s, sample.speed_mps, sample.slip, sample.normal_force_n,
                                sample.body_force_mu, sample.lateral_mu)
            self._body_force_doubt = sample.body_force_doubt

    def _body_sum_estimate(self, now_s: float, speed: float) -> FrictionEstimate | None:
        """The estimate from the body's force; None without a fit (too few rows)."""
        o = self.options
        fit = self._body_sum.result(now_s, speed)
        if fit is None:
            return None
        mu_max = max(fit.mu_max, self._body_floor(now_s))   # (no road gives less than the car just used)
        # In a turn the sum's peak is what the lateral force leaves of the road's (`_turning`).
        _, mu_max, lateral_doubt = self._lateral_grip((mu_max,) * N_WHEELS, mu_max)
        drift = self._body_drift(self._body_sum_history, now_s, mu_max)
        if speed < o.peak_evidence_min_speed:
            # A stop ending, where slips are no evidence: a VALID standing is held, as the
            # wheels' fit's; without one, this stop's last fit stands, CONVERGING (`_starved`),
            # not the prior: the wheels were braked past the slip excursion NOT_EXCITED denies.
            return self._starved(now_s, speed)
        confidence, spread2 = self._body_confidence(mu_max, drift, fit, self._body_force_doubt, lateral_doubt)
        detail = {"body_sum": 1.0, "body_sum_rms": fit.rms_share, "body_sum_rise": fit.rise_share,
                  "body_sum_curve_se": fit.curve_se_share,
                  "body_sum_spanning": float(sum(fit.spans)), "body_sum_rows": float(fit.rows)}
        last = self._last_estimate
        threshold = o.keep_valid_confidence if last is not None and last.status == Status.VALID else o.valid_confidence
        if fit.verdict:
            # One ABS cycle without evidence keeps a VALID, as the wheels' fit's does; a curve that
            # no longer fits, or no longer shows the peak it showed over several cycles, does not:
            # the road may be changing under it.
            recent = self._last_valid is not None and now_s - self._last_excited_s <= o.excitation_hold_s
            if recent and fit.verdict not in (MISFIT, ROAD_CHANGE, CURVE_LOST):
                return self._hold(now_s, speed)
            self._not_valid = not_valid.body_sum_reason(fit.verdict)
            confidence = 0.0
        elif mu_max < self._body_fit_floor(fit, self._body_force_doubt):
            self._not_valid = not_valid.BELOW_STOP_FLOOR
            confidence = min(confidence, 0.5 * threshold)
        elif confidence < threshold:
            self._not_valid = not_valid.LOW_CONFIDENCE
        else:
            self._not_valid = ""
        status = Status.VALID if not self._not_valid else Status.CONVERGING
        estimate = FrictionEstimate(now_s, status, mu_max, fit.slip_star, fit.theta, confidence,
                                    (mu_max,) * N_WHEELS, mu_max * math.sqrt(spread2), detail)
        if status == Status.VALID:
            self._last_valid = estimate
            self._last_excited_s = now_s
        return estimate
