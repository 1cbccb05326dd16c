"""Randomised braking campaign (issue 21): both estimators over random stops, against targets.

    .venv/bin/python benchmarks/campaign.py [--stops 1000] [--set held-out|dev|both] [--workers N]
        [--chunk 8] [--family ABS[/TYRE[/MANOEUVRE]]] [--clean-sensors] [--pre-roll S] [--grade G]
        [--payload KG] [--accel-offset A] [--cruise-lift S] [--tyre-model tmeasy] [--rear-select-low]
        [--tyre-radii P] [--save FILE.json|.parquet] [--worst 15]
    .venv/bin/python benchmarks/campaign.py --reproduce SEED [--family F] [--clean-sensors] [--pre-roll S]
        [--grade G] [--payload KG] [--accel-offset A] [--cruise-lift S] [--tyre-model tmeasy] [--rear-select-low]
        [--tyre-radii P] [--write-log DIR]

Each stop is drawn from its seed (`frictiond.campaign.draw`, ranges in its docstring): a car,
tyres (Burckhardt or Magic Formula, never the estimator's LuGre), an ABS family, sensors and a
manoeuvre; integrated at 1 kHz, put on the bus through the car's own DBC, and replayed through
the real pipeline once with `lugre-tr` and once with `burckhardt-rls` (the baseline). Stops
run in chunks on the embedded local Dask cluster (`frictiond.fleet.cluster.open_executor`).
Development seeds are 0…N−1, held-out seeds 1,000,000…: tune on dev, report held-out.
`--clean-sensors` runs the same stops with their sensors' imperfections taken off (no noise,
jitter, loss, offsets or pressure lag; `draw.clean`): another simulator's signals may be that
clean, and what the noise kept from VALID is then judged too. `--pre-roll S` brakes every stop S
seconds after the start instead of 0.8–1.2 s (`draw.with_pre_roll`; a change of road stays where it
was along the braking distance): the front end then has had little or no free rolling to learn
the accelerometer's offset from, as after a start-up just before a stop. `--grade G` puts every
stop on a grade of G (rise over run, uphill positive) in place of the one it drew: what free
rolling teaches of the accelerometer then holds gravity's share along the road. `--payload KG`
puts KG aboard every car (the config knows none of it; drawn: 0–120 kg) and `--accel-offset A`
gives every accelerometer an offset of size A (its drawn sign kept; drawn: 0–0.3 m/s²): a loaded
car, a sensor mounted tilted, beyond the ranges the estimator was tuned on. `--cruise-lift S`
drives every car at a steady speed, with no drive torque on the bus, until S seconds before its
brakes, where the draw has it coast: the engine's push then reads like an accelerometer offset to
what coasting teaches (`frontend.coasting_offset`). `--tyre-model tmeasy` replaces every road's
tyre by Rill's TMeasy curve of the same peak μ, its shape drawn from the seed: a tyre none of the
estimator's development saw. `--rear-select-low` has every ABS regulate the rear axle
select-low, as most production systems do: one pressure for both rear wheels. `--tyre-radii P`
gives every wheel a true rolling radius off the configured one by a share drawn within ±P, each
wheel its own (worn, soft or mixed tyres; drawn: none off): the ECU turns ω into a speed over the
configured radius, so every wheel's speed is off by its tyre's share (`frontend`'s
`rolling_radius`).
Printed: the issue's targets with PASS/FAIL per estimator, the comparison, a table per family,
distributions, and the worst stops each with the command that reproduces it.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time

from frictiond.campaign.draw import STRESS_TYRE_MODELS, Stress, draw_stop, seeds_for
from frictiond.campaign.logs import replay_commands, write_stop_files
from frictiond.campaign.report import full_report, reason
from frictiond.campaign.run import run_campaign, save_rows
from frictiond.campaign.score import score_stop
from frictiond.campaign.simulate import simulate_stop


def reproduce(seed: int, family: str | None, directory: str | None, stress: Stress | None = None) -> int:
    spec = draw_stop(seed, family, stress)
    stop = simulate_stop(spec)
    row = score_stop(stop)
    print(f"seed {seed}: {spec.family}, surfaces {spec.surface_labels}, {spec.speed0_mps * 3.6:.0f} km/h, "
          f"{len(stop.frames)} frames, max utilisation {row['max_utilisation']:.2f}, max slip {row['max_slip']:.2f}")
    for p, kind in (("lugre", "lugre-tr"), ("rls", "burckhardt-rls")):
        print(f"  {kind:15s} {reason(row, p)}  (convergence {row[f'{p}_conv_s']:.2f} s)")
    print(json.dumps({k: v for k, v in row.items() if not k.startswith(("lugre_cal", "rls_cal"))}, default=str))
    if directory:
        paths = write_stop_files(stop, directory)
        print(f"wrote {', '.join(str(p) for p in paths.values())}")
        for command in replay_commands(paths):
            print(f"  {command}")
    return 0


def progress_printer(label: str, started: float):
    step = {"n": 0}

    def show(done: int, total: int) -> None:
        if done - step["n"] >= max(total // 10, 1) or done == total:
            step["n"] = done
            print(f"  {label}: {done}/{total} stops, {time.perf_counter() - started:.0f} s", file=sys.stderr, flush=True)
    return show


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stops", type=int, default=1000, help="stops per seed set (default 1000)")
    parser.add_argument("--set", dest="which", default="held-out", choices=("held-out", "dev", "both"))
    parser.add_argument("--workers", type=int, default=None, help="Dask worker processes (default: one per core; "
                        "0: sequential in this process)")
    parser.add_argument("--scheduler", default=None, help="an existing Dask scheduler (tcp://HOST:8786)")
    parser.add_argument("--chunk", type=int, default=8, help="stops per Dask task")
    parser.add_argument("--family", default=None, help="force ABS[/TYRE[/MANOEUVRE]] (prefixes, * for any)")
    parser.add_argument("--clean-sensors", action="store_true", help="the same stops without noise, jitter, "
                        "frame loss, offsets or pressure lag")
    parser.add_argument("--pre-roll", type=float, default=None, metavar="S", help="brake every stop S seconds "
                        "after the start (default: drawn, 0.8-1.2 s)")
    parser.add_argument("--grade", type=float, default=None, metavar="G", help="every stop on this grade, rise "
                        "over run, uphill positive (default: drawn; a third level, the rest within ±0.08)")
    parser.add_argument("--payload", type=float, default=None, metavar="KG", help="every car this loaded "
                        "beyond its configured mass (default: drawn, 0-120 kg)")
    parser.add_argument("--accel-offset", type=float, default=None, metavar="A", help="every accelerometer's "
                        "offset this large, m/s², its drawn sign kept (default: drawn, 0-0.3)")
    parser.add_argument("--cruise-lift", type=float, default=None, metavar="S", help="every car driven at a "
                        "steady speed, no drive torque on the bus, until S seconds before the brakes "
                        "(default: it coasts)")
    parser.add_argument("--tyre-model", default=None, choices=STRESS_TYRE_MODELS, help="every road's tyre "
                        "replaced by this truth curve of the same peak μ, its shape drawn from the seed "
                        "(tmeasy: Rill's TMeasy, a shape the estimator was never developed on)")
    parser.add_argument("--rear-select-low", action="store_true", help="every ABS regulates the rear axle "
                        "select-low: one pressure for both rear wheels, the command of the wheel asking for less")
    parser.add_argument("--tyre-radii", type=float, default=None, metavar="P", help="every wheel's true rolling "
                        "radius off the configured one by a share drawn within ±P, each wheel its own "
                        "(worn, soft or mixed tyres; default: none off)")
    parser.add_argument("--radius-scale", type=float, default=None, metavar="P", help="all four wheels' true "
                        "rolling radius off the configured one by one share drawn within ±P (a radius taken "
                        "from the tyre's size, not measured rolling; default: none off)")
    parser.add_argument("--averaged-wheel-speeds", action="store_true", help="every wheel speed the mean over "
                        "its frame period before the frame, as an ECU counting a toothed ring's edges sends it "
                        "(default: the speed at the frame's instant)")
    parser.add_argument("--save", default=None, help="per-stop rows to .json or .parquet")
    parser.add_argument("--worst", type=int, default=15)
    parser.add_argument("--reproduce", type=int, default=None, metavar="SEED", help="run one stop and print its scores")
    parser.add_argument("--write-log", default=None, metavar="DIR", help="with --reproduce: write log, DBC, "
                        "configs, truth CSV")
    args = parser.parse_args(argv)
    try:
        stress = Stress(args.clean_sensors, args.pre_roll, args.grade, args.payload, args.accel_offset,
                        args.cruise_lift, args.tyre_model, args.rear_select_low, args.tyre_radii,
                        args.radius_scale, args.averaged_wheel_speeds)
    except ValueError as exc:
        parser.error(str(exc).replace("pre_roll_s", "--pre-roll").replace("payload_kg", "--payload")
                     .replace("accel_offset_mps2", "--accel-offset").replace("grade", "--grade")
                     .replace("cruise_lift_s", "--cruise-lift").replace("tyre_radii", "--tyre-radii")
                     .replace("radius_scale", "--radius-scale"))
    if args.reproduce is not None:
        return reproduce(args.reproduce, args.family, args.write_log, stress)
    sets = ("dev", "held-out") if args.which == "both" else (args.which,)
    all_rows = []
    for which in sets:
        seeds = seeds_for(which, args.stops)
        started = time.perf_counter()
        rows = run_campaign(seeds, workers=args.workers, chunk=args.chunk, family=args.family,
                            scheduler=args.scheduler, progress=progress_printer(which, started),
                            stress=stress)
        wall = time.perf_counter() - started
        cpu = sum(r.get("sim_cpu_s", 0.0) + r.get("lugre_cpu_s", 0.0) + r.get("rls_cpu_s", 0.0) for r in rows)
        print(f"\n##### {which} seeds {seeds[0]}…{seeds[-1]}: {len(rows)} stops in {wall:.0f} s wall "
              f"({args.workers if args.workers is not None else os.cpu_count()} workers; CPU per stop "
              f"{cpu / max(len(rows), 1):.2f} s: simulation + both estimators)\n")
        print(full_report(rows, f"{which} seeds{stress.describe()}", args.worst, args.family, stress))
        for r in rows:
            r["set"] = which
        all_rows.extend(rows)
    if args.save:
        save_rows(all_rows, args.save, {"stops": args.stops, "sets": list(sets), "family": args.family,
                                        **dataclasses.asdict(stress)})
        print(f"\nsaved {len(all_rows)} rows to {args.save}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
