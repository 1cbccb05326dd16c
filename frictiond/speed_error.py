"""How far the speed estimate, and with it every slip, may be off: `SpeedErrorBound`.

Each slip is measured against the front end's speed estimate. Where two wheels roll nearly free,
a reference speed is fresh or no brake is on, the estimate is anchored to the ground's speed.
Under an ABS that holds every wheel in slip (a slip controller) it coasts on the accelerometer,
and its error grows with the error of the accelerometer's learnt offset (σ ≈ 0.02 m/s²: median
0.014, p90 0.036 over the development campaign's stops), or, while free rolling has not yet
taught the offset, with what is not yet known of it (`PhysicalSample.accel_offset_doubt_mps2`:
a slip controller's stop braked 0.15 s after the start coasted on an offset 0.115 m/s² off, and
its held slips' drift passed for a plateau, 21 % low).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from .samples import PhysicalSample


@dataclass(frozen=True, slots=True)
class SpeedErrorOptions:
    """Set from the estimator's options (`LugreTROptions.speed_error_mps` and its neighbours)."""

    error_mps: float                # the estimate's error while anchored
    drift_mps2: float               # ... growing this fast while it coasts (the offset's error)
    anchor_slip: float              # anchored: the second-least-slipping wheel within this slip of it
    window_s: float                 # the span over which a spread of slips is read


class SpeedErrorBound:
    """Per sample `follow`; `slip_spread` is the spread of a held slip that the estimate's
    error alone makes over the window."""

    def __init__(self, options: SpeedErrorOptions) -> None:
        self.options = options
        self._anchor_s = -float("inf")
        self._speeds: deque[tuple[float, float]] = deque()   # (time, speed) over the window
        self._drift_mps2 = options.drift_mps2                 # the newest sample's (`follow`)

    def follow(self, sample: PhysicalSample) -> None:
        o = self.options
        t = sample.time_s
        slips = sample.slip
        self._drift_mps2 = max(o.drift_mps2, sample.accel_offset_doubt_mps2)
        # (Started while braking: its error then is taken as the anchored one.)
        if (sample.speed_from_reference or not sample.braking or self._anchor_s == -float("inf")
                or sorted(slips)[1] <= o.anchor_slip):
            self._anchor_s = t
        speeds = self._speeds
        speeds.append((t, sample.speed_mps))
        while speeds[0][0] < t - o.window_s:
            speeds.popleft()

    def shift(self, step_s: float) -> None:
        """The clock stepped by `step_s`: the anchor moves with it, the window starts again."""
        self._anchor_s += step_s
        self._speeds.clear()

    def slip_spread(self, now_s: float, speed: float) -> float:
        """A slip reads λ − e/v with e the estimate's error. Over the window e/v changes by
        e·Δv/v² as the car slows, and by the drift's own growth over v. At walking pace after
        seconds of coasting, a slip a controller holds to ±0.1 % spreads by 1–2 % of slip with
        μ constant, which is what a plateau looks like."""
        o = self.options
        speeds = self._speeds
        if not speeds:
            return 0.0
        drift = self._drift_mps2
        error = o.error_mps + drift * max(0.0, now_s - self._anchor_s)
        v = max(speed, 1.0)
        change = abs(speeds[0][1] - speeds[-1][1])
        span = speeds[-1][0] - speeds[0][0]
        return error * change / (v * v) + drift * span / v
