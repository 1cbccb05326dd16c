"""Shared helpers of the benchmark scripts (simulated inputs, timing statistics)."""
from __future__ import annotations

import statistics
from typing import Sequence

from frictiond.config import default_config_path, load_config
from frictiond.pipeline import Pipeline
from frictiond.sim_frames import simulate_frames


def default_config():
    return load_config(default_config_path())


def braking_samples(scenarios: Sequence[str] = ("dry", "wet", "snow", "split_mu"), seed: int = 1):
    """The front end's PhysicalSamples of simulated ABS stops, in order (one per trigger frame)."""
    config = default_config()
    samples = []
    for k, scenario in enumerate(scenarios):
        frames, _ = simulate_frames(config, scenario, seed=seed + k, time_offset_s=100.0 * k)
        samples += pipeline_samples(Pipeline(config), frames)
    return config, samples


def pipeline_samples(pipeline: Pipeline, frames) -> list:
    """The PhysicalSamples `pipeline` updates its estimator with over `frames`, in order."""
    samples: list = []
    # (each update's sample once: one frame may release several, `trigger_hold`, and a held
    # estimate repeats the last sample)
    pipeline.on_estimate = lambda _e, s: samples.append(s) if s is not None and (not samples or s is not samples[-1]) else None
    for frame in frames:
        pipeline.process(frame)
    pipeline.flush()
    return samples


def percentile(values: Sequence[float], q: float) -> float:
    ordered = sorted(values)
    if not ordered:
        return float("nan")
    k = min(len(ordered) - 1, max(0, int(round(q / 100.0 * (len(ordered) - 1)))))
    return ordered[k]


def summary_us(values_s: Sequence[float]) -> str:
    us = [v * 1e6 for v in values_s]
    return (f"median {statistics.median(us):8.1f} µs  p99 {percentile(us, 99):8.1f} µs  "
            f"max {max(us):8.1f} µs  (n={len(us)})")
