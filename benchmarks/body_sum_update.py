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
import time

import numpy as np

from frictiond.estimator import LugreTrustRegionEstimator


def stop_samples(seed: int) -> tuple[list, object, object]:
    """The front end's samples of a campaign stop, with its estimator options and vehicle."""
    from frictiond.campaign.draw import draw_stop
    from frictiond.campaign.simulate import simulate_stop
    from frictiond.pipeline import Pipeline

    stop = simulate_stop(draw_stop(seed))
    pipeline = Pipeline(stop.config("lugre-tr"))
    samples = []
    original = LugreTrustRegionEstimator.update

    def capture(self, sample):
        samples.append(sample)
        return original(self, sample)

    # (on the class: the pipeline builds its estimator again once it has measured the cycle time)
    LugreTrustRegionEstimator.update = capture
    try:
        for frame in stop.frames:
            pipeline.process(frame)
    finally:
        LugreTrustRegionEstimator.update = original
    return samples, pipeline.estimator.options, pipeline.estimator.vehicle


def timed(options, vehicle, samples) -> np.ndarray:
    estimator = LugreTrustRegionEstimator(options, vehicle)
    times = []
    for sample in samples:
        start = time.perf_counter()
        estimator.update(sample)
        times.append(time.perf_counter() - start)
    return np.array(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[175, 18, 859])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    with_fit, without = [], []
    for seed in args.seeds:
        samples, options, vehicle = stop_samples(seed)
        body = np.array([s.wheel_torques_unknown and not any(s.usable) for s in samples])
        if not body.any():
            print(f"stop {seed}: no update without a known wheel torque")
            continue
        off = dataclasses.replace(options, body_sum=False)
        for _ in range(args.repeat):
            with_fit.append(timed(options, vehicle, samples)[body])
            without.append(timed(off, vehicle, samples)[body])
    if not with_fit:
        return 1
    on, off = np.concatenate(with_fit) * 1e6, np.concatenate(without) * 1e6
    print(f"updates without a known wheel torque: n={len(on)} over {len(args.seeds)} stops × {args.repeat}")
    print(f"body-sum fit on   median {np.median(on):8.1f} µs  p99 {np.quantile(on, 0.99):8.1f} µs  max {on.max():8.1f} µs"
          f"  mean {on.mean():8.1f} µs")
    print(f"body-sum fit off  median {np.median(off):8.1f} µs  p99 {np.quantile(off, 0.99):8.1f} µs  max {off.max():8.1f} µs"
          f"  mean {off.mean():8.1f} µs")
    print(f"ratio on / off (mean): {on.mean() / off.mean():.1f}x; share of a 10 ms bus cycle (mean): "
          f"{on.mean() / 1e4:.1%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
