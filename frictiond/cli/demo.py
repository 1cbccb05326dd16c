"""`frictiond demo`: the live pipeline on python-can's in-process virtual bus, fed by the simulator.

Three endpoints share one virtual channel, as ECUs share a wire: the simulated vehicle sends
its sensor frames, frictiond answers with FRICTION_ESTIMATE/FRICTION_WHEEL, and a listener
decodes those (checking their E2E protection) and prints the estimate next to the truth.
"""
from __future__ import annotations

import argparse
import sys

from .common import add_config_argument, load_config_or_exit

DEFAULT_SCENARIOS = "dry,wet,snow"


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "demo",
        help="watch the estimator converge on simulated braking (no car, no vcan needed)",
        description="Stream simulated braking manoeuvres over python-can's virtual bus into the "
        "daemon's pipeline and print the decoded estimate beside the simulator's truth.",
    )
    add_config_argument(parser)
    parser.add_argument("--scenarios", default=DEFAULT_SCENARIOS,
                        help=f"comma-separated scenario names (default {DEFAULT_SCENARIOS})")
    parser.add_argument("--speed", type=float, default=4.0,
                        help="pace as a multiple of real time (default 4; 1 = real time)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--channel", default="frictiond-demo", help="virtual bus channel name")
    parser.set_defaults(func=_do_demo)


def _do_demo(args: argparse.Namespace) -> int:
    from ..simulator import SCENARIOS

    names = [s.strip() for s in args.scenarios.split(",") if s.strip()]
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown or not names:
        print(f"frictiond: unknown scenario(s) {', '.join(unknown) or '(none)'}; "
              f"choose from {', '.join(sorted(SCENARIOS))}", file=sys.stderr)
        return 2
    if args.speed <= 0:
        print("frictiond: --speed must be positive", file=sys.stderr)
        return 2
    config = load_config_or_exit(args.config)
    from ..demo import run_demo

    results = run_demo(config, names, pace=args.speed, seed=args.seed, channel=args.channel, out=sys.stdout)
    print()
    print(f"{'scenario':12s} {'final status':12s} {'MuMax':>6s} {'truth':>6s} {'error':>6s}")
    for r in results:
        print(f"{r.scenario:12s} {r.final_status:12s} {r.mu_max:6.3f} {r.truth_mu_max:6.3f} {r.mu_max - r.truth_mu_max:+6.3f}")
    return 0 if all(r.final_status != "FAULT" for r in results) else 1
