"""What each canonical input can be and do (`SignalLimit`, `signal_limits`), and a frame's values
checked against that (`ValueChecks`, a part of `plausibility.InputGate`; its state is the gate's):
in range, within the rate limits since the last accepted frame, and not the sender's "no value"
marker."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Mapping

from .vehicle import GRAVITY_MPS2, VehicleParams

if TYPE_CHECKING:
    from .plausibility import _Track

# The most brake pressure a hydraulic unit produces [bar], and its fastest rise or fall [bar/s]
# (an ABS dump valve ~3000 bar/s): the wheel's torque bound and the pressures' rate limit.
MAX_BRAKE_PRESSURE_BAR = 250.0
MAX_PRESSURE_RATE_BAR_S = 6000.0
# No tyre on any road transmits more than this share of its load.
MAX_POSSIBLE_MU = 1.5
MAX_DRIVE_TORQUE_NM = 2000.0        # a drive line's torque at one wheel (traction spinning it up)
# Body jerk [m/s³]: M Δa = Δ ΣF_x, and an ABS dumping every wheel takes the tyre forces from the
# peak (up to 1.5 g) to a fraction of it within ~20 ms: ~750 m/s³ (a brake onset alone is 50-100).
MAX_JERK_MPS3 = 750.0


@dataclass(frozen=True, slots=True)
class SignalLimit:
    """What one canonical input can be and do."""

    low: float
    high: float
    rate: float       # largest physical |dx/dt| [unit/s]
    noise: float      # allowance per frame on top (sensor noise, quantisation, jitter)
    spike: float = math.inf   # a value off both (agreeing) neighbours by more than this is a spike
    rise: float = math.nan    # largest dx/dt upwards when it differs from `rate` [unit/s]
    active: float = math.inf  # |value| above which a frame of zeros after it is an invalid marker


def wheel_accel_bound(vehicle: VehicleParams, wheel: int, up: bool = False) -> float:
    """|dω/dt| a wheel can reach [rad/s²]: J ω̇ = −T_b + R F_x + T_e with the largest force any
    road gives at the largest load the car can put on the wheel (1.5 g of braking, 1 g of
    cornering) and, slowing down, the largest brake torque the hydraulics give on top; speeding
    up, a brake only holds it back, a drive line adds at most `MAX_DRIVE_TORQUE_NM`."""
    loads = [vehicle.normal_forces(ax * GRAVITY_MPS2, ay * GRAVITY_MPS2)[wheel]
             for ax in (-1.5, 1.5) for ay in (-1.0, 1.0)]
    road = MAX_POSSIBLE_MU * max(loads) * vehicle.wheel_radius
    torque = road + (MAX_DRIVE_TORQUE_NM if up else vehicle.brake_gain(wheel) * MAX_BRAKE_PRESSURE_BAR)
    return torque / max(vehicle.wheel_inertia, 1e-3)


def signal_limits(vehicle: VehicleParams) -> dict[str, SignalLimit]:
    """The limits of every canonical input that has them (flags have none)."""
    limits = {
        "accel_long": SignalLimit(-30.0, 30.0, MAX_JERK_MPS3, 1.0, 2.0, active=0.5),
        "accel_lat": SignalLimit(-30.0, 30.0, MAX_JERK_MPS3, 1.0, 2.0),
        # (a car's yaw rate: at most ~1 rad/s, changing at most ~10 rad/s² in a spin)
        "yaw_rate": SignalLimit(-3.0, 3.0, 10.0, 0.05, 0.1),
        "vehicle_speed_ref": SignalLimit(0.0, 120.0, 2.0 * GRAVITY_MPS2, 0.5, 1.0),
        "brake_pressure_master": SignalLimit(-1.0, 350.0, MAX_PRESSURE_RATE_BAR_S, 3.0, 15.0),
    }
    for i, w in enumerate(("fl", "fr", "rl", "rr")):
        limits[f"wheel_speed_{w}"] = SignalLimit(0.0, 400.0, wheel_accel_bound(vehicle, i), 1.0,
                                                 rise=wheel_accel_bound(vehicle, i, up=True), active=1.0)
        limits[f"brake_pressure_{w}"] = SignalLimit(-1.0, 350.0, MAX_PRESSURE_RATE_BAR_S, 3.0, 15.0, active=5.0)
        # (a motor's torque steps within a few ms: the range, wild jumps, and one frame out and
        # back, which no drive line does within a cycle)
        limits[f"drive_torque_{w}"] = SignalLimit(-5000.0, 5000.0, 200_000.0, 200.0, 300.0)
    return limits


def is_marker(values: Mapping[str, float], previous: Mapping[str, float], limits: Mapping[str, SignalLimit]) -> bool:
    """A frame of zeros (all bits 0, or all 1 in a signed signal: one step below zero) right after
    one that showed a moving, braking or decelerating car: the sender's "no value" marker. No live
    sensor reads exactly zero on every channel at once (four wheel speeds, four pressures, or
    the accelerometer's three axes), and no car stops or releases its brakes within one frame."""
    checked = False
    for name, x in values.items():    # (every frame passes here: out at its first live value)
        if name in limits:
            if abs(x) > 0.002:
                return False
            checked = True
    return checked and any(abs(previous.get(name, 0.0)) > limits[name].active for name in values if name in limits)


class ValueChecks:
    """A frame's values against the limits (`limits`, `_bounds`) and another frame's."""

    def _values(self, time_s: float, track: _Track, values: Mapping[str, float]) -> str | None:
        bounds = self._bounds
        previous = track.values
        dt = time_s - track.time_s
        live = False    # a value seen so far that is not zero: then the frame is no marker
        kind = None
        for name, x in values.items():
            b = bounds.get(name)
            if b is None:
                continue
            if x > 0.002 or x < -0.002:
                live = True
            low, high, rate, rise, noise = b
            if not low <= x <= high:      # (NaN: out)
                kind = "out of range"
                break
            last = previous.get(name)
            if last is not None and abs(x - last) > (rise if x > last else rate) * dt + noise:
                kind = "rate"
                break
        # A marker is told first: (only) a frame without a live value can be one.
        if not live and is_marker(values, previous, self.limits):
            return "marker"
        return kind

    def _agrees(self, time_s: float, values: Mapping[str, float], earlier: tuple[float, dict] | None) -> bool:
        """Whether `values` are within the rate limits of an earlier rejected frame's."""
        if earlier is None or not time_s > earlier[0]:
            return False
        dt = time_s - earlier[0]
        for name, x in values.items():
            lim = self.limits.get(name)
            last = earlier[1].get(name)
            if lim is None or last is None:
                continue
            rate = lim.rise if x > last and lim.rise == lim.rise else lim.rate
            if not abs(x - last) <= rate * dt + lim.noise:
                return False
        return True
