"""`frictiond monitor`: watch frictiond's output on a bus or in a log — full screen, or `--json`."""
from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

from .common import (EXIT_CONFIG, EXIT_DATA_ERROR, EXIT_NO_INPUT, EXIT_UNAVAILABLE, add_config_argument, fail,
                     load_config_or_exit)


def _speed(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value >= 0 or value == float("inf"):
        raise argparse.ArgumentTypeError("must be ≥ 0 (0 = as fast as possible)")
    return value


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "monitor",
        help="watch frictiond's estimates on a bus or in a log (full screen, or --json lines)",
        description="Decode frictiond's FRICTION_ESTIMATE/FRICTION_WHEEL frames with the output DBC and "
        "show MuMax, status, confidence, per-wheel values, input freshness and rates, E2E health and "
        "undecodable frames. Keys: q quit, p pause, r reset counters. With --json, print one JSON "
        "object per FRICTION_ESTIMATE instead.",
    )
    add_config_argument(parser)
    parser.add_argument("--interface", "-i", metavar="I", help="python-can interface (default: the config's)")
    parser.add_argument("--channel", metavar="C", help="bus channel (default: the config's, e.g. vcan0)")
    parser.add_argument("--log", metavar="FILE", help="play a log file (.log/.asc/.blf/.csv/.trc) instead of a bus")
    parser.add_argument("--speed", type=_speed, default=None, metavar="X",
                        help="with --log: pace as a multiple of real time (default 1; 0 = as fast as possible)")
    parser.add_argument("--json", action="store_true",
                        help="one JSON object per estimate on stdout instead of the screen")
    parser.set_defaults(func=_do_monitor)


def _do_monitor(args: argparse.Namespace) -> int:
    if args.log and (args.interface or args.channel):
        return fail("monitor: --log and --interface/--channel exclude each other", 2)
    if args.speed is not None and not args.log:
        return fail("monitor: --speed only applies to --log", 2)
    speed = 1.0 if args.speed is None else args.speed

    from ..codec import validate_against_dbc
    from ..config import ConfigError
    from ..monitor import MonitorModel

    config = load_config_or_exit(args.config, check_dbc=False)
    try:
        input_codec, output_codec = validate_against_dbc(config)
    except ConfigError as exc:
        print(f"frictiond: config error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    model = MonitorModel(output_codec, input_codec, vehicle=config.vehicle)

    if not args.json:
        if not (sys.stdout.isatty() and sys.stdin.isatty()):
            return fail("monitor: the full-screen view needs a terminal; use --json for pipes and files", 2)
        try:
            from .. import monitor_tui
        except ImportError as exc:
            return fail(f"monitor: no curses on this system ({exc}); use --json", EXIT_UNAVAILABLE)

    opened = (_log_source(Path(args.log), speed) if args.log
              else _bus_source(args, config, input_codec, output_codec))
    if isinstance(opened, int):
        return opened
    source, waiting_on, bus = opened

    try:
        if args.json:
            return _run_json(model, source)
        return monitor_tui.run(model, source, waiting_on)
    except KeyboardInterrupt:
        return 0
    finally:
        if bus is not None:
            try:
                bus.shutdown()
            except Exception:
                pass


def _log_source(path: Path, speed: float) -> tuple | int:
    """(the log's frames at `speed`, what the view waits on, no bus), or an exit code."""
    from ..busio import LogFormatError, read_log
    from ..monitor import LogSource

    if not path.is_file():
        return fail(f"{path}: no such log file", EXIT_NO_INPUT)
    try:
        frames = read_log(path)
        first = list(itertools.islice(frames, 1))
    except LogFormatError as exc:
        return fail(str(exc), EXIT_DATA_ERROR)
    except (OSError, ValueError) as exc:
        return fail(f"{path}: cannot read log: {exc}", EXIT_DATA_ERROR)
    pace = " (max speed)" if speed == 0 else "" if speed == 1 else f" ×{speed:g}"
    source = LogSource(itertools.chain(first, frames), speed, description=f"log {path.name}{pace}")
    return source, f"log {path}", None


def _bus_source(args: argparse.Namespace, config: Any, input_codec: Any, output_codec: Any) -> tuple | int:
    """(the bus's frames, what the view waits on, the bus to shut down), or an exit code."""
    from ..busio import message_to_frame, open_bus
    from ..monitor import BusSource

    interface = args.interface or config.can.interface
    channel = args.channel or config.can.channel
    ids = set(input_codec.input_ids) | {output_codec.estimate_id, output_codec.wheel_id}
    kwargs = {}
    if config.can.bitrate and interface not in ("socketcan", "virtual"):
        kwargs["bitrate"] = config.can.bitrate
    try:
        bus = open_bus(interface, channel, ids, fd=input_codec.fd, extended_ids=input_codec.extended_input_ids, **kwargs)
    except Exception as exc:  # python-can raises CanError, OSError, ValueError, ImportError...
        return fail(f"cannot open {interface} channel {channel}: {exc}", EXIT_UNAVAILABLE)
    return BusSource(bus, message_to_frame, description=f"{interface} {channel}"), channel, bus


def _run_json(model, source) -> int:
    """One compact JSON object per FRICTION_ESTIMATE; a closed pipe (`| head -1`) ends quietly."""
    out = sys.stdout
    try:
        def emit(obj) -> None:
            if obj is not None:
                out.write(json.dumps(obj, separators=(",", ":"), allow_nan=False) + "\n")
                out.flush()

        while not source.finished:
            frames = source.poll(0.2, time)
            for frame in frames:
                emit(model.feed(frame))
            if not frames:
                emit(model.flush())  # idle: do not sit on an estimate whose wheel frames are not coming
        emit(model.flush())
        if getattr(source, "error", None):
            print(f"frictiond: monitor: {source.error}", file=sys.stderr)
            return EXIT_DATA_ERROR
    except BrokenPipeError:
        # The reader has gone. Point stdout at /dev/null so the interpreter's final flush is quiet.
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
        except (OSError, ValueError):
            pass
        return 0
    return 0


def main(argv: list[str] | None = None) -> int:
    """`python -m frictiond.cli.monitor ...`: the subcommand on its own (as `frictiond monitor ...`)."""
    parser = argparse.ArgumentParser(prog="frictiond")
    add_subparser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["monitor", *(sys.argv[1:] if argv is None else argv)])
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
