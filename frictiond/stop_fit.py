"""The stop's last fit: what the estimator says where its window has run short of samples.

`StopFit` is a part of `LugreTrustRegionEstimator` (its options, state and hold are the
estimator's): `update` follows when the brakes were last applied (`_follow_braking`), keeps each
fit it reports (`_kept_as_stop_fit`), and where there is neither a fit nor a fit to restate (nor
a body sum published), gives that one (`_starved`). A detected change of road (`road_change`) and a clock step forget it.
"""
from __future__ import annotations

from .samples import FrictionEstimate, Status


class StopFit:
    """The last fit of the stop under way, said `CONVERGING` where the window starved."""

    def _follow_braking(self, t: float, braking: bool) -> None:
        """When the brakes were last applied; a stop begun after `window_s` without them forgets
        the last stop's fit: the road may be another."""
        if braking:
            if t - self._last_braking_s > self.options.window_s:
                self._stop_fit = None
            self._last_braking_s = t

    def _kept_as_stop_fit(self, estimate: FrictionEstimate, t: float) -> FrictionEstimate:
        """`estimate`, kept as this stop's last fit when it is one (not a hold, not the fit that
        just saw the road change: that one describes the old road)."""
        if estimate.status in (Status.CONVERGING, Status.VALID) and self._last_jump_s != t:
            self._stop_fit = estimate
        return estimate

    def _starved(self, now_s: float, speed: float) -> FrictionEstimate:
        """A cycle with too few samples in the window to fit (or, below `peak_evidence_min_speed`,
        a body sum not published), nothing VALID standing, the brakes applied within `window_s`:
        this stop's last fit, CONVERGING. The wheels ran deep into slip
        and their samples left the window (a threshold ABS dwelling past the peak, a car whose
        wheel torques are unknown while its body sum refills). The contract's NOT_EXCITED says no
        slip excursion was seen yet, and its MuMax, the nominal dry road's peak, was off by a
        median of 118–148 % there (the campaign's ABS stops); the stop's last fit, by 22–24 %.
        Else the hold: a VALID standing, the last VALID, or the prior."""
        fit = self._stop_fit
        if fit is None or self._last_valid is not None or now_s - self._last_braking_s > self.options.window_s:
            return self._hold(now_s, speed)
        return FrictionEstimate(now_s, Status.CONVERGING, fit.mu_max, fit.slip_at_mu_max, fit.theta, 0.0,
                                fit.wheel_mu_max, fit.mu_max_std, dict(fit.detail))
