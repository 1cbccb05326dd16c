"""Accuracy of both estimators over the simulator's scenario set.

Runs each scenario (and truth-model / reference-speed variants) through the full pipeline —
frames encoded with the default DBC, decoded, front end, estimator — once per estimator, and
prints per scenario and estimator the metrics of `frictiond.evaluation`, then, per estimator,
how its errors fall with the confidence it reported (every output with a confidence > 0).

    python benchmarks/accuracy.py [--seeds 3] [--scenarios dry,wet] [--estimators lugre-tr,burckhardt-rls]
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import statistics
import sys
import time

from frictiond.config import default_config_path, load_config
from frictiond.evaluation import calibration_table, evaluate
from frictiond.pipeline import Pipeline
from frictiond.replay import ReplayRecorder, replay_frames
from frictiond.sim_frames import simulate_frames

# (label, scenario, truth model override, reference speed override)
CASES = [
    ("dry", "dry", None, None),                       # Magic Formula truth
    ("dry/burckhardt", "dry", "burckhardt", None),
    ("dry/ref", "dry", None, True),                   # with a ground-speed sensor
    ("wet", "wet", None, None),                       # Burckhardt truth
    ("wet/mf", "wet", "magic-formula", None),
    ("wet/ref", "wet", None, True),
    ("snow", "snow", None, None),                     # dynamic LuGre truth
    ("snow/burckhardt", "snow", "burckhardt", None),
    ("ice", "ice", None, None),                       # Burckhardt truth
    ("ice/mf", "ice", "magic-formula", None),
    ("ice_fast", "ice_fast", None, None),             # μ_max ~0.026 at 35 m/s
    ("cobblestone_wet", "cobblestone_wet", None, None),
    ("dry_to_wet", "dry_to_wet", None, None),         # μ jump mid-stop
    ("dry_to_wet/mf", "dry_to_wet", "magic-formula", None),
    ("split_mu", "split_mu", None, None),
    ("noisy", "noisy", None, None),                   # heavy noise, 3 % frame loss
    ("noisy/ref", "noisy", None, True),
    ("moderate", "moderate", None, None),             # never near the peak: must not claim VALID
    ("moderate_wet", "moderate_wet", None, None),     # 65 % of the grip on wet, then released: neither
    ("moderate_wet/burckhardt", "moderate_wet", "burckhardt", None),
    ("cornering", "cornering", None, None),
    ("loaded", "loaded", None, None),                 # 25 % heavier than the config says
]


def run_case(config, scenario, truth_model, reference_speed, seed):
    frames, sim = simulate_frames(
        config, scenario, seed=seed, truth_model=truth_model, reference_speed=reference_speed
    )
    pipeline = Pipeline(config)
    recorder = ReplayRecorder()
    replay_frames(pipeline, frames, None, recorder)
    truth_rows = sim.truth.rows() if hasattr(sim.truth, "rows") else sim.truth
    return evaluate(recorder.estimates, truth_rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--scenarios", default=None, help="comma-separated case labels")
    parser.add_argument("--estimators", default="lugre-tr,burckhardt-rls")
    args = parser.parse_args(argv)
    base = load_config(default_config_path())
    kinds = args.estimators.split(",")
    cases = [c for c in CASES if args.scenarios is None or c[0] in args.scenarios.split(",")]
    header = f"{'case':16s} {'estimator':15s} {'MAE':>6s} {'MAE%':>5s} {'valid%':>6s} {'conv s':>6s} {'reconv':>6s} {'falseV%':>7s} {'truth':>6s}"
    print(header)
    print("-" * len(header))
    overall: dict[str, list[float]] = {k: [] for k in kinds}
    false_valid: dict[str, list[int]] = {k: [0, 0] for k in kinds}
    calibration: dict[str, list[tuple[float, float]]] = {k: [] for k in kinds}
    t0 = time.perf_counter()
    for label, scenario, model, ref in cases:
        for kind in kinds:
            config = dataclasses.replace(base, estimator=dataclasses.replace(base.estimator, kind=kind))
            reports = [run_case(config, scenario, model, ref, seed) for seed in range(args.seeds)]
            mae = statistics.mean(r.mae for r in reports)
            mae_rel = statistics.mean(r.mae_rel for r in reports)
            valid = statistics.mean(r.valid_share for r in reports)
            conv = max(r.convergence_s for r in reports)
            reconv = [r.reconvergence_s for r in reports if r.reconvergence_s is not None]
            fv = sum(r.false_valid_count for r in reports)
            nv = sum(r.valid_count for r in reports)
            calibration[kind].extend(p for r in reports for p in r.confidence_errors)
            false_valid[kind][0] += fv
            false_valid[kind][1] += nv
            if math.isfinite(mae) and not scenario.startswith("moderate"):
                overall[kind].append(mae)
            truth = statistics.mean(r.mean_truth for r in reports)
            print(
                f"{label:16s} {kind:15s} {mae:6.3f} {100 * mae_rel:5.1f} {100 * valid:6.1f} "
                f"{conv:6.2f} {(max(reconv) if reconv else float('nan')):6.2f} "
                f"{(100 * fv / nv if nv else 0.0):7.2f} {truth:6.3f}",
                flush=True,
            )
    print()
    for kind in kinds:
        vals = overall[kind]
        fv, nv = false_valid[kind]
        print(
            f"{kind:15s} mean MAE over cases {statistics.mean(vals) if vals else float('nan'):.4f}; "
            f"false valid {fv}/{nv} = {100 * fv / max(nv, 1):.2f} %"
        )
    if len(kinds) == 2 and all(overall[k] for k in kinds):
        a, b = (statistics.mean(overall[k]) for k in kinds)
        print(f"ratio {kinds[0]} / {kinds[1]} mean MAE: {a / b:.3f}")
    print()
    for kind in kinds:
        print(f"{kind}: |relative error| of MuMax by reported confidence")
        for row in calibration_table(calibration[kind]):
            print(f"  confidence {row.low:.1f}-{row.high:.1f}: n {row.count:6d}  median {100 * row.median_error:5.1f} %  "
                  f"p90 {100 * row.p90_error:5.1f} %  >10 % off {100 * row.share_over_10:5.1f} %  "
                  f">20 % off {100 * row.share_over_20:5.1f} %")
    print(f"({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
