"""Memory and soak: RSS while replaying a long simulated drive at full speed.

The drive (ABS stops on rotating surfaces, each with its free-rolling lead-in, plus unrelated
traffic at a 30 % bus load) is generated on the fly, so only frictiond's own memory grows.
Prints RSS at drive-minute 5 and at the end (default minute 60), their difference and the peak.

    python benchmarks/memory_soak.py [--minutes 60 | --quick]
"""
from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import default_config  # noqa: E402

from frictiond.pipeline import Pipeline  # noqa: E402
from frictiond.sim_frames import background_traffic, frames_per_second_for_load, merge_frames, simulate_frames  # noqa: E402

ROTATION = ("dry", "wet", "moderate", "snow", "cornering", "dry_to_wet", "noisy", "split_mu", "ice")


def rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=60.0, help="drive length (default 60)")
    parser.add_argument("--quick", action="store_true", help="a 7-minute drive (minute 5 vs the end)")
    args = parser.parse_args(argv)
    if args.quick:
        args.minutes = 7.0
    config = default_config()
    pipeline = Pipeline(config)
    t_drive, k, marks = 0.0, 0, {}
    start = time.perf_counter()
    ids = pipeline.input_codec.input_ids | {0x3E0, 0x3E1}
    while t_drive < args.minutes * 60.0:
        frames, _ = simulate_frames(config, ROTATION[k % len(ROTATION)], seed=k, time_offset_s=t_drive)
        end = frames[-1].time_s + 0.01
        other = background_traffic(t_drive, end, frames_per_second_for_load(0.3), ids, seed=k, n_ids=20)
        for frame in merge_frames(frames, other):
            pipeline.process(frame)
        t_drive, k = end, k + 1
        minute = int(t_drive // 60)
        if minute >= 5 and 5 not in marks:
            marks[5] = rss_mb()
        if minute not in marks and minute % 10 == 0:
            marks[minute] = rss_mb()
            print(f"drive minute {minute:3d}: RSS {marks[minute]:6.1f} MB  (wall {time.perf_counter() - start:6.0f} s)",
                  flush=True)
    final = rss_mb()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"RSS at minute 5: {marks.get(5, float('nan')):.1f} MB; at minute {t_drive / 60:.0f}: {final:.1f} MB; "
          f"growth {final - marks.get(5, final):+.2f} MB (target within 5 MB); peak RSS {peak:.1f} MB (target ≤ 150)")
    print(f"updates {pipeline.stats.updates}, frames {pipeline.stats.frames_read}, "
          f"speed {t_drive / (time.perf_counter() - start):.0f}x real time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
