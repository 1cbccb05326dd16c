"""Generated drive logs for fleet tests and benchmarks: free rolling, then one ABS stop each.

Each log is a simulator run (`sim_frames.simulate_frames`) of a base scenario from
`CORPUS_SCENARIOS`, in turn, with the free rolling stretched so the log lasts about `seconds`,
its own seed, and the formats .log, .asc and .blf in turn. Deterministic for a given seed.
"""
from __future__ import annotations

import concurrent.futures
import dataclasses
from pathlib import Path

CORPUS_SCENARIOS = ("wet", "dry", "snow", "split_mu", "cobblestone_wet", "noisy")
FORMATS = (".log", ".asc", ".blf")
# How long the ABS stop itself runs from the initial speed below, at most (the simulator ends
# the run below its stop speed): what is left of `seconds` is free rolling before it.
_SHORT_STOP_S = 1.6
_LONG_STOP_S = 5.0


def log_name(index: int) -> str:
    return f"drive-{index:05d}{FORMATS[index % len(FORMATS)]}"


def write_log(folder: Path, index: int, seconds: float, seed: int = 0) -> Path:
    """Log number `index` of a corpus of logs lasting about `seconds` each."""
    from ..busio import LogWriter
    from ..config import default_config_path, load_config
    from ..sim_frames import simulate_frames
    from ..simulator import SCENARIOS

    base = SCENARIOS[CORPUS_SCENARIOS[index % len(CORPUS_SCENARIOS)]]
    short = seconds < 6.0
    stop_s = _SHORT_STOP_S if short else _LONG_STOP_S
    scenario = dataclasses.replace(
        base, name=f"{base.name}-fleet", initial_speed_mps=12.0 if short else min(base.initial_speed_mps, 25.0),
        brake_start_s=max(1.0, seconds - stop_s), duration_s=seconds, surfaces_after=None, surface_change_s=None,
        brake_release_s=None)
    frames, _ = simulate_frames(load_config(default_config_path()), scenario, seed=seed * 100_003 + index)
    path = folder / log_name(index)
    with LogWriter(path) as writer:
        writer.write_all(frames)
    return path


def write_corpus(folder: Path, count: int, seconds: float, seed: int = 0,
                 executor: concurrent.futures.Executor | None = None) -> list[Path]:
    """`count` logs in folder (existing ones of the same name are kept: a corpus is reused)."""
    folder.mkdir(parents=True, exist_ok=True)
    todo = [k for k in range(count) if not (folder / log_name(k)).is_file()]
    if executor is None:
        for k in todo:
            write_log(folder, k, seconds, seed)
    else:
        for future in concurrent.futures.as_completed([executor.submit(write_log, folder, k, seconds, seed) for k in todo]):
            future.result()
    return [folder / log_name(k) for k in range(count)]
