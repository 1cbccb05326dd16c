"""Vehicle parameters and the rigid-body relations of model.md (load transfer, wheel torque balance)."""
from __future__ import annotations

from dataclasses import dataclass

GRAVITY_MPS2 = 9.80665


@dataclass(frozen=True, slots=True)
class VehicleParams:
    """Vehicle description; field names are the config keys under `vehicle:`. SI units throughout.

    mass [kg], cg_to_front_axle / cg_to_rear_axle / cg_height / track_front / track_rear /
    wheel_radius [m], wheel_inertia [kg m^2], brake_gain_front / brake_gain_rear [N m/bar],
    brake_pushout_pressure [bar], drag_area_coefficient = 0.5 rho Cd A [kg/m],
    rolling_resistance = B_v [N s/m]; drag_area_doubt [kg/m] and wind_doubt [m/s], how far the
    air drag may be off (`resistance_doubt_n`).
    """

    mass: float = 1500.0
    cg_to_front_axle: float = 1.2
    cg_to_rear_axle: float = 1.5
    cg_height: float = 0.55
    track_front: float = 1.55
    track_rear: float = 1.55
    wheel_radius: float = 0.31
    wheel_inertia: float = 1.2
    brake_gain_front: float = 25.0
    brake_gain_rear: float = 12.0
    brake_pushout_pressure: float = 0.0
    drag_area_coefficient: float = 0.4
    rolling_resistance: float = 0.0
    drag_area_doubt: float = 0.0
    # A wind along the road that the estimate allows for [m/s], either way. 0 by default: at 5 m/s
    # the drag a stop at 25 m/s meets may be 110 N more than configured, a fifth of the tyres'
    # force on μ 0.034 ice, and no brake gain learnt there would be trusted (see README).
    wind_doubt: float = 0.0

    @property
    def wheelbase(self) -> float:
        return self.cg_to_front_axle + self.cg_to_rear_axle

    def normal_forces(self, accel_long_mps2: float, accel_lat_mps2: float) -> tuple[float, float, float, float]:
        """Static load transfer (model.md, physics signs): forward-positive a_x, left-positive a_y."""
        g = GRAVITY_MPS2
        h = self.cg_height
        front_axle = self.mass * (g * self.cg_to_rear_axle - h * accel_long_mps2) / self.wheelbase
        rear_axle = self.mass * (g * self.cg_to_front_axle + h * accel_long_mps2) / self.wheelbase
        lat_f = h * accel_lat_mps2 / (self.track_front * g)
        lat_r = h * accel_lat_mps2 / (self.track_rear * g)
        return (
            front_axle * (0.5 - lat_f),
            front_axle * (0.5 + lat_f),
            rear_axle * (0.5 - lat_r),
            rear_axle * (0.5 + lat_r),
        )

    def resistance_force(self, speed_mps: float) -> float:
        """Rolling resistance and aerodynamic drag on the car at `speed_mps` [N]."""
        return self.rolling_resistance * speed_mps + self.drag_area_coefficient * speed_mps * speed_mps

    def resistance_doubt_n(self, speed_mps: float, wind_mps: float | None = None) -> float:
        """How much more resistance than `resistance_force` the car may meet at `speed_mps` [N]:
        the drag of a car whose ½ρC_dA is larger by `drag_area_doubt`, in a head wind of
        `wind_doubt` (or `wind_mps`). The body equation cannot tell that force from the tyres'
        (both slow the car), so it is what the brake gain and the car's measured grip may be off by."""
        wind = self.wind_doubt if wind_mps is None else wind_mps
        air = speed_mps + wind
        # ((D + ΔD)·air² − D·v², as its two parts: no rounding leaves a doubt where both are 0)
        return self.drag_area_doubt * air * air + self.drag_area_coefficient * wind * (speed_mps + air)

    def brake_gain(self, wheel_index: int) -> float:
        return self.brake_gain_front if wheel_index < 2 else self.brake_gain_rear

    def brake_torque_nm(self, wheel_index: int, pressure_bar: float) -> float:
        return self.brake_gain(wheel_index) * max(0.0, pressure_bar - self.brake_pushout_pressure)
