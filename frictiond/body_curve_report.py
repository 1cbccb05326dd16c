"""The car's total force beside the wheels' fit: where that fit is not VALID, the free curve of the
body's force (`body_sum_curve`) may be.

`BodyCurveReport` is a part of `LugreTrustRegionEstimator` (beside `BodySumReport`, whose fit,
drift and confidence it shares). On a car whose wheels' brake torques
are known, the wheels' fit reads each wheel's μ from its torque balance: through the brakes' gain
(±20 % off what the config says until the body equation corrects it) and through the derivative
filter, whose mean over a sample's slips falls short of the curve where it bends at the top. Under
a threshold ABS, whose wheels cross the peak in a sample or two and dwell deep past it, that fit's
spread often keeps it from VALID. The accelerometer has neither error: the body's μ against the
four slips, fitted with a curve of no shape over a window of several ABS cycles, shows the peak
where the force falls past its top on every cycle. The same fit reads master-cylinder-only cars'
deep windows (`body_sum_report`); here it is a second source, read only in windows whose wheels
run mostly deep past the peak (a threshold ABS; where they stay near it, the fall past the top
rests on few rows, and on the development campaign's slip and deceleration controllers the curve
read changes of road and split μ as peaks), and published only where it shows the peak with VALID's
confidence above the grip the car used within its window (`_body_fit_floor`), the wheels' fit is
not VALID, and that fit puts the peak near the curve's. In a turn both are read by the friction
circle (`EstimateReport._lateral_grip`).
"""
from __future__ import annotations

import math
from collections import deque

from .body_sum_fit import BodySumOptions
from .samples import N_WHEELS, FrictionEstimate, PhysicalSample, Status


class BodyCurveReport:
    """Rows of the body's force in beside the wheels' samples; a VALID from the free curve out
    where the wheels' fit gives none (`_beside_body_curve`)."""

    def _init_body_curve(self) -> None:
        self._body_curve = self._new_body_fit(BodySumOptions(deep_only=True))
        self._body_curve_history: deque[tuple[float, float]] = deque()

    def _clear_body_curve(self) -> None:
        self._body_curve.clear()
        self._body_curve_history.clear()

    def _take_in_body_curve(self, sample: PhysicalSample) -> None:
        """The sample's row of the body's force, where the wheels' torques are known (where they
        are not, `body_sum_report` reads the rows)."""
        if self.options.body_curve_beside_wheels and sample.braking and not sample.wheel_torques_unknown:
            self._body_curve.push(sample.time_s, sample.speed_mps, sample.slip, sample.normal_force_n,
                                  sample.body_force_mu, sample.lateral_mu)

    def _beside_body_curve(self, estimate: FrictionEstimate, sample: PhysicalSample) -> FrictionEstimate:
        """`estimate` (the wheels' fit's, a restated or held one), or where it is not VALID the
        free curve's, VALID, if that shows the peak with the confidence VALID needs (the body
        sum's, `_body_confidence`)."""
        o = self.options
        now_s, speed = sample.time_s, sample.speed_mps
        if (estimate.status == Status.VALID or not o.body_curve_beside_wheels or sample.wheel_torques_unknown
                or not speed >= o.peak_evidence_min_speed):
            return estimate
        fit = self._body_curve.result(now_s, speed)
        if fit is None or fit.verdict:
            self._body_curve_history.clear()
            return estimate
        # (in a turn, by the friction circle, as the wheels' estimate it is compared with)
        _, mu_max, lateral_doubt = self._lateral_grip((fit.mu_max,) * N_WHEELS, fit.mu_max)
        drift = self._body_drift(self._body_curve_history, now_s, mu_max)
        confidence, spread2 = self._body_confidence(mu_max, drift, fit, sample.body_force_doubt, lateral_doubt)
        last = self._last_estimate
        threshold = o.keep_valid_confidence if last is not None and last.status == Status.VALID else o.valid_confidence
        if (not confidence >= threshold or not mu_max >= self._body_fit_floor(fit, sample.body_force_doubt)
                or not self._agrees_with_wheels(estimate, mu_max)):
            return estimate
        detail = dict(estimate.detail or {})
        detail.update({"body_curve": 1.0, "body_sum_curve_se": fit.curve_se_share, "body_sum_rows": float(fit.rows)})
        valid = FrictionEstimate(now_s, Status.VALID, mu_max, fit.slip_star, estimate.theta, confidence,
                                 (mu_max,) * N_WHEELS, mu_max * math.sqrt(spread2), detail)
        self._not_valid = ""
        self._last_valid = valid
        self._last_excited_s = now_s
        return valid

    def _agrees_with_wheels(self, estimate: FrictionEstimate, mu_max: float) -> bool:
        """Whether the wheels' fit, CONVERGING, puts the peak within `body_curve_agreement` of
        the curve's. The two read one road's peak through different sensors; far apart, one of
        them is fooled (a road changing within the window, a tyre's force lagging its slip, a
        peak beyond the slips the wheels reached), and neither is claimed. Without a fit of the
        wheels (NOT_EXCITED, a prior held) there is nothing to check the curve against."""
        return (estimate.status == Status.CONVERGING
                and abs(estimate.mu_max - mu_max) <= self.options.body_curve_agreement * mu_max)
