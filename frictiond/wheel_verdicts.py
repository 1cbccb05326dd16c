"""Each wheel's verdict on whether its newest data show the tyre's peak.

`WheelVerdicts` is a part of `LugreTrustRegionEstimator` (through `peak_evidence.PeakEvidence`,
which pools the verdicts into the excitation; the window, options and fit state are the
estimator's): a wheel whose slips are held carries an earlier verdict on, and a wheel whose slips
spread is read by the shape of its μ–slip data (bending over, flat at the top beyond the noise
and the derivative filter's smear, the road's top slope pooled over the wheels) and then by how
close they came to the fitted peak. The numpy reference of the compiled top-of-slips slope sits
beside it.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from .samples import N_WHEELS, REAR_WHEELS
from .tyre_model import MAX_MODEL_SLIP

# A wheel verdict's proximity when the wheel's data contradict the fitted curve (`_wheel_verdict`).
CONTRADICTED = -1.0
# A rear wheel's verdict while its axle may be crossing a change of road met by the front one.
REAR_CROSSING = "rear axle crossing a change of road"


def _top_elasticity_numpy(slip: np.ndarray, mu: np.ndarray, wheel: np.ndarray, times: np.ndarray, spread: np.ndarray,
                          start: int, end: int, since: float, wheel_i: int, min_n: int,
                          min_upper: int) -> tuple[float, float, float] | None:
    """`LugreTrustRegionEstimator._top_elasticity` on the window's columns (the compiled
    `top_elasticity`'s reference): the elasticity, its standard error and the smear."""
    lo = int(times[start:end].searchsorted(since)) + start
    rows = np.flatnonzero(wheel[lo:end] == wheel_i) + lo
    slips = slip[rows]
    if len(slips) < min_n or len(slips) < 1:
        return None
    median, top = np.quantile(slips, (0.5, 0.95))
    upper = (slips >= median) & (slips <= top)
    if int(upper.sum()) < min_upper or not top - median >= 1e-4:
        return None
    rows = rows[upper]
    ls, us = slip[rows], mu[rows]
    l_mean, u_mean = float(ls.mean()), float(us.mean())
    dl = ls - l_mean
    sxx_raw = float(dl @ dl)
    sxx = max(sxx_raw, 1e-12)
    slope = float(dl @ (us - u_mean)) / sxx
    residuals = (us - u_mean) - slope * dl
    slope_se = math.sqrt(float(residuals @ residuals) / max(len(ls) - 2, 1) / sxx)
    scale = l_mean / max(u_mean, 1e-6)
    sweep = float(np.sum(spread[2, rows] * (spread[0, rows] - ls) ** 2 + spread[3, rows] * (spread[1, rows] - ls) ** 2))
    smear = math.sqrt(sweep / sxx_raw) if sxx_raw > 0.0 else (math.inf if sweep > 0.0 else 0.0)
    return slope * scale, slope_se * scale, smear


class WheelVerdicts:
    """Per wheel, a verdict on whether its newest data show the peak: (reason, proximity to the
    peak, fresh)."""

    def _wheel_verdict(self, wheel: int, stats: tuple[float, ...], mu_star: float, lam_star: float, fit_at_hi: float,
                       capped: bool, speed: float, peak_seen: bool, abs_working: bool) -> tuple[Any, float, bool]:
        """One wheel's evidence of its peak: (reason, proximity to the peak, fresh).

        `fresh` is False for the one verdict that only carries earlier evidence on (a wheel held
        past the peak seen before), True where these data show the peak themselves.
        """
        o = self.options
        n, _, _, lam_lo, lam_hi, mu_hi, runaway_rate = stats[:7]
        if n < self._min_wheel_samples:
            return "few samples", 0.0, True
        if speed < o.peak_evidence_min_speed and not (peak_seen and self._wheel_shown_moving[wheel]):
            # Below it only a wheel that showed its own peak above it on this road may show it
            # again: on split μ the other side's peak says nothing of this wheel's, and at walking
            # pace the speed estimate's error alone spreads a held slip into a seeming peak (dev
            # stop 381 braked 0.15 s after start-up, the offset unlearnt: the dry side's slips
            # held at 0.11 "showed" it at 3.7 m/s, and 103 VALID outputs were 27 % low).
            return "too slow to show a peak", 0.0, True
        if wheel in REAR_WHEELS and self._rear_axle_crossing():
            return REAR_CROSSING, 0.0, True
        if not peak_seen and not abs_working and not self._running_away(wheel, runaway_rate, lam_hi, mu_hi, speed):
            return "slip not running away", 0.0, True
        if lam_hi * speed < o.excitation_min_sliding_mps:
            # Slip is a speed difference over the speed: at walking pace a few quanta of the
            # wheel-speed signals (0.01–0.06 km/h each) and the speed estimate's error make
            # several % of slip. A sliding speed that small is not measured, whatever the ratio.
            return "sliding too slow", 0.0, True
        # An ABS working the wheel is evidence of the limit by itself (it releases the pressure
        # the driver still demands), but the shape tests below still read the curve from the
        # spread of the slips: a slip controller holding its target to ±1 % leaves them nothing
        # but noise, and one of its verdicts passing at random would claim a peak that may lie
        # at twice that slip.
        needed_spread = o.abs_min_slip_spread if abs_working else o.min_slip_spread
        # (Beyond twice what the speed estimate's error alone spreads a held slip by: `speed_error`.)
        speed_error_spread = self._speed_error.slip_spread(self._last_sample_s, speed)
        spread = (lam_hi >= o.excitation_min_slip
                  and (lam_hi - lam_lo) >= needed_spread * lam_hi + 2.0 * speed_error_spread)
        if not spread:
            return self._held_slip_verdict(wheel, lam_lo, lam_hi, mu_hi, mu_star, lam_star, peak_seen)
        verdict = self._shape_verdict(wheel, stats, mu_star, lam_star, fit_at_hi, capped)
        self._shape_proximity[wheel] = verdict[1]
        self._shape_verdict_s[wheel] = self._last_sample_s
        return verdict

    def _rear_axle_crossing(self) -> bool:
        """Whether the rear wheels' newest data may still straddle the change of road last
        detected (`road_change.RoadChangeTest._detect_jump`)."""
        return self._last_sample_s <= self._rear_straddles_until_s

    def _held_slip_verdict(self, wheel: int, lam_lo: float, lam_hi: float, mu_hi: float, mu_star: float,
                           lam_star: float, peak_seen: bool) -> tuple[Any, float, bool]:
        """`_wheel_verdict` for a wheel whose slips do not spread, or are too small for any road's
        peak (≥ 1.5–3 % even on ice): the shape of the curve near its peak is not observed ...
        """
        o = self.options
        shown = self._shape_proximity[wheel]
        if (peak_seen and shown >= o.excitation_slip_ratio and lam_hi >= o.excitation_min_slip
                and lam_lo >= lam_star and mu_hi >= o.min_utilisation * mu_star
                and self._last_sample_s - self._shape_verdict_s[wheel] <= o.window_s):
            # ... unless this stop's data have shown the peak already, this wheel's own last
            # slips with spread said so, and the wheel now stays past it, using the grip the
            # fit says is there (ABS holding a wheel on an ice plateau): the peak is still
            # being used, not left behind. (Where the wheel's slips last spread its data were
            # still rising, the fit's peak under a held slip is where the fit put it, free
            # to: a slip target short of the peak leaves nothing to locate it.)
            # It carries no more than that verdict showed: the slip is held, and only the
            # fit's peak has moved under it since (a peak moved below a held slip is the
            # fit talking itself into excitation). And only while the samples behind that
            # verdict are in the window: then the fit has the held slip alone, whose μ bounds
            # μ_max from below and says nothing of the curve beyond it (a slip target short of
            # a rising peak and one on a plateau look the same).
            return ("past the peak ({:.2f})", lam_lo / lam_star), shown, False
        return "no slip spread", 0.0, True

    def _shape_verdict(self, wheel: int, stats: tuple[float, ...], mu_star: float, lam_star: float,
                       fit_at_hi: float, capped: bool) -> tuple[Any, float, bool]:
        """`_wheel_verdict` for a wheel whose slips spread: what the shape of its μ–slip data says."""
        not_flat = self._flatness_verdict(wheel, stats, lam_star)
        if not_flat is not None:
            return not_flat
        lam_hi, mu_hi = stats[4], stats[5]
        return self._proximity_verdict(lam_hi, mu_hi, mu_star, lam_star, fit_at_hi, capped)

    def _flatness_verdict(self, wheel: int, stats: tuple[float, ...],
                          lam_star: float) -> tuple[Any, float, bool] | None:
        """`_shape_verdict`'s tests of the data's top: None where they bend over, lie flat at the top
        slips beyond the noise and the filter's smear, and are past the linear region; else the
        verdict saying why not."""
        o = self.options
        _, _, _, _, lam_hi, mu_hi, _, s2, s3, s4, y1, y2 = stats
        # (With an ABS too: a deceleration-triggered ABS releases a soft tyre at half its grip,
        # by its own thresholds; only the data bending over show the tyre itself near its peak.)
        bent = self._bending(lam_hi, s2, s3, s4, y1, y2)
        if bent is not None:
            return bent, 0.0, True
        top = self._wheel_tops()[wheel]
        if top is None:
            return "too few samples at the top slips", 0.0, True
        elasticity, elasticity_se, smear = top
        if elasticity > o.flat_elasticity:
            if elasticity > o.contradiction_elasticity and lam_hi > o.contradiction_slip_ratio * lam_star:
                # μ still rising clearly (twice the flat threshold) at slips well past where the
                # fit puts this wheel's peak: the fitted curve is not the tyre's, and no wheel's
                # proximity to its peak can be read from it (a relaxing tyre's loops, a fit whose
                # peak moved onto the data of another wheel).
                return ("rising past the fitted peak ({:.2f})", elasticity), CONTRADICTED, True
            # The quadratic's bend is a shape over all the slips; the test of the peak is local:
            # at its peak a tyre's μ stops rising with slip. Under an ABS that releases below the
            # peak (a wheel-deceleration trigger on a soft tyre, a slip target short of a snow
            # curve's peak) the top slips still show μ rising at 0.4–0.7 of its secant.
            return ("still rising ({:.2f})", elasticity), 0.0, True
        if smear > o.max_top_smear:
            # μ is read through the derivative filter as a mean over the slips the wheel swept
            # within its window. Where those sweeps are wide against the top slips' own spread,
            # no sample's μ belongs to its slip closely enough to resolve a slope across them:
            # the error in the regressor shrinks the slope towards zero, and a curve still
            # rising reads flat (a deceleration ABS cycling a soft cobblestone tyre at 60 % of
            # its grip, dev stop 245 forced split with a select-low rear axle: 0.3 read where
            # the same samples' true slips and μ give 0.6–0.7).
            return ("top slips within the filter's sweep ({:.1f})", smear), 0.0, True
        slope_bound = self._road_top_bound()
        if slope_bound > o.rising_elasticity:
            # A flat-looking slope whose road's (the wheels' pooled) is within one standard
            # error of a curve still at 80 % of its peak is not a flat top: the top slips barely
            # spread (a slip held below the peak, then a release sweeping under it), or μ
            # scatters as much as such a curve climbs over them.
            return ("flat top not resolved ({:.2f})", slope_bound), 0.0, True
        if mu_hi > o.max_peak_secant * lam_hi:
            # Near any road's peak, μ/λ is well below the tyre's initial slip stiffness
            # (dry asphalt ≈ 1.0/0.1, ice ≈ 0.05/0.03); a steep secant is the linear region.
            return "steep secant", 0.0, True
        return None

    def _proximity_verdict(self, lam_hi: float, mu_hi: float, mu_star: float, lam_star: float, fit_at_hi: float,
                           capped: bool) -> tuple[Any, float, bool]:
        """`_shape_verdict` for data whose top is flat: how close they came to the fitted peak."""
        o = self.options
        # How close to the fitted peak the data came: in slip, in measured μ, and in the
        # fitted curve's own height at the data's high slip (on a flat-topped road the
        # peak slip is ill-defined but μ_max is not: the curve is already at its plateau).
        fit_ratio = fit_at_hi / max(mu_star, 1e-6)
        by_plateau = o.excitation_slip_ratio + (fit_ratio - o.excitation_fit_ratio) / (
            1.0 - o.excitation_fit_ratio) * (1.0 - o.excitation_slip_ratio)
        if capped:
            # μ_max was read at the extrapolation limit, not at a peak: only a plateau
            # (the fitted curve already flat where the data are) counts as evidence.
            proximity = by_plateau
        else:
            proximity = max(lam_hi / lam_star, mu_hi / mu_star * o.excitation_slip_ratio / o.excitation_mu_ratio,
                            by_plateau)
        if mu_hi < o.min_utilisation * mu_star:
            # The measured utilisation never came near the claimed peak: whatever the fit
            # says beyond the data is extrapolation.
            return "low utilisation", 0.0, True
        if lam_star >= 0.9 * MAX_MODEL_SLIP and fit_ratio < o.excitation_fit_ratio:  # (uncapped)
            return "no peak", 0.0, True   # no peak short of lock, and the data far below the fitted maximum
        return ("proximity {:.2f}", proximity), proximity, True

    def _wheel_tops(self) -> list[tuple[float, float, float] | None]:
        """Each wheel's `_top_elasticity` over the window of this fit, computed once for the
        wheels' own verdicts and the road's bound (`_road_top_bound`)."""
        if self._tops_fit != self._fits:
            self._tops = [self._top_elasticity(w) for w in range(N_WHEELS)]
            self._tops_fit = self._fits
        return self._tops

    def _road_top_bound(self) -> float:
        """The road's top-of-slips slope one standard error up: the wheels' `_top_elasticity`
        pooled by their inverse variances (∞ when no wheel has one).

        The slope over the top of the slips, as an elasticity, is the shape of the curve near
        its peak, which the four tyres on one road share whatever their loads; one wheel's
        samples alone leave it ±1 on ice, where μ is small against the noise of a measured μ.
        (On split μ the sides' shapes differ: the pooled bound is then the average road's, and
        each wheel's own slope must still be flat.)
        """
        tops = [t for t in self._wheel_tops() if t is not None]
        if not tops:
            return math.inf
        weights = [1.0 / max(se, 1e-9) ** 2 for _, se, _ in tops]
        total = sum(weights)
        return sum(w * e for w, (e, _, _) in zip(weights, tops)) / total + 1.0 / math.sqrt(total)

    def _top_elasticity(self, wheel: int) -> tuple[float, float, float] | None:
        """The wheel's local elasticity (dμ/dλ)·λ̄/μ̄ over the top half of its slips of the newest
        `flat_window_s`: a least-squares slope over the samples between the median slip and the
        95 % quantile (the single highest are noise and runaway), with its standard error from
        the residuals, and the smear of those slips: the rms of the sweeps the derivative filter
        averaged each sample's μ over (`PhysicalSample.slip_spread`) against their standard
        deviation; None without enough of them.

        1 on a linear flank, ≈ 0 at the peak, < 0 past it. At 90 % of the peak the tangent is
        about a third of the secant: median 0.36 over Magic Formula shapes (B 4–14, C 1.2–2.5,
        E −1…0.9) and Burckhardt's roads, 0.54 at 80 % (0.27–0.68).
        """
        o = self.options
        w = self._window
        args = (w.slip, w.mu, w.wheel, w.time, w.spread, w.start, w.end, self._last_sample_s - o.flat_window_s, wheel,
                o.flat_min_samples, max(4, o.flat_min_samples // 2))
        if self.core is not None:
            return self.core.top_elasticity(*args)
        return _top_elasticity_numpy(*args)

    @staticmethod
    def _bending(lam_hi: float, s2: float, s3: float, s4: float, y1: float, y2: float) -> Any:
        """None when the wheel's recent μ–slip data bend over (the through-origin quadratic's
        tangent at the high slip below half its secant), else why not."""
        det = s2 * s4 - s3 * s3
        if det <= 1e-18 * max(s2 * s4, 1e-300):
            return "degenerate"
        a = (y1 * s4 - y2 * s3) / det
        b = (s2 * y2 - s3 * y1) / det
        secant = a + b * lam_hi
        if secant <= 0:
            return "negative secant"
        bending = (a + 2 * b * lam_hi) / secant
        if bending > 0.5:
            return ("not bending ({:.2f})", bending)
        return None

