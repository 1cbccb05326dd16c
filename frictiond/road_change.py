"""A change of road read from the fit's newest residuals.

A few hundred older samples pin the fit, so a change of road under it shows first as a mean
offset of the newest residuals far beyond the noise (all wheels', or the front wheels' alone, which
meet a new road a wheelbase before the rear ones); beyond twice the threshold the window's older
samples are dropped and everything learnt of the old road is forgotten (`_detect_jump`).
`RoadChangeTest` is a part of `LugreTrustRegionEstimator` through `window_fit.WindowFit` (its
window, options and state are the estimator's); the compiled fit computes the same bias
(`_fitcore.residual_bias`).
"""
from __future__ import annotations

import math

import numpy as np

from .samples import N_WHEELS


class RoadChangeTest:
    """The newest residuals' bias in standard errors (`_innovation`, `_front_score`) and the
    window dropped on a change of road (`_detect_jump`)."""

    def _innovation(self, now_s: float, times: np.ndarray, r_data: np.ndarray, weights: np.ndarray) -> float:
        """How far the newest samples' mean residual sits from zero, in standard errors (and,
        into `_front_innovation_score`, the front wheels' alone: `_front_score`).

        A few hundred older samples pin the fit, so a change of road shows first as a mean
        offset of the newest residuals far beyond the noise.
        """
        o = self.options
        first = int(times.searchsorted(now_s - o.jump_window_s, side="left"))   # (times ascend)
        n_recent = len(times) - first
        self._front_innovation_score = 0.0
        if not self._innovation_counts(len(times), n_recent):
            return 0.0
        # Back from weighted, normalised residuals to μ units (model − measurement).
        resid = r_data[first:] * o.measurement_std / np.sqrt(weights[first:])
        w = self._window
        front = resid[w.wheel[w.start + first:w.end] < 2]
        self._front_innovation_score = self._front_score(len(front), *residual_bias(front))
        return self._innovation_score_of(n_recent, *residual_bias(resid))

    def _front_score(self, n_front: int, mean: float, rms: float, same_sign: float) -> float:
        """`_innovation_score_of` the front wheels' newest residuals alone (0 with fewer than 8).

        A change of road reaches the front axle a wheelbase before the rear one (0.1–0.3 s at
        30–10 m/s), and the fit's VALID output is wrong from then on. Pooled with the rear
        wheels' residuals, still on the old road, the front's bias is halved and the opposite
        signs fail the same-sign test. It lowers the confidence only: a front axle's residuals
        also lean one way for a moment where its force lags its slip (a relaxing tyre deep in an
        ABS excursion), and dropping the window on that cost a sixth of the VALID outputs of
        stops with a change of road. The rear axle is not tested alone: a change reaches it after
        the front, and its own bias was misfit more often than road (testing it too cost another
        6 % of the development campaign's VALID outputs, for 5 fewer false ones of 94).
        """
        return self._innovation_score_of(n_front, mean, rms, same_sign) if n_front >= 8 else 0.0

    def _innovation_counts(self, samples: int, n_recent: int) -> bool:
        """Whether the newest `n_recent` of `samples` are enough, and few enough, to judge."""
        return not (n_recent < 8 or self._fits < 5 or samples - n_recent < 2 * n_recent)

    def _innovation_score_of(self, n_recent: int, mean: float, rms: float, same_sign: float) -> float:
        o = self.options
        noise = max(o.measurement_std, rms)
        score = abs(mean) / (noise / math.sqrt(n_recent))
        return score if same_sign > 0.7 else min(score, o.jump_threshold)

    def _detect_jump(self, now_s: float, speed: float, score: float) -> None:
        """Drop the window's older samples when the newest ones disagree with the fit (a μ jump).

        A change of road met by the front axle reaches the rear one a wheelbase later. Until then,
        and until the rear wheels' newest `excitation_window_s` of data lie past it, their slips
        move from one road's curve to the other's: a slip controller's rear wheels then run from
        wet asphalt's peak slip deeper into a dry road's rising branch, and μ falling as the slip
        grows reads as a peak passed (dev 20614: VALID 34 % low). Their data show no peak till then.
        The residuals do not tell a change met by the front axle from one both axles have met or
        from a fit that strayed (the first fits of a stop): each is read as the first. A change
        detected while the rear wheels wait is the rear axle meeting it (the front one's a
        wheelbase later): the samples kept are past it, and the wait ends.
        """
        o = self.options
        if score > o.jump_threshold * 2.0 and now_s - self._last_jump_s > o.jump_refractory_s:
            self._window.drop_before(now_s - o.jump_window_s - 1e-9, self.core)
            self._radius = None  # let the parameters move freely again
            self._jumps += 1
            self._last_jump_s = now_s
            if now_s <= self._rear_straddles_until_s:
                # The rear axle meeting the change the front one met: the samples kept are past it.
                self._rear_straddles_until_s = -math.inf
            else:
                rear_crossing_s = self.vehicle.wheelbase / max(speed, 1.0)
                self._rear_straddles_until_s = now_s + rear_crossing_s + o.excitation_window_s
            self._jump_times.append(now_s)
            # What was valid described the old road: nothing may be held VALID from it.
            self._last_valid = None
            self._stop_fit = None
            self._last_excited_s = -math.inf
            self._excitation_cache = None
            self._data_above_fit = 0.0
            self._mu_history.clear()
            self._body_mu.clear()      # (the grip used on the old road bounds nothing on the new)
            self._measured_peaks = [0.0] * N_WHEELS
            self._band_ratio = 0.0
            self._forget_shown_peaks()   # (the peaks the wheels showed were the old road's)


def residual_bias(resid: np.ndarray) -> tuple[float, float, float]:
    """Mean, rms deviation and |Σ sign| / n of residuals (np.mean / np.std without their
    wrappers: the same operations in the same order as `_fitcore.residual_bias`)."""
    n = len(resid)
    if n == 0:
        return 0.0, 0.0, 0.0
    mean = float(resid.sum()) / n
    dev = resid - mean
    dev *= dev
    return mean, math.sqrt(float(dev.sum()) / n), abs(float(np.sign(resid).sum()) / n)
