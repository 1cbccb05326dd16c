"""`frictiond replay`: the full pipeline over a recorded log, offline."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import EXIT_DATA_ERROR, EXIT_NO_INPUT, add_config_argument, fail, load_config_or_exit


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "replay",
        help="run the estimator over a log file and write its output frames",
        description="Replay a CAN log (candump .log, .asc, .blf, chosen by suffix) through the "
        "full pipeline; output frames are stamped with the time of the input frame that caused them.",
    )
    parser.add_argument("input", metavar="INPUT", help="input log file")
    add_config_argument(parser)
    parser.add_argument("--output", "-o", metavar="OUTPUT", help="output log file (format by suffix)")
    parser.add_argument("--truth", metavar="CSV", help="simulator truth CSV (for --plot and the summary)")
    parser.add_argument("--plot", metavar="FILE", help="draw the replay to FILE (.png/.svg/.pdf); needs frictiond[plot]")
    parser.add_argument("--plot-size", metavar="WxH", default=None,
                        help="pixel size of the --plot image (default 1200x800; for .svg/.pdf at 100 dpi)")
    parser.add_argument("--quiet", "-q", action="store_true", help="no summary")
    parser.set_defaults(func=_do_replay)


def _do_replay(args: argparse.Namespace) -> int:
    from ..busio import LogFormatError, LogWriter
    from ..replay import ReplayRecorder, replay_log

    config = load_config_or_exit(args.config)
    input_path = Path(args.input)
    if not input_path.is_file():
        return fail(f"{input_path}: no such log file", EXIT_NO_INPUT)
    if args.plot:
        from ..plot import plotting_available

        if not plotting_available():
            return fail("--plot needs matplotlib: pip install 'frictiond[plot]'", EXIT_DATA_ERROR)
        from ..plot import check_plot_path

        try:
            check_plot_path(args.plot)
        except ValueError as exc:
            return fail(f"--plot: {exc}", 2)
    plot_pixels = None
    if args.plot_size:
        from ..plot import parse_size

        try:
            plot_pixels = parse_size(args.plot_size)
        except ValueError as exc:
            return fail(f"--plot-size: {exc}", 2)

    from ..pipeline import Pipeline

    pipeline = Pipeline(config)
    recorder = ReplayRecorder() if args.plot else None
    writer = None
    try:
        if args.output:
            writer = LogWriter(args.output)
        summary = replay_log(pipeline, input_path, writer, recorder)
    except LogFormatError as exc:
        return fail(str(exc), EXIT_DATA_ERROR)
    except (OSError, ValueError) as exc:
        return fail(f"{input_path}: cannot read log: {exc}", EXIT_DATA_ERROR)
    finally:
        if writer is not None:
            writer.close()
    if args.truth and not Path(args.truth).is_file():
        return fail(f"{args.truth}: no such truth file", EXIT_NO_INPUT)
    if not args.quiet:
        print(summary.format(truth_path=args.truth), file=sys.stdout)
    if args.plot and recorder is not None:
        from ..plot import plot_replay

        try:
            plot_replay(recorder, args.plot, truth_path=args.truth, estimator=pipeline.estimator,
                        pixels=plot_pixels or (1200, 800))
        except (OSError, ValueError) as exc:
            return fail(f"--plot: cannot write {args.plot}: {exc}", EXIT_DATA_ERROR)
        if not args.quiet:
            print(f"plot written to {args.plot}")
    return 0
