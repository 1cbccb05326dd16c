"""Fault injection over input frame streams, for the fault-replay tests and benchmark.

Pure functions: a list of frames (plus the input codec to rewrite signals) in, a new list out.
Each models something that happens on real vehicles: a stuck sensor, a silent ECU, a spoofing
node, a brake-pressure signal stuck at zero, an accelerometer offset.
"""
from __future__ import annotations

import math
import random
from typing import Callable, Iterable, Iterator, NamedTuple

from .codec import DecodeFailure, InputCodec
from .frames import Frame
from .samples import Status


def _rewrite(frames: Iterable[Frame], codec: InputCodec, start_s: float, end_s: float,
             change: Callable[[str, dict[str, float]], None]) -> list[Frame]:
    """Decode input frames inside [start, end), let `change` edit the values, re-encode."""
    out = []
    for f in frames:
        if start_s <= f.time_s < end_s:
            try:
                decoded = codec.decode(f)
            except DecodeFailure:
                decoded = None
            if decoded is not None:
                values = dict(decoded.values)
                change(decoded.message, values)
                payloads = codec.encode_input(decoded.message, values)
                if payloads:
                    f = f._replace(data=payloads[0])
        out.append(f)
    return out


def stuck_wheel_speed(frames, codec: InputCodec, wheel: str, start_s: float, end_s: float = float("inf")) -> list[Frame]:
    """One wheel-speed sensor freezes at its value at `start_s`."""
    name = f"wheel_speed_{wheel.lower()}"
    held: dict[str, float] = {}

    def change(message: str, values: dict[str, float]) -> None:
        if name in values:
            values[name] = held.setdefault(name, values[name])

    return _rewrite(frames, codec, start_s, end_s, change)


def drop_message(frames, can_id: int, start_s: float, end_s: float) -> list[Frame]:
    """An ECU falls silent: no frames of `can_id` in [start, end)."""
    return [f for f in frames if not (f.can_id == can_id and start_s <= f.time_s < end_s)]


def pressure_stuck_at_zero(frames, codec: InputCodec, start_s: float, end_s: float = float("inf")) -> list[Frame]:
    """All brake-pressure signals read zero (a sensor supply failure) while braking goes on."""
    def change(message: str, values: dict[str, float]) -> None:
        for k in values:
            if k.startswith("brake_pressure"):
                values[k] = 0.0

    return _rewrite(frames, codec, start_s, end_s, change)


def pressure_scaled(frames, codec: InputCodec, factor: float) -> list[Frame]:
    """Every brake pressure reads `factor` times the truth (a wrong DBC scale, a sensor gone off)."""
    def change(message: str, values: dict[str, float]) -> None:
        for k in values:
            if k.startswith("brake_pressure"):
                values[k] *= factor

    return _rewrite(frames, codec, float("-inf"), float("inf"), change)


def accel_offset(frames, codec: InputCodec, offset_mps2: float, start_s: float = 0.0) -> list[Frame]:
    """The longitudinal accelerometer reads `offset` too high (mounting, calibration)."""
    def change(message: str, values: dict[str, float]) -> None:
        if "accel_long" in values:
            values["accel_long"] += offset_mps2

    return _rewrite(frames, codec, start_s, float("inf"), change)


def spoof_flood(frames, codec: InputCodec, start_s: float, end_s: float, rate_hz: float = 10_000.0,
                seed: int = 0) -> list[Frame]:
    """A spoofing node floods the trigger (wheel-speed) ID with plausible but wrong values."""
    rng = random.Random(seed)
    trigger = next(m for m in codec.input_messages() if m.frame_id == codec.trigger_id)
    spoofed = []
    t = start_s
    while t < end_s:
        speed = rng.uniform(20.0, 90.0)
        payloads = codec.encode_input(trigger.name, {n: speed for n in trigger.signals})
        spoofed.append(Frame(t, codec.trigger_id, payloads[0], codec.trigger_extended))
        t += 1.0 / rate_hz
    return sorted(list(frames) + spoofed, key=lambda f: f.time_s)


def wheel_speed_spikes(frames, codec: InputCodec, probability: float, seed: int = 0) -> list[Frame]:
    """Single-sample glitches: a wheel speed jumps by a large amount for one frame."""
    rng = random.Random(seed)

    def change(message: str, values: dict[str, float]) -> None:
        names = [k for k in values if k.startswith("wheel_speed")]
        if names and rng.random() < probability:
            k = rng.choice(names)
            values[k] = max(0.0, values[k] + rng.choice((-1, 1)) * rng.uniform(10.0, 60.0))

    return _rewrite(frames, codec, float("-inf"), float("inf"), change)


def wheel_speed_zero(frames, codec: InputCodec, wheel: str, start_s: float, end_s: float = float("inf")) -> list[Frame]:
    """One wheel-speed sensor goes dead and reads 0 (a broken wire on most ABS sensors)."""
    name = f"wheel_speed_{wheel.lower()}"

    def change(message: str, values: dict[str, float]) -> None:
        if name in values:
            values[name] = 0.0

    return _rewrite(frames, codec, start_s, end_s, change)


def raw_signal(frames, codec: InputCodec, name: str, raw: int | None, start_s: float,
               end_s: float = float("inf")) -> list[Frame]:
    """Canonical input `name` carries the raw code `raw` (None: all ones, the usual "invalid"
    marker such as 0xFFFF) in [start, end): the other signals of the frame are untouched."""
    source = next(r for r in codec.resolved if r.name == name)
    message = codec.db.get_message_by_name(source.message)
    signal = message.get_signal_by_name(source.signal)
    if raw is None:
        raw = -1 if signal.is_signed else (1 << signal.length) - 1
    out = []
    for f in frames:
        if f.can_id == message.frame_id and start_s <= f.time_s < end_s and len(f.data) == message.length:
            try:
                values = message.decode(f.data, decode_choices=False, scaling=False)
            except Exception:  # noqa: BLE001 - an already broken frame stays as it is
                values = None
            if values is not None and source.signal in values:
                values[source.signal] = raw
                f = f._replace(data=bytes(message.encode(values, scaling=False, strict=False, padding=False)))
        out.append(f)
    return out


def wrong_dlc(frames, can_id: int, length: int, start_s: float, end_s: float = float("inf")) -> list[Frame]:
    """A gateway truncates (or pads) frames of `can_id` to `length` bytes in [start, end)."""
    out = []
    for f in frames:
        if f.can_id == can_id and start_s <= f.time_s < end_s:
            data = bytes(f.data[:length]) + b"\x00" * max(0, length - len(f.data))
            f = f._replace(data=data)
        out.append(f)
    return out


def duplicate_frames(frames, probability: float, seed: int = 0, start_s: float = float("-inf"),
                     end_s: float = float("inf")) -> list[Frame]:
    """Each frame in [start, end) arrives twice with `probability` (gateway retransmission)."""
    rng = random.Random(seed)
    out = []
    for f in frames:
        out.append(f)
        if start_s <= f.time_s < end_s and rng.random() < probability:
            out.append(f)
    return out


def reorder_frames(frames, probability: float, seed: int = 0, start_s: float = float("-inf"),
                   end_s: float = float("inf")) -> list[Frame]:
    """Neighbouring frames swap places (their timestamps with them, so time steps back)."""
    rng = random.Random(seed)
    out = list(frames)
    k = 0
    while k < len(out) - 1:
        if start_s <= out[k].time_s < end_s and rng.random() < probability:
            out[k], out[k + 1] = out[k + 1], out[k]
            k += 2
        else:
            k += 1
    return out


def time_jump(frames, at_s: float, jump_s: float) -> list[Frame]:
    """The clock steps by `jump_s` (hours, either way) at `at_s`: every later frame carries it."""
    return [f._replace(time_s=f.time_s + jump_s) if f.time_s >= at_s else f for f in frames]


def burst(frames, at_s: float, count: int) -> list[Frame]:
    """A queue flushes: the `count` frames from `at_s` on arrive at one instant, then the stream goes on."""
    frames = list(frames)
    start = next((i for i, f in enumerate(frames) if f.time_s >= at_s), len(frames))
    held = frames[start:start + count]
    if not held:
        return frames
    instant = held[-1].time_s
    return frames[:start] + [f._replace(time_s=instant) for f in held] + frames[start + count:]


# ------------------------------------------------------------------------------------------------
# The standard set, shared by tests/test_faults.py and benchmarks/faults.py.

class FaultCase(NamedTuple):
    frames: list[Frame]
    flag_from: float | None      # the status must say something is wrong in [flag_from, flag_until)
    flag_until: float | None     # (None: a fault to tolerate, judged by the absence of false VALID)
    clock_step: tuple[float, float] | None = None   # (at_s, jump_s) for the time-jump faults

    def original_time(self, time_s: float) -> float:
        """The simulator time of an output stamped `time_s` (undoes an injected clock step)."""
        if self.clock_step is None:
            return time_s
        at, jump = self.clock_step
        shifted = time_s - jump
        return shifted if abs(time_s - at) > abs(jump) / 2 else time_s


def standard_faults(frames, codec: InputCodec, seed: int = 0, start_s: float = 2.0, end_s: float = 3.0,
                    rate_guard: Callable[[], Callable[[float], bool]] | None = None,
                    ) -> dict[str, FaultCase]:
    """Every fault injected into one drive, by name.

    `rate_guard()`, when given, makes a fresh admission test for trigger frames (the daemon's
    flood guard) that is applied to the spoofing flood.
    """
    trigger = codec.trigger_id
    pressures = next(m.frame_id for m in codec.input_messages() if "brake_pressure_fl" in m.signals)
    accels = next(m.frame_id for m in codec.input_messages() if "accel_long" in m.signals)
    t0, t1 = start_s, end_s
    cases: dict[str, FaultCase] = {
        "stuck wheel speed": FaultCase(stuck_wheel_speed(frames, codec, "FL", t0), t0 + 0.3, t1 + 0.5),
        "dead wheel speed (reads 0)": FaultCase(wheel_speed_zero(frames, codec, "FL", t0), t0 + 0.3, t1 + 0.5),
        "wheel speed 0xFFFF marker": FaultCase(raw_signal(frames, codec, "wheel_speed_fr", None, t0, t1), t0 + 0.1, t1),
        "pressures lost 1 s": FaultCase(drop_message(frames, pressures, t0, t1), t0 + 0.06, t1 - 0.05),
        "accelerations lost 1 s": FaultCase(drop_message(frames, accels, t0, t1), t0 + 0.06, t1 - 0.05),
        "wheel speeds lost 1 s": FaultCase(drop_message(frames, trigger, t0, t1), t0 + 0.06, t1 - 0.05),
        "pressure stuck at zero": FaultCase(pressure_stuck_at_zero(frames, codec, t0), t0 + 0.2, t1 + 0.5),
        "pressure 0xFFFF marker": FaultCase(raw_signal(frames, codec, "brake_pressure_rl", None, t0, t1), t0 + 0.1, t1),
        "accel 0x8000 marker": FaultCase(raw_signal(frames, codec, "accel_long", -0x8000, t0, t1), t0 + 0.1, t1),
        "accelerometer offset +0.3": FaultCase(accel_offset(frames, codec, 0.3), None, None),
        "accelerometer offset -0.5": FaultCase(accel_offset(frames, codec, -0.5), None, None),
        "wheel-speed spikes 3 %": FaultCase(wheel_speed_spikes(frames, codec, 0.03, seed=seed), None, None),
        "wheel speeds wrong DLC": FaultCase(wrong_dlc(frames, trigger, 6, t0, t1), t0 + 0.06, t1 - 0.05),
        "pressures wrong DLC": FaultCase(wrong_dlc(frames, pressures, 9, t0, t1), t0 + 0.06, t1 - 0.05),
        "duplicated frames 30 %": FaultCase(duplicate_frames(frames, 0.3, seed=seed), None, None),
        "reordered frames 10 %": FaultCase(reorder_frames(frames, 0.1, seed=seed), None, None),
        "clock jumps back 3 h": FaultCase(time_jump(frames, t0, -3 * 3600.0), None, None, (t0, -3 * 3600.0)),
        "clock jumps ahead 5 h": FaultCase(time_jump(frames, t0, 5 * 3600.0), None, None, (t0, 5 * 3600.0)),
        "burst of 200 frames": FaultCase(burst(frames, t0, 200), None, None),
    }
    flood = spoof_flood(frames, codec, t0, t0 + 0.5, rate_hz=10_000, seed=seed)
    if rate_guard is not None:
        allow = rate_guard()
        flood = [f for f in flood if f.can_id != trigger or allow(f.time_s)]
    cases["spoofing flood 10 kHz"] = FaultCase(flood, t0 + 0.1, t0 + 0.5)
    return cases


# ------------------------------------------------------------------------------------------------
class BusEstimate(NamedTuple):
    """One FRICTION_ESTIMATE frame as a receiver decodes it off the bus."""

    time_s: float
    status: Status
    mu_max: float
    confidence: float


def replay_on_bus(config, frames: Iterable[Frame], tick_s: float = 0.01, pipeline=None):
    """Frames through a `Pipeline` the way the daemon drives it: `process` per frame and `tick`
    whenever `tick_s` of frame time has passed. Returns (pipeline, decoded FRICTION_ESTIMATEs,
    output frames whose payload decodes to a non-finite number or an undefined status).
    Pass `pipeline` to continue with one that has already seen frames."""
    from .pipeline import Pipeline

    if pipeline is None:
        pipeline = Pipeline(config)
    codec = pipeline.output_codec
    estimates: list[BusEstimate] = []
    bad: list[Frame] = []
    last_tick = -math.inf
    for frame in _then_end(frames):
        if frame is None:   # (the end: what the pipeline still held)
            out = pipeline.flush()
        else:
            out = pipeline.process(frame)
            t = frame.time_s
            if math.isfinite(t) and (t - last_tick >= tick_s or t < last_tick):
                last_tick = t
                out = out + pipeline.tick(t)
        for f in out:
            values = codec.decode_output(f)
            numbers = [v for k, v in values.items() if isinstance(v, (int, float)) and k != "time_s"]
            if values.get("e2e") in ("length", "undecodable") or not all(math.isfinite(v) for v in numbers):
                bad.append(f)
                continue
            if f.can_id != codec.estimate_id:
                continue
            try:
                status = Status[values["EstimatorStatus"]]
            except KeyError:
                bad.append(f)
                continue
            estimates.append(BusEstimate(f.time_s, status, float(values["MuMax"]), float(values["Confidence"])))
    return pipeline, estimates, bad


def _then_end(frames: Iterable[Frame]) -> Iterator[Frame | None]:
    """The frames, then None: where `replay_on_bus` flushes the pipeline's held inputs."""
    yield from frames
    yield None
