"""Frame-level corruption of input streams at a given rate (issue 22; `benchmarks/corruption.py`).

Inputs carry no CRC: a frame that a gateway, a bit error the CAN CRC missed, a logging tool or a
second node got wrong decodes to plausible numbers. Each kind below corrupts a share `rate` of the
input frames (chosen at random, seeded) the way it happens on a vehicle; `corrupt` dispatches by
name. Pure functions: a list of frames in, a new list out (time order is that of the arrival, so a
reordered or clock-stepped frame is out of time order, as on the bus).
"""
from __future__ import annotations

import random
from typing import Callable

from .codec import InputCodec
from .frames import Frame

KINDS = ("random payload", "bit flip", "short DLC", "0xFF/0x00 marker", "duplicate", "reorder",
         "clock step back", "clock step ahead", "spoofing node", "mixed")
STEPPED_BACK_FRAMES = 10    # "mixed": input frames stepped back 1 s besides its share


def _picked(frames: list[Frame], ids: frozenset[int], rate: float, rng: random.Random) -> list[bool]:
    """Which frames to corrupt: a share `rate` of the input frames (exactly, at random)."""
    inputs = [k for k, f in enumerate(frames) if f.can_id in ids]
    chosen = set(rng.sample(inputs, min(len(inputs), round(rate * len(inputs)))))
    return [k in chosen for k in range(len(frames))]


def _each(frames: list[Frame], ids: frozenset[int], rate: float, seed: int,
          change: Callable[[Frame, random.Random], list[Frame]]) -> tuple[list[Frame], int]:
    rng = random.Random(seed)
    picked = _picked(frames, ids, rate, rng)
    out: list[Frame] = []
    for f, p in zip(frames, picked):
        out.extend(change(f, rng) if p else (f,))
    return out, sum(picked)


def _signal_fields(codec: InputCodec) -> dict[int, list[tuple[int, int]]]:
    """Per input frame ID, the (start bit, length) of each mapped little-endian signal."""
    fields: dict[int, list[tuple[int, int]]] = {}
    for r in codec.resolved:
        message = codec.db.get_message_by_name(r.message)
        signal = message.get_signal_by_name(r.signal)
        if signal.byte_order == "little_endian":
            fields.setdefault(message.frame_id, []).append((signal.start, signal.length))
    return fields


def corrupt(kind: str, frames: list[Frame], codec: InputCodec, rate: float, seed: int = 0) -> tuple[list[Frame], int]:
    """`frames` with a share `rate` of the input frames corrupted by `kind`; and how many were."""
    ids = frozenset(codec.input_ids)
    frames = list(frames)
    if kind == "random payload":
        return _each(frames, ids, rate, seed, lambda f, rng: [f._replace(data=rng.randbytes(len(f.data)))])
    if kind == "bit flip":
        fields = _signal_fields(codec)

        def flip(f: Frame, rng: random.Random) -> list[Frame]:
            start, length = rng.choice(fields.get(f.can_id) or [(0, 8 * len(f.data))])
            bit = start + rng.randrange(length)
            data = bytearray(f.data)
            if bit // 8 < len(data):
                data[bit // 8] ^= 1 << (bit % 8)
            return [f._replace(data=bytes(data))]

        return _each(frames, ids, rate, seed, flip)
    if kind == "short DLC":
        return _each(frames, ids, rate, seed, lambda f, rng: [f._replace(data=f.data[:rng.randrange(len(f.data))])])
    if kind == "0xFF/0x00 marker":
        return _each(frames, ids, rate, seed,
                     lambda f, rng: [f._replace(data=bytes([rng.choice((0xFF, 0x00))]) * len(f.data))])
    if kind == "duplicate":
        return _each(frames, ids, rate, seed, lambda f, rng: [f, f])
    if kind in ("clock step back", "clock step ahead"):
        step = -1.0 if kind == "clock step back" else 1.0
        return _each(frames, ids, rate, seed, lambda f, rng: [f._replace(time_s=f.time_s + step)])
    if kind == "reorder":
        return _reorder(frames, ids, rate, seed)
    if kind == "spoofing node":
        return _spoof(frames, codec, rate, seed)
    if kind == "mixed":
        return _mixed(frames, codec, rate, seed)
    raise ValueError(f"unknown corruption kind {kind!r}")


def _mixed(frames: list[Frame], codec: InputCodec, rate: float, seed: int) -> tuple[list[Frame], int]:
    """The mix a user met on a clean ABS stop (issue 22's report), scaled so that its four parts
    sum to `rate`: 3/7 of it random payloads and 2/7 short DLC on the input frames, 1/7 all-0xFF
    frames of the wheel-speed message (a share of its own frames), 1/7 duplicates; and
    `STEPPED_BACK_FRAMES` input frames stepped back 1 s. At 7 % it is that report's mix."""
    frames, n = corrupt("random payload", frames, codec, rate * 3 / 7, seed)
    frames, k = corrupt("short DLC", frames, codec, rate * 2 / 7, seed + 1)
    n += k
    frames, k = _each(frames, frozenset({codec.trigger_id}), rate / 7, seed + 2,
                      lambda f, rng: [f._replace(data=b"\xff" * len(f.data))])
    n += k
    frames, k = corrupt("duplicate", frames, codec, rate / 7, seed + 3)
    n += k
    ids = frozenset(codec.input_ids)
    rng = random.Random(seed + 4)
    inputs = [i for i, f in enumerate(frames) if f.can_id in ids]
    stepped = rng.sample(inputs, min(STEPPED_BACK_FRAMES, len(inputs)))
    for i in stepped:
        frames[i] = frames[i]._replace(time_s=frames[i].time_s - 1.0)
    return frames, n + len(stepped)


def _reorder(frames: list[Frame], ids: frozenset[int], rate: float, seed: int) -> tuple[list[Frame], int]:
    """A picked frame arrives after the next two (its timestamp with it: time steps back)."""
    rng = random.Random(seed)
    picked = _picked(frames, ids, rate, rng)
    out = list(frames)
    n = 0
    k = 0
    while k < len(out) - 2:
        if picked[k]:
            out[k], out[k + 1], out[k + 2] = out[k + 1], out[k + 2], out[k]
            picked[k], picked[k + 1], picked[k + 2] = picked[k + 1], picked[k + 2], False
            n += 1
            k += 3
        else:
            k += 1
    return out, n


def _spoof(frames: list[Frame], codec: InputCodec, rate: float, seed: int) -> tuple[list[Frame], int]:
    """A second node sends one input message at its own rate, at a random phase, in
    bursts of 0.2 s, with that message's payloads from 0.5 s earlier (a replay: every value is
    plausible on its own). Bursts are added until `rate` × the input frames are spoofed."""
    rng = random.Random(seed)
    ids = frozenset(codec.input_ids)
    inputs = [f for f in frames if f.can_id in ids]
    if not inputs:
        return frames, 0
    message_ids = sorted({f.can_id for f in inputs})
    target = message_ids[seed % len(message_ids)]
    own = [f for f in inputs if f.can_id == target]
    times = [f.time_s for f in own]
    period = (times[-1] - times[0]) / max(1, len(times) - 1)
    wanted = round(rate * len(inputs))
    spoofed: list[Frame] = []
    t_lo, t_hi = times[0] + 0.5, times[-1] - 0.2
    tries = 0
    busy: list[float] = []
    while len(spoofed) < wanted and t_hi > t_lo and tries < 1000:
        tries += 1
        start = rng.uniform(t_lo, t_hi)
        if any(abs(start - b) < 0.25 for b in busy):
            continue    # (one second node: its bursts do not overlap)
        busy.append(start)
        k = 0
        t = start
        while t < start + 0.2 and len(spoofed) < wanted:
            while k + 1 < len(own) and own[k + 1].time_s <= t - 0.5:
                k += 1
            spoofed.append(own[k]._replace(time_s=t))
            t += period
    merged = sorted(frames + spoofed, key=lambda f: f.time_s)
    return merged, len(spoofed)
