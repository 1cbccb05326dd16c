"""A synthetic braking drive encoded as input frames (used until/unless the simulator is there).

Straight-line braking from `v0`: slip ramps up along a Burckhardt dry-asphalt curve and then
cycles through its peak as an ABS would (±45 % at 4 Hz), so the estimator sees real
excitation; brake pressures follow the wheel equation. Deterministic.
"""
from __future__ import annotations

import math
from typing import Iterator

from frictiond.config import Config
from frictiond.frames import Frame
from frictiond.codec import InputCodec, load_databases
from frictiond.vehicle import GRAVITY_MPS2

C1, C2, C3 = 1.2801, 23.99, 0.52     # Burckhardt, dry asphalt
SPEED_NAMES = ("wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl", "wheel_speed_rr")
PRESSURE_NAMES = ("brake_pressure_fl", "brake_pressure_fr", "brake_pressure_rl", "brake_pressure_rr")


def mu_of(slip: float) -> float:
    return C1 * (1.0 - math.exp(-C2 * slip)) - C3 * slip


def braking_frames(
    config: Config,
    duration_s: float = 4.0,
    start_s: float = 1000.0,
    v0: float = 27.0,
    cruise_s: float = 0.5,
    ramp_s: float = 1.0,
    peak_slip: float = 0.17,
    period_s: float = 0.01,
    skip: frozenset[str] = frozenset(),
) -> Iterator[Frame]:
    """Frames of the required inputs (plus the reference speed) every `period_s`, time-ordered."""
    codec = InputCodec(load_databases(config.can.dbc, strict=config.can.dbc_strict), config.signals,
                       config.vehicle.wheel_radius)
    veh = config.vehicle
    ids = {m.name: m.frame_id for m in codec.input_messages()}
    r = veh.wheel_radius
    v = v0
    steps = int(duration_s / period_s)
    for k in range(steps):
        t = k * period_s
        cycle = 2 * math.pi * 4.0
        if t < cruise_s:
            slip, slip_rate = 0.0, 0.0
        elif t < cruise_s + ramp_s:
            slip, slip_rate = peak_slip * (t - cruise_s) / ramp_s, peak_slip / ramp_s
        else:
            phase = cycle * (t - cruise_s - ramp_s)
            slip = peak_slip * (1.0 + 0.45 * math.sin(phase))
            slip_rate = peak_slip * 0.45 * cycle * math.cos(phase)
        mu = mu_of(slip) if slip > 0 else 0.0
        decel = GRAVITY_MPS2 * mu
        loads = veh.normal_forces(-decel, 0.0)
        omega = v * (1.0 - slip) / r
        omega_dot = (-decel * (1.0 - slip) - v * slip_rate) / r
        pressures = []
        for i in range(4):
            torque = mu * loads[i] * r - veh.wheel_inertia * omega_dot
            gain = veh.brake_gain(i)
            pressures.append(max(0.0, torque / gain + veh.brake_pushout_pressure) if mu > 0 else 0.0)
        values = {
            "WHEEL_SPEEDS": dict(zip(SPEED_NAMES, (omega,) * 4)),
            "ACCELERATIONS": {"accel_long": -decel, "accel_lat": 0.0, "yaw_rate": 0.0},
            "BRAKE_PRESSURES": dict(zip(PRESSURE_NAMES, pressures)),
            "VEHICLE_SPEED_REF": {"vehicle_speed_ref": v},
        }
        for j, (name, vals) in enumerate(values.items()):
            if name in skip or name not in ids:
                continue
            t_frame = start_s + t + 0.002 * j
            for payload in codec.encode_input(name, {k2: v2 for k2, v2 in vals.items() if k2 in _mapped(codec, name)}):
                yield Frame(round(t_frame, 6), ids[name], payload)
        v = max(0.5, v - decel * period_s)


def _mapped(codec, message: str) -> set[str]:
    return {r.name for r in codec.resolved if r.message == message}
