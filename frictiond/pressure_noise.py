"""Each brake-pressure sensor's noise (`PressureNoise`), measured from its own frames.

What a pressure reading does between its neighbours is, at the rates pressures are sent
(50–100 Hz), mostly the sensor's noise: the brake line's pressure is smooth over 10–20 ms but
for a valve's step now and then. So each reading's distance from the straight line through the
readings before and after it, scaled to one reading's noise, has a median of 0.6745 σ.

An ABS at work steps its valves at most frames for as long as it works, and a median over those
residuals reads 1.5–10 times the noise. The noise does not change, the valves' work comes and
goes: each block of `NOISE_BLOCK` residuals gives its own median, and the sensor's noise is the
second lowest of its last `NOISE_BLOCKS` blocks (the quietest stretch of the last seconds, not
the one lowest by chance; the first block's alone until there are two, and its first
`NOISE_FIRST` residuals' until it is full). Where no stretch is quiet (a sensor that reads 0
until the brakes go on, then an ABS at work) the noise reads high: a release then needs more
than it would, never less. A pressure that ramps at the pedal's speed leaves its sampling jitter
in the residuals too: that reads as more noise, never less.

What is not used: a reading at or below 0 (a sensor reads no pressure below 0: its noise is cut
there) and a reading equal to the one before (a sender that repeats its last value would read as
half the noise). A third equal reading in a row is a pressure held by a sensor quieter than its
resolution, and counts as a residual of 0: without it an ABS's holds, read by a noiseless
sensor, would leave only its valves' steps to measure.

Pure numbers: nothing here knows of CAN.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Iterable, Mapping

NOISE_BLOCK = 64            # residuals per block: each block's median is one estimate of the noise
NOISE_BLOCKS = 16           # the newest blocks kept (10–20 s); the noise is their second lowest estimate
NOISE_FIRST = 32            # until the first block is full, its median from this many residuals on
GAUSSIAN_MEDIAN_ABS = 0.6745


class _SensorNoise:
    __slots__ = ("times", "values", "repeats", "block", "blocks", "sigma")

    def __init__(self) -> None:
        self.times: deque[float] = deque(maxlen=2)
        self.values: deque[float] = deque(maxlen=2)
        self.repeats = 0            # readings equal to the last one taken, in a row
        self.block: list[float] = []
        self.blocks: deque[float] = deque(maxlen=NOISE_BLOCKS)
        self.sigma: float | None = None

    def push(self, time_s: float, value: float) -> bool:
        """Take one reading; True when the stated noise changed."""
        if not (math.isfinite(value) and value > 0.0) or (self.times and time_s <= self.times[-1]):
            self.times.clear()      # (a cut or a step back in time: start a new triple)
            self.values.clear()
            return False
        if self.values and value == self.values[-1]:
            # (a repeat may be a sender's; a third equal reading in a row is a pressure held
            # by a sensor quieter than its resolution, and the line to the next reading starts
            # where the hold ends)
            self.repeats += 1
            self.times[-1] = time_s
            return self._add(0.0) if self.repeats >= 2 else False
        self.repeats = 0
        changed = False
        if len(self.times) == 2:
            (t0, t1), (x0, x1) = self.times, self.values
            span = time_s - t0
            a, b = (time_s - t1) / span, (t1 - t0) / span
            # x1 less the line through its neighbours; its noise is σ·√(1 + a² + b²)
            changed = self._add(abs(x1 - a * x0 - b * value) / math.sqrt(1.0 + a * a + b * b))
        self.times.append(time_s)
        self.values.append(value)
        return changed

    def _add(self, residual: float) -> bool:
        """One residual into the current block; True when the stated noise changed."""
        self.block.append(residual)
        n = len(self.block)
        if n == NOISE_BLOCK:
            self.block.sort()
            self.blocks.append(self.block[n // 2] / GAUSSIAN_MEDIAN_ABS)
            self.block = []
            self.sigma = sorted(self.blocks)[min(1, len(self.blocks) - 1)]
            return True
        if not self.blocks and n >= NOISE_FIRST and n % 16 == 0:
            self.sigma = sorted(self.block)[n // 2] / GAUSSIAN_MEDIAN_ABS
            return True
        return False


class PressureNoise:
    """The pressure sensors' noise σ in bar, from the frames of the given signals."""

    def __init__(self, names: Iterable[str]) -> None:
        self._names = tuple(names)
        self.reset()

    def reset(self) -> None:
        self._sensors: dict[str, _SensorNoise] = {}

    def push(self, time_s: float, values: Mapping[str, float]) -> bool:
        """One pressure message's raw readings; True when `sigma()` may have changed."""
        changed = False
        sensors = self._sensors
        for name in self._names:
            value = values.get(name)
            if value is None:
                continue    # (not in this frame: another multiplexer page, another message)
            sensor = sensors.get(name)
            if sensor is None:
                sensor = sensors[name] = _SensorNoise()
            changed = sensor.push(time_s, value) or changed
        return changed

    def sigma(self) -> float | None:
        """The largest noise of the sensors seen, or None while one of them has too few
        residuals to say (`NOISE_FIRST`). The wheels' sensors are taken as one: a noise
        underestimated reads as ABS releases, and the median of a few dozen residuals may be a
        third low."""
        sigmas = [s.sigma for s in self._sensors.values()]
        if not sigmas or any(s is None for s in sigmas):
            return None
        return max(sigmas)  # type: ignore[type-var]
