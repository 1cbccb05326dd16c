"""The brake gain the body equation teaches, with the accelerometer's own offset as its intercept.

`BrakeGain` is a part of `body_equation.BodyEquation`: its state (the gain's sums, the gain and
the offset with their doubts) lives on the front end, where the compiled
`_frontcore.sample_physics` reads and writes it by these names; the code here is the fallback
without a C compiler and the reference (tests compare). Each braking sample the body equation
judges (`BodyEquation._update_brake_gain`), unless an ABS has released wheels behind a
master-cylinder pressure, moves the gain's least-squares sums (`_learn_brake_gain`); the gain and
the offset are fitted together (`gain_and_sensor_offset`) and the gain held to what its limits
and the offset's doubt allow (`gain_within_offset_ambiguity`).
"""
from __future__ import annotations

import math

from .free_rolling_offset import UNLEARNT_ACCEL_TOLERANCE_MPS2

# The accelerometer's own offset, told from the brake gain by the body equation over braking
# (`gain_and_sensor_offset`): a prior of none weighing like this much braking at a steady torque
# (the body equation's residuals stay correlated for ~0.05 s and carry the axles' gain split and
# the pressure sensors' lag, which a lighter prior reads as offset: on dev stops at a 5 % grade
# its error was least from 0.1 to 0.2 s, and covered by its doubt in 86 % of them at 0.2 s), and
# each sample's disagreement taken as at most this much of an offset. (Also in _frontcore.c.)
SENSOR_OFFSET_PRIOR_S = 0.2
SENSOR_OFFSET_LIMIT_MPS2 = 1.0


class BrakeGain:
    """The brake gain and the accelerometer's own offset, fitted by least squares with exponential
    forgetting to the braking samples of the body equation."""

    def _learn_brake_gain(self, brake_read: float, needed: float) -> None:
        """The gain and the accelerometer's own offset, fitted to the torque the body needs as the
        raw accelerometer says it (`needed` takes off the offset held so far: that share is put
        back), lagged as the pressure sensors lag (`_needed_as_sensed`), against the torque the
        pressures give as read (`gain_and_sensor_offset`); on level ground
        the gain alone, `needed` as it is, free rolling's offset being the sensor's. By least
        squares with exponential forgetting: the first instants of a stop (a few N·m
        against a wheel's inertia and a lagging accelerometer) weigh little against full
        braking. It converges within a stop, which matters because the gain also absorbs the
        car's load (a 25 % heavier car read 20 % too much μ until learnt); the gain's prior
        weighs like 10 samples at 1 kN·m. Each sample is clipped first to what the gain limits
        and `SENSOR_OFFSET_LIMIT_MPS2` allow: one wild sample (spoofed wheel speeds give inertia
        torques of kN·m) moves the sums no more than a plausible one."""
        opts = self.options
        veh = self.vehicle
        lim = opts.brake_gain_limits
        mass_radius = veh.mass * veh.wheel_radius
        keep = self._brake_gain_keep()
        level = opts.level_road
        band = 0.0 if level else mass_radius * SENSOR_OFFSET_LIMIT_MPS2
        if not level:
            needed -= mass_radius * self._sensor_offset_mps2
        needed = min(max(needed, (1.0 - lim) * brake_read - band), (1.0 + lim) * brake_read + band)
        self._gain_sum_tt = keep * self._gain_sum_tt + brake_read * brake_read
        self._gain_sum_tn = keep * self._gain_sum_tn + brake_read * needed
        if level:
            self._brake_gain_factor, self._brake_gain_doubt = gain_within_offset_ambiguity(
                self._gain_sum_tn / self._gain_sum_tt, lim, self._unlearnt_offset_torque_nm())
            return
        self._gain_sum_t = keep * self._gain_sum_t + brake_read
        self._gain_sum_n = keep * self._gain_sum_n + needed
        self._gain_sum_w = keep * self._gain_sum_w + 1.0
        gain, offset, doubt = gain_and_sensor_offset(
            self._gain_sum_tt, self._gain_sum_tn, self._gain_sum_t, self._gain_sum_n, self._gain_sum_w,
            SENSOR_OFFSET_PRIOR_S / self.sample_period_s, mass_radius, opts.accel_offset_tolerance,
            *self.rolling_offset_prior())
        self._sensor_offset_mps2, self._sensor_offset_doubt_mps2 = offset, doubt
        ambiguity = self._unlearnt_offset_torque_nm()
        if not 1.0 - lim <= gain <= 1.0 + lim:
            # The body asks for a gain beyond its limits with the offset the fit allows: the
            # pressures do not say what the brakes do (the verdict's to tell, when it is beyond
            # the offset's tolerance too), and the gain at its limit is vouched for by nothing.
            self._brake_gain_factor, self._brake_gain_doubt = min(max(gain, 1.0 - lim), 1.0 + lim), lim
        else:
            self._brake_gain_factor, self._brake_gain_doubt = gain_within_offset_ambiguity(gain, lim, ambiguity)

    def _brake_gain_keep(self) -> float:
        """What a braking sample leaves of the gain's sums (and `resistance_doubt_share`'s): the
        exponential forgetting over `brake_gain_time_constant`."""
        return 1.0 - min(1.0, self.sample_period_s / max(self.options.brake_gain_time_constant, 1e-3))

    def _unlearnt_offset_torque_nm(self) -> float:
        """The share of the brakes' torque that what is not yet known of the accelerometer's
        offset may hide: its doubt times mass and radius, over the brake-weighted mean brake
        torque of the last ~0.2 s."""
        doubt = self._sensor_offset_doubt_mps2
        if doubt <= 0.0 or self._recent_brake_nm <= 0.0:
            return 0.0
        veh = self.vehicle
        mean_brake = self._recent_brake_nm / max(self._recent_weight_nm, 1e-9)
        return veh.mass * veh.wheel_radius * doubt / max(mean_brake, 1e-9)


def gain_and_sensor_offset(sum_tt: float, sum_tn: float, sum_t: float, sum_n: float, sum_w: float,
                           prior_samples: float, mass_radius: float,
                           tolerance: float = UNLEARNT_ACCEL_TOLERANCE_MPS2, prior_offset: float = 0.0,
                           prior_width: float | None = None) -> tuple[float, float, float]:
    """The brake gain G and the accelerometer's offset s of N = G·T − M·R·s, the torque the body
    needs (from the raw accelerometer) against the torque the pressures give, fitted by least
    squares from the sums given (with the gain's prior in them) and a prior of s = 0 weighing like
    `prior_samples` samples; and the half-width of what s may still be off by.

    The accelerometer reads the contact and air forces plus its offset; on a grade, free rolling
    teaches the offset and gravity's share together (`_learn_accel_bias`), which the wheels'
    forces do not feel. Only a torque that varies through the stop (the pedal, an ABS's cycles)
    tells an offset, constant, from a gain, proportional: with a steady torque the prior stays,
    and the doubt with it. An offset within the sensor's tolerance is uniform a priori
    (`tolerance` its half-width, `frontend.accel_offset_tolerance`), the doubt that half-width times the
    posterior's share of the prior's standard deviation."""
    width = tolerance if prior_width is None else min(max(prior_width, 1e-6), tolerance)
    weight = prior_samples * (tolerance / width) ** 2
    a11, a12, a22 = sum_tt, sum_t, sum_w + weight
    det = a11 * a22 - a12 * a12
    if not (det > 0.0 and math.isfinite(det)):
        return sum_tn / sum_tt, prior_offset, width
    sum_n -= weight * mass_radius * prior_offset
    offset = -(a11 * sum_n - a12 * sum_tn) / det / mass_radius
    doubt = width * math.sqrt(min(1.0, weight * a11 / det))
    # No sensor reads beyond its tolerance: what the fit allows within it (the middle, and the
    # half-width), and the gain that offset leaves. A steady torque lets the gain's prior pull the
    # offset anywhere (a pressure reading 2.5 times the brakes' on ice fitted an offset of 0.25
    # m/s² and a gain at its limit); held within the tolerance the fault verdict still sees it.
    # A fit beyond the tolerance is a body equation no offset and gain explain (halved pressures
    # on snow fitted -0.75 m/s²): its edge, vouched for by nothing.
    if abs(offset) > tolerance:
        offset, doubt = math.copysign(tolerance, offset), tolerance
    else:
        low, high = max(-tolerance, offset - doubt), min(tolerance, offset + doubt)
        offset, doubt = 0.5 * (low + high), 0.5 * (high - low)
    return (sum_tn + mass_radius * offset * sum_t) / sum_tt, offset, doubt


def gain_within_offset_ambiguity(gain: float, limits: float, ambiguity: float) -> tuple[float, float]:
    """The brake gain the body equation supports when an accelerometer offset may account for
    `ambiguity` of it (a share of the brakes' torque), and how far off it may still be: the middle
    and the half-width of what both the gain limits (1 ± `limits`) and the body equation
    (`gain` ± `ambiguity`) allow. Before free rolling has taught the offset it may be 0.3 m/s²: on
    snow (1.2 m/s² of deceleration) a quarter of the brakes' torque, and the gain learnt from it
    was 23 % high where the brakes were 5 % strong, the wheels' μ with it, VALID at confidence
    0.95. A well resolved gain (dry asphalt: 3 %) stays as learnt. (`_frontcore.c`'s
    `gain_within_offset_ambiguity` is the same.)"""
    if ambiguity <= 0.0:
        return gain, 0.0
    low = max(1.0 - limits, gain - ambiguity)
    high = min(1.0 + limits, gain + ambiguity)
    return (0.5 * (low + high), 0.5 * (high - low)) if low <= high else (gain, 0.0)
