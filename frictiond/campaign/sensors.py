"""What the campaign car's sensors put on the bus: rates, resolution, noise, lag, loss.

`SensorSpec` is drawn per stop (ranges in `draw.py`); `bus_dbc_text` writes the DBC that
describes this car's input messages (wheel speeds in km/h at the drawn resolution, cycle times
at the drawn rates, per-wheel or master-cylinder pressure, optional reference speed and ABS
flags); `sensor_events` samples the 1 kHz truth trace at each frame's own time.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from scipy.signal import lfilter

WHEELS = ("fl", "fr", "rl", "rr")
WHEEL_MESSAGE = "WHEEL_SPEEDS"
REAR_WHEEL_MESSAGE = "WHEEL_SPEEDS_REAR"
ACCEL_MESSAGE = "ACCELERATIONS"
PRESSURE_MESSAGE = "BRAKE_PRESSURES"
MASTER_MESSAGE = "BRAKE_MASTER"
REFERENCE_MESSAGE = "VEHICLE_SPEED_REF"
ABS_MESSAGE = "ABS_STATUS"


@dataclass(frozen=True, slots=True)
class SensorSpec:
    """Sensor and bus imperfections of one car (units in the names)."""

    wheel_hz: int                   # 50, 83 or 100
    accel_hz: int
    pressure_hz: int
    wheel_resolution_kmh: float     # DBC factor of the wheel speeds
    wheel_noise_kmh: float          # σ of white noise before quantisation
    jitter_s: float                 # ± uniform reception jitter
    drop_rate: float                # share of frames lost, each message independently
    accel_offset_mps2: float
    accel_lat_offset_mps2: float
    accel_noise_mps2: float
    pressure_lag_s: float           # first-order lag of the pressure sensor
    pressure_offset_bar: float
    pressure_noise_bar: float
    master_only: bool               # only the master-cylinder pressure is sent
    reference_speed: bool           # a ground-speed sensor sends VEHICLE_SPEED_REF
    abs_flags: str                  # "none", "global" or "wheel"
    # "one": the four wheel speeds in one message; "axles": the rear ones in a message of their own
    # (big-endian, own phase, jitter and losses), as cars that send front and rear apart do
    wheel_messages: str = "one"
    # whether the DBC gives its messages' cycle times (GenMsgCycleTime); without, frictiond
    # measures them from the first frames
    cycle_times_in_dbc: bool = True
    # how long each wheel speed is averaged over before the frame that sends it (0: its value at
    # the frame's instant); an ECU that counts a toothed ring's edges over its frame period sends
    # the mean speed of that period, half a period late (the stress run `Stress.averaged_wheel_speeds`)
    wheel_average_s: float = 0.0


class BusEvent(NamedTuple):
    """One frame's worth of canonical SI values (the codec's input names) at its reception time."""

    time_s: float
    message: str
    values: dict[str, float]


def _cycle_ms(hz: int) -> int:
    return int(round(1000.0 / hz))


def bus_dbc_text(spec: SensorSpec) -> str:
    """The input DBC of this car (inputs only; frictiond's outputs come from its own DBC)."""
    res = spec.wheel_resolution_kmh
    lines = ['VERSION "frictiond campaign"', "", "NS_ :", "\tBA_", "\tBA_DEF_", "\tBA_DEF_DEF_", "\tCM_", "",
             "BS_:", "", "BU_: VEHICLE FRICTIOND", "", ""]
    in_trigger = WHEELS if spec.wheel_messages == "one" else WHEELS[:2]
    msgs: list[tuple[int, str, int, list[str]]] = [
        (0xB0, WHEEL_MESSAGE, spec.wheel_hz,
         [f" SG_ WheelSpeed_{w.upper()} : {16 * k}|16@1+ ({res!r},0) [0|{res * 65535:.4f}] \"km/h\" FRICTIOND"
          for k, w in enumerate(in_trigger)]),
        (0xC0, ACCEL_MESSAGE, spec.accel_hz,
         [' SG_ AccelLong : 0|16@1- (0.001,0) [-32.768|32.767] "m/s^2" FRICTIOND',
          ' SG_ AccelLat : 16|16@1- (0.001,0) [-32.768|32.767] "m/s^2" FRICTIOND',
          ' SG_ YawRate : 32|16@1- (0.0001,0) [-3.2768|3.2767] "rad/s" FRICTIOND']),
    ]
    if spec.wheel_messages == "axles":
        msgs.append((0xB1, REAR_WHEEL_MESSAGE, spec.wheel_hz,
                     [f" SG_ WheelSpeed_{w.upper()} : {8 * k + 7}|16@0+ ({res!r},0) [0|{res * 65535:.4f}] \"km/h\" "
                      "FRICTIOND" for k, w in ((0, "rl"), (2, "rr"))]))
    if spec.master_only:
        msgs.append((0xD4, MASTER_MESSAGE, spec.pressure_hz,
                     [' SG_ MasterCylPressure : 0|16@1+ (0.01,0) [0|655.35] "bar" FRICTIOND']))
    else:
        msgs.append((0xD0, PRESSURE_MESSAGE, spec.pressure_hz,
                     [f' SG_ BrakePressure_{w.upper()} : {16 * k}|16@1+ (0.01,0) [0|655.35] "bar" FRICTIOND'
                      for k, w in enumerate(WHEELS)]))
    if spec.reference_speed:
        msgs.append((0xE0, REFERENCE_MESSAGE, 100,
                     [' SG_ VehicleSpeedRef : 0|16@1+ (0.01,0) [0|655.35] "m/s" FRICTIOND']))
    if spec.abs_flags != "none":
        msgs.append((0xE8, ABS_MESSAGE, spec.wheel_hz,
                     [' SG_ AbsActive : 0|1@1+ (1,0) [0|1] "" FRICTIOND']
                     + [f' SG_ AbsActive_{w.upper()} : {1 + k}|1@1+ (1,0) [0|1] "" FRICTIOND'
                        for k, w in enumerate(WHEELS)]))
    for frame_id, name, _hz, sigs in msgs:
        lines += [f"BO_ {frame_id} {name}: 8 VEHICLE", *sigs, ""]
    lines += ['BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;', 'BA_DEF_DEF_ "GenMsgCycleTime" 0;']
    if spec.cycle_times_in_dbc:
        lines += [f'BA_ "GenMsgCycleTime" BO_ {frame_id} {_cycle_ms(hz)};' for frame_id, _n, hz, _s in msgs]
    return "\n".join(lines) + "\n"


def signal_map(spec: SensorSpec) -> dict[str, dict[str, Any]]:
    """The config's `signals:` section for this car's DBC."""
    m: dict[str, dict[str, Any]] = {
        f"wheel_speed_{w}": {"message": REAR_WHEEL_MESSAGE if spec.wheel_messages == "axles" and w[0] == "r"
                             else WHEEL_MESSAGE, "signal": f"WheelSpeed_{w.upper()}"} for w in WHEELS}
    m["accel_long"] = {"message": ACCEL_MESSAGE, "signal": "AccelLong"}
    m["accel_lat"] = {"message": ACCEL_MESSAGE, "signal": "AccelLat"}
    m["yaw_rate"] = {"message": ACCEL_MESSAGE, "signal": "YawRate"}
    for w in WHEELS:
        m[f"brake_pressure_{w}"] = ({"message": MASTER_MESSAGE, "signal": "MasterCylPressure"} if spec.master_only
                                    else {"message": PRESSURE_MESSAGE, "signal": f"BrakePressure_{w.upper()}"})
    if spec.master_only:
        m["brake_pressure_master"] = {"message": MASTER_MESSAGE, "signal": "MasterCylPressure"}
    if spec.reference_speed:
        m["vehicle_speed_ref"] = {"message": REFERENCE_MESSAGE, "signal": "VehicleSpeedRef"}
    if spec.abs_flags == "global":
        m["abs_active"] = {"message": ABS_MESSAGE, "signal": "AbsActive"}
    elif spec.abs_flags == "wheel":
        for w in WHEELS:
            m[f"abs_active_{w}"] = {"message": ABS_MESSAGE, "signal": f"AbsActive_{w.upper()}"}
    return m


def _frame_times(rng: np.random.Generator, hz: int, end_s: float, spec: SensorSpec) -> np.ndarray:
    period = 1.0 / hz
    phase = rng.uniform(0.0, period)
    nominal = phase + period * np.arange(int((end_s - phase) / period) + 1)
    times = nominal + rng.uniform(-spec.jitter_s, spec.jitter_s, len(nominal))
    keep = (times >= 0.0) & (times <= end_s) & (rng.random(len(nominal)) >= spec.drop_rate)
    return np.sort(times[keep])


def _lagged(x: np.ndarray, lag_s: float, dt_s: float) -> np.ndarray:
    if lag_s <= 0.0:
        return x
    a = dt_s / (lag_s + dt_s)
    return lfilter([a], [1.0, a - 1.0], x, axis=0, zi=(1.0 - a) * x[:1])[0]


def sensor_events(spec: SensorSpec, trace: Any, radius_m: float, rng: np.random.Generator) -> list[BusEvent]:
    """Every input frame of the stop, in time order, sampled from the 1 kHz `trace` (t, omega,
    pressure, master, ax, ay, yaw, v, abs_active). Wheel speeds go out as ground speed in km/h
    over the *configured* radius (what a wheel-speed ECU does), noisy and quantised."""
    t = trace.t
    end_s = float(t[-1])
    dt_s = float(t[1] - t[0])
    per_message: list[tuple[np.ndarray, str, list[dict[str, float]]]] = []

    times = _frame_times(rng, spec.wheel_hz, end_s, spec)
    rad_s = _wheel_speeds(spec, trace, times, radius_m, rng)
    names = [f"wheel_speed_{w}" for w in WHEELS]
    if spec.wheel_messages == "axles":
        # The rear message's own times and noise, from a stream of its own: every other frame of
        # the stop is the one-message car's.
        rear_rng = np.random.default_rng(rng.bit_generator.seed_seq.spawn(1)[0])  # type: ignore[attr-defined]
        rear_times = _frame_times(rear_rng, spec.wheel_hz, end_s, spec)
        rear = _wheel_speeds(spec, trace, rear_times, radius_m, rear_rng)[:, 2:]
        per_message.append((rear_times, REAR_WHEEL_MESSAGE, _rows(names[2:], rear)))
        rad_s, names = rad_s[:, :2], names[:2]
    per_message.append((times, WHEEL_MESSAGE, _rows(names, rad_s)))

    times = _frame_times(rng, spec.accel_hz, end_s, spec)
    n = len(times)
    acc = np.column_stack([
        np.interp(times, t, trace.ax) + spec.accel_offset_mps2 + rng.normal(0.0, spec.accel_noise_mps2, n),
        np.interp(times, t, trace.ay) + spec.accel_lat_offset_mps2 + rng.normal(0.0, spec.accel_noise_mps2, n),
        np.interp(times, t, trace.yaw) + rng.normal(0.0, 0.002, n),
    ])
    per_message.append((times, ACCEL_MESSAGE, _rows(["accel_long", "accel_lat", "yaw_rate"], acc)))

    times = _frame_times(rng, spec.pressure_hz, end_s, spec)
    n = len(times)
    if spec.master_only:
        p = np.interp(times, t, _lagged(trace.master, spec.pressure_lag_s, dt_s))
        p = np.maximum(p + spec.pressure_offset_bar + rng.normal(0.0, spec.pressure_noise_bar, n), 0.0)
        names = [f"brake_pressure_{w}" for w in WHEELS] + ["brake_pressure_master"]
        per_message.append((times, MASTER_MESSAGE, _rows(names, np.repeat(p[:, None], 5, axis=1))))
    else:
        lagged = _lagged(trace.pressure, spec.pressure_lag_s, dt_s)
        p = np.column_stack([np.interp(times, t, lagged[:, i]) for i in range(4)])
        p = np.maximum(p + spec.pressure_offset_bar + rng.normal(0.0, spec.pressure_noise_bar, p.shape), 0.0)
        per_message.append((times, PRESSURE_MESSAGE, _rows([f"brake_pressure_{w}" for w in WHEELS], p)))

    if spec.reference_speed:
        times = _frame_times(rng, 100, end_s, spec)
        v = np.maximum(np.interp(times, t, trace.v) + rng.normal(0.0, 0.03, len(times)), 0.0)
        per_message.append((times, REFERENCE_MESSAGE, _rows(["vehicle_speed_ref"], v[:, None])))
    if spec.abs_flags != "none":
        times = _frame_times(rng, spec.wheel_hz, end_s, spec)
        idx = np.clip(np.searchsorted(t, times), 0, len(t) - 1)
        flags = trace.abs_active[idx] > 0.5
        if spec.abs_flags == "global":
            per_message.append((times, ABS_MESSAGE, _rows(["abs_active"], flags.any(axis=1)[:, None].astype(float))))
        else:
            per_message.append((times, ABS_MESSAGE, _rows([f"abs_active_{w}" for w in WHEELS], flags.astype(float))))
    return _merge(per_message)


def _wheel_speeds(spec: SensorSpec, trace: Any, times: np.ndarray, radius_m: float,
                  rng: np.random.Generator) -> np.ndarray:
    """The four wheel speeds at `times` as a wheel-speed ECU sends them, in rad/s: ground speed in
    km/h over the configured radius, noisy and quantised."""
    kmh = _omega_at(spec, trace, times) * radius_m * 3.6
    kmh += rng.normal(0.0, spec.wheel_noise_kmh, kmh.shape)
    kmh = np.maximum(np.round(kmh / spec.wheel_resolution_kmh) * spec.wheel_resolution_kmh, 0.0)
    return kmh / 3.6 / radius_m    # canonical unit; the DBC factor makes the encoding exact


def _omega_at(spec: SensorSpec, trace: Any, times: np.ndarray) -> np.ndarray:
    """The four wheels' ω at `times`: the instant's, or the mean over the `wheel_average_s` before
    each (the wheel's angle turned over that window, over the window)."""
    t = trace.t
    if spec.wheel_average_s <= 0.0:
        return np.column_stack([np.interp(times, t, trace.omega[:, i]) for i in range(4)])
    steps = 0.5 * (trace.omega[1:] + trace.omega[:-1]) * np.diff(t)[:, None]
    angle = np.vstack([np.zeros((1, 4)), np.cumsum(steps, axis=0)])
    start = np.maximum(times - spec.wheel_average_s, t[0])
    width = np.maximum(times - start, 1e-9)
    return np.column_stack([(np.interp(times, t, angle[:, i]) - np.interp(start, t, angle[:, i])) / width
                            for i in range(4)])


def _rows(names: list[str], values: np.ndarray) -> list[dict[str, float]]:
    return [dict(zip(names, row)) for row in values.tolist()]


def _merge(per_message: list[tuple[np.ndarray, str, list[dict[str, float]]]]) -> list[BusEvent]:
    events = [BusEvent(float(tt), name, vals) for times, name, rows in per_message
              for tt, vals in zip(times.tolist(), rows)]
    events.sort(key=lambda e: e.time_s)   # stable: equal stamps keep the message order
    return events
