"""Bridge from the (CAN-free) simulator to frames, through any config's signal map."""
from __future__ import annotations

import heapq
import random
from typing import Iterable, Iterator

from .codec import InputCodec, load_databases
from .config import Config
from .frames import Frame
from .simulator import MessageSchedule, SimulationResult, simulate


def input_codec_for(config: Config) -> InputCodec:
    db = load_databases(config.can.dbc, strict=config.can.dbc_strict)
    return InputCodec(db, config.signals, config.vehicle.wheel_radius)


def schedules_for(codec: InputCodec) -> list[MessageSchedule]:
    """What the simulator must send: each input message at its DBC cycle time."""
    return [MessageSchedule(m.name, m.period_s or 0.01, tuple(m.signals)) for m in codec.input_messages()]


def events_to_frames(codec: InputCodec, events: Iterable, time_offset_s: float = 0.0) -> Iterator[Frame]:
    """One frame per event; a multiplexed message sends its pages in turn, one per event."""
    ids = {m.name: (m.frame_id, m.is_extended) for m in codec.input_messages()}
    page_counter: dict[str, int] = {}
    for ev in events:
        payloads = codec.encode_input(ev.message, ev.values)
        if not payloads:
            continue
        k = page_counter.get(ev.message, 0)
        page_counter[ev.message] = k + 1
        frame_id, extended = ids[ev.message]
        yield Frame(ev.time_s + time_offset_s, frame_id, payloads[k % len(payloads)], extended)


def simulate_frames(
    config: Config,
    scenario: str,
    *,
    seed: int = 0,
    truth_model: str | None = None,
    reference_speed: bool | None = None,
    time_offset_s: float = 0.0,
    grade: float | None = None,
) -> tuple[list[Frame], SimulationResult]:
    """Run one scenario and encode its sensor events as input frames of the config's DBC."""
    codec = input_codec_for(config)
    result = simulate(
        scenario,
        config.vehicle,
        schedules_for(codec),
        seed=seed,
        truth_model=truth_model,
        reference_speed=reference_speed,
        grade=grade,
    )
    return list(events_to_frames(codec, result.events, time_offset_s)), result


def background_traffic(
    start_s: float,
    end_s: float,
    frames_per_s: float,
    exclude_ids: Iterable[int],
    seed: int = 0,
    n_ids: int = 40,
) -> Iterator[Frame]:
    """Unrelated periodic traffic (other ECUs), as on a real bus: fixed IDs, own periods."""
    rng = random.Random(seed)
    excluded = set(exclude_ids)
    ids = []
    while len(ids) < n_ids:
        cid = rng.randrange(0x100, 0x7FF)
        if cid not in excluded and cid not in ids:
            ids.append(cid)
    per_id = frames_per_s / n_ids
    heap = [(start_s + rng.random() / per_id, cid) for cid in ids]
    heapq.heapify(heap)
    while heap:
        t, cid = heapq.heappop(heap)
        if t >= end_s:
            continue
        yield Frame(t, cid, rng.randbytes(8))
        heapq.heappush(heap, (t + (1.0 / per_id) * (0.95 + 0.1 * rng.random()), cid))


def merge_frames(*streams: Iterable[Frame]) -> Iterator[Frame]:
    return heapq.merge(*streams, key=lambda f: f.time_s)


# Bits per classical frame with 8 data bytes, including stuffing on average (~125).
BITS_PER_FRAME = 125


def frames_per_second_for_load(load: float, bitrate: int = 500_000) -> float:
    return load * bitrate / BITS_PER_FRAME
