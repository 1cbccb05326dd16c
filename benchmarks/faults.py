"""Hostile-input figures for the closing note: inputs tried, faults injected and detected,
crashes, false VALID outputs.

  1. Random frames (arbitrary IDs among the inputs, payloads, DLCs, invalid markers, time jumps)
     through the pipeline, checking every output payload decodes to finite values.
  2. Every fault of `frictiond.faults` injected into simulated stops on several surfaces;
     "detected" means the status or the confidence says so during the fault (or the faulty
     input is rejected outright), "false VALID" is a VALID estimate > 20 % off the truth.

    python benchmarks/faults.py [--random-frames 50000]
"""
from __future__ import annotations

import argparse
import math
import random
import sys
from pathlib import Path

import cantools
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import default_config  # noqa: E402

from frictiond import faults  # noqa: E402
from frictiond.daemon import RateGuard  # noqa: E402
from frictiond.frames import Frame  # noqa: E402
from frictiond.pipeline import Pipeline
from frictiond.replay import estimates_of  # noqa: E402
from frictiond.samples import Status  # noqa: E402
from frictiond.sim_frames import simulate_frames  # noqa: E402

DBC = cantools.database.load_file(str(Path(__file__).resolve().parents[1] / "dbc" / "frictiond.dbc"))


def finite_outputs(frames) -> bool:
    for f in frames:
        values = DBC.decode_message(f.can_id, f.data, decode_choices=False)
        if not all(math.isfinite(v) for v in values.values()):
            return False
    return True


def random_frames(config, n: int, seed: int = 0) -> tuple[int, int, int]:
    rng = random.Random(seed)
    pipeline = Pipeline(config)
    ids = sorted(pipeline.input_codec.input_ids)
    markers = [b"\xff" * 8, b"\x00" * 8, b"\x7f\xff" * 4, b"\x80\x00" * 4]
    crashes = bad = 0
    t = 0.0
    for _ in range(n):
        r = rng.random()
        t += rng.choice([0.001, 0.0, -0.002, 0.01]) if r < 0.98 else rng.choice([3600.0, -3600.0, 1e-9])
        data = rng.choice(markers) if rng.random() < 0.2 else rng.randbytes(rng.randrange(0, 9))
        frame = Frame(t, rng.choice(ids) if rng.random() < 0.9 else rng.randrange(0, 0x800), data,
                      is_extended=rng.random() < 0.02, is_error=rng.random() < 0.01, is_remote=rng.random() < 0.01)
        try:
            out = pipeline.process(frame) + (pipeline.tick(t + 0.05) if rng.random() < 0.01 else [])
        except Exception:  # noqa: BLE001 - counting is the point
            crashes += 1
            continue
        if not finite_outputs(out):
            bad += 1
    return n, crashes, bad


def run(config, frames):
    return estimates_of(config, frames)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--random-frames", type=int, default=50_000)
    args = parser.parse_args(argv)
    config = default_config()
    n, crashes, non_finite = random_frames(config, args.random_frames)
    print(f"random frames tried: {n}; crashes: {crashes}; outputs with NaN/inf: {non_finite}")
    injected = detected = false_valid = total_valid = 0
    for scenario in ("dry", "wet", "snow", "split_mu"):
        for seed in (1, 2):
            frames, sim = simulate_frames(config, scenario, seed=seed)
            codec = Pipeline(config).input_codec
            rows = sim.truth.rows()
            t_truth = np.array([r["time_s"] for r in rows])
            mu_truth = np.array([r["mu_max"] for r in rows])
            cases = {
                "stuck wheel speed": (faults.stuck_wheel_speed(frames, codec, "FL", 2.0), 2.3, 3.5),
                "pressures lost 1 s": (faults.drop_message(frames, 0x0D0, 2.0, 3.0), 2.06, 2.95),
                "accelerations lost 1 s": (faults.drop_message(frames, 0x0C0, 2.0, 3.0), 2.06, 2.95),
                "pressure stuck at zero": (faults.pressure_stuck_at_zero(frames, codec, 2.0), 2.2, 3.5),
                "accelerometer offset +0.3": (faults.accel_offset(frames, codec, 0.3), None, None),
                "wheel-speed spikes 3 %": (faults.wheel_speed_spikes(frames, codec, 0.03, seed=seed), None, None),
            }
            flood = faults.spoof_flood(frames, codec, 2.0, 2.5, rate_hz=10_000, seed=seed)
            guard = RateGuard(config.daemon.max_update_rate)
            cases["spoofing flood 10 kHz"] = ([f for f in flood if f.can_id != codec.trigger_id or guard.allow(f.time_s)],
                                              2.1, 2.5)
            for name, (damaged, t0, t1) in cases.items():
                injected += 1
                pipeline, estimates = run(config, damaged)
                if t0 is None:
                    ok = True  # tolerated faults: judged by the absence of false VALID below
                else:
                    inside = [e for e in estimates if t0 <= e.time_s < t1]
                    ok = bool(inside) and sum(e.status != Status.VALID or e.confidence < 0.5 for e in inside) >= 0.75 * len(inside)
                    if name == "stuck wheel speed":
                        ok = ok or pipeline.stats.faults.total() > 0
                detected += ok
                case_false = 0
                for e in estimates:
                    if e.status == Status.VALID:
                        total_valid += 1
                        truth = mu_truth[min(np.searchsorted(t_truth, e.time_s), len(t_truth) - 1)]
                        case_false += abs(e.mu_max - truth) > 0.2 * truth
                false_valid += case_false
                if case_false:
                    print(f"  false VALID: {scenario}/{seed} {name}: {case_false}")
                if not ok:
                    print(f"  not flagged: {scenario}/{seed} {name}")
    print(f"faults injected: {injected}; detected/flagged: {detected}; "
          f"false VALID outputs: {false_valid} of {total_valid} VALID")
    return 0


if __name__ == "__main__":
    sys.exit(main())
