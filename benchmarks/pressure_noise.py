"""Brake-pressure sensors noisier than the campaign draws, against the ABS releases they fake.

The campaign's pressure sensors have 0.1–0.6 bar of noise, and a pressure drop of 5 bar (8 σ of
0.6 bar) counts as an ABS release (`abs_activity`): evidence that the tyre worked at its limit.
A noisier sensor's noise alone makes such drops, and a stop without ABS then looks like one at
the limit. The front end measures each sensor's noise from its frames (`pressure_noise`) and
raises the threshold to 8 σ of it. This script runs the same campaign stops with every pressure
sensor's noise set to each level given, once as frictiond runs them and once with the threshold
held at 5 bar whatever the noise (the baseline, same process), and prints per level: VALID
outputs, false VALID (more than 20 % off the truth) and the stops they are in, the stops without
ABS that had any VALID output, and the noise the front end measured (median over the stops, as a
share of the true one).

    python benchmarks/pressure_noise.py [--stops 200] [--first-seed 0] [--levels 0.3,0.6,0.9,1.2,1.5] [--workers 2]

Seeds from `--first-seed` are the campaign's (0: the development seeds, 1000000: held-out).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from contextlib import nullcontext
from dataclasses import replace
from pathlib import Path
from unittest import mock

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from frictiond.abs_activity import AbsActivity  # noqa: E402
from frictiond.campaign.draw import draw_stop  # noqa: E402
from frictiond.campaign.simulate import simulate_stop  # noqa: E402
from frictiond.evaluation import evaluate  # noqa: E402
from frictiond.pipeline import Pipeline  # noqa: E402

VARIANTS = ("measured", "fixed 5 bar")


def run_stop(seed: int, noise_bar: float, variant: str, level: bool = False) -> tuple[int, str, int, int, float]:
    """(seed, ABS family, VALID outputs, false VALID, measured noise / true) of one stop; `level`:
    on level ground with the front end told so (`level_road`), as the stops were before the
    campaign drew grades."""
    spec = draw_stop(seed)
    spec = replace(spec, sensors=replace(spec.sensors, pressure_noise_bar=noise_bar))
    if level:
        spec = replace(spec, grade=0.0)
    stop = simulate_stop(spec)
    config = stop.config("lugre-tr")
    if level:
        config = replace(config, frontend=replace(config.frontend, level_road=True))
    pipeline = Pipeline(config)
    estimates = []
    held = nullcontext() if variant == "measured" else mock.patch.object(AbsActivity, "set_noise", lambda s, sigma: None)
    with held:
        for frame in stop.frames:
            if pipeline.process(frame):
                estimates.append(pipeline.last_estimate)
    measured = pipeline.front_end.pressure_noise_bar
    metrics = evaluate(estimates, stop.truth)
    return (seed, spec.abs_family, metrics.valid_count, metrics.false_valid_count,
            measured / noise_bar if measured is not None else float("nan"))


def _run(args: tuple[int, float, str]) -> tuple[int, str, int, int, float]:
    return run_stop(*args)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stops", type=int, default=200)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--levels", default="0.3,0.6,0.9,1.2,1.5", help="pressure noise σ in bar, comma-separated")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    levels = [float(x) for x in a.levels.split(",")]
    seeds = range(a.first_seed, a.first_seed + a.stops)
    jobs = [(s, level, variant) for level in levels for variant in VARIANTS for s in seeds]
    started = time.perf_counter()
    with ProcessPoolExecutor(a.workers) as pool:
        results = list(pool.map(_run, jobs, chunksize=4))
    print(f"{a.stops} campaign stops from seed {a.first_seed}, {len(jobs)} runs in {time.perf_counter() - started:.0f} s")
    print(f"{'noise σ':>8s} {'threshold':>12s} {'VALID':>7s} {'false':>6s} {'share':>7s} {'stops':>6s} "
          f"{'no-ABS stops VALID':>19s} {'measured/true':>14s}  stops with false VALID")
    k = 0
    for level in levels:
        for variant in VARIANTS:
            rows = results[k:k + len(seeds)]
            k += len(seeds)
            valid = sum(r[2] for r in rows)
            false = sum(r[3] for r in rows)
            no_abs = sum(1 for r in rows if r[1] == "d-none" and r[2] > 0)
            ratios = [r[4] for r in rows if r[4] == r[4]]
            ratio = f"{statistics.median(ratios):.2f}" if ratios and variant == "measured" else "-"
            worst = ", ".join(f"{r[0]} ({r[1]}: {r[3]})" for r in sorted(rows, key=lambda r: -r[3]) if r[3])[:80]
            print(f"{level:8.2f} {variant:>12s} {valid:7d} {false:6d} {100 * false / max(valid, 1):6.2f}% "
                  f"{sum(1 for r in rows if r[3]):6d} {no_abs:19d} {ratio:>14s}  {worst}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
