"""Fault injection over input frame streams, for the fault-replay tests and benchmark.

Pure functions: a list of frames (plus the input codec to rewrite signals) in, a new list out.
Each models something that happens on real vehicles: a stuck sensor, a silent ECU, a spoofing
node, a brake-pressure signal stuck at zero, an accelerometer offset.
"""
from __future__ import annotations

import random
from typing import Callable, Iterable

from .codec import DecodeFailure, InputCodec
from .frames import Frame


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
        spoofed.append(Frame(t, codec.trigger_id, payloads[0]))
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
