"""`frictiond` command line: one module per subcommand, listed explicitly."""
from __future__ import annotations

import argparse
import importlib
import logging
import sys
from typing import Sequence

from .. import __version__

# (module, what it needs beyond the core) — a command whose optional dependency is missing is
# still listed, and says how to install it when called.
COMMAND_MODULES = (
    "demo",
    "simulate",
    "replay",
    "run",
    "monitor",
    "check_config",
    "fleet",          # needs the `fleet` extra (dask, pyarrow) when called, not to be listed
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="frictiond",
        description="Online tyre/road friction estimation from CAN (static LuGre, trust-region fit).",
    )
    parser.add_argument("--version", action="version", version=f"frictiond {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    subparsers = parser.add_subparsers(title="commands", dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"frictiond.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name and exc.name.startswith("frictiond.cli"):
                continue  # command not built in this version
            raise
        module.add_subparser(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="frictiond: %(levelname)s: %(message)s")
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # Output piped into `head` and friends: not an error of ours.
        try:
            sys.stdout = None  # type: ignore[assignment]
        finally:
            return 0


if __name__ == "__main__":
    sys.exit(main())
