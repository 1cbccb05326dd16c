"""False FAULT during normal ABS (issue 21, class 1): clean stops of the randomised campaign whose
ABS dumps slowly (family "a-threshold": wheels run into slip 0.6-1.0 for tens of ms), replayed;
per stop whether any output was FAULT and why, and the false VALID outputs (> 20 % off).

    python benchmarks/deep_slip.py [--stops 40] [--family a-threshold] [--first-seed 0]
"""
from __future__ import annotations

import argparse
import sys
from collections import Counter

import numpy as np

from frictiond.faults import replay_on_bus
from frictiond.samples import Status


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stops", type=int, default=40)
    parser.add_argument("--family", default="a-threshold")
    parser.add_argument("--first-seed", type=int, default=0)
    args = parser.parse_args(argv)
    try:
        from frictiond.campaign.draw import draw_stop
        from frictiond.campaign.simulate import simulate_stop
    except ImportError:
        print("needs the randomised campaign (frictiond.campaign)")
        return 2
    by_manoeuvre: dict[str, list[float]] = {}
    reasons: Counter = Counter()
    stops_with: Counter = Counter()     # stops where the front end counted each fault at least once
    faulted = valid = false_valid = outputs = faults = 0
    for seed in range(args.first_seed, args.first_seed + args.stops):
        stop = simulate_stop(draw_stop(seed, args.family))
        t = np.array([r["time_s"] for r in stop.truth])
        mu = np.array([r["mu_max"] for r in stop.truth])
        pipeline, estimates, bad = replay_on_bus(stop.config(), stop.frames)
        n_fault = sum(e.status == Status.FAULT for e in estimates)
        faults += n_fault
        outputs += len(estimates)
        faulted += n_fault > 0
        reasons.update(pipeline.stats.faults)
        stops_with.update(pipeline.stats.faults.keys())
        by_manoeuvre.setdefault(stop.spec.manoeuvre, []).append(n_fault > 0)
        for e in estimates:
            if e.status == Status.VALID:
                truth = mu[min(int(np.searchsorted(t, e.time_s)), len(t) - 1)]
                valid += 1
                false_valid += abs(e.mu_max - truth) > 0.2 * truth
    print(f"{args.stops} clean campaign stops, ABS family {args.family!r}: {faulted} with a FAULT output "
          f"({faulted / args.stops:.0%}); FAULT {faults / max(outputs, 1):.2%} of all outputs; "
          f"false VALID {false_valid} of {valid} VALID")
    for name, flags in sorted(by_manoeuvre.items()):
        print(f"  {name:10s} {sum(flags)}/{len(flags)} stops with FAULT")
    print("front-end faults counted: " + ("; ".join(f"{k}: {v} ({stops_with[k]} stops)" for k, v in reasons.most_common())
                                          or "none"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
