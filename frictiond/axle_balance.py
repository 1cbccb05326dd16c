"""The front/rear split of the brake-gain error, learnt from the fitted peaks.

`AxleBalance` is a part of `LugreTrustRegionEstimator` (its options, window and balance are the
estimator's): `_take_in` scales each wheel's utilised μ by `_axle_scales`, and each report of a
fit moves the balance (`_balance_axles`).
"""
from __future__ import annotations

import math

import numpy as np


class AxleBalance:
    """The axles' brake-gain balance: learnt slowly from the fitted peaks, applied to the data."""

    def _axle_scale(self, wheel: int) -> float:
        """Correction of a wheel's utilised μ for the front/rear brake-gain split (see below)."""
        a = self._axle_balance
        return math.exp(0.35 * a) if wheel < 2 else math.exp(-0.65 * a)

    def _axle_scales(self) -> tuple[float, float]:
        """(front, rear) `_axle_scale`, kept until the balance moves (it rests between stops)."""
        cached = self._axle_scales_cache
        if cached[0] != self._axle_balance:
            cached = self._axle_scales_cache = (self._axle_balance, (self._axle_scale(0), self._axle_scale(2)))
        return cached[1]

    def _balance_axles(self, now_s: float, wheel_mu: np.ndarray) -> None:
        """Learn the front/rear split of the brake-gain error.

        Pad friction drifts per axle (±20 %); the front end's body-equation check only fixes the
        total. On one road the front and rear tyres' peaks agree, so a lasting front/rear ratio
        of the fitted peaks is a brake-gain split: it is removed slowly (time constant
        `axle_balance_time_constant`), weighting the axles by their usual share of the braking
        force (≈ 65/35) so the total stays what the body equation says. Brief real front/rear
        differences (a μ change crossing the wheelbase) last a fraction of a second and barely
        move it.
        """
        o = self.options
        last = self._last_update_s
        self._last_update_s = now_s
        if last is None or o.axle_balance_time_constant <= 0:
            return
        dt = min(max(now_s - last, 0.0), 0.1)
        # Both axles among the samples weighted above e⁻¹ (younger than the forgetting time).
        since = now_s - o.forgetting_time_constant
        if not (self._window.has_recent(0, since) and self._window.has_recent(1, since)):
            return
        ratio = float(wheel_mu[0] + wheel_mu[1]) / max(float(wheel_mu[2] + wheel_mu[3]), 1e-6)
        self._axle_balance += (dt / o.axle_balance_time_constant) * math.log(max(ratio, 1e-6)) * -1.0
        self._axle_balance = min(max(self._axle_balance, -o.axle_balance_limit), o.axle_balance_limit)
