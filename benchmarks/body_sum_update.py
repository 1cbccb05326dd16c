"""The estimator's update cost where no wheel's brake torque is known (a master-cylinder-only car
under ABS: the fit of the car's total force, `body_sum_fit`), against the same updates with that
fit turned off, in the same process.

    python benchmarks/body_sum_update.py [--seeds 175 18 859] [--repeat 3]

The samples are the front end's, from the randomised campaign's development stops given (each a
master-cylinder-only car under ABS); each is fed to a fresh estimator per run.
"""
from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import pipeline_samples, summary_us  # noqa: E402

from frictiond.estimator import LugreTrustRegionEstimator  # noqa: E402


def stop_samples(seed: int) -> tuple[list, object, object]:
    """The front end's samples of a campaign stop, with its estimator options and vehicle."""
    from frictiond.campaign.draw import draw_stop
    from frictiond.campaign.simulate import simulate_stop
    from frictiond.pipeline import Pipeline

    stop = simulate_stop(draw_stop(seed))
    pipeline = Pipeline(stop.config("lugre-tr"))
    samples = pipeline_samples(pipeline, stop.frames)
    return samples, pipeline.estimator.options, pipeline.estimator.vehicle


def timed(options, vehicle, samples, chosen: list[bool]) -> list[float]:
    """Each chosen update's time, a fresh estimator fed every sample."""
    estimator = LugreTrustRegionEstimator(options, vehicle)
    times = []
    for sample, keep in zip(samples, chosen):
        start = time.perf_counter()
        estimator.update(sample)
        if keep:
            times.append(time.perf_counter() - start)
    return times


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[175, 18, 859])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    on: list[float] = []
    off: list[float] = []
    for seed in args.seeds:
        samples, options, vehicle = stop_samples(seed)
        chosen = [s.wheel_torques_unknown and not any(s.usable) for s in samples]
        if not any(chosen):
            print(f"stop {seed}: no update without a known wheel torque")
            continue
        without = dataclasses.replace(options, body_sum=False)
        for _ in range(args.repeat):
            on += timed(options, vehicle, samples, chosen)
            off += timed(without, vehicle, samples, chosen)
    if not on:
        return 1
    print(f"updates without a known wheel torque over {len(args.seeds)} stops × {args.repeat}")
    print(f"body-sum fit on   {summary_us(on)}  mean {statistics.mean(on) * 1e6:8.1f} µs")
    print(f"body-sum fit off  {summary_us(off)}  mean {statistics.mean(off) * 1e6:8.1f} µs")
    print(f"ratio on / off (mean): {statistics.mean(on) / statistics.mean(off):.1f}x; share of a 10 ms bus cycle "
          f"(mean): {statistics.mean(on) / 0.01:.1%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
