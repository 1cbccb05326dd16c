"""Each brake-pressure sensor's zero point (`PressureZeros`): its reading with the brakes
released, learnt while the car rolls free, taken off its readings. A part of
`frontend.FrontEnd` (its state is the front end's)."""
from __future__ import annotations

import math
import statistics
from collections import deque
from typing import Mapping

from .input_names import PRESSURE_NAMES

PRESSURE_ZERO_READINGS = 128   # free-rolling readings a pressure sensor's zero point is the median of
PRESSURE_ZERO_AT_ZERO = 0.4    # ... and the share of them at 0 that says its zero point is 0


class PressureZeros:
    """Learning the pressure sensors' zero points and taking them off."""

    def _reset_pressure_zeros(self) -> None:
        # Each pressure sensor's reading with the brakes released (its zero point, learnt while
        # free rolling: `_learn_pressure_zeros`), taken off its readings; the newest raw readings.
        self._pressure_zero = dict.fromkeys(PRESSURE_NAMES, 0.0)
        self._pressure_zero_readings = {name: deque(maxlen=PRESSURE_ZERO_READINGS) for name in PRESSURE_NAMES}
        self._pressure_zero_samples = 0
        self._pressure_zeroed = False
        self._raw_pressures: dict[str, float] = {}

    def _zeroed_pressures(self, values: Mapping[str, float]) -> Mapping[str, float]:
        """A pressure message's values less each sensor's zero point (`_learn_pressure_zeros`),
        not below 0; the raw readings are kept for the learning."""
        raw = self._raw_pressures
        zero = self._pressure_zero
        for name, value in values.items():
            if name in zero:
                raw[name] = value
        if not self._pressure_zeroed:
            return values
        return {name: max(0.0, value - zero[name]) if name in zero and value == value else value
                for name, value in values.items()}

    def _learn_pressure_zeros(self) -> None:
        """Free rolling (the samples the accelerometer's offset is learnt from: no brake, the
        wheels' acceleration the body's): the brakes are released and each pressure sensor
        reads its own zero point. A sensor that reads 0.9 bar there reads 0.9 bar too much
        under the brakes, 10-30 % of an ABS's pressures on ice. The zero point is the median
        of the last `PRESSURE_ZERO_READINGS` readings, not their mean: a sensor reads no
        pressure below 0, so its noise around a true zero is cut to 0 on one side, and a mean
        would take half a noise's width off every pressure. For the same reason a sensor that
        reads exactly 0 in `PRESSURE_ZERO_AT_ZERO` of them or more has its zero point at 0 (its
        median is then as likely one noise sample above it). A negative zero point is not seen
        either: nothing is taken off those sensors."""
        raw = self._raw_pressures
        if not raw:
            return
        self._pressure_zero_samples += 1
        readings = self._pressure_zero_readings
        for name, value in raw.items():
            if name in readings and math.isfinite(value):
                readings[name].append(value)
        n = self._pressure_zero_samples
        if n > PRESSURE_ZERO_READINGS and n % 8:
            return    # (a window of readings moves slowly: its median every 8th sample)
        zero = self._pressure_zero
        for name, values in readings.items():
            if not values:
                continue
            # (reading exactly 0 this often, the zero point is within a quarter of the noise of
            # 0: a median of readings cut at 0 would be a noise sample above it)
            if sum(v <= 0.0 for v in values) >= PRESSURE_ZERO_AT_ZERO * len(values):
                zero[name] = 0.0
            else:
                zero[name] = max(0.0, float(statistics.median_low(values)))
        self._pressure_zeroed = any(z > 0.0 for z in zero.values())
