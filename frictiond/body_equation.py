"""The body equation as the front end's check on its own brake inputs.

M·dv/dt = −ΣF_x − B·v − D·v² (model.md) says what torque the brakes gave in total; set against the
torque the pressures say, it gives a brake-gain correction (pads move ±20 % in service, and the
gain absorbs the car's load), the pressure sensors' lag, and a verdict: the pressures do not say
what the brakes do (a fault), or, on a car sending one master-cylinder pressure, an ABS has released
wheels (no wheel's brake torque is known from then on); and, as the intercept of that gain's fit,
the accelerometer's own offset, with what coasting shows of it as the fit's prior. The pressure
sensors' lag is `pressure_lag`'s, the gain's fit with the offset `brake_gain`'s, and the offset
free rolling shows (with gravity's share on a grade, for the speed estimate) `free_rolling_offset`'s.
`BodyEquation` is a part of `frontend.FrontEnd`: its state lives
on the front end, where the compiled `_frontcore.sample_physics` reads and writes it by these
names; the code here is the fallback without a C compiler and the reference (tests compare).
"""
from __future__ import annotations

import math

from .brake_gain import SENSOR_OFFSET_LIMIT_MPS2, SENSOR_OFFSET_PRIOR_S, BrakeGain, gain_and_sensor_offset
from .free_rolling_offset import FREE_ROLLING_STATE, FreeRollingOffset, spread_variance
from .pressure_lag import PRESSURE_LAG_STATE, PRESSURE_SENSOR_LAG_S, PressureLag

_BRAKE_GAIN_PRIOR_WEIGHT = 10 * 1000.0**2   # ten samples at 1 kN·m saying brake gain 1
_BRAKE_MODEL_MARGIN = 1.25                  # "far outside the gain limits": beyond them by this factor
_BRAKE_MODEL_WINDOW_S = 0.2                 # the body check's window: about this much braking
# A wheel slower than this share of the car's speed (and 0.3 m/s) is locked: its brake clamps it
# and passes only the tyre's sliding force, not the torque its pressure could give.
LOCKED_WHEEL_RATIO = 0.05      # (also in _frontcore.c)
# What the body equation cannot resolve, as a torque: what is left of an accelerometer offset
# (this much of a deceleration) and each wheel's pressure offset (bar, times its gain). A smaller
# disagreement proves no signal wrong, however large its ratio (ice, where the brake torques are
# of the order of the wheels' inertia torques). (Also in _frontcore.c.)
BODY_ACCEL_TOLERANCE_MPS2 = 0.05
PRESSURE_TOLERANCE_BAR = 0.25
# A wind along the road the config cannot know (m/s, a gentle breeze): the drag it adds or takes
# away is weather, not a broken pressure signal, and the fault verdict allows for it (at 25 m/s a
# 5 m/s head wind is 110 N more drag, a fifth of the tyres' force on μ 0.034 ice; wind_doubt, 0
# by default, is what the gain's doubt allows for). (Also in _frontcore.c.)
FAULT_WIND_MPS = 5.0
# What coasting has shown of the accelerometer's offset (`_learn_rolling_offset`), and ...
_COASTING_STATE = ("_rolling_offset_mps2", "_rolling_offset_samples", "_rolling_offset_m2",
                   "_rolling_air_doubt_mps2")
# ... what the front end learns from each sample (`_compute_sample` on both paths): a suspect sample
# must not teach it (a corrupted wheel speed's inertia torque moved the brake gain by 10 %).
LEARNT_STATE = ("_gain_sum_tt", "_gain_sum_tn", "_gain_sum_t", "_gain_sum_n", "_gain_sum_w",
                 "_sensor_offset_mps2", "_sensor_offset_doubt_mps2", "_recent_weight_nm", "_recent_needed_nm",
                 "_recent_brake_nm", "_recent_lag_nm", "_last_brake_nm", "_brake_released", "_brake_gain_factor",
                 "_brake_gain_doubt", "_brake_model_holds", "_unjudged_s", "_resistance_doubt_sum_n",
                 "_tyre_force_sum_n") + PRESSURE_LAG_STATE + FREE_ROLLING_STATE + _COASTING_STATE


class BodyEquation(BrakeGain, PressureLag, FreeRollingOffset):
    """Brake gain, pressure lag (`PressureLag`), the accelerometer's own offset and the brake
    model's verdict, learnt from the body equation sample by sample (`_update_brake_gain`,
    `_learn_rolling_offset`); the gain's fit is `BrakeGain`'s, the offset free rolling shows
    `FreeRollingOffset`'s."""

    def _reset_body_equation(self) -> None:
        """What the body equation has learnt: nothing yet."""
        self._reset_pressure_lag()
        self._reset_free_rolling_offset()
        self._slipping_time_s = -math.inf   # the newest sample with a braked wheel slipping
        self._brake_gain_factor = 1.0
        self._brake_gain_doubt = 0.0        # what the body equation leaves of its error (`gain_within_offset_ambiguity`)
        self._gain_sum_tt = self._gain_sum_tn = _BRAKE_GAIN_PRIOR_WEIGHT   # Σ T², Σ T·N
        self._gain_sum_t = self._gain_sum_n = self._gain_sum_w = 0.0       # Σ T, Σ N, Σ 1
        # The accelerometer's own offset (what it reads beyond the contact and air forces), the
        # intercept of the gain's regression, and the half-width of what it may still be off by.
        self._sensor_offset_mps2 = 0.0
        self._sensor_offset_doubt_mps2 = self.options.accel_offset_tolerance
        # The same offset as free rolling's body equation gives it (`_learn_rolling_offset`): its
        # mean, samples, Σ squared deviations, and the mean of what the air's drag may be off by.
        self._rolling_offset_mps2 = 0.0
        self._rolling_offset_samples = 0
        self._rolling_offset_m2 = 0.0
        self._rolling_air_doubt_mps2 = 0.0
        # Over ~0.2 s of braking: Σ brake torque T, Σ T × torque the body needed, Σ T², ...
        self._recent_weight_nm = self._recent_needed_nm = self._recent_brake_nm = 0.0
        self._recent_lag_nm = 0.0          # ... Σ T × what the pressure sensors' lag may hide (signed)
        self._last_brake_nm = 0.0
        self._brake_released = False       # one master pressure overstating the brakes: an ABS at work
        self._brake_model_holds = True
        self._unjudged_s = 0.0             # time since a sample last entered that window
        # Over the brake gain's time constant of braking: Σ what the car's resistance may be off
        # by, Σ the tyres' total force (`resistance_doubt_share`).
        self._resistance_doubt_sum_n = self._tyre_force_sum_n = 0.0

    @property
    def brake_gain_factor(self) -> float:
        return self._brake_gain_factor

    @property
    def brake_gain_doubt(self) -> float:
        """How far the brake gain may still be off, as a share of it (the half-width of what the
        gain limits and the body equation allow): what the accelerometer's offset may still be
        off by, over the deceleration."""
        return self._brake_gain_doubt

    @property
    def resistance_doubt_share(self) -> float:
        """How far the brake gain may be off because the car's air drag may be (a share of it,
        the half-width of a uniform error, as `brake_gain_doubt`): what the resistance may be off
        by (`VehicleParams.resistance_doubt_n`) over the tyres' total force, both averaged over the
        braking the gain was learnt from. On ice at 30 m/s a wind of 5 m/s is a tenth of it."""
        if not self.options.brake_gain_correction or self._tyre_force_sum_n <= 0.0:
            return 0.0
        return self._resistance_doubt_sum_n / self._tyre_force_sum_n

    def _learn_resistance_doubt(self, speed_mps: float, tyre_force_n: float) -> None:
        """`resistance_doubt_share`'s sums, from a braking sample (forgotten as the gain is)."""
        doubt = self.vehicle.resistance_doubt_n(speed_mps)
        if not (math.isfinite(doubt) and math.isfinite(tyre_force_n)) or tyre_force_n <= 0.0:
            return
        keep = self._brake_gain_keep()
        self._resistance_doubt_sum_n = keep * self._resistance_doubt_sum_n + doubt
        self._tyre_force_sum_n = keep * self._tyre_force_sum_n + tyre_force_n

    @property
    def wheel_torques_unknown(self) -> bool:
        """Whether no wheel's brake torque is known: the car sends one master-cylinder pressure
        for all wheels, and an ABS has released wheels in this stop (`_brake_released`)."""
        return self.pressures_are_master and self._brake_released

    def body_equation_note(self) -> str | None:
        """What the body equation has learnt, for a user checking a car's config: the brake gain
        against the configured one, the accelerometer's own offset (and what coasting showed of it)
        and the pressure sensors' lag, each with what it may still be off by; None before any
        braking taught it. An offset held
        at its tolerance's edge is said so: the sensor may read further off than the config allows
        (`frontend.accel_offset_tolerance`), or the pressures are off by a factor."""
        level = self.options.level_road
        if not self.options.brake_gain_correction or self._gain_sum_tt <= _BRAKE_GAIN_PRIOR_WEIGHT:
            return None
        tolerance = self.options.accel_offset_tolerance
        offset, doubt = self._sensor_offset_mps2, self._sensor_offset_doubt_mps2
        where = "free rolling's, level roads" if level else f"tolerance {tolerance:.2f}"
        if not level and self._rolling_offset_samples:
            shown, width = self.rolling_offset_prior()
            where += f"; coasting showed {shown:+.2f} ± {width:.2f}"
        note = (f"brake gain {self._brake_gain_factor:.2f} ± {self._brake_gain_doubt:.2f} of the configured "
                f"(pads, load); accelerometer offset {offset:+.2f} ± {doubt:.2f} m/s² ({where}); "
                f"pressure lag {1e3 * self.pressure_lag_s:.0f} ms")
        if not level and abs(offset) >= tolerance and doubt >= tolerance:
            note += (" — the offset at its tolerance's edge: a sensor reading further off (say so, "
                     "frontend.accel_offset_tolerance) or pressures off by a factor")
        return note

    def _learn_rolling_offset(self, speed: float, omega_dot: list[float], accel_long_raw: float,
                              drive: list[float]) -> None:
        """The accelerometer's own offset from a free-rolling sample of the body equation: with no
        brake torque, what it reads beyond the air's drag and the wheels' inertia and drive torques.
        Gravity along a grade is no contact force, so unlike `_learn_accel_bias` this is the sensor's
        offset alone; and a resistance the config does not know (rolling, the drivetrain's drag) is
        in it as it is in every braking sample, the intercept of `gain_and_sensor_offset`'s fit.
        Braking alone tells that intercept only from how its torque varies (a steady stop on snow:
        not at all). The mean of these samples, with its doubt (`rolling_offset_prior`), is that
        fit's prior, and the offset the forces take off until the brakes go on."""
        opts, veh = self.options, self.vehicle
        if opts.level_road or not opts.brake_gain_correction or not opts.coasting_offset:
            return
        mass_radius = veh.mass * veh.wheel_radius
        torque = veh.wheel_inertia * sum(omega_dot) - sum(drive)
        offset = accel_long_raw + veh.resistance_force(speed) / veh.mass + torque / mass_radius
        if not (math.isfinite(offset) and abs(offset) <= SENSOR_OFFSET_LIMIT_MPS2):
            return
        # What the drag the config gives may be off by at this speed, a breeze at least: braking
        # at other speeds meets another drag error, which the intercept cannot hold.
        air_doubt = veh.resistance_doubt_n(speed, max(veh.wind_doubt, FAULT_WIND_MPS)) / veh.mass
        self._rolling_offset_samples += 1
        alpha = max(min(1.0, self.sample_period_s / max(opts.accel_bias_time_constant, 1e-3)),
                    1.0 / self._rolling_offset_samples)
        before = self._rolling_offset_mps2
        self._rolling_offset_mps2 += alpha * (offset - before)
        self._rolling_offset_m2 += (offset - before) * (offset - self._rolling_offset_mps2)
        self._rolling_air_doubt_mps2 += alpha * (air_doubt - self._rolling_air_doubt_mps2)
        fit = gain_and_sensor_offset(
            self._gain_sum_tt, self._gain_sum_tn, self._gain_sum_t, self._gain_sum_n, self._gain_sum_w,
            SENSOR_OFFSET_PRIOR_S / self.sample_period_s, mass_radius, opts.accel_offset_tolerance,
            *self.rolling_offset_prior())
        self._sensor_offset_mps2, self._sensor_offset_doubt_mps2 = fit[1:]

    def take_coasting_from(self, other: BodyEquation) -> None:
        """What `other` (the same car's front end, built for other cycle times) learnt of the
        accelerometer's offset while coasting: its samples' inputs (the raw accelerometer, the
        wheels' ω̇ fitted over their own timestamps, the speed) do not depend on the period."""
        for name in _COASTING_STATE:
            setattr(self, name, getattr(other, name))

    def rolling_offset_prior(self) -> tuple[float, float]:
        """What free rolling's body equation says of the accelerometer's offset before braking
        weighs in: its mean and the half-width of its error (its samples' standard error and the
        drag's doubt, at least `BODY_ACCEL_TOLERANCE_MPS2`), both within the sensor's tolerance;
        (0, the tolerance) before any free rolling."""
        tolerance = self.options.accel_offset_tolerance
        samples = self._rolling_offset_samples
        if samples == 0:
            return 0.0, tolerance
        remembered = min(float(samples), max(self.options.accel_bias_time_constant, 1e-3) / self.sample_period_s)
        variance = spread_variance(samples, self._rolling_offset_m2, tolerance)
        width = math.sqrt(3.0 * variance / remembered) + self._rolling_air_doubt_mps2
        width = min(tolerance, max(BODY_ACCEL_TOLERANCE_MPS2, width))
        return min(max(self._rolling_offset_mps2, -tolerance), tolerance), width

    def _update_brake_gain(
        self,
        accel_long: float,
        speed: float,
        inertia_torques: list[float],
        brake_torques: list[float],
        drive: list[float],
        wheel_linear: list[float],
        brake_rates: list[float],
        braking: bool,
    ) -> None:
        """Body equation M dv/dt = −ΣF_x − B v − D v² as an independent check on brake force."""
        opts = self.options
        veh = self.vehicle
        decel = -accel_long
        raw_brake, raw_rate = sum(brake_torques), sum(brake_rates)
        total_brake = max(raw_brake + self.pressure_lag_s * raw_rate, 0.0)   # (advanced by the lag learnt)
        brake_rate = (total_brake - self._last_brake_nm) / self.sample_period_s
        self._last_brake_nm = total_brake
        # The verdict is on the last ~0.2 s of braking: after as long with no sample judged (brakes
        # off, the car not yet decelerating, a wheel locked) it has nothing to say, and the next
        # judged sample starts the window again.
        self._unjudged_s += self.sample_period_s
        if self._unjudged_s > _BRAKE_MODEL_WINDOW_S:
            self._brake_model_holds = True
            self._recent_weight_nm = self._recent_needed_nm = self._recent_brake_nm = self._recent_lag_nm = 0.0
        # Only while some wheel is braked: below that the pressures are their sensors' offsets
        # and the deceleration is drag and the accelerometer's offset (before free rolling has
        # taught it), and a window of those met the next stop's first samples as a "fault".
        if not braking or decel < opts.brake_gain_min_decel or total_brake < 1.0 or not math.isfinite(brake_rate):
            return
        # Not at walking pace (slip and the wheels' derivatives are ill-conditioned there, and a
        # car held at rest by its brakes decelerates by nothing), nor with a wheel locked: a
        # clamped wheel passes the tyre's sliding force, far less than its pressure could.
        locked = max(0.3, LOCKED_WHEEL_RATIO * speed)
        if speed < opts.min_speed or min(wheel_linear) < locked:
            return
        drag = veh.resistance_force(speed)
        total_force = veh.mass * decel - drag
        other = sum(inertia_torques) - sum(drive)
        needed = total_force * veh.wheel_radius - other
        ratio = needed / total_brake
        if not math.isfinite(ratio):
            return      # a NaN here would stay in the sums for good
        if not self._judge_brake_model(total_brake, brake_rate, needed, ratio, speed):
            if opts.pressure_lag_compensation:
                self._learn_pressure_lag(raw_brake, raw_rate, needed)
            self._learn_brake_gain(raw_brake, self._needed_as_sensed(needed))

    def _judge_brake_model(self, total_brake: float, brake_rate: float, needed: float, ratio: float,
                           speed: float) -> bool:
        """Whether the pressures still say what the brakes do (`_brake_model_holds`), and whether an
        ABS has released wheels behind a master-cylinder pressure in this stop: returned, as then
        neither the gain nor the lag is learnt from the sample. `needed` is the brakes' torque the
        body needs, `ratio` it over `total_brake`, the torque the pressures give, at `speed`."""
        veh = self.vehicle
        lim = self.options.brake_gain_limits
        # The pressures against the body over the last ~0.2 s of braking (sums of torques, so that
        # the pressure sensors' lag and the wheels' inertia torques through an ABS cycle average
        # out, and small torques count little): far outside the gain limits, by more than an
        # accelerometer offset, the pressures' offsets and the sensors' lag explain on top, the
        # pressures do not say what the brakes do (a signal scaled wrong, a sensor drifting by a
        # factor). Then no wheel's μ is trusted and the front end reports a fault.
        # Each sample weighs by its brake torque (the first instants of a stop, a few N·m against
        # the wheels' inertia and a lagging accelerometer, count little).
        recent = 1.0 - min(1.0, self.sample_period_s / _BRAKE_MODEL_WINDOW_S)
        self._unjudged_s = 0.0
        self._recent_weight_nm = recent * self._recent_weight_nm + total_brake
        self._recent_needed_nm = recent * self._recent_needed_nm + total_brake * needed
        self._recent_brake_nm = recent * self._recent_brake_nm + total_brake * total_brake
        self._recent_lag_nm = recent * self._recent_lag_nm + total_brake * PRESSURE_SENSOR_LAG_S * brake_rate
        window_ratio = self._recent_needed_nm / self._recent_brake_nm
        accel_tolerance = BODY_ACCEL_TOLERANCE_MPS2 + self._sensor_offset_doubt_mps2
        tolerance = veh.mass * veh.wheel_radius * accel_tolerance + PRESSURE_TOLERANCE_BAR * sum(self._brake_gains)
        resolved = _unexplained_torque(self._recent_needed_nm, self._recent_brake_nm, self._recent_lag_nm,
                                       self._recent_weight_nm, 1.0, 1.0) > tolerance
        wind = veh.drag_area_coefficient * FAULT_WIND_MPS * (2.0 * speed + FAULT_WIND_MPS) * veh.wheel_radius
        beyond_gains = _unexplained_torque(self._recent_needed_nm, self._recent_brake_nm, self._recent_lag_nm,
                                           self._recent_weight_nm, (1.0 - lim) / _BRAKE_MODEL_MARGIN,
                                           (1.0 + lim) * _BRAKE_MODEL_MARGIN) > tolerance + wind
        # With one master pressure for all wheels, brakes giving less than it says beyond what the
        # gain correction explains are an ABS releasing wheels, not a wrong signal: no gain is
        # learnt then, and no wheel's brake torque is known (`_brake_released`). Judged on this
        # sample too, not only over the window: the first dump's samples, read with the master's
        # torque, would put a peak far above the road's into the fit.
        released = self.pressures_are_master and (
            (window_ratio < 1.0 - lim and resolved) or (ratio < 1.0 - lim and total_brake - needed > tolerance))
        # Once an ABS has released wheels in a stop it modulates them until the stop ends: from
        # then on the master pressure bounds the wheels' pressures and says nothing more.
        self._brake_released = released = released or self._brake_released
        self._brake_model_holds = released or not beyond_gains
        return released


def _unexplained_torque(needed: float, brake: float, lag: float, weight: float, low: float, high: float) -> float:
    """How far the torque the body needs lies outside what the pressures give times a gain in
    [`low`, `high`], beyond what the pressure sensors' lag explains (N·m; 0 inside the band).

    The arguments are the brake-weighted window sums: Σb·N, Σb·b, Σb·lag·ḃ and Σb. A sensor
    trailing the brakes reads low while they apply and high while they release: a lag of up to
    `PRESSURE_SENSOR_LAG_S` explains a disagreement of that sign, up to that size. The gain band
    and the lag are one allowance, not two tests: a car whose brakes are 18 % stronger than
    configured, seen through a lagging sensor as the pedal goes down, is within both together.
    (`_frontcore.c`'s `unexplained_torque` is the same.)
    """
    mean_needed, mean_brake, lag_explains = needed / weight, brake / weight, lag / weight
    if mean_needed > high * mean_brake:
        return mean_needed - high * mean_brake - max(lag_explains, 0.0)
    if mean_needed < low * mean_brake:
        return low * mean_brake - mean_needed - max(-lag_explains, 0.0)
    return 0.0
