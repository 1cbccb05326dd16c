"""How the share of corrupted input costs the estimate its confidence and its VALID (issue 22).

The front end rejects frames that break physics or their own history (`plausibility`) and puts
the share of rejected or repaired input frames of about the last second into each sample
(`PhysicalSample.input_suspect_share`). What the gate rejects never reaches the fit, but the
corruption that looks plausible gets through at a rate that grows with it. So:

- up to `FREE_SHARE` (a few frames a second on a busy bus) costs nothing;
- beyond it the confidence falls linearly, to `FACTOR_AT_LEAVE` at `LEAVE_VALID_SHARE`;
- above `LEAVE_VALID_SHARE` (8 % of the input frames) the estimate is not VALID: CONVERGING,
  with the confidence capped, until the share is back under `RETURN_VALID_SHARE` (hysteresis:
  no flicker at the edge). The replay summary and the monitor say why.
"""
from __future__ import annotations

import math

FREE_SHARE = 0.03
LEAVE_VALID_SHARE = 0.08
RETURN_VALID_SHARE = 0.06
FACTOR_AT_LEAVE = 0.8
CAPPED_CONFIDENCE = 0.3
REASON = "corrupt input"


def confidence_factor(share: float) -> float:
    """The factor on the estimator's confidence for a suspect share of the input."""
    if not math.isfinite(share) or share <= FREE_SHARE:
        return 1.0 if share <= FREE_SHARE else FACTOR_AT_LEAVE
    x = min(1.0, (share - FREE_SHARE) / (LEAVE_VALID_SHARE - FREE_SHARE))
    return 1.0 - (1.0 - FACTOR_AT_LEAVE) * x


def leaves_valid(share: float, was_out: bool) -> bool:
    """Whether the status must leave VALID at this share (`was_out`: it had left last update)."""
    if not math.isfinite(share):
        return True
    return share > (RETURN_VALID_SHARE if was_out else LEAVE_VALID_SHARE)
