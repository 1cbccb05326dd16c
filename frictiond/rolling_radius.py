"""Each wheel's rolling radius against the others' (`RollingRadii`), learnt while the car rolls
free, its wheel speed corrected by it. A part of `frontend.FrontEnd` (its state is the front end's).

A wheel-speed ECU turns a wheel's ω into a speed over the one radius it is configured with, but
tyres differ: 6 mm of tread worn is 2 % of the radius, a soft tyre a few tenths of a percent. A
wheel 2 % smaller turns 2 % faster, and under the brakes every slip measured against it is 2 %
off: a slip controller holding all four tyres at one slip then shows four different slips at one
μ, a flat top where there is none. Rolling free (no brake, no drive torque, the wheels following
the body, speeds within `FREE_ROLLING_SPREAD` of each other), straight and near a constant speed,
every wheel turns at its ground speed: what its slip reads beyond the four wheels' mean is its
radius's difference. Each wheel's speed is scaled by the factor learnt, its mean over the
samples (a plain mean, then forgetting over `RADIUS_AVERAGE_SAMPLES`), kept to ±`FREE_ROLLING_SPREAD`.
The four factors keep a mean of 1: without a ground-speed sensor nothing tells the four
wheels' common radius from the car's speed. With one, a radius wrong for all four alike (a
nominal radius configured, not the one measured rolling) shows as a slip all four read rolling
free, and every slip measured against that sensor under the brakes is off by it:
`_radius_scale` learns it from those samples, and the four wheels' speeds are scaled by it too.
A factor within `RADIUS_RESOLUTION` of 1 is not applied: tyres alike, or whose radii the ECU
already corrects, give factors within the noise of 1 (the common one, within
`RADIUS_SCALE_RESOLUTION`: what a driven axle's traction slip makes of it).
"""
from __future__ import annotations

import math

from .sample_physics import FREE_ROLLING_SPREAD
from .samples import WHEELS, PhysicalSample

# Below this the wheel speeds' quantisation (0.06 km/h is 0.4 % at 18 km/h) is as large as what
# is learnt.
RADIUS_MIN_SPEED_MPS = 5.0
# Turning harder, the loads shift across the car (a loaded tyre rolls on a smaller radius) and
# the outer track's extra speed rests on the lateral accelerometer: not a radius's difference.
RADIUS_MAX_LATERAL_MPS2 = 1.0
# Accelerating or slowing harder, a driven axle's traction slip (or an engine's drag) is a few
# tenths of a percent: not a radius's difference either.
RADIUS_MAX_LONGITUDINAL_MPS2 = 1.0
# Samples the factors average over before they forget (5–10 s of free rolling at 50–100 Hz): a
# tyre's radius changes only with its pressure and temperature.
RADIUS_AVERAGE_SAMPLES = 500
# A factor within this of 1 is not applied: below the wheel speeds' resolution (0.01–0.06 km/h at
# 50 km/h), it would move every slip by noise, not take a tyre's difference off.
RADIUS_RESOLUTION = 0.001
# The four's common radius is applied from this far off 1: rolling "free" as the bus tells it (no
# drive torque sent) a car may still be driven, and its driven axle's traction slip, 0.1-0.2 % at a
# cruise, reads as a common radius of that size (the campaign's cars as drawn learnt 0.11 %).
RADIUS_SCALE_RESOLUTION = 0.003
# ... and once this many samples are averaged: one reading of a ground-speed sensor is off by its
# noise, a few hundredths of a m/s or 0.1-0.3 % of the speed, as much as that floor.
RADIUS_SCALE_MIN_SAMPLES = 20
# A difference worth telling a user (replay's summary): below it, tyres and noise as usual.
RADIUS_NOTE_SHARE = 0.005


class RollingRadii:
    """Learning each wheel's radius factor (`_learn_rolling_radii`) and scaling its speed by it
    (`_scaled_wheel_speeds`); the derivative window's speeds are rescaled with each change."""

    def _reset_rolling_radii(self) -> None:
        self._radius_factors = [1.0, 1.0, 1.0, 1.0]
        self._radius_applied = [1.0, 1.0, 1.0, 1.0]   # (those beyond `RADIUS_RESOLUTION`)
        self._radius_samples = 0
        self._radius_scale = 1.0              # the four's common radius over the configured (`rolling_radius_scale`)
        self._radius_scale_samples = 0
        self._radius_slipping_s = -math.inf   # the last braked sample whose four wheels slipped (mean)
        self._free_rolling_sample = False     # (whether the newest sample rolled free: `SamplePhysics`)

    @property
    def rolling_radius_factors(self) -> tuple[float, float, float, float]:
        """Each wheel's rolling radius over the configured one's share of the four's mean
        (`WHEELS`' order; 1.0 until learnt): its ω is scaled by this (times the common
        `rolling_radius_scale`) where that is `RADIUS_RESOLUTION` or more off 1."""
        f = self._radius_factors
        return (f[0], f[1], f[2], f[3])

    @property
    def rolling_radius_scale(self) -> float:
        """The four wheels' common rolling radius over the configured one, as the ground-speed
        sensor shows it (1.0 without one, or until learnt); applied with each wheel's factor."""
        return self._radius_scale

    def rolling_radius_note(self) -> str | None:
        """The tyres' radii as learnt, for a user checking a car (worn, soft or mixed tyres, a
        nominal radius configured): None until learnt, or while every one is within
        `RADIUS_NOTE_SHARE` of the four's mean and their common one within it of 1."""
        f = self._radius_factors
        notes = []
        if self._radius_samples and any(abs(x - 1.0) >= RADIUS_NOTE_SHARE for x in f):
            wheels = ", ".join(f"{w} {100.0 * (x - 1.0):+.1f} %" for w, x in zip(WHEELS, f))
            notes.append(f"{wheels} of the four's mean, learnt over {self._radius_samples} free-rolling samples")
        if self._radius_scale_samples and abs(self._radius_scale - 1.0) >= RADIUS_NOTE_SHARE:
            notes.append(f"the four {100.0 * (self._radius_scale - 1.0):+.1f} % of vehicle.wheel_radius against the "
                         f"ground-speed sensor, over {self._radius_scale_samples} samples")
        if not notes:
            return None
        return "; ".join(notes) + "; each wheel's speed corrected by it"

    def _scaled_wheel_speeds(self, speeds: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
        f = self._radius_applied
        return (speeds[0] * f[0], speeds[1] * f[1], speeds[2] * f[2], speeds[3] * f[3])

    def _applied_scale(self) -> float:
        if self._radius_scale_samples < RADIUS_SCALE_MIN_SAMPLES:
            return 1.0
        return self._radius_scale if abs(self._radius_scale - 1.0) >= RADIUS_SCALE_RESOLUTION else 1.0

    def _learn_rolling_radii(self, sample: PhysicalSample, free_rolling: bool) -> None:
        """Each sample fitted (not a suspect one): on one that teaches the radii
        (`_radius_teaching_slips`), each wheel's slip beyond the four's mean is its radius's
        difference still left; against a ground-speed sensor, the four's mean slip is their
        common radius's error (`_learn_radius_scale`)."""
        slips = self._radius_teaching_slips(sample, free_rolling)
        if slips is None:
            return
        mean = sum(slips) / 4.0
        excess = [s - mean for s in slips]
        if not all(abs(e) <= FREE_ROLLING_SPREAD for e in excess):   # (NaN: not learnt)
            return
        self._radius_samples += 1
        weight = 1.0 / min(self._radius_samples, RADIUS_AVERAGE_SAMPLES)
        # This sample's factor for each wheel: the one applied (over the common scale), and what
        # its slip still reads beyond the mean (reading slow, slip > mean: a larger radius than
        # configured, its speed scaled up). The factors learnt are these samples' mean.
        scale = self._applied_scale()
        shown = [a / scale * (1.0 + e) for a, e in zip(self._radius_applied, excess)]
        factors = [f + weight * (x - f) for f, x in zip(self._radius_factors, shown)]
        norm = sum(factors) / 4.0
        low, high = 1.0 - FREE_ROLLING_SPREAD, 1.0 + FREE_ROLLING_SPREAD
        factors = [min(max(f / norm, low), high) for f in factors]
        self._radius_factors = factors
        if sample.speed_from_reference:
            scale = self._learn_radius_scale(scale * (1.0 + mean))
        applied = [f * scale for f in factors]
        self._apply_radii([a if abs(a - 1.0) >= RADIUS_RESOLUTION else 1.0 for a in applied])

    def _radius_teaching_slips(self, sample: PhysicalSample, free_rolling: bool) -> tuple[float, ...] | None:
        """The sample's slips if it teaches the radii, else None: rolling free (`SamplePhysics`:
        no brake or drive torque, the wheels following the body, their speeds within
        `FREE_ROLLING_SPREAD`), straight, near a constant speed and fast enough.

        Not the accelerometer's offset's free rolling: that waits `accel_bias_settle_s` after
        any braked wheel slipped over `SETTLE_SLIP`, and a tyre 1 % smaller than the others
        reads that much whenever a pressure sensor's offset makes its wheel "braked" at rest:
        the radii would then never be learnt. Here the wait counts from a braked sample whose
        four wheels' mean slip is beyond what the tyres' differences (and a speed estimate at
        the fastest of them) can read, `FREE_ROLLING_SPREAD`: wheels still closing the slip of
        a stop together cancel in the mean, and a tail they close at different rates is past
        within the wait."""
        t = sample.time_s
        if t < self._radius_slipping_s:
            self._radius_slipping_s = -math.inf     # (the clock went back)
        if sample.braking and sum(sample.slip) / 4.0 > FREE_ROLLING_SPREAD:
            self._radius_slipping_s = t
        if not free_rolling or t - self._radius_slipping_s < self.options.accel_bias_settle_s:
            return None
        accel, lateral = self._sample_accel, self._value("accel_lat", t)
        if (sample.speed_mps < RADIUS_MIN_SPEED_MPS or accel is None or lateral is None
                or not abs(accel - self._sensor_offset_mps2) <= RADIUS_MAX_LONGITUDINAL_MPS2
                or not abs(lateral) <= RADIUS_MAX_LATERAL_MPS2):
            return None
        return sample.slip

    def _learn_radius_scale(self, shown: float) -> float:
        """One sample's common radius (`shown`: the scale applied, times what the four's mean slip
        against the ground-speed sensor still reads) into their mean; the scale to apply now."""
        self._radius_scale_samples += 1
        weight = 1.0 / min(self._radius_scale_samples, RADIUS_AVERAGE_SAMPLES)
        scale = self._radius_scale + weight * (shown - self._radius_scale)
        self._radius_scale = min(max(scale, 1.0 - FREE_ROLLING_SPREAD), 1.0 + FREE_ROLLING_SPREAD)
        return self._applied_scale()

    def _apply_radii(self, applied: list[float]) -> None:
        """Scale the wheel speeds by `applied` from now on, and the derivative window's speeds,
        scaled by the factors before, to match: no step in its fit."""
        ratio = [a / b for a, b in zip(applied, self._radius_applied)]
        if ratio == [1.0, 1.0, 1.0, 1.0]:
            return
        self._radius_applied = applied
        window = self._wheel_speeds
        for k in range(len(window)):
            s = window[k]
            window[k] = (s[0] * ratio[0], s[1] * ratio[1], s[2] * ratio[2], s[3] * ratio[3])
