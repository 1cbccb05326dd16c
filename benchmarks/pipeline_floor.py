"""Replay cost against its floor: reading the same log and decoding its input frames.

Builds a long simulated drive (default 10 min of 100 Hz inputs: cruising with an ABS stop every
~20 s, on several surfaces) plus unrelated traffic filling a 50 %-loaded 500 kbit/s bus, writes
it as a candump log, then times in the same process:
  floor:  python-can's reader over the log + cantools decoding of the input frames;
  replay: the full `frictiond replay` pipeline over the same log (without writing output).
The two alternate over `--rounds` pairs; the ratio is the median of the pairs' ratios.

    python benchmarks/pipeline_floor.py [--minutes 10] [--load 0.5] [--log drive.log] [--rounds 3]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import can
import cantools

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import default_config  # noqa: E402

from frictiond.busio import LogWriter, read_log  # noqa: E402
from frictiond.pipeline import Pipeline  # noqa: E402
from frictiond.replay import replay_log  # noqa: E402
from frictiond.sim_frames import (  # noqa: E402
    background_traffic,
    frames_per_second_for_load,
    input_codec_for,
    merge_frames,
    simulate_frames,
)

ROTATION = ("dry", "wet", "moderate", "snow", "cornering", "dry_to_wet", "noisy", "split_mu")


def build_log(path: Path, minutes: float, load: float) -> tuple[int, float]:
    config = default_config()
    codec = input_codec_for(config)
    streams = []
    t, k = 0.0, 0
    while t < minutes * 60.0:
        frames, sim = simulate_frames(config, ROTATION[k % len(ROTATION)], seed=k, time_offset_s=t)
        streams.append(frames)
        t = frames[-1].time_s + 0.01
        k += 1
    inputs = [f for s in streams for f in s]
    end = inputs[-1].time_s
    other = background_traffic(0.0, end, frames_per_second_for_load(load) - len(inputs) / end,
                               codec.input_ids | {0x3E0, 0x3E1}, seed=7)
    n = 0
    with LogWriter(path) as writer:
        for frame in merge_frames(inputs, other):
            writer.write(frame)
            n += 1
    return n, end


def floor_pass(path: Path, dbc_path: Path, input_ids: set[int]) -> int:
    db = cantools.database.load_file(str(dbc_path))
    messages = {m.frame_id: m for m in db.messages if m.frame_id in input_ids}
    decoded = 0
    for msg in can.LogReader(str(path)):
        m = messages.get(msg.arbitration_id)
        if m is not None and not msg.is_extended_id:
            m.decode(msg.data)
            decoded += 1
    return decoded


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--load", type=float, default=0.5)
    parser.add_argument("--log", type=Path, help="keep the drive in this .log (reused when it exists)")
    parser.add_argument("--rounds", type=int, default=3, help="floor/replay pairs to time (default 3)")
    args = parser.parse_args(argv)
    config = default_config()
    with tempfile.TemporaryDirectory() as tmp:
        log = args.log or Path(tmp) / "drive.log"
        t0 = time.perf_counter()
        if args.log is not None and log.exists():
            first = last = None
            n_frames = 0
            for frame in read_log(log):
                first = frame.time_s if first is None else first
                last = frame.time_s
                n_frames += 1
            span = (last or 0.0) - (first or 0.0)
            built = "reused"
        else:
            n_frames, span = build_log(log, args.minutes, args.load)
            built = f"built in {time.perf_counter() - t0:.1f} s"
        print(f"log: {n_frames} frames, {span / 60:.1f} min of bus time, {log.stat().st_size / 1e6:.1f} MB ({built})")
        input_ids = set(input_codec_for(config).input_ids)
        # Floor and replay alternate, and each round's ratio pairs two neighbouring passes: this
        # VM's speed drifts by tens of per cent within a minute, which one pass of each would
        # read as a property of frictiond.
        ratios, floors, replays = [], [], []
        for round_ in range(args.rounds):
            t0 = time.perf_counter()
            decoded = floor_pass(log, config.can.dbc[0], input_ids)
            floor_s = time.perf_counter() - t0
            pipeline = Pipeline(config)
            t0 = time.perf_counter()
            summary = replay_log(pipeline, log)
            replay_s = time.perf_counter() - t0
            floors.append(floor_s)
            replays.append(replay_s)
            ratios.append(replay_s / floor_s)
            print(f"round {round_ + 1}: floor {floor_s:6.2f} s, replay {replay_s:6.2f} s, ratio {replay_s / floor_s:.2f}x")
    print(f"floor  (read + decode inputs): best {min(floors):7.2f} s  ({decoded} input frames decoded)")
    print(f"replay (full pipeline):        best {min(replays):7.2f} s  ({summary.stats.updates} updates, "
          f"{summary.stats.frames_out} frames out)")
    print(f"ratio replay / floor: median of rounds {statistics.median(ratios):.2f}x "
          f"(rounds {min(ratios):.2f}-{max(ratios):.2f}x; best times {min(replays) / min(floors):.2f}x)")
    print(f"replay speed: {span / min(replays):.0f}x real time (floor {span / min(floors):.0f}x), best rounds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
