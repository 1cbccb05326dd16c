"""The estimator's records of samples over time: the window the fit reads, and the body's
smoothed maximum.

`_Window` holds the wheels' samples of the last `window_s` (slip, speed, μ, time, wheel) in
preallocated columns that the compiled fit reads and writes in place, beside the parts of the model
that depend on a sample alone and the rows cached at the last fit; `_spread_loss_numpy` is the
numpy reference of the compiled `_fitcore.spread_loss` over it. `_SmoothedMaximum` keeps the
highest mean of a series over a trailing span (the body's utilised μ: the floors of
`EstimateConfidence`). Plain containers: the estimator's options and fit state stay the estimator's.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from .fit_parameters import SHARED
from .samples import N_WHEELS
from .tyre_model import MAX_MODEL_SLIP, LugreParams, braking_mu_and_partials


class _Window:
    """Preallocated ring of samples (slip, speed, μ, time, wheel); amortised O(1) append.

    Next to each sample it keeps the parts of the model that depend on the sample alone (with
    the held α and L): λ·v, (λ·v)^α and L·λ/(1−λ); and, in
    `rows`, the unweighted Jacobian row and model − measurement of each sample at the
    parameters of the last accepted fit (valid for the samples before `cached_end`).
    """

    def __init__(self, capacity: int = 4096, alpha: float = 0.5, patch_length: float = 0.2) -> None:
        self.capacity = capacity
        self.alpha = alpha
        self.patch_length = patch_length
        self.slip = np.empty(capacity)
        self.speed = np.empty(capacity)
        self.mu = np.empty(capacity)
        # Per sample: the slips at the derivative window's ends and their weights (`slip_spread`).
        self.spread = np.zeros((4, capacity))
        self.time = np.empty(capacity)
        self.wheel = np.empty(capacity, dtype=np.intp)
        self.lam_v = np.empty(capacity)
        self.pow_lam_v = np.empty(capacity)
        self.stiff = np.empty(capacity)
        self.rows = np.empty((N_WHEELS + len(SHARED) + 1, capacity))
        # The compiled fit's cache of the same: per sample its 5 unweighted row values at the
        # parameters `LugreTrustRegionEstimator._core_rows_x`, valid before `core_cached_end`.
        self.core_rows = np.empty((capacity, 5))
        self.core_cached_end = 0
        # The compiled fit's buffers: the weighted residuals, a trial's, the forgetting weights
        # and the rows' weights √w/σ.
        self.scratch = np.empty((4, capacity))
        self.start = 0
        self.end = 0
        self.cached_end = 0
        self.last_time_by_axle = [-math.inf, -math.inf]   # newest sample of a front / rear wheel
        # The columns `_fitcore.fit_window` reads and writes (never reallocated: `_compact` moves
        # samples within them).
        self.core_columns = (self.pow_lam_v, self.stiff, self.lam_v, self.mu, self.wheel, self.time, self.scratch,
                             self.core_rows)
        self.append_columns = (self.slip, self.speed, self.mu, self.time, self.wheel, self.lam_v, self.pow_lam_v,
                               self.stiff)

    def __len__(self) -> int:
        return self.end - self.start

    def clear(self) -> None:
        self.start = self.end = self.cached_end = self.core_cached_end = 0
        self.last_time_by_axle = [-math.inf, -math.inf]

    def has_recent(self, axle: int, since_s: float) -> bool:
        """Whether the window holds a sample of the axle (0 front, 1 rear) newer than `since_s`."""
        t = self.last_time_by_axle[axle]
        return t > since_s and self.end > self.start and t >= self.time.item(self.start)

    def _compact(self) -> None:
        """Move the window's samples to the front of the columns."""
        n = len(self)
        s, e = self.start, self.end
        for arr in self.append_columns:
            arr[:n] = arr[s:e]
        self.spread[:, :n] = self.spread[:, s:e]
        self.rows[:, :n] = self.rows[:, s:e]
        self.core_rows[:n] = self.core_rows[s:e]
        self.cached_end = max(self.cached_end - s, 0)
        self.core_cached_end = max(self.core_cached_end - s, 0)
        self.start, self.end = 0, n

    def append(self, slip: float, speed: float, mu: float, time_s: float, wheel: int) -> None:
        if self.end == self.capacity:
            self._compact()
            if self.end == self.capacity:
                # Full (a long window_s at a high rate): the oldest quarter goes, and its room
                # is made free again.
                self.start = self.capacity // 4
                self._compact()
        k = self.end
        self.slip[k], self.speed[k], self.mu[k], self.time[k], self.wheel[k] = slip, speed, mu, time_s, wheel
        self.spread[:, k] = 0.0
        lam = min(slip, MAX_MODEL_SLIP)
        lam_v = lam * speed
        self.lam_v[k] = lam_v
        self.pow_lam_v[k] = lam_v**self.alpha if lam_v > 0 else 0.0
        self.stiff[k] = self.patch_length * lam / (1.0 - lam)
        self.last_time_by_axle[0 if wheel < 2 else 1] = time_s
        self.end += 1

    def append_instant(self, slips: list[float], speed: float, mus: list[float], time_s: float,
                       wheels: list[int], core: Any = None) -> None:
        """`append` of one instant's samples (a few wheels), in one compiled call when `core` is given."""
        n = len(slips)
        if core is None or self.end + n > self.capacity:
            for slip, mu, wheel in zip(slips, mus, wheels):
                self.append(slip, speed, mu, time_s, wheel)
            return
        core.append_samples(self.append_columns, self.end, slips, speed, mus, time_s, wheels, self.alpha,
                            self.patch_length, MAX_MODEL_SLIP)
        self.spread[:, self.end:self.end + n] = 0.0
        for wheel in wheels:
            self.last_time_by_axle[0 if wheel < 2 else 1] = time_s
        self.end += n

    def set_spread(self, n: int, spreads: list[tuple[float, float]], weights: tuple[float, float]) -> None:
        """The derivative-window slips (`slip_spread`) of the newest `n` samples, one pair each."""
        spread = self.spread
        a_lo, a_hi = weights
        k = self.end - n
        for lo, hi in spreads:   # (a few wheels: scalar stores cost less than building arrays)
            spread[0, k] = lo
            spread[1, k] = hi
            spread[2, k] = a_lo
            spread[3, k] = a_hi
            k += 1

    def drop_before(self, time_s: float, core: Any = None) -> None:
        if core is not None:
            self.start = core.search_left(self.time, self.start, self.end, time_s)
            return
        times = self.time[self.start:self.end]
        self.start += int(times.searchsorted(time_s, side="left"))

    def view(self) -> tuple[np.ndarray, ...]:
        s = slice(self.start, self.end)
        return self.slip[s], self.speed[s], self.mu[s], self.time[s], self.wheel[s]


def _spread_loss_numpy(w: _Window, lo: int, thetas: list[float], params: LugreParams) -> float:
    """`LugreTrustRegionEstimator._spread_loss` over the window's samples from `lo` (`_fitcore.spread_loss`)."""
    hi = w.end
    rows = np.flatnonzero(w.spread[2, lo:hi] + w.spread[3, lo:hi] > 0.0) + lo
    wheel, mu = w.wheel[rows], w.mu[rows]
    top = np.zeros(len(rows), dtype=bool)
    for i in range(N_WHEELS):
        mine = wheel == i
        if np.count_nonzero(mine) >= 3:
            top |= mine & (mu >= 0.9 * mu[mine].max())
    rows = rows[top]
    n = len(rows)
    if n == 0:
        return 0.0
    theta = np.asarray(thetas)[w.wheel[rows]]
    lam = np.concatenate((w.slip[rows], w.spread[0, rows], w.spread[1, rows]))
    model = braking_mu_and_partials(lam, np.tile(w.speed[rows], 3), np.tile(theta, 3), params, np.empty((3 * n, 4)))
    centre = model[:n]
    loss = w.spread[2, rows] * (centre - model[n:2 * n]) + w.spread[3, rows] * (centre - model[2 * n:])
    share = float(np.mean(loss / np.maximum(centre, 0.05)))
    return share if share > 0.0 else 0.0


class _SmoothedMaximum:
    """The maximum, over a trailing span, of a series' mean over `smoothing_s`: O(1) a sample
    (a running sum for the mean, a monotonic queue for the maximum)."""

    def __init__(self, smoothing_s: float) -> None:
        self.smoothing_s = smoothing_s
        self._raw: deque[tuple[float, float]] = deque()
        self._sum = 0.0
        self.highest = 0.0          # the highest mean since the last clear
        self._means: deque[tuple[float, float]] = deque()   # (time, mean), means decreasing

    def push(self, time_s: float, value: float) -> None:
        raw = self._raw
        if raw and time_s < raw[-1][0]:
            self.clear()            # the clock went back
        raw.append((time_s, value))
        self._sum += value
        while raw[0][0] < time_s - self.smoothing_s:
            self._sum -= raw.popleft()[1]
        if time_s - raw[0][0] < 0.5 * self.smoothing_s:
            return                  # not yet a mean over the span
        mean = self._sum / len(raw)
        if mean > self.highest:
            self.highest = mean
        means = self._means
        while means and means[-1][1] <= mean:
            means.pop()
        means.append((time_s, mean))

    def maximum(self, since_s: float) -> float | None:
        means = self._means
        while means and means[0][0] < since_s:
            means.popleft()
        return means[0][1] if means else None

    def clear(self) -> None:
        self._raw.clear()
        self._means.clear()
        self._sum = 0.0
        self.highest = 0.0
