"""What the accelerometer reads while the car rolls free: its offset, and on a grade gravity's share.

With no brake and no drive torque on any wheel the wheels' own acceleration is the car's, and what
the accelerometer reads beyond it is its offset plus, on a grade, gravity along the road. The
speed estimate takes that sum off (`_learn_accel_bias`, with its doubt `accel_offset_doubt_mps2`);
the forces do not feel gravity along the road, and take the sensor's own offset from the body
equation instead (`body_equation`). `FreeRollingOffset` is a part of `body_equation.BodyEquation`
(its state, `_accel_bias_*`, lives on the front end, where the compiled `_frontcore.sample_physics`
reads and writes it by these names; the code here is the fallback and the reference).
"""
from __future__ import annotations

import math

# The offset an accelerometer may have until the body equation has told it from the brake gain
# (a fault seen right after start-up would be the accelerometer's); also how far the offset for
# the speed estimate may be off until free rolling has taught it (this many samples).
UNLEARNT_ACCEL_TOLERANCE_MPS2 = 0.3
ACCEL_BIAS_LEARNT_SAMPLES = 50
# How far the offset learnt so far may be off (`offset_doubt_mps2`): its samples' standard error,
# their spread taken with a prior of this many samples spread by the tolerance above (two or three
# samples that happen to agree do not make an offset known). (Also in _frontcore.c.)
ACCEL_BIAS_PRIOR_SAMPLES = 2.0
# What free rolling's learning keeps from sample to sample (in `body_equation.LEARNT_STATE`).
FREE_ROLLING_STATE = ("_accel_bias_mps2", "_accel_bias_samples", "_accel_bias_m2")


class FreeRollingOffset:
    """The accelerometer's reading beyond the free-rolling wheels' acceleration, learnt sample by
    sample (a plain mean, then forgetting over `accel_bias_time_constant`), with its doubt."""

    def _reset_free_rolling_offset(self) -> None:
        """Nothing learnt yet."""
        self._accel_bias_mps2 = 0.0
        self._accel_bias_samples = 0
        self._accel_bias_m2 = 0.0           # Σ of squared deviations from the running mean (Welford)

    @property
    def accel_bias_mps2(self) -> float:
        return self._accel_bias_mps2

    @property
    def accel_offset_doubt_mps2(self) -> float:
        """The standard error of the accelerometer offset learnt from free rolling so far (m/s²),
        the one the speed estimate takes off: 0 once learnt."""
        return offset_doubt_mps2(self._accel_bias_samples, self._accel_bias_m2,
                                 self.options.accel_offset_tolerance) / math.sqrt(3.0)

    def _learn_accel_bias(self, time_s: float, omega_dot: list[float], accel_long_raw: float) -> None:
        # Free rolling: the wheels' own acceleration is the vehicle's; the difference is offset
        # and, on a grade, gravity's share: what the speed estimate takes off, not the forces.
        wheel_accel = self.vehicle.wheel_radius * (sum(omega_dot) / len(omega_dot))
        alpha = min(1.0, self.sample_period_s / max(self.options.accel_bias_time_constant, 1e-3))
        error = accel_long_raw - wheel_accel
        if abs(error) < 2.0:
            # The plain mean of the first samples, then the exponential forgetting: right after
            # start-up the offset is known after a second of rolling, not only after several τ.
            self._accel_bias_samples += 1
            alpha = max(alpha, 1.0 / self._accel_bias_samples)
            before = self._accel_bias_mps2
            self._accel_bias_mps2 += alpha * (error - before)
            self._accel_bias_m2 += (error - before) * (error - self._accel_bias_mps2)
            if self.options.level_road:
                # (no grade: what free rolling taught is the sensor's own offset)
                self._sensor_offset_mps2 = self._accel_bias_mps2
                self._sensor_offset_doubt_mps2 = offset_doubt_mps2(self._accel_bias_samples, self._accel_bias_m2,
                                                                   self.options.accel_offset_tolerance)


def offset_doubt_mps2(samples: int, sum_squares: float, tolerance: float = UNLEARNT_ACCEL_TOLERANCE_MPS2) -> float:
    """How far the accelerometer offset learnt from `samples` free-rolling samples (their squared
    deviations summing to `sum_squares`) may be off, as the half-width of a uniform error of the
    same σ as its standard error (√3 σ): at most the sensor's `tolerance` (none learnt),
    0 once learnt (`ACCEL_BIAS_LEARNT_SAMPLES`, as the brake check counts it). The samples'
    spread is 0.07–0.5 m/s² by car and sensors: three samples leave the offset 0.25 m/s² off,
    forty 0.01–0.03."""
    if samples >= ACCEL_BIAS_LEARNT_SAMPLES:
        return 0.0
    return min(tolerance, math.sqrt(3.0 * spread_variance(samples, sum_squares, tolerance) / max(samples, 1)))


def spread_variance(samples: int, sum_squares: float, tolerance: float) -> float:
    """The variance of offset samples whose squared deviations sum to `sum_squares`, with a prior
    of `ACCEL_BIAS_PRIOR_SAMPLES` samples spread by `tolerance` (a few that happen to agree do
    not make an offset known)."""
    prior = ACCEL_BIAS_PRIOR_SAMPLES
    return (sum_squares + prior * tolerance**2) / (max(samples - 1, 0) + prior)
