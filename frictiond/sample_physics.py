"""The front end's physics of one sample (`SamplePhysics`, a part of `frontend.FrontEnd`; its
state is the front end's, which `_frontcore.sample_physics` reads and writes by name).

From the wheels' ω and ω̇ at the derivative window's centre and the inputs interpolated there:
the inputs' range checks, each wheel's ground speed, stuck and dead sensors stood in for, the
vehicle speed and accelerometer offset, normal loads (model.md, physics signs), tyre forces from
the wheel equation, utilised friction, slip, and which wheels' samples may be fitted. Pure
numerics: canonical signal names only, no CAN.
"""
from __future__ import annotations

import math

from .free_rolling_offset import UNLEARNT_ACCEL_TOLERANCE_MPS2
from .samples import FrontEndResult, PhysicalSample
from .sensor_faults import stood_in_for
from .speed_estimate import MAX_ABS_ACCEL_MPS2
from .vehicle import GRAVITY_MPS2

FREE_ROLLING_SPREAD = 0.04     # relative wheel-speed spread a curve can explain without any slip
FREE_ROLLING_ACCEL_MPS2 = 2.0  # a free-rolling wheel's acceleration follows the body's within this
SETTLE_SLIP = 0.01             # a braked wheel slipping more has a spin-up to settle (`accel_bias_settle_s`)
MAX_PRESSURE_BAR = 350.0
BODY_WHEELS_TOLERANCE = 0.25   # the body's and the wheels' total force agree within this (pad friction ±20 %)
MIN_LOAD_N = 50.0              # a wheel carrying less has no μ worth the name (a lifted wheel)
MIN_DRIVE_TORQUE_NM = 20.0     # a wheel driven harder than this is torqued as a braked one is
LATERAL_OFFSET_MPS2 = UNLEARNT_ACCEL_TOLERANCE_MPS2   # (no free rolling teaches the lateral offset)

# What `_frontcore.sample_physics` builds its results from: the two result types, then the
# fault messages it can give (those of `_compute_sample`, in this order).
PHYSICS_TYPES = (PhysicalSample, FrontEndResult, "acceleration out of range", "brake pressure out of range",
                 "brake pressure implausible", "wheel speed glitch", "wheel speed stuck",
                 "brake pressure disagrees with deceleration")


class SamplePhysics:
    """`_compute_sample`: a `FrontEndResult` from the fitted wheels and the inputs at their
    instant (compiled in one call when installed, else the float code here, its reference)."""

    def _plan_physics(self) -> None:
        """`_compute_sample`'s compiled part reads its settings as one tuple of numbers, in the
        order of `_frontcore.c`'s K_ constants."""
        vehicle, options = self.vehicle, self.options
        self._physics_constants = tuple(float(x) for x in (
            options.stuck_frames, vehicle.brake_pushout_pressure, options.min_brake_pressure, options.min_speed,
            options.dead_wheel_ratio, options.dead_wheel_s, options.dead_wheel_unbraked_s, options.max_gap,
            options.unexplained_decel, vehicle.wheel_radius, options.speed_gain_free_rolling,
            options.speed_gain_up, options.speed_gain_down, options.min_braked_slip, options.max_all_wheel_slip,
            self.sample_period_s, options.accel_bias_time_constant, vehicle.mass, vehicle.cg_height,
            vehicle.cg_to_front_axle, vehicle.cg_to_rear_axle, vehicle.track_front, vehicle.track_rear,
            vehicle.wheel_inertia, options.brake_gain_correction, options.brake_gain_min_decel,
            vehicle.rolling_resistance, vehicle.drag_area_coefficient, options.brake_gain_limits,
            options.brake_gain_time_constant, options.max_slip, self._has_drive_torque, self._has_yaw_rate,
            float(self.pressures_are_master), *self._brake_gains, options.pressure_lag_compensation,
            options.accel_bias_settle_s, options.speed_correction_rate, options.speed_correction_hold_s,
            vehicle.drag_area_doubt, vehicle.wind_doubt, options.level_road,
            options.accel_offset_tolerance, options.coasting_offset, options.released_wheel_s,
            options.released_min_slip))

    def _compute_sample(self, stale: tuple[str, ...]) -> FrontEndResult:
        t_c, omega, omega_dot, glitch = self._fit_wheels()
        inputs = self._values_at(t_c)
        self._sample_accel = inputs[0]   # (`_attach_slip_spread`)
        if self.core is not None:
            # The rest in one compiled call on this object's state (`_physics_of`, line by line).
            ref, ref_fresh = None, False
            if self._has_ref_speed:
                ref = self._value("vehicle_speed_ref", t_c)
                ref_fresh = ref is not None and self._ref_fresh(t_c)
            return self.core.sample_physics(self, self._physics_constants, PHYSICS_TYPES, t_c, omega, omega_dot,
                                            glitch, inputs, stale, self._matched_lookups, self._wheel_times,
                                            self._torque_weights, ref, ref_fresh, self._torque_omega_dot)
        return self._physics_of(stale, t_c, omega, omega_dot, glitch, inputs)

    def _physics_of(self, stale: tuple[str, ...], t_c: float, omega: list[float], omega_dot: list[float],
                    glitch: bool, inputs: tuple[float | None, ...]) -> FrontEndResult:
        """The float code of `_frontcore.sample_physics`."""
        opts = self.options
        veh = self.vehicle
        accel_long_raw, accel_lat = inputs[0], inputs[1]
        pressures = list(inputs[2:6])
        if accel_long_raw is None or accel_lat is None or None in pressures:
            return FrontEndResult(None, stale, None)
        fault = _out_of_range(accel_long_raw, accel_lat, pressures)
        if fault is not None:
            return FrontEndResult(None, stale, fault)
        drive = self._drive_torques(inputs)

        # What the car's speed does (free rolling's offset off: on a grade, gravity's share too), and
        # what its contact and air forces do (the sensor's own offset off).
        accel_long = accel_long_raw - self._accel_bias_mps2
        accel_contact = accel_long_raw - self._sensor_offset_mps2
        wheel_linear, stuck, braked, dead = self._wheel_states(t_c, omega, accel_long, pressures)
        braking = any(braked)
        if not braking:
            self._brake_released = False    # (a new stop: the master pressure is the wheels' again)
        driving = self._has_drive_torque and any(abs(d) > MIN_DRIVE_TORQUE_NM for d in drive)

        if self._deceleration_unexplained(t_c, braking or driving, accel_contact, omega_dot, max(wheel_linear)):
            return FrontEndResult(None, stale, "brake pressure implausible")
        speed, from_ref = self._speed_and_offset(t_c, wheel_linear, omega_dot, accel_long, accel_long_raw,
                                                 braking or driving, drive)

        yaw_rate = inputs[-1] if self._has_yaw_rate else None
        if yaw_rate is None or not math.isfinite(yaw_rate):
            yaw_rate = accel_lat / speed if speed > opts.min_speed else 0.0

        loads = veh.normal_forces(accel_contact, accel_lat)   # (on a grade gravity shifts no load)
        forces = self._tyre_forces(t_c, omega_dot, glitch, pressures, accel_long_raw, speed, drive, wheel_linear,
                                   braking)
        mus = [force / load if load > MIN_LOAD_N else 0.0 for force, load in zip(forces, loads)]
        slips = self._slips(speed, yaw_rate, wheel_linear)
        for i in range(4):
            if braked[i] and slips[i] > SETTLE_SLIP:
                self._slipping_time_s = t_c
        usable = self._usable(speed, glitch, slips, self._torqued_by_brakes(t_c, braked, slips), drive, loads,
                              stuck, dead, mus)

        sample = PhysicalSample(
            time_s=t_c,
            speed_mps=speed,
            slip=tuple(slips),  # type: ignore[arg-type]
            mu_used=tuple(mus),  # type: ignore[arg-type]
            normal_force_n=tuple(loads),
            tyre_force_n=tuple(forces),  # type: ignore[arg-type]
            usable=tuple(usable),  # type: ignore[arg-type]
            braking=braking,
            speed_from_reference=from_ref,
        )
        fault = ("wheel speed glitch" if glitch else "wheel speed stuck" if any(stuck)
                 else None if self._brake_model_holds or not braking or speed < opts.min_speed
                 else "brake pressure disagrees with deceleration")
        return FrontEndResult(sample, stale, fault, tuple(i for i in range(4) if dead[i]))

    def _drive_torques(self, inputs: tuple[float | None, ...]) -> list[float]:
        """Each wheel's drive torque at the sample (0 where not mapped or not a number)."""
        drive = [0.0, 0.0, 0.0, 0.0]
        if self._has_drive_torque:
            for i in range(4):
                v = inputs[6 + i]
                drive[i] = v if v is not None and math.isfinite(v) else 0.0
        return drive

    def _wheel_states(self, t_c: float, omega: list[float], accel_long: float,
                      pressures: list[float]) -> tuple[list[float], list[bool], list[bool], list[bool]]:
        """Each wheel's linear speed (a stuck or dead sensor's stood in for by the others), and
        which wheels are stuck, braked and dead."""
        opts = self.options
        veh = self.vehicle
        wheel_linear = [veh.wheel_radius * float(w) for w in omega]
        # (repeated readings are a stuck sensor only while the car's speed changes: its acceleration
        # is the accelerometer's less what free rolling taught, a car at rest on a hill reads gravity)
        stuck = [n >= opts.stuck_frames for n in self._repeats] if abs(accel_long) > 0.5 else [False] * 4
        braked = [p - veh.brake_pushout_pressure > opts.min_brake_pressure for p in pressures]
        dead = self._dead_wheels(t_c, wheel_linear, braked)
        wheel_linear = stood_in_for([st or d for st, d in zip(stuck, dead)], wheel_linear)
        return wheel_linear, stuck, braked, dead

    def _tyre_forces(self, t_c: float, omega_dot: list[float], glitch: bool, pressures: list[float],
                     accel_long_raw: float, speed: float, drive: list[float], wheel_linear: list[float],
                     braking: bool) -> list[float]:
        """Each tyre's longitudinal force from the wheel equation, J·ω̇ + G·T_brake − T_drive over
        the radius, with the brake gain learnt from the body (and updated by this sample) and the
        pressures advanced by their sensors' lag."""
        veh = self.vehicle
        brake_torques, accel_long_matched = self._matched_inputs(pressures, accel_long_raw)
        brake_rates = self._brake_torque_rates(t_c, brake_torques)
        # (the rates at the sample's instant where the pressure series give them)
        brake_rates = [r if m is None else m for r, m in zip(brake_rates, self._matched_brake_rates())]
        torque_omega_dot = omega_dot if self._torque_omega_dot is None else self._torque_omega_dot
        inertia_torques = [veh.wheel_inertia * float(a) for a in torque_omega_dot]
        if self.options.brake_gain_correction and not glitch:
            # The body's deceleration through the same filter as the torques it is compared with.
            self._update_brake_gain(accel_long_matched - self._sensor_offset_mps2,
                                    speed, inertia_torques, brake_torques, drive, wheel_linear, brake_rates, braking)
        gain = self._brake_gain_factor
        # A sensor lagging by τ reads p(t) − τ·ṗ(t): the brakes' torque is the reading advanced by τ.
        lag = self.pressure_lag_s
        brake_torques = [max(b + lag * r, 0.0) for b, r in zip(brake_torques, brake_rates)]   # (NaN stays NaN)
        radius = veh.wheel_radius
        return [(inertia_torques[i] + gain * brake_torques[i] - drive[i]) / radius for i in range(4)]

    def _torqued_by_brakes(self, t_c: float, braked: list[bool], slips: list[float]) -> list[bool]:
        """Which wheels the brakes torque now or turned into the slip they spin back up from: braked,
        or released within `released_wheel_s` and still slipping `released_min_slip` or more (not
        across a clock stepped back: the braking then is not known to be this stop's)."""
        opts = self.options
        last = self._braked_time_s
        torqued = []
        for i in range(4):
            if braked[i]:
                last[i] = t_c
            since = t_c - last[i]
            torqued.append(braked[i] or (0.0 <= since <= opts.released_wheel_s and slips[i] >= opts.released_min_slip))
        return torqued

    def _usable(self, speed: float, glitch: bool, slips: list[float], torqued: list[bool], drive: list[float],
                loads: list[float], stuck: list[bool], dead: list[bool], mus: list[float]) -> list[bool]:
        """Which wheels' samples the estimator may fit: a sound sample (speed, no glitch, the brake
        model holding) of a torqued wheel (`_torqued_by_brakes`, or driven), short of lock, loaded,
        its sensor working."""
        opts = self.options
        good = (speed >= opts.min_speed and not glitch and self._brake_model_holds and not self._brake_released)
        return [
            good
            and abs(slips[i]) <= opts.max_slip
            and (torqued[i] or (self._has_drive_torque and abs(drive[i]) > MIN_DRIVE_TORQUE_NM))
            and loads[i] > MIN_LOAD_N
            and not stuck[i]
            and not dead[i]
            and math.isfinite(mus[i])
            for i in range(4)
        ]

    def _speed_and_offset(self, t_c: float, wheel_linear: list[float], omega_dot: list[float],
                          accel_long: float, accel_long_raw: float, torqued: bool,
                          drive: list[float]) -> tuple[float, bool]:
        """The ground speed (and whether from the car's reference) after this sample; while the
        wheels roll free, settled since their last braked slip, the accelerometer's offset learnt."""
        # No pressure is not yet free rolling: wheels released by the ABS (pressure below the
        # threshold on a low-μ road) may still be spinning back up from deep slip, all together.
        # Only wheels that agree with each other (within what a curve explains) and accelerate
        # with the body read the ground speed.
        radius = self.vehicle.wheel_radius
        fastest = max(wheel_linear)
        free_rolling = (not torqued
                        and fastest - min(wheel_linear) <= FREE_ROLLING_SPREAD * fastest + 0.3
                        and all(abs(radius * a - accel_long) < FREE_ROLLING_ACCEL_MPS2 for a in omega_dot))
        self._free_rolling_sample = free_rolling
        speed, from_ref = self._update_speed(t_c, wheel_linear, accel_long, not free_rolling)
        if free_rolling and t_c - self._slipping_time_s >= self.options.accel_bias_settle_s:
            self._learn_accel_bias(t_c, omega_dot, accel_long_raw)
            self._learn_rolling_offset(speed, omega_dot, accel_long_raw, drive)
        return speed, from_ref

    def _slips(self, speed: float, yaw_rate: float, wheel_linear: list[float]) -> list[float]:
        """Each wheel's slip against its own ground speed: in a turn the outer wheels travel faster."""
        slips = []
        for i, (side, half_track) in enumerate(self._wheel_offsets):
            ground = speed + side * yaw_rate * half_track
            denom = max(ground, wheel_linear[i])
            slips.append((ground - wheel_linear[i]) / denom if denom > 0.1 else 0.0)
        return slips

    def _mark_lateral_mu(self, sample: PhysicalSample) -> None:
        """`sample.lateral_mu`: the lateral force per unit load the tyres carry (`_lateral_mu`)."""
        sample.lateral_mu = _lateral_mu(self._value("accel_lat", sample.time_s))

    def _mark_body_mu(self, sample: PhysicalSample) -> None:
        """`sample.body_mu`: the car's total longitudinal tyre force over its weight, from the
        accelerometer (offset removed) less drag and rolling resistance (at the most the air's
        doubt allows), where the wheels' own sum agrees (the smaller of the two).

        An accelerometer reads the contact and air forces over the mass, not gravity, so this
        holds on a slope, and the mass cancels (a loaded car reads the same). No road gives less
        grip than the tyres just used: the load-weighted μ_max is at least this.
        """
        if not sample.braking:
            return
        accel = self._value("accel_long", sample.time_s)
        if accel is None or not math.isfinite(accel):
            return
        veh = self.vehicle
        v = sample.speed_mps
        sample.wheel_torques_unknown = self.wheel_torques_unknown
        sample.body_force_mu = (-(accel - self._sensor_offset_mps2) - veh.resistance_force(v) / veh.mass) / GRAVITY_MPS2
        sample.body_force_doubt = (veh.resistance_doubt_n(v) / veh.mass + self._sensor_offset_doubt_mps2) / GRAVITY_MPS2
        # (the most resistance the car may meet: what it leaves is grip the tyres surely used)
        resistance = (veh.resistance_force(v) + veh.resistance_doubt_n(v)) / veh.mass
        body = (-(accel - self._sensor_offset_mps2) - resistance - self._sensor_offset_doubt_mps2) / GRAVITY_MPS2
        # The same total from the wheels (brake torques, inertia): a bound must not rest on one
        # sensor alone. Beyond what brake-gain error explains, one of them is wrong: no bound.
        load = sum(sample.normal_force_n)
        wheels = sum(sample.tyre_force_n) / load if load > 0.0 else math.nan
        if abs(body - wheels) <= BODY_WHEELS_TOLERANCE * abs(wheels) + 0.05:
            sample.body_mu = min(body, wheels)


def _lateral_mu(accel_lat: float | None) -> float:
    """`PhysicalSample.lateral_mu` of a lateral acceleration: its size over g, with the offset an
    accelerometer may read taken off in quadrature (as the estimator adds the result to the
    longitudinal grip), so that driving straight reads 0."""
    if accel_lat is None or not math.isfinite(accel_lat):
        return 0.0
    return math.sqrt(max(accel_lat * accel_lat - LATERAL_OFFSET_MPS2 ** 2, 0.0)) / GRAVITY_MPS2


def _out_of_range(accel_long_raw: float, accel_lat: float, pressures: list[float]) -> str | None:
    """The fault of inputs beyond what a working sensor reads, or None."""
    if abs(accel_long_raw) > MAX_ABS_ACCEL_MPS2 or abs(accel_lat) > MAX_ABS_ACCEL_MPS2:
        return "acceleration out of range"
    if any(not (-1.0 <= p <= MAX_PRESSURE_BAR) for p in pressures):
        return "brake pressure out of range"
    return None
