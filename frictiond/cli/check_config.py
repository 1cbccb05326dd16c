"""`frictiond check-config`: validate a config against its DBC(s) and show the resolved mapping."""
from __future__ import annotations

import argparse
import sys

from .common import EXIT_CONFIG


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "check-config",
        help="validate a config against its DBC and print the resolved signal mapping",
        description="Loads the config and its DBC file(s), binds every input to its DBC signal and prints "
        "message, signal, unit, conversion and expected rate. Exit 78 naming the first problem found.",
    )
    parser.add_argument("config_path", metavar="CFG", nargs="?", help="config file (default: the built-in one)")
    parser.add_argument("--config", "-c", dest="config_option", metavar="CFG", help="the same, as an option")
    parser.set_defaults(func=_do_check)


def _do_check(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..codec import validate_against_dbc
    from ..config import ConfigError, default_config_path, load_config
    from ..input_names import OPTIONAL_INPUTS, REQUIRED_INPUTS

    chosen = args.config_path or args.config_option
    path = Path(chosen) if chosen else default_config_path()
    try:
        config = load_config(path)
        input_codec, output_codec = validate_against_dbc(config)
    except ConfigError as exc:
        print(f"frictiond: config error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    out = sys.stdout
    print(f"config   {config.path}", file=out)
    print(f"dbc      {', '.join(str(p) for p in config.can.dbc)} (strict={config.can.dbc_strict})", file=out)
    print(f"bus      {config.can.interface} {config.can.channel}", file=out)
    print(f"estimator {config.estimator.kind}", file=out)
    messages = {m.name: m for m in input_codec.input_messages()}
    mw = max(len("message"), *(len(n) for n in messages))
    sw = max(len("signal"), *(len(r.signal) + (6 + len(str(list(r.multiplexer_ids))) if r.multiplexer_ids else 0)
                               for r in input_codec.resolved))
    print(f"\n{'input':18s} {'message':{mw}s} {'signal':{sw}s} {'dbc unit':8s} {'as':6s} {'scale':>13s} "
          f"{'to SI':>11s}  rate", file=out)
    resolved = {r.name: r for r in input_codec.resolved}
    for name in REQUIRED_INPUTS + OPTIONAL_INPUTS:
        r = resolved.get(name)
        if r is None:
            tag = "(absent: optional)" if name in OPTIONAL_INPUTS else "(MISSING)"
            print(f"{name:18s} {tag}", file=out)
            continue
        msg = messages[r.message]
        rate = _rate(msg.period_s, input_codec.pages(r.message) if r.multiplexer_ids else 1)
        scale = f"×{r.scale:g}" + (f" {r.offset:+g}" if r.offset else "")
        conv = f"×{r.scale * r.factor:.6g}" + (f" {r.offset * r.factor:+.4g}" if r.offset else "")
        mux = f" mux {list(r.multiplexer_ids)}" if r.multiplexer_ids else ""
        note = f"  [{r.note}]" if r.note else ""
        print(f"{name:18s} {r.message:{mw}s} {r.signal + mux:{sw}s} {r.dbc_unit or '-':8s} {r.unit:6s} {scale:>13s} "
              f"{conv:>11s}  {rate}{note}", file=out)
    print("\nmessages", file=out)
    for m in sorted(messages.values(), key=lambda m: m.frame_id):
        counter = input_codec.counter_signal(m.name)
        kind = f", multiplexed ({input_codec.pages(m.name)} pages)" if m.is_multiplexed else ""
        ident = f"0x{m.frame_id:08X} (29-bit)" if m.is_extended else f"0x{m.frame_id:03X}"
        print(f"  {m.name:{mw}s} {ident}  {m.length} bytes  {_rate(m.period_s, 1)}{kind}  "
              + (f"alive counter {counter} checked" if counter else "no alive counter"), file=out)
    if input_codec.fd:
        print("CAN FD   some inputs are CAN FD frames: a socketcan bus is opened for FD "
              "(another interface needs its own FD settings)", file=out)
    print(f"\ntrigger  {input_codec.trigger_message} (one estimator update per frame)", file=out)
    for partner, names in input_codec.wheel_partners.items():
        print(f"         {', '.join(names)} from {partner}: interpolated at each trigger frame's instant "
              "(an update waits for its next frame)", file=out)
    print(f"outputs  FRICTION_ESTIMATE 0x{output_codec.estimate_id:03X}, FRICTION_WHEEL 0x{output_codec.wheel_id:03X} "
          f"(from {config.can.output_dbc})", file=out)
    print("OK", file=out)
    return 0


def _rate(period_s: float | None, pages: int) -> str:
    """Expected rate of a signal: its message's rate, divided among the multiplexer pages."""
    if not period_s:
        return "? (no GenMsgCycleTime: measured from the first frames)"
    text = f"{1 / period_s:.0f} Hz"
    if pages > 1:
        text += f" ({1 / (period_s * pages):.0f} Hz per page)"
    return text
