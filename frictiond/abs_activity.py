"""Whether the ABS is working a wheel: evidence, independent of the fit, that the tyre reached its limit.

An ABS releases a wheel's pressure only when its controller judged the wheel at or past the peak
of its tyre curve (the wheel decelerating faster than the car can, its slip running away). A
release while the driver keeps the pedal down is therefore an outside observation that the tyre
worked at its grip limit. It is the only evidence a well-tuned ABS gives: one that catches the
wheel within a few per cent of slip never lets the slip run away, which is what the estimator
otherwise waits for before it trusts a first peak.

Two sources, the pressures read two ways; any one marks a wheel:
- the car's own flags, when the signal map has them: `abs_active` (the ABS is regulating, any
  wheel) or `abs_active_fl` … `abs_active_rr` (per wheel); a value ≥ 0.5 is "on";
- the wheel pressures: a wheel's pressure fallen well below its own maximum of the last
  `window_s` while the driver's demand has not fallen with it. The demand is the master-cylinder
  pressure (`brake_pressure_master`) when mapped, else the highest wheel pressure now: a
  four-channel ABS does not release every wheel in the same instant, except on ice, where the
  slip then runs away and the estimator has that evidence instead. A car that reports only its
  master-cylinder pressure on every wheel shows no per-wheel release: only its flags count.
- the wheel pressures apart from each other: a wheel's pressure fallen by a smaller share of its
  maximum than that, more than the demand (or, without the master cylinder's pressure, the
  least fallen other wheel) fell over the same window. One master cylinder feeds every wheel:
  the pedal moves all of them by the same share, and only the ABS valves move one wheel
  against another. An ABS that reapplies in small steps and dumps briefly (a wheel-deceleration
  controller at the top of its pressure, a slip controller) modulates by 10–20 % and never
  lets go by a quarter.

A drop of 5 bar is 8 σ of a sensor with 0.6 bar of noise. A noisier sensor (`pressure_noise`
measures it from the frames) would read its noise as releases, and a stop without ABS as one at
the grip limit: its threshold rises to 8 σ. Quieter sensors do not lower it: releases of a
few bar (an ABS on ice) counted, and slip controllers holding a late-peaking tyre well below
its peak then passed for the limit (benchmarks/README.md, session 66).

A mark lasts `memory_s` (about the estimator's excitation window): the release comes after the
peak, the evidence is for the samples just before it.

Pure physics on numbers: nothing here knows of CAN or of the tyre model.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

NO_ACTIVITY = (False, False, False, False)


@dataclass(frozen=True, slots=True)
class AbsActivityOptions:
    window_s: float = 0.3            # a wheel's pressure is compared with its own maximum over this
    min_drop_bar: float = 5.0        # a release: at least this far below that maximum ...
    noise_drop_ratio: float = 8.0    # ... or this many σ of the sensors' noise, if more, ...
    min_drop_ratio: float = 0.25     # ... and this share of it
    min_relative_drop: float = 0.10  # or this share more than the demand (other wheels) fell
    min_pressure_bar: float = 10.0   # only where the wheel was braked this hard
    demand_kept_ratio: float = 0.8   # the driver's demand stays above this share of its own maximum
    memory_s: float = 0.3            # a mark lasts this long


class AbsActivity:
    """Per-wheel ABS activity from flags and pressures, one call per front-end sample."""

    def __init__(self, options: AbsActivityOptions | None = None) -> None:
        self.options = options or AbsActivityOptions()
        # Running maxima over `window_s` (monotonic queues of (time, value)): the four wheels'
        # pressures, then the demand.
        self._maxima: tuple[deque[tuple[float, float]], ...] = tuple(deque() for _ in range(5))
        self._last_time_s = -math.inf
        self._last_active_s = [-math.inf] * 4
        self._min_drop_bar = self.options.min_drop_bar

    def set_noise(self, sigma_bar: float | None) -> None:
        """The pressure sensors' noise σ (None: not known; `pressure_noise`). A release is a
        drop the noise cannot make: over a window the highest reading is about 2 σ above the
        pressure and the present one may be 2–3 σ below it, so a drop counts from
        `noise_drop_ratio` σ where that is more than `min_drop_bar`. Never less: the fixed
        threshold is what the estimator's trust in a release was measured at."""
        o = self.options
        drop = o.min_drop_bar
        if sigma_bar is not None and math.isfinite(sigma_bar):
            drop = max(o.min_drop_bar, o.noise_drop_ratio * sigma_bar)
        self._min_drop_bar = drop

    def noise_note(self, sigma_bar: float | None) -> str | None:
        """What a user is told when the sensors' noise `sigma_bar` raised the drop a release
        needs above `min_drop_bar`; None when it did not."""
        if sigma_bar is None or self._min_drop_bar <= self.options.min_drop_bar:
            return None
        return (f"the brake-pressure sensors are noisy (σ {sigma_bar:.2f} bar measured): a wheel's pressure counts "
                f"as released by the ABS only from a {self._min_drop_bar:.1f} bar drop "
                f"({self.options.min_drop_bar:g} bar for quieter sensors)")

    def reset(self) -> None:
        for q in self._maxima:
            q.clear()
        self._last_time_s = -math.inf
        self._last_active_s = [-math.inf] * 4

    def update(self, time_s: float, pressures: tuple[float | None, ...], master_bar: float | None,
               car_flag: float | None, wheel_flags: tuple[float | None, ...]) -> tuple[bool, bool, bool, bool]:
        """The wheels the ABS works at `time_s`; None marks a signal not mapped or not yet seen."""
        o = self.options
        if time_s < self._last_time_s:
            self.reset()            # the clock went back: the maxima belong to another time
        self._last_time_s = time_s
        released = self._released(time_s, pressures, master_bar)
        for i in range(4):
            flag = wheel_flags[i] if wheel_flags[i] is not None else car_flag
            if released[i] or (flag is not None and flag >= 0.5):
                self._last_active_s[i] = time_s
        return tuple(time_s - t <= o.memory_s for t in self._last_active_s)  # type: ignore[return-value]

    def _released(self, time_s: float, pressures: tuple[float | None, ...],
                  master_bar: float | None) -> tuple[bool, bool, bool, bool]:
        o = self.options
        for p in pressures:
            if p is None or not math.isfinite(p):
                return NO_ACTIVITY
        now = [float(p) for p in pressures]  # type: ignore[arg-type]
        has_master = master_bar is not None and math.isfinite(master_bar)
        demand = float(master_bar) if has_master else max(now)  # type: ignore[arg-type]
        since = time_s - o.window_s
        queues = self._maxima
        maxima = [_running_max(queues[i], time_s, now[i], since) for i in range(4)]
        demand_max = _running_max(queues[4], time_s, demand, since)
        if demand < o.demand_kept_ratio * demand_max:
            return NO_ACTIVITY      # the driver is letting go: every pressure falls, none is a release
        fallen = [(m - p) / m if m > 0.0 else 0.0 for m, p in zip(maxima, now)]
        demand_fallen = (demand_max - demand) / demand_max if demand_max > 0.0 else 0.0
        min_pressure, min_drop, min_ratio, min_relative = (o.min_pressure_bar, self._min_drop_bar, o.min_drop_ratio,
                                                           o.min_relative_drop)
        out = []
        for i in range(4):
            peak = maxima[i]
            drop = peak - now[i]
            if not (peak >= min_pressure and drop >= min_drop):
                out.append(False)
                continue
            # What the pedal took off every wheel: the master's fall, else the other wheels' least.
            pedal = demand_fallen if has_master else min([fallen[j] for j in range(4) if j != i])
            out.append(drop >= min_ratio * peak or fallen[i] - pedal >= min_relative)
        return tuple(out)  # type: ignore[return-value]


def _running_max(queue: deque[tuple[float, float]], time_s: float, value: float, since_s: float) -> float:
    """Push (time_s, value) on a monotonic queue and return the maximum of the values since `since_s`."""
    while queue and queue[-1][1] <= value:
        queue.pop()
    queue.append((time_s, value))
    while queue[0][0] < since_s:
        queue.popleft()
    return queue[0][1]
