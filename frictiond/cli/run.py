"""`frictiond run`: the daemon on a live bus (systemd `Type=notify`)."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from .common import EXIT_CONFIG, add_config_argument, fail, load_config_or_exit


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "run",
        help="run the estimator on a live CAN bus (the daemon)",
        description="Receive the configured input frames (kernel filters on SocketCAN), estimate, and "
        "send FRICTION_ESTIMATE/FRICTION_WHEEL at once. Speaks sd_notify when started by systemd "
        "(READY, STATUS, WATCHDOG, STOPPING). SIGTERM/SIGINT stop cleanly; SIGHUP reloads the config.",
    )
    add_config_argument(parser)
    parser.add_argument("--interface", "-i", metavar="IF", help="python-can interface (overrides can.interface)")
    parser.add_argument("--channel", metavar="CH", help="CAN channel, e.g. can0 (overrides can.channel)")
    parser.add_argument("--state-file", metavar="PATH", help="persisted estimator state (overrides daemon.state_file)")
    parser.add_argument("--estimate-log", metavar="LOG",
                        help="log every sent frame to LOG (.log/.blf/.asc; overrides output.estimate_log)")
    parser.set_defaults(func=_do_run)


def _do_run(args: argparse.Namespace) -> int:
    config = load_config_or_exit(args.config)
    if getattr(args, "verbose", 0) < 2:
        logging.getLogger("can").setLevel(logging.WARNING)   # python-can's INFO per socket opened
    from ..daemon import Daemon, Overrides, StartupError

    overrides = Overrides(
        interface=args.interface,
        channel=args.channel,
        state_file=Path(args.state_file).absolute() if args.state_file else None,
        estimate_log=Path(args.estimate_log).absolute() if args.estimate_log else None,
    )
    config_path = Path(args.config).absolute() if args.config else None
    try:
        daemon = Daemon(config, config_path=config_path, overrides=overrides)
        return daemon.run()
    except StartupError as exc:
        return fail(f"config error: {exc}", EXIT_CONFIG)
