"""Corrupted input frames against clean ABS stops (issue 22).

Each stop is replayed clean, then with 1, 3, 5 and 10 % of its input frames corrupted in each way of
`frictiond.corruption.KINDS` (random payloads, a bit flip in one signal, short DLC, 0xFF/0x00
markers, duplicates, reordering, single frames stepped 1 s back or ahead, a second node replaying
one message at the same rate; and "mixed", the mix of issue 22's report scaled to the rate: at 7 %,
3 % random payloads, 2 % short DLC, 1 % all-0xFF wheel-speed frames, 1 % duplicates, with ten
frames stepped back 1 s). Outputs are judged as a receiver decodes them off the bus
(`faults.replay_on_bus`). Per kind and rate:

- false VALID: VALID outputs more than 20 % off the truth, share of all VALID outputs;
- ΔMAE: the VALID outputs' mean absolute error less the same stop's clean run's (worst stop;
  and their mean over the stops);
- paired: the same over only the outputs VALID in both runs at the same instant (worst stop): how
  far corruption bent the estimate itself, apart from which outputs it left VALID (corruption
  that withdraws a stop's early, accurate VALID outputs raises ΔMAE without bending any);
- coverage: VALID outputs / the clean run's (lowest stop; and all stops together);
- FAULT: share of outputs with status FAULT;
- frames corrupted, crashes, outputs with NaN/inf;
- worst: the stop of the worst ΔMAE. A campaign stop is replayed alone, with the same corruption
  (each stop's draw comes from its name), by `--first-seed SEED --stops 1 --simulator-stops 0`
  with that row's `--kinds` and `--rates`; a simulator scenario by `--simulator`.

    python benchmarks/corruption.py [--stops 60] [--first-seed 0] [--simulator-stops 8] [--kinds 'random payload,bit flip'] [--rates 0.05]

Stops: ABS stops of the randomised campaign (`frictiond.campaign`, families a, b, c; seeds from
`--first-seed`: 0 the development seeds, 2000 a set nothing was tuned on) and the simulator's ABS
scenarios; a stop is used when its clean run has at least 100 VALID outputs and
at most 1 % of them more than 20 % off (a stop the estimator gets wrong when clean, issue 21's
other classes, says nothing about corruption).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import default_config  # noqa: E402

from frictiond.corruption import KINDS, corrupt  # noqa: E402
from frictiond.faults import replay_on_bus  # noqa: E402
from frictiond.samples import Status  # noqa: E402
from frictiond.sim_frames import input_codec_for, simulate_frames  # noqa: E402

RATES = (0.01, 0.03, 0.05, 0.10)
MIN_CLEAN_VALID = 100   # a stop whose clean run is seldom VALID gives no coverage ratio worth reading
SIM_SCENARIOS = ("dry", "wet", "snow", "cobblestone_wet", "split_mu", "noisy", "loaded", "cornering")


@dataclass
class Stop:
    name: str
    frames: list
    truth: Callable[[float], float]
    config: object


def _truth_of(t: np.ndarray, mu: np.ndarray) -> Callable[[float], float]:
    return lambda time_s: float(mu[min(int(np.searchsorted(t, time_s)), len(t) - 1)])


def simulator_stops(config, n: int) -> list[Stop]:
    stops = []
    for k in range(n):
        scenario = SIM_SCENARIOS[k % len(SIM_SCENARIOS)]
        seed = 1 + k // len(SIM_SCENARIOS)
        frames, sim = simulate_frames(config, scenario, seed=seed)
        rows = sim.truth.rows()
        t = np.array([r["time_s"] for r in rows])
        mu = np.array([r["mu_max"] for r in rows])
        stops.append(Stop(f"{scenario}/{seed}", frames, _truth_of(t, mu), config))
    return stops


def campaign_stops(n: int, first_seed: int = 0) -> list[Stop] | None:
    """ABS stops of the randomised campaign (None when it is not installed): ABS families a, b, c
    (d has no ABS), seeds from `first_seed`, each with its own car, DBC and config."""
    try:
        from frictiond.campaign.draw import draw_stop
        from frictiond.campaign.simulate import simulate_stop
    except ImportError:
        return None
    stops = []
    seed = first_seed
    while len(stops) < n and seed < first_seed + 50 * n:
        spec = draw_stop(seed)
        seed += 1
        if spec.abs_family == "d-none":
            continue
        stop = simulate_stop(spec)
        t = np.array([r["time_s"] for r in stop.truth], dtype=float)
        mu = np.array([r["mu_max"] for r in stop.truth], dtype=float)
        stops.append(Stop(f"campaign/{seed - 1}/{spec.family}", list(stop.frames), _truth_of(t, mu), stop.config()))
    return stops


@dataclass
class Outcome:
    valid: int = 0
    false_valid: int = 0
    abs_error: float = 0.0
    outputs: int = 0
    faults: int = 0
    bad: int = 0
    crashed: bool = False
    reasons: dict = field(default_factory=dict)
    errors: dict = field(default_factory=dict)   # |error| of each VALID output, by its (stop's own) time in ms

    def paired_dmae(self, clean: "Outcome") -> float:
        """MAE change over the outputs VALID in both runs at the same instant: how far corruption
        bent the estimate itself, apart from which outputs it left VALID."""
        common = self.errors.keys() & clean.errors.keys()
        if not common:
            return math.nan
        return sum(self.errors[k] - clean.errors[k] for k in common) / len(common)

    @property
    def mae(self) -> float:
        return self.abs_error / self.valid if self.valid else math.nan


def judge(stop: Stop, frames: list, original_time: Callable[[float], float] = lambda t: t) -> Outcome:
    out = Outcome()
    try:
        pipeline, estimates, bad = replay_on_bus(stop.config, frames)
    except Exception:  # noqa: BLE001 - a crash is a result here
        out.crashed = True
        return out
    out.bad = len(bad)
    out.outputs = len(estimates)
    for e in estimates:
        out.faults += e.status == Status.FAULT
        if e.status != Status.VALID:
            continue
        at = original_time(e.time_s)
        mu = stop.truth(at)
        err = abs(e.mu_max - mu)
        out.errors[round(at * 1000.0)] = err
        out.valid += 1
        out.abs_error += err
        out.false_valid += err > 0.2 * mu
    out.reasons = dict(pipeline.stats.faults)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stops", type=int, default=60, help="campaign stops to draw (ABS families a, b, c)")
    parser.add_argument("--simulator-stops", type=int, default=8, help="the simulator's ABS scenarios besides")
    parser.add_argument("--kinds", default=",".join(KINDS))
    parser.add_argument("--rates", default=",".join(str(r) for r in RATES))
    parser.add_argument("--seed", type=int, default=0, help="the corruption's draw")
    parser.add_argument("--first-seed", type=int, default=0,
                        help="the campaign's first seed (0: development seeds; 2000: a set not tuned on)")
    parser.add_argument("--simulator", action="store_true", help="only the simulator's scenarios")
    args = parser.parse_args(argv)
    kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    rates = [float(r) for r in args.rates.split(",")]
    config = default_config()
    drawn = [] if args.simulator else (campaign_stops(args.stops, args.first_seed) or [])
    source = f"{len(drawn)} from the campaign, " if drawn else ""
    stops = drawn + simulator_stops(config, args.simulator_stops)
    source += f"{args.simulator_stops} from the simulator"
    started = time.perf_counter()
    clean = [judge(s, s.frames) for s in stops]
    # A stop the estimator gets wrong when clean (issue 21's other classes) says nothing about
    # corruption: only stops whose clean run has VALID outputs, ≤ 1 % of them false, are used.
    kept = [(s, c) for s, c in zip(stops, clean) if c.valid >= MIN_CLEAN_VALID and c.false_valid <= 0.01 * c.valid]
    print(f"{len(stops)} ABS stops ({source}), {len(kept)} used (clean run: ≥ {MIN_CLEAN_VALID} VALID outputs, "
          f"≤ 1 % of them false); clean: "
          f"{sum(c.valid for _, c in kept)} VALID outputs, false VALID {sum(c.false_valid for _, c in kept)}, "
          f"MAE {np.nanmean([c.mae for _, c in kept]):.4f}, FAULT {sum(c.faults for _, c in kept) / max(1, sum(c.outputs for _, c in kept)):.2%}")
    stops, clean = [s for s, _ in kept], [c for _, c in kept]
    header = (f"{'kind':18} {'rate':>5} {'false VALID':>11} {'ΔMAE worst':>10} {'ΔMAE mean':>9} {'paired':>8} "
              f"{'coverage min':>12} {'cov all':>8} {'FAULT':>6} {'frames':>7} {'crash':>5} {'NaN':>4}  worst")
    print(header)
    total_frames = crashes = nan = 0
    for kind in kinds:
        for rate in rates:
            row = _row(stops, clean, kind, rate, args.seed)
            total_frames += row["frames"]
            crashes += row["crashes"]
            nan += row["nan"]
            print(f"{kind:18} {rate:5.0%} {row['false']:11.2%} {row['dmae_worst']:+10.4f} {row['dmae_mean']:+9.4f} "
                  f"{row['paired_worst']:+8.4f} {row['cov_min']:12.2f} {row['cov_all']:8.2f} {row['fault']:6.2%} {row['frames']:7d} "
                  f"{row['crashes']:5d} {row['nan']:4d}  {row['worst']}", flush=True)
    print(f"corrupted frames in all: {total_frames}; crashes: {crashes}; outputs with NaN/inf: {nan}; "
          f"{time.perf_counter() - started:.0f} s")
    return 0


def _row(stops: list[Stop], clean: list[Outcome], kind: str, rate: float, seed: int) -> dict:
    valid = false = faults = outputs = frames_n = crashes = nan = 0
    dmae, cov, paired, names = [], [], [], []
    for stop, base in zip(stops, clean):
        codec = input_codec_for(stop.config)
        # (each stop's corruption drawn from its name: a change that drops one stop from the kept
        # set must not redraw every other stop's, which moved single rows by 1 % of false VALID)
        frames, n = corrupt(kind, stop.frames, codec, rate, seed=seed + zlib.crc32(stop.name.encode()))
        frames_n += n
        shift = 1.0 if kind == "clock step back" else -1.0 if kind == "clock step ahead" else 0.0
        # (an output stamped with a stepped frame's time is judged at the stop's own time)
        end = stop.frames[-1].time_s
        o = judge(stop, frames, lambda t: t + shift if shift and (t > end + 0.5 or t < stop.frames[0].time_s - 0.5) else t)
        crashes += o.crashed
        nan += o.bad
        valid += o.valid
        false += o.false_valid
        faults += o.faults
        outputs += o.outputs
        if base.valid:
            cov.append(o.valid / base.valid)
            if o.valid:
                dmae.append(o.mae - base.mae)
                names.append(stop.name)
                paired.append(o.paired_dmae(base))
    base_valid = sum(b.valid for b in clean)
    paired = [d for d in paired if d == d]
    return {"false": false / valid if valid else 0.0, "dmae_worst": max(dmae) if dmae else math.nan,
            "paired_worst": max(paired) if paired else math.nan,
            "cov_all": valid / base_valid if base_valid else math.nan,
            "dmae_mean": float(np.mean(dmae)) if dmae else math.nan, "cov_min": min(cov) if cov else math.nan,
            "cov_mean": float(np.mean(cov)) if cov else math.nan, "fault": faults / outputs if outputs else 0.0,
            "frames": frames_n, "crashes": crashes, "nan": nan,
            "worst": names[int(np.argmax(dmae))] if dmae else "-"}


if __name__ == "__main__":
    sys.exit(main())
