"""Argument builders and error handling shared by the subcommands."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

EXIT_DATA_ERROR = 65      # sysexits EX_DATAERR
EXIT_NO_INPUT = 66        # EX_NOINPUT
EXIT_UNAVAILABLE = 69     # EX_UNAVAILABLE
EXIT_CONFIG = 78          # EX_CONFIG: systemd's RestartPreventExitStatus


def add_config_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config",
        "-c",
        metavar="CFG",
        default=None,
        help="frictiond YAML config (default: the built-in frictiond.yaml)",
    )


def load_config_or_exit(path: str | None, check_dbc: bool = True):  # -> Config, or SystemExit(78)
    """The validated config, checked against its DBC(s); exit 78 with one line if unusable."""
    from ..config import ConfigError, default_config_path, load_config

    try:
        config = load_config(Path(path) if path else default_config_path())
        if check_dbc:
            from ..codec import validate_against_dbc

            validate_against_dbc(config)
        return config
    except ConfigError as exc:
        print(f"frictiond: config error: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_CONFIG) from None


def fail(message: str, code: int) -> int:
    print(f"frictiond: {message}", file=sys.stderr)
    return code
