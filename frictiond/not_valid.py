"""Why an estimate is not VALID, in words: what `frictiond replay` sums over a log's braking.

The estimator leaves one reason per update (`LugreTrustRegionEstimator.not_valid_reason`, empty
when VALID): no wheel's data showed the peak (with the wheels' most common verdict), a bar on
VALID whatever the confidence, or a confidence short of the threshold. Users asking why a stop
stayed CONVERGING get the estimator's own answer, not a guess from its status alone.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from typing import Any

NOT_EXCITED = "no peak shown"
LOW_CONFIDENCE = "confidence below the VALID threshold"
BELOW_STOP_FLOOR = "μ_max below the grip the car used this stop"
MISFIT = "the static model misfits this tyre (changes of road too often)"
UNSHOWN_WHEELS = "μ_max leans on wheels that have not shown their peak"
UNSAMPLED_SIDE = "μ_max leans on a side of the car with no usable sample"
FEW_SAMPLES = "too few usable samples"
BODY_SUM = "no peak shown in the car's total force"

# A wheel verdict that is a number against a threshold reads, short of it, as what it missed.
_SHORT_OF = {"proximity": "short of the fitted peak"}


def wheel_verdict_words(why: Any) -> str:
    """A wheel's excitation verdict (`PeakEvidence._excitation_why` entry: a string, or a format
    and its value) without its number: "still rising (0.62)" → "still rising"."""
    text = why if isinstance(why, str) else why[0]
    words = text.split("{", 1)[0].strip().rstrip("(").strip()
    return _SHORT_OF.get(words, words)


def body_sum_reason(verdict: str) -> str:
    """`BODY_SUM` with why the fit of the car's total force does not show the peak."""
    return f"{BODY_SUM} ({verdict})"


def not_excited_reason(wheel_whys: Sequence[Any]) -> str:
    """`NOT_EXCITED` with the verdict most of the wheels gave at the last check."""
    counts = Counter(w for w in map(wheel_verdict_words, wheel_whys) if w)
    if not counts:
        return NOT_EXCITED
    return f"{NOT_EXCITED} ({counts.most_common(1)[0][0]})"
