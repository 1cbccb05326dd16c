"""The campaign's truth car: what the car really is, against what its frictiond config says.

Rigid body on four wheels (model.md): static load transfer, but from a pitch-lagged
longitudinal acceleration (the body takes `pitch_lag_s` to settle on its springs, which the
estimator's static transfer does not know), brake torque k_b · max(0, p − p_0) with the *true*
gains (±20 % off the configured ones: pads in service), drag and rolling resistance.
Written here again rather than imported from frictiond.vehicle: the truth must not share code
with what it referees.
"""
from __future__ import annotations

from dataclasses import dataclass

GRAVITY_MPS2 = 9.80665


@dataclass(frozen=True, slots=True)
class CarSpec:
    """SI units. `*_gain_*`: N·m/bar. `config_*`: what the frictiond config is told."""

    mass_kg: float
    cg_to_front_m: float
    cg_to_rear_m: float
    cg_height_m: float
    track_m: float
    wheel_radius_m: float
    wheel_inertia_kgm2: float
    brake_gain_front: float          # true
    brake_gain_rear: float           # true
    config_brake_gain_front: float
    config_brake_gain_rear: float
    payload_kg: float                # on top of the configured mass, at the CG
    pushout_bar: float
    drag_area_coefficient: float     # ½ ρ C_d A [kg/m]
    pitch_lag_s: float
    # Each wheel's true rolling radius over the configured one (FL, FR, RL, RR): worn or soft
    # tyres (the stress run `Stress.tyre_radii`; drawn: all 1).
    radius_factors: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)

    @property
    def wheelbase_m(self) -> float:
        return self.cg_to_front_m + self.cg_to_rear_m

    @property
    def true_mass_kg(self) -> float:
        return self.mass_kg + self.payload_kg

    def radii(self) -> list[float]:
        """Each wheel's true rolling radius [m] (FL, FR, RL, RR)."""
        return [self.wheel_radius_m * f for f in self.radius_factors]

    def gains(self) -> tuple[float, float, float, float]:
        kf, kr = self.brake_gain_front, self.brake_gain_rear
        return (kf, kf, kr, kr)

    def config_vehicle(self) -> dict[str, float]:
        """The `vehicle:` section of the frictiond config (the car as configured)."""
        return {
            "mass": round(self.mass_kg, 1),
            "cg_to_front_axle": round(self.cg_to_front_m, 4),
            "cg_to_rear_axle": round(self.cg_to_rear_m, 4),
            "cg_height": round(self.cg_height_m, 4),
            "track_front": round(self.track_m, 4),
            "track_rear": round(self.track_m, 4),
            "wheel_radius": round(self.wheel_radius_m, 4),
            "wheel_inertia": round(self.wheel_inertia_kgm2, 4),
            "brake_gain_front": round(self.config_brake_gain_front, 3),
            "brake_gain_rear": round(self.config_brake_gain_rear, 3),
            "brake_pushout_pressure": round(self.pushout_bar, 3),
            "drag_area_coefficient": round(self.drag_area_coefficient, 4),
            "rolling_resistance": 0.0,
        }


def normal_loads(car: CarSpec, accel_long_mps2: float, accel_lat_mps2: float,
                 gravity_normal_mps2: float = GRAVITY_MPS2) -> list[float]:
    """F_N per wheel (FL, FR, RL, RR) [N]: forward-positive a_x, left-positive a_y (model.md).
    The accelerations are the contact forces' (what an accelerometer reads): on a grade the
    gravity along the road shifts no load, its normal share `gravity_normal_mps2` carries it."""
    m, g, h, l = car.true_mass_kg, gravity_normal_mps2, car.cg_height_m, car.wheelbase_m
    front = m * (g * car.cg_to_rear_m - h * accel_long_mps2) / l
    rear = m * (g * car.cg_to_front_m + h * accel_long_mps2) / l
    lat = h * accel_lat_mps2 / (car.track_m * g)
    # A wheel never leaves the road in the campaign's ranges; the floor keeps it so.
    left, right = max(0.5 - lat, 0.05), max(0.5 + lat, 0.05)
    return [max(front, 0.1 * m * g) * left, max(front, 0.1 * m * g) * right,
            max(rear, 0.05 * m * g) * left, max(rear, 0.05 * m * g) * right]


def lock_pressure_bar(car: CarSpec, mu: float, front: bool = True) -> float:
    """Pressure that brings one wheel of an axle to `mu` on a car braking at μ g (true gains)."""
    m, g, h, l = car.true_mass_kg, GRAVITY_MPS2, car.cg_height_m, car.wheelbase_m
    if front:
        axle = m * (g * car.cg_to_rear_m + h * mu * g) / l
        gain = car.brake_gain_front
    else:
        axle = m * (g * car.cg_to_front_m - h * mu * g) / l
        gain = car.brake_gain_rear
    return mu * 0.5 * axle * car.wheel_radius_m / gain + car.pushout_bar
