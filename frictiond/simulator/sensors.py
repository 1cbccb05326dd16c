"""Sensors and bus timing: the simulated truth seen through noisy, quantised, periodic messages.

Each scheduled message is sent every `period_s` with its own random phase, ±1 ms of timing jitter
and a small chance of being lost. Its values are sampled at the frame's own timestamp (the front
end differentiates wheel speeds on those timestamps), in canonical SI units:

| signal | model |
|---|---|
| `wheel_speed_*` [rad/s] | ω + N(0, 0.02) quantised to 0.01 rad/s (ABS sensor resolution) |
| `accel_long` [m/s², forward +] | dv/dt + constant bias (±0.03…0.08, seeded) + N(0, 0.05) |
| `accel_lat` [m/s², left +] | v²/R_c + bias (±0.02…0.05) + N(0, 0.05) |
| `yaw_rate` [rad/s, left +] | v/R_c + bias (±0.001) + N(0, 0.002) |
| `brake_pressure_*` [bar] | p + N(0, 0.3), not below 0 |
| `vehicle_speed_ref` [m/s] | v + N(0, 0.03) (ground-speed sensor) |
| `drive_torque_*` [N·m] | 0 (the drive line is open while braking) |

Every noise level is multiplied by the scenario's `noise_scale`.
"""
from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

WHEEL_SUFFIXES = ("fl", "fr", "rl", "rr")
WHEEL_SPEED = tuple(f"wheel_speed_{w}" for w in WHEEL_SUFFIXES)
BRAKE_PRESSURE = tuple(f"brake_pressure_{w}" for w in WHEEL_SUFFIXES)
DRIVE_TORQUE = tuple(f"drive_torque_{w}" for w in WHEEL_SUFFIXES)
SIGNALS: frozenset[str] = frozenset(
    WHEEL_SPEED + BRAKE_PRESSURE + DRIVE_TORQUE + ("accel_long", "accel_lat", "yaw_rate", "vehicle_speed_ref")
)
REFERENCE_SPEED_SIGNALS = frozenset({"vehicle_speed_ref"})

JITTER_S = 0.001
WHEEL_SPEED_RESOLUTION = 0.01
WHEEL_SPEED_NOISE = 0.02
ACCEL_NOISE = 0.05
YAW_RATE_NOISE = 0.002
PRESSURE_NOISE = 0.3
REFERENCE_SPEED_NOISE = 0.03


class MessageSchedule(NamedTuple):
    """One periodic input message: its name, cycle time and the canonical signals it carries."""

    name: str
    period_s: float
    signals: tuple[str, ...]


class SensorEvent(NamedTuple):
    """One frame's worth of canonical SI values, stamped with its reception time."""

    time_s: float
    message: str
    values: dict[str, float]


class SensorModel:
    """Per-run sensor imperfections (biases drawn once) and the sampling of the truth trace."""

    def __init__(self, trace, rng: np.random.Generator, noise_scale: float = 1.0) -> None:
        self.trace = trace
        self.rng = rng
        self.scale = float(noise_scale)
        sign = rng.choice([-1.0, 1.0], size=3)
        self.accel_long_bias = float(sign[0] * rng.uniform(0.03, 0.08))
        self.accel_lat_bias = float(sign[1] * rng.uniform(0.02, 0.05))
        self.yaw_rate_bias = float(sign[2] * rng.uniform(0.0, 0.001))

    def sample(self, signal: str, times: np.ndarray) -> np.ndarray:
        tr = self.trace
        rng = self.rng
        n = len(times)
        s = self.scale
        if signal in WHEEL_SPEED:
            i = WHEEL_SPEED.index(signal)
            x = np.interp(times, tr.t, tr.omega[:, i]) + rng.normal(0.0, WHEEL_SPEED_NOISE * s, n)
            return np.maximum(np.round(x / WHEEL_SPEED_RESOLUTION) * WHEEL_SPEED_RESOLUTION, 0.0)
        if signal in BRAKE_PRESSURE:
            i = BRAKE_PRESSURE.index(signal)
            x = np.interp(times, tr.t, tr.pressure[:, i]) + rng.normal(0.0, PRESSURE_NOISE * s, n)
            return np.maximum(x, 0.0)
        if signal in DRIVE_TORQUE:
            return np.zeros(n)
        if signal == "accel_long":
            return np.interp(times, tr.t, tr.ax) + self.accel_long_bias + rng.normal(0.0, ACCEL_NOISE * s, n)
        if signal == "accel_lat":
            return np.interp(times, tr.t, tr.ay) + self.accel_lat_bias + rng.normal(0.0, ACCEL_NOISE * s, n)
        if signal == "yaw_rate":
            return np.interp(times, tr.t, tr.yaw) + self.yaw_rate_bias + rng.normal(0.0, YAW_RATE_NOISE * s, n)
        if signal == "vehicle_speed_ref":
            x = np.interp(times, tr.t, tr.v) + rng.normal(0.0, REFERENCE_SPEED_NOISE * s, n)
            return np.maximum(x, 0.0)
        raise ValueError(f"unknown signal {signal!r}")


def check_schedules(schedules: Sequence[MessageSchedule]) -> None:
    names = set()
    for m in schedules:
        if m.name in names:
            raise ValueError(f"message {m.name!r} scheduled twice")
        names.add(m.name)
        if not (m.period_s > 0.0):
            raise ValueError(f"message {m.name!r}: period must be positive, got {m.period_s!r}")
        unknown = [s for s in m.signals if s not in SIGNALS]
        if unknown:
            raise ValueError(f"message {m.name!r}: unknown signal(s) {', '.join(unknown)}; "
                             f"the simulator knows {', '.join(sorted(SIGNALS))}")


def generate_events(
    schedules: Sequence[MessageSchedule],
    sensors: SensorModel,
    rng: np.random.Generator,
    end_s: float,
    *,
    drop_rate: float,
    reference_speed: bool,
) -> list[SensorEvent]:
    """Periodic frames of every scheduled message over [0, end_s], merged in time order."""
    check_schedules(schedules)
    per_message: list[tuple[np.ndarray, str, list[dict[str, float]]]] = []
    for m in schedules:
        signals = tuple(m.signals)
        if not reference_speed:
            if set(signals) <= REFERENCE_SPEED_SIGNALS:
                continue
            signals = tuple(s for s in signals if s not in REFERENCE_SPEED_SIGNALS)
        if not signals:
            continue
        period = float(m.period_s)
        phase = rng.uniform(0.0, period)
        nominal = phase + period * np.arange(int(np.floor((end_s - phase) / period)) + 1)
        times = nominal + rng.uniform(-JITTER_S, JITTER_S, len(nominal))
        keep = (times >= 0.0) & (times <= end_s) & (rng.random(len(nominal)) >= drop_rate)
        times = times[keep]
        columns = {s: sensors.sample(s, times) for s in signals}
        values = [dict(zip(signals, vals)) for vals in zip(*(columns[s].tolist() for s in signals))]
        per_message.append((times, m.name, values))
    if not per_message:
        return []
    all_t = np.concatenate([t for t, _, _ in per_message])
    msg_idx = np.concatenate([np.full(len(t), k) for k, (t, _, _) in enumerate(per_message)])
    row_idx = np.concatenate([np.arange(len(t)) for t, _, _ in per_message])
    order = np.lexsort((msg_idx, all_t))
    times_l = all_t.tolist()
    return [
        SensorEvent(times_l[j], per_message[msg_idx[j]][1], per_message[msg_idx[j]][2][row_idx[j]])
        for j in order.tolist()
    ]
