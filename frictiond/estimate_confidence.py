"""How far a published μ_max can be trusted: the estimator's confidence and its vetoes.

The confidence is the probability that μ_max is within `confidence_band` of the road's, from the
fit's spread, its drift, the model mismatch and the mismatch the data measure; the vetoes keep a
μ_max below the grip the car or its wheels measured, or resting on wheels that have not shown their
peak, from being VALID. `EstimateConfidence` is a part of `LugreTrustRegionEstimator`.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from . import input_quality, not_valid
from .samples import LEFT_WHEELS, N_WHEELS, RIGHT_WHEELS
# Each wheel's partner in its track: the other axle's wheel on the same side.
_IN_TRACK = {a: b for side in (LEFT_WHEELS, RIGHT_WHEELS) for a, b in (side, side[::-1])}
# Bands of slip, as multiples of a wheel's fitted peak slip, in which `_excess_over_fit` averages
# the data's excess over the fitted curve: narrow around the peak, wider past it.
_MISFIT_SLIP_BANDS = np.array([0.5, 0.75, 0.9, 1.1, 1.4, 2.0, 3.0])
# The bands of `_band_ratio_of`: those of them from 0.75 to 2 times the peak slip.
_BAND_FLOOR_SLIPS = _MISFIT_SLIP_BANDS[1:6]
_BAND_FLOOR_EDGES = tuple(_BAND_FLOOR_SLIPS.tolist())
_MISFIT_EDGES = tuple(_MISFIT_SLIP_BANDS.tolist())


def _data_peaks_numpy(slip: np.ndarray, mu: np.ndarray, wheel: np.ndarray, k: int, min_samples: int,
                      margin: float) -> list[float]:
    """`LugreTrustRegionEstimator._data_peaks`'s statistics on the samples given (time order);
    `_fitcore.data_peaks` is the same, compiled."""
    out = [0.0] * N_WHEELS
    # All wheels at once (a handful of numpy calls, not a handful per wheel): the samples in
    # (wheel, slip) order, each wheel's first n − n mod k of them in groups of k.
    order = np.lexsort((slip, wheel))
    counts = np.bincount(wheel.astype(np.intp), minlength=N_WHEELS)[:N_WHEELS]
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    used = np.where(counts >= max(k, min_samples), counts - counts % k, 0)
    if not used.any():
        return out
    picks = np.concatenate([order[a:a + u] for a, u in zip(starts.tolist(), used.tolist()) if u])
    groups = mu[picks].reshape(-1, k)
    means = groups.mean(axis=1)
    spread = np.sqrt(((groups - means[:, None]) ** 2).sum(axis=1) / (k - 1))
    lower = means - 2.0 * spread / math.sqrt(k)
    first = 0
    for i, u in enumerate(used.tolist()):
        if u:
            out[i] = max(0.0, float(lower[first:first + u // k].max()) * (1.0 - margin))
            first += u // k
    return out


def _band_ratio_numpy(slip: np.ndarray, mu: np.ndarray, wheel: np.ndarray, peak_mu: Sequence[float],
                      peak_slip: Sequence[float], min_samples: int) -> float:
    """`EstimateConfidence._band_ratio_of`'s band means on the samples given; `_fitcore.band_ratio`
    is the same, compiled."""
    wheel = wheel.astype(np.intp)
    fitted = np.maximum(np.asarray(peak_mu, dtype=float), 1e-3)[wheel]
    at = slip / np.maximum(np.asarray(peak_slip, dtype=float), 1e-3)[wheel]
    means, full = _band_means(_BAND_FLOOR_SLIPS, at, mu / fitted, min_samples)
    means, full = means[1:-1], full[1:-1]   # (between the first and the last edge)
    return float(means[full].max()) if full.any() else 0.0


def _band_means(edges: np.ndarray, at: np.ndarray, values: np.ndarray,
                min_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Per band of `at` between consecutive `edges` (band 0 below the first edge, the last one
    past the last edge): the mean of `values` over its samples, and whether it has `min_samples`
    of them."""
    band = np.searchsorted(edges, at, side="right")
    counts = np.bincount(band, minlength=len(edges) + 1)
    sums = np.bincount(band, weights=values, minlength=len(edges) + 1)
    return np.divide(sums, counts, out=np.zeros(len(counts)), where=counts > 0), counts >= min_samples


def excess_over_fit_numpy(model_minus_data: np.ndarray, slip: np.ndarray, wheel: np.ndarray,
                          wheel_mu: Sequence[float], fitted_mu: Sequence[float], wheel_lam: Sequence[float],
                          min_samples: int) -> float:
    """`EstimateConfidence._excess_over_fit` on the samples given (model − data per sample);
    `_fitcore.excess_over_fit` is the same, compiled."""
    published = np.maximum(np.asarray(wheel_mu, dtype=float), 1e-3)
    lift = published - np.asarray(fitted_mu, dtype=float)
    peak_mu = published[wheel]
    peak_slip = np.maximum(np.asarray(wheel_lam, dtype=float), 1e-3)[wheel]
    excess = (-model_minus_data - lift[wheel]) / peak_mu
    means, full = _band_means(_MISFIT_SLIP_BANDS, slip / peak_slip, excess, min_samples)
    full[0] = False   # (below half the peak slip: the slip stiffness and the pedal's transient, not the peak)
    if not full.any():
        return 0.0
    return max(0.0, float(means[full].max()))


class EstimateConfidence:
    """The confidence of a fit's μ_max, and what bars it from VALID whatever its confidence."""

    def _data_peaks(self) -> list[float]:
        """Per wheel, the highest μ its newest samples (`excitation_window_s`) show with
        confidence; 0 without enough of them.

        The samples in slip order, in groups of `peak_group_samples` neighbours: each group's
        mean μ less twice its standard error; the highest of these. Means over neighbouring slips
        average the noise of the wheel-acceleration filter (several % of μ on dry asphalt under
        ABS) that a single high sample carries; the two standard errors cover the maximum over
        a few groups picking the noisiest.
        """
        o = self.options
        w = self._window
        k = o.peak_group_samples
        out = [0.0] * N_WHEELS
        if k <= 1 or len(w) < k or self._last_sample_s - self._event_start_s < o.measured_peak_settle_s:
            # (Early in a stop a wheel's μ carries the brake gain's error, ±20 %, until the front
            # end's body-equation check has corrected it: then it bounds nothing.)
            return out
        lo = int(w.time[w.start:w.end].searchsorted(self._last_sample_s - o.excitation_window_s)) + w.start
        if self.core is not None:
            return self.core.data_peaks(w.slip, w.mu, w.wheel, lo, w.end, k, self._min_wheel_samples,
                                        o.measured_peak_margin)
        return _data_peaks_numpy(w.slip[lo:w.end], w.mu[lo:w.end], w.wheel[lo:w.end], k, self._min_wheel_samples,
                                 o.measured_peak_margin)

    def _band_ratio_of(self, wheel_mu: Sequence[float], wheel_lam: Sequence[float]) -> float:
        """The highest mean, over a band of slips around the wheels' fitted peaks, of the window's
        samples' μ each over its wheel's fitted peak; 0 without such a band of `misfit_bin_samples`
        samples, or early in a stop (as `_data_peaks`).

        A band's mean is the grip the tyres gave over those slips, averaged over many samples and
        the window's ABS cycles: their peak is at least that. Where the static curve rounds off a
        sharp peak (a Magic Formula tyre falling 20–55 % past it) the band at the peak lies above
        the fitted peak on every cycle, while no single group of neighbours stands out of the noise
        (`_data_peaks`). The bands reach from 0.75 to 2 times the fitted peak slip: a rounded
        peak's fit puts λ* off the tyre's, either side. The whole window, not its newest samples:
        a change of road detected drops the older samples (`_detect_jump`).
        """
        o = self.options
        w = self._window
        if len(w) < o.misfit_bin_samples or self._last_sample_s - self._event_start_s < o.measured_peak_settle_s:
            return 0.0
        lo, hi = w.start, w.end
        if self.core is not None:
            return self.core.band_ratio(w.slip, w.mu, w.wheel, lo, hi, wheel_mu, wheel_lam, _BAND_FLOOR_EDGES,
                                        o.misfit_bin_samples)
        return _band_ratio_numpy(w.slip[lo:hi], w.mu[lo:hi], w.wheel[lo:hi], wheel_mu, wheel_lam, o.misfit_bin_samples)

    def _body_floor(self, now_s: float) -> float:
        """The least μ_max the car's own deceleration allows: the highest utilisation it showed
        over the last `body_floor_window_s` (each a mean over `body_floor_smoothing_s`), less the
        accelerometer's margins; 0 without such data. The load-weighted μ_max bounds the total
        tyre force over the weight: Σ μ_i F_N,i / Σ F_N,i ≤ Σ μ_max,i F_N,i / Σ F_N,i."""
        o = self.options
        best = self._body_mu.maximum(now_s - o.body_floor_window_s)
        return 0.0 if best is None else self._less_accelerometer_margins(best)

    def _less_accelerometer_margins(self, body_mu: float) -> float:
        """A body utilisation less what the accelerometer's offset and the car's pitch may add."""
        o = self.options
        return body_mu * (1.0 - o.body_floor_relative_margin) - o.body_floor_margin

    def _barred_from_valid(self, now_s: float, mu_max: float, wheel_mu: Sequence[float]) -> str:
        """What bars μ_max from VALID whatever its confidence ("" when nothing does): below the
        stop's floor, from a model that misfits the tyre (`_misfit`), leaning on wheels that
        have not shown their peak (`_leans_on_unshown_wheels`) or on a side of the car without
        samples (`_a_side_unsampled`)."""
        if mu_max < self._stop_floor():
            return not_valid.BELOW_STOP_FLOOR
        if self._misfit(now_s):
            return not_valid.MISFIT
        if self._leans_on_unshown_wheels(now_s, wheel_mu):
            return not_valid.UNSHOWN_WHEELS
        if self._a_side_unsampled():
            return not_valid.UNSAMPLED_SIDE
        return ""

    def _a_side_unsampled(self) -> bool:
        """Whether the window holds samples of one side of the car and none of the other.

        μ_max is the load-weighted mean of the four wheels' peaks, and on split μ each side has
        its own road: an unsampled side's peaks are the fit's coupling of it to the other side,
        not a measurement of its road, and `_leans_on_unshown_wheels` cannot tell (they agree
        with the sampled side by construction). At the end of a split-μ stop, with the pedal
        released, only the low side's wheels spin back up from deep slip: their samples alone
        read the car's μ_max as the low side's."""
        w = self._window
        if w.end == w.start:
            return False
        counts = np.bincount(w.wheel[w.start:w.end], minlength=N_WHEELS).tolist()
        return (counts[LEFT_WHEELS[0]] + counts[LEFT_WHEELS[1]] == 0
                or counts[RIGHT_WHEELS[0]] + counts[RIGHT_WHEELS[1]] == 0)

    def _leans_on_unshown_wheels(self, now_s: float, wheel_mu: Sequence[float]) -> bool:
        """Whether μ_max depends on the peaks of wheels whose data have not shown them lately.

        μ_max is the load-weighted mean of the four wheels' peaks; excitation needs only one
        wheel at its peak. On one road the others' fits follow it (they share the road), but on
        split μ a wheel on the grippy side, its slip held far below its peak (a slip target
        short of a cobblestone's peak at 0.4), contributes an extrapolation: VALID with a mean
        as wrong as that. So μ_max is compared with the mean the shown wheels' peaks alone give,
        and with the one where such a wheel takes the peak of the wheel in its track, if shown
        (a rear wheel rolls where the front one rolled: on split μ the shown wheels' mean mixes
        both roads and can agree with an extrapolation by chance).
        """
        o = self.options
        hold = o.wheel_evidence_hold_s
        shown = [now_s - t <= hold for t in self._wheel_shown_s]
        if all(shown) or not any(shown):
            return False
        share = self._load_share
        shown_weight = sum(w for w, s in zip(share, shown) if s)
        reference = sum(w * m for w, m, s in zip(share, wheel_mu, shown) if s) / max(shown_weight, 1e-9)
        total = max(sum(share), 1e-9)
        published = sum(w * m for w, m in zip(share, wheel_mu)) / total
        by_mean = [reference] * N_WHEELS
        by_track = [wheel_mu[_IN_TRACK[i]] if shown[_IN_TRACK[i]] else reference for i in range(N_WHEELS)]
        for stand_in in (by_mean, by_track):
            if_shown = sum(w * (m if s else x) for w, m, s, x in zip(share, wheel_mu, shown, stand_in)) / total
            if abs(published - if_shown) > o.unshown_wheel_tolerance * max(if_shown, 1e-6):
                return True
        return False

    def _misfit(self, now_s: float) -> bool:
        """Whether `misfit_changes` changes of road were detected within `misfit_window_s`. A real
        change shows at most twice in a few seconds, once per axle a wheelbase apart; more often,
        the newest residuals' bias is the static model not describing this tyre (a sharp peak the
        wheels pass in a few ms, a tyre whose force lags its slip): its μ_max is not VALID."""
        times = self._jump_times
        while times and now_s - times[0] > self.options.misfit_window_s:
            times.popleft()
        return self.options.misfit_changes > 0 and len(times) >= self.options.misfit_changes

    def _stop_floor(self) -> float:
        """The least μ_max the car's highest utilisation since this stop (or road) began allows,
        with the tolerance of a fit that rounds a sharp peak: a fit below it has forgotten the
        peak the car used (the wheels held deep in slip since), so its μ_max is not VALID."""
        return self._less_accelerometer_margins(self._body_mu.highest) * (1.0 - self.options.stop_floor_tolerance)

    def _confidence(self, now_s: float, mu_max: float, mu_std: float, excitation: float) -> float:
        """0…1: the probability that μ_max is within `confidence_band` of the road's, as far as
        these data tell.

        The Gauss–Newton covariance alone measures noise, not model mismatch. Combined here: the
        delta-method spread of μ_max (from the residuals' own size), the drift of μ_max over the
        last `drift_window_s` (an estimate still moving is not settled), a floor for model
        mismatch, the excitation, a ramp over the first `settle_s` of excitation (the first fits
        after onset are the worst), and the bias of the newest residuals (a road changing under
        the fit), and how far the data rise above the fitted curve (`_excess_over_fit`).
        """
        o = self.options
        history = self._mu_history
        history.append((now_s, mu_max))
        while history and history[0][0] < now_s - o.drift_window_s - 0.05:
            history.popleft()
        if excitation <= 0.0:
            if now_s - self._excited_since_s > 0.5:
                self._excited_since_s = math.inf
            return 0.0
        if self._excited_since_s == math.inf or now_s < self._excited_since_s:
            self._excited_since_s = now_s
        scale = max(mu_max, 0.05)
        drift = abs(mu_max - self._drift_reference(now_s)) / scale
        rel_std = mu_std * self._residual_scale / scale if math.isfinite(mu_std) else 10.0
        # The error's σ: the delta-method spread, the drift and the floor. The spread counts the
        # samples as independent evidence of the peak; they are not: a static model's misfit of a
        # tyre (a sharp peak rounded off, a force lagging its slip) repeats over each ABS cycle,
        # and more samples of the same cycles do not shrink it. On the randomised campaign's
        # independent truths the error is 4–6 times that spread, 4 with wheel speeds at 50 Hz and
        # 6 at 100 Hz: √(`evidence_interval_s` / sample period).
        # The brake gain's doubt scales every wheel's μ alike, so μ_max too: uniform over its
        # half-width d, a σ of d/√3 (0 once the accelerometer's offset is learnt). So does the
        # share of μ_max the lateral μ's tolerance could take off in a turn (`_with_lateral_grip`).
        spread2 = (self._variance_inflation * rel_std * rel_std + drift**2 + o.model_mismatch**2
                   + (o.misfit_peak_ratio * self._data_above_fit)**2
                   + (o.spread_loss_weight * self._peak_spread_loss)**2
                   + self._brake_gain_doubt**2 / 3.0 + self._lateral_doubt**2 / 3.0)
        ramp = min(1.0, (now_s - self._excited_since_s) / o.settle_s) if o.settle_s > 0 else 1.0
        # Newest residuals biased beyond the noise, of all wheels or of the front ones (which
        # meet a new road first): the road may be changing under the fit.
        excess = max(0.0, max(self._innovation_score, self._front_innovation_score) - o.jump_threshold)
        innovation = math.exp(-excess * excess / 8.0)
        # (σ is 0 only with `model_mismatch` configured to 0 and a fit without spread or drift)
        within_band = math.erf(o.confidence_band / math.sqrt(2.0 * spread2)) if spread2 > 0.0 else 1.0
        confidence = excitation * ramp * innovation * within_band
        confidence *= input_quality.confidence_factor(self._input_share)
        return confidence if math.isfinite(confidence) else 0.0

    def _drift_reference(self, now_s: float) -> float:
        """What μ_max is compared with for its drift: the median of the fits around
        `drift_window_s` ago (± a sixth of it), not the single oldest one. A fit that dipped for a
        cycle (an ABS release, 6 % on MF ice) would otherwise cost the confidence twice, when it
        happens and again a drift window later as the reference, making a settled estimate
        CONVERGING for a cycle."""
        o = self.options
        history = self._mu_history
        since = now_s - o.drift_window_s * (7.0 / 6.0)
        if self.core is not None:
            reference = self.core.drift_reference(history, since, o.drift_window_s / 3.0)
            if reference is not None:
                return reference
        values: list[float] = []
        until = math.inf
        for t, m in history:     # (ascending times)
            if t < since:
                continue
            if not values:
                until = t + o.drift_window_s / 3.0
            elif t > until:
                break
            values.append(m)
        values.sort()
        return values[len(values) // 2]   # (never empty: the newest fit was just appended)

    def _excess_over_fit(self, fitted_mu: Sequence[float], wheel_mu: Sequence[float],
                         wheel_lam: Sequence[float]) -> float:
        """How far the window's data rise above the curve published, as a share of its peak: the
        largest mean of (μ_measured − μ_fit − lift)/μ_max,wheel over the samples of a band of slips
        (relative to the wheel's fitted peak slip, from half of it up) with `misfit_bin_samples`
        or more; 0 if none.

        Where the tyre gave more than the curve says, its peak is higher than the curve's: the
        static model rounding off a sharp peak (a Magic Formula tyre that falls 30 % past it, an
        ABS dwelling deep in slip pulling the fit down to the plateau) shows here, as a band of
        slips the fit passes under on every ABS cycle. The spread of μ_max cannot show it (the
        samples agree with each other), the model-mismatch floor is the same for every tyre: this
        is the mismatch the data measure. `_confidence` counts it `misfit_peak_ratio` times: at
        1 (the band mean itself) the campaign's outputs are within 10 % at least as often as
        their confidence says; at 2 (the top of an excess that falls to nothing at a band's
        edges) they were within it far more often. The lift is how far the published peak was
        raised above the fitted one (by the wheel's measured peak or the car's deceleration):
        that much of the excess is already answered.
        """
        w = self._window
        lo, hi = w.start, w.end
        if hi - lo < self.options.misfit_bin_samples:
            return 0.0
        if self.core is not None:
            return self.core.excess_over_fit(w.scratch, w.slip, w.wheel, lo, hi, wheel_mu, fitted_mu, wheel_lam,
                                             _MISFIT_EDGES, self.options.misfit_bin_samples)
        if self._numpy_residuals is None or len(self._numpy_residuals) != hi - lo:
            return 0.0
        return excess_over_fit_numpy(self._numpy_residuals, w.slip[lo:hi], w.wheel[lo:hi], wheel_mu, fitted_mu,
                                     wheel_lam, self.options.misfit_bin_samples)
