"""Whether the data show the tyre's peak: the estimator's excitation evidence.

A static fit always has a peak; whether the data located it is a separate question, answered
here from the data themselves (slips near the fitted peak, the μ–slip curve bending over and
flat at its top, a wheel running away into slip, an ABS working the wheel) and never from the
fit alone. `PeakEvidence` is a part of `LugreTrustRegionEstimator` (its window, options and fit
state are the estimator's), and each wheel's verdict its part `wheel_verdicts.WheelVerdicts`;
the numpy reference implementations of the compiled statistics sit beside it.
"""
from __future__ import annotations

import math

import numpy as np

from .runaway import RunawayEvidence
from .samples import N_WHEELS
from .tyre_model import braking_mu_and_partials_few
from .wheel_verdicts import CONTRADICTED, WheelVerdicts


def _quantile_pair(values: np.ndarray, q_low: float, q_high: float) -> tuple[float, float]:
    """`np.quantile(values, (q_low, q_high))` (linear method, finite values), by one partition."""
    n = len(values)
    picks = []
    for q in (q_low, q_high):
        virtual = (n - 1) * q
        i = min(int(math.floor(virtual)), n - 1)
        picks.append((i, virtual - i))
    kth = sorted({min(k, n - 1) for i, _ in picks for k in (i, i + 1)})
    part = np.partition(values, kth)
    out = []
    for i, t in picks:
        if i >= n - 1:
            out.append(float(part[n - 1]))
            continue
        a, b = float(part[i]), float(part[i + 1])
        diff = b - a
        out.append(b - diff * (1 - t) if t >= 0.5 else a + diff * t)
    return out[0], out[1]

def _wheel_stats_numpy(slip: np.ndarray, mu: np.ndarray, wheel: np.ndarray, times: np.ndarray, lag: int,
                       elasticity: float) -> tuple[tuple[float, ...], ...]:
    """Per wheel, over the samples given (time order), what the slip range and the excitation
    test read from them: n; the 10 % and 90 % slip quantiles; the slips of order k_lo and k_hi
    and the μ of order k_hi (k = max(1, n // 10) from each end); the fastest slip run-away over
    `lag` samples whose force did not follow (Δμ/μ ≤ elasticity·Δλ/λ), −∞ without any; the
    sums Σλ², Σλ³, Σλ⁴, Σλμ, Σλ²μ of the through-origin quadratic. `_fitcore.wheel_stats` is
    the same, compiled."""
    out = []
    for i in range(N_WHEELS):
        sel = wheel == i
        n = int(np.count_nonzero(sel))
        if n == 0:
            out.append((0.0,) + (math.nan,) * 6 + (0.0,) * 5)
            continue
        lam, m, t = slip[sel], mu[sel], times[sel]
        q_low, q_high = _quantile_pair(lam, 0.1, 0.9)
        k_hi = max(0, n - 1 - max(1, n // 10))
        k_lo = min(n - 1, max(1, n // 10))
        ordered = np.partition(lam, (k_lo, k_hi))
        mu_hi = float(np.partition(m, k_hi)[k_hi])
        d_lam = lam[lag:] - lam[:-lag]
        rate = d_lam / np.maximum(t[lag:] - t[:-lag], 1e-3)
        rate[(m[lag:] - m[:-lag]) * lam[:-lag] > elasticity * d_lam * m[:-lag]] = 0.0
        best = float(rate.max()) if len(rate) else -math.inf
        lam2 = lam * lam
        out.append((float(n), q_low, q_high, float(ordered[k_lo]), float(ordered[k_hi]), mu_hi, best,
                    float(lam @ lam), float(lam @ lam2), float(lam2 @ lam2), float(lam @ m), float(lam2 @ m)))
    return tuple(out)

class PeakEvidence(WheelVerdicts, RunawayEvidence):
    """The excitation: per wheel a verdict on whether its newest data show the peak, and the
    stop-long evidence behind it (runaways, peaks shown, the wheels' last verdicts on spread slips)."""

    def _forget_shown_peaks(self) -> None:
        """Forget the peaks the wheels showed and each wheel's last verdict on spread slips (and
        when it was given): a new stop, or a new road, has shown nothing yet."""
        self._wheel_shown_s = [-math.inf] * N_WHEELS
        self._wheel_shown_moving = [False] * N_WHEELS   # (shown at `peak_evidence_min_speed` or above)
        self._shape_proximity = [0.0] * N_WHEELS
        self._shape_verdict_s = [-math.inf] * N_WHEELS
        self._tops_fit = -1               # (`_wheel_tops` of the window this fit saw)
        self._tops: list[tuple[float, float, float] | None] = [None] * N_WHEELS

    def _slip_range(self, weights: np.ndarray | None) -> tuple[list[float], list[float]]:
        """The low (10 %, ≥ 0) and high (90 %) ends of each wheel's recent slips; a wheel
        without data gets (0, ∞): no bound on either side."""
        low = [0.0] * N_WHEELS
        high = [math.inf] * N_WHEELS
        for i, stats in enumerate(self._wheel_stats(weights)):
            if stats[0] >= self._min_wheel_samples:
                low[i], high[i] = max(0.0, stats[1]), stats[2]
        return low, high

    def _wheel_stats(self, weights: np.ndarray | None) -> tuple[tuple[float, ...], ...]:
        """`_wheel_stats_numpy` of the window's newest `excitation_window_s` (compiled when built:
        on the window's columns and the weights `fit_window` left there; `weights` is not used)."""
        w = self._window
        o = self.options
        if self.core is not None:
            return self.core.recent_wheel_stats(w.slip, w.core_columns, w.start, w.end, self._recent_threshold,
                                                self._runaway_lag, o.excitation_runaway_elasticity)
        lo = w.start + self._recent_start(weights)
        args = (w.slip[lo:w.end], w.mu[lo:w.end], w.wheel[lo:w.end], w.time[lo:w.end], self._runaway_lag,
                self.options.excitation_runaway_elasticity)
        return _wheel_stats_numpy(*args)

    def _recent_start(self, weights: np.ndarray) -> int:
        """Index of the first window sample weighted above the excitation window's threshold
        (the newest `excitation_window_s`); the weights rise along the window."""
        return int(weights.searchsorted(self._recent_threshold, side="right"))

    def _fit_at_high_slip(self, speed: float) -> np.ndarray:
        """The fitted μ of each wheel at the high end of its recent slips."""
        lam_hi = [s if math.isfinite(s) else 1e-3 for s in self._slip_support]
        if self.core is not None:   # (braking_mu_and_partials_few's compiled call, without its arrays)
            _, theta_list, shared = self._floats_of_x()
            return self.core.mu_partials_few(lam_hi, max(speed, 1.0), theta_list, shared)[0]
        mu, _ = braking_mu_and_partials_few(lam_hi, max(speed, 1.0), self._thetas(self._x), self._params(self._x))
        return mu

    def _excitation(self, weights: np.ndarray, wheel_mu: np.ndarray, wheel_lam: np.ndarray, speed: float = 10.0) -> float:
        """0 unless some wheel's recent data show the peak; rises to 1 as they reach it.

        Two independent pieces of evidence must agree, so that the fit cannot talk itself into
        excitation by moving its peak onto the data (constant-slip braking would do that):
        (1) the data come near the fitted peak (slip ≥ `excitation_slip_ratio`·λ*, or utilised μ
            near μ_max), and
        (2) the wheel is at its limit by a measure that does not come from the fit: the data
            themselves bend over — a through-origin quadratic μ ≈ aλ + bλ² fitted to the wheel's
            recent samples has, at the high-slip end, a tangent slope below half its secant
            slope, which a linear region never does — and, until this stop has shown its peak
            once, an ABS works the wheel (its controller released it: `abs_activity`) or the
            wheel ran away into slip, its force no longer following, and ran on towards lock-up
            (firm braking below the peak bends the data too: tyre curves bend well before their
            peak).
        Once shown, a wheel held past the fitted peak at its grip stays excited (ABS holding
        an ice plateau at nearly constant slip, where the bending has no spread to work on)
        while the samples that showed it are in the window.
        No excitation at all while one wheel's data contradict the fitted curve (μ still rising
        at slips well past that wheel's fitted peak).
        """
        o = self.options
        # Only the newest ABS cycles count: after a change of road the older samples describe
        # the old one.
        wheel_stats = self._wheel_stats(weights)
        fit_at_hi = self._fit_at_high_slip(speed)
        peak_seen = self._peak_seen_at(speed)
        at_bound = self._thetas_at_bound()
        best = best_fresh = 0.0
        contradicted = False
        why = self._excitation_why = ["", "", "", ""]
        for i in range(N_WHEELS):
            if at_bound[i]:
                why[i] = "θ at its bound"
                continue
            abs_working = self._last_sample_s - self._abs_seen_s[i] <= o.excitation_window_s
            why[i], proximity, fresh = self._wheel_verdict(
                i, wheel_stats[i], float(wheel_mu[i]), float(wheel_lam[i]), float(fit_at_hi[i]),
                bool(self._capped is not None and self._capped[i]), speed, peak_seen, abs_working)
            contradicted = contradicted or proximity == CONTRADICTED
            best = max(best, proximity)
            if proximity >= o.excitation_slip_ratio:
                self._wheel_shown_s[i] = self._last_sample_s
                self._wheel_shown_moving[i] |= speed >= o.peak_evidence_min_speed
            if fresh:
                best_fresh = max(best_fresh, proximity)
        if best < o.excitation_slip_ratio:
            return 0.0
        if best_fresh >= o.excitation_slip_ratio:
            self._peak_seen_speed = speed
        if contradicted:
            return 0.0
        return min(1.0, (best - o.excitation_slip_ratio) / 0.15 + 0.5)

    def _peak_seen_at(self, speed: float) -> bool:
        """Whether the peak this stop has shown is evidence at `speed`."""
        # The peak, once seen in this stop, describes the road at the speed it was seen at: the
        # peak moves with speed (more grip at walking pace on most roads), so a wheel "held past
        # it" at a much lower speed proves nothing until the data show the peak there again.
        return (self._peak_seen_speed > 0.0
                and speed >= self.options.peak_evidence_speed_ratio * self._peak_seen_speed)

    def _thetas_at_bound(self) -> list[bool]:
        """Per wheel, whether its fitted θ is held at its bound."""
        # A θ held at its bound is not where the data put it: its peak proves nothing.
        return [x - lb < 1e-6 or ub - x < 1e-6 for x, (lb, ub) in
                zip(self._floats_of_x()[0][:N_WHEELS], self._theta_bounds)]

    @property
    def excitation_reasons(self) -> list[str]:
        """Why each wheel counts as excited or not at the last excitation check (for diagnosis:
        formatted when asked for, not on every check)."""
        return [why if isinstance(why, str) else why[0].format(why[1]) for why in self._excitation_why]
