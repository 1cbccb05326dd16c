"""`frictiond simulate`: generate a braking manoeuvre as a CAN log (and its truth)."""
from __future__ import annotations

import argparse
from pathlib import Path

from .common import EXIT_DATA_ERROR, add_config_argument, fail, load_config_or_exit


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    from ..simulator import SCENARIOS, TRUTH_MODELS

    parser = subparsers.add_parser(
        "simulate",
        help="simulate a braking manoeuvre and write it as a CAN log",
        description="Four-wheel braking simulation (load transfer, wheel dynamics, hydraulics, ABS, "
        "sensor noise, jitter and drops), encoded through the config's DBC and signal map.",
    )
    parser.add_argument("--scenario", "-s", default="dry", choices=sorted(SCENARIOS), help="manoeuvre (default dry)")
    parser.add_argument("--output", "-o", metavar="LOG", help="log file to write (format by suffix)")
    parser.add_argument("--truth", metavar="CSV", help="write the simulator's truth (every 10 ms) to CSV")
    add_config_argument(parser)
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--truth-model", choices=sorted(TRUTH_MODELS), help="override the scenario's tyre truth")
    ref = parser.add_mutually_exclusive_group()
    ref.add_argument("--reference-speed", dest="reference_speed", action="store_true", default=None,
                     help="send VEHICLE_SPEED_REF (ground speed sensor)")
    ref.add_argument("--no-reference-speed", dest="reference_speed", action="store_false",
                     help="do not send the reference speed")
    parser.add_argument("--background-load", type=float, default=0.0, metavar="FRACTION",
                        help="add unrelated traffic filling this fraction of a 500 kbit/s bus")
    parser.add_argument("--start-time", type=float, default=0.0, metavar="S",
                        help="timestamp of the first frame (default 0; e.g. a wall-clock epoch)")
    parser.add_argument("--grade", type=float, default=None, metavar="G",
                        help="put the road on a grade, rise over run, uphill positive (e.g. -0.06)")
    parser.add_argument("--list", action="store_true", help="list the scenarios and exit")
    parser.set_defaults(func=_do_simulate)


def _do_simulate(args: argparse.Namespace) -> int:
    from ..simulator import SCENARIOS

    if args.list:
        for name in sorted(SCENARIOS):
            print(f"{name:18s} {SCENARIOS[name].description}")
        return 0
    if not args.output:
        return fail("simulate: --output LOG is required", 2)
    if not 0.0 <= args.background_load < 0.95:
        return fail("--background-load must be in [0, 0.95)", 2)
    from ..simulator.scenarios import MAX_GRADE

    if args.grade is not None and not abs(args.grade) <= MAX_GRADE:
        return fail(f"--grade must lie within ±{MAX_GRADE:g}, not {args.grade}", 2)
    config = load_config_or_exit(args.config)
    from ..busio import LogFormatError, LogWriter
    from ..sim_frames import (
        background_traffic,
        frames_per_second_for_load,
        input_codec_for,
        merge_frames,
        simulate_frames,
    )

    frames, result = simulate_frames(
        config,
        args.scenario,
        seed=args.seed,
        truth_model=args.truth_model,
        reference_speed=args.reference_speed,
        time_offset_s=args.start_time,
        grade=args.grade,
    )
    stream = iter(frames)
    if args.background_load > 0 and frames:
        codec = input_codec_for(config)
        extra = background_traffic(
            frames[0].time_s,
            frames[-1].time_s,
            frames_per_second_for_load(args.background_load),
            codec.input_ids | {0x3E0, 0x3E1},
            seed=args.seed + 1,
        )
        stream = merge_frames(frames, extra)
    try:
        with LogWriter(args.output) as writer:
            writer.write_all(stream)
            count = writer.frames_written
    except LogFormatError as exc:
        return fail(str(exc), EXIT_DATA_ERROR)
    except OSError as exc:
        return fail(f"{args.output}: cannot write: {exc}", EXIT_DATA_ERROR)
    if args.truth:
        result.truth_csv(Path(args.truth))
    print(f"{args.scenario}: {count} frames, {result.events[-1].time_s - result.events[0].time_s:.2f} s -> {args.output}")
    return 0
