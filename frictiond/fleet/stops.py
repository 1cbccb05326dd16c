"""Braking stops of one replay, found from the front end's physical samples.

A *stop* is a span of braking: the front end's `braking` flag (brake pressure above the push-out
pressure on any wheel) with the tyres retarding the car by at least `MIN_BRAKING_G` (pressure
noise around a push-out of 0 bar sets the flag while rolling freely), held, with gaps shorter than `MERGE_GAP_S` bridged (an ABS release cycle
or a dropped frame is not the end of a stop), lasting at least `MIN_DURATION_S` and slowing the
car by at least `MIN_SPEED_DROP_MPS` (a foot resting on the pedal at constant speed is no stop).

Per stop it reports what the estimator said over that span: the status at its end, the `MuMax`
of the last VALID estimate in it (what a function using the estimate would have held), that
estimate's confidence, and the time from the stop's start to the first VALID estimate.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..replay import ReplayRecorder
from ..samples import FrictionEstimate, PhysicalSample, Status

MIN_BRAKING_G = 0.05     # Σ tyre force / Σ normal force: ~0.5 m/s² of braking
MERGE_GAP_S = 0.3
MIN_DURATION_S = 0.3
MIN_SPEED_DROP_MPS = 1.0
# Estimates carry the time of the frame that caused them, samples the (filter-delayed) instant
# they describe: an estimate this long after a stop's last braking sample still belongs to it.
END_MARGIN_S = 0.1


@dataclass
class AlignedRecorder(ReplayRecorder):
    """A `ReplayRecorder` that also keeps, per output, the sample it was computed with (or None).

    `ReplayRecorder.samples` drops repeats, so its entries do not line up with the estimates;
    stop detection needs each estimate next to the sample behind it.
    """

    pairs: list[tuple[FrictionEstimate, PhysicalSample | None]] = field(default_factory=list)

    def record(self, estimate: FrictionEstimate | None, sample: PhysicalSample | None) -> None:
        if estimate is not None:
            self.pairs.append((estimate, sample))


@dataclass(frozen=True)
class Stop:
    start_s: float              # log time of the first braking sample
    end_s: float                # log time of the last braking sample
    speed_start_mps: float
    speed_end_mps: float
    final_status: str           # `Status` name of the last estimate within the stop
    mu_max_valid: float         # MuMax of the last VALID estimate within the stop; NaN if none
    confidence: float           # that estimate's confidence (else the last estimate's)
    time_to_valid_s: float      # first VALID estimate − start_s; NaN if never VALID
    valid_share: float          # VALID estimates / estimates within the stop

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


def is_braking(sample: PhysicalSample) -> bool:
    return sample.braking and sum(sample.tyre_force_n) >= MIN_BRAKING_G * sum(sample.normal_force_n)


def braking_spans(samples: list[PhysicalSample]) -> list[tuple[int, int]]:
    """Index ranges [first, last] of the samples that form stops (see the module's rules)."""
    spans: list[tuple[int, int]] = []
    first = last = None
    for k, sample in enumerate(samples):
        if not is_braking(sample):
            continue
        if last is not None and sample.time_s - samples[last].time_s <= MERGE_GAP_S:
            last = k
            continue
        if first is not None:
            spans.append((first, last))
        first = last = k
    if first is not None:
        spans.append((first, last))
    return [(a, b) for a, b in spans
            if samples[b].time_s - samples[a].time_s >= MIN_DURATION_S
            and samples[a].speed_mps - samples[b].speed_mps >= MIN_SPEED_DROP_MPS]


def find_stops(recorder: AlignedRecorder) -> list[Stop]:
    """The stops of a replay recorded with `AlignedRecorder`, in time order."""
    samples = [s for _, s in recorder.pairs if s is not None]
    # One sample stays set while the pipeline holds an estimate: count each once.
    unique = [s for k, s in enumerate(samples) if k == 0 or s is not samples[k - 1]]
    stops = []
    for a, b in braking_spans(unique):
        start_s, end_s = unique[a].time_s, unique[b].time_s
        inside = [e for e, _ in recorder.pairs if start_s <= e.time_s <= end_s + END_MARGIN_S]
        stops.append(_summarise(start_s, end_s, unique[a].speed_mps, unique[b].speed_mps, inside))
    return stops


def _summarise(start_s: float, end_s: float, speed_start_mps: float, speed_end_mps: float,
               estimates: list[FrictionEstimate]) -> Stop:
    valid = [e for e in estimates if e.status == Status.VALID]
    last = estimates[-1] if estimates else None
    held = valid[-1] if valid else last
    return Stop(
        start_s=start_s,
        end_s=end_s,
        speed_start_mps=speed_start_mps,
        speed_end_mps=speed_end_mps,
        final_status=Status(last.status).name if last is not None else "NONE",
        mu_max_valid=valid[-1].mu_max if valid else math.nan,
        confidence=held.confidence if held is not None else math.nan,
        time_to_valid_s=valid[0].time_s - start_s if valid else math.nan,
        valid_share=len(valid) / len(estimates) if estimates else 0.0,
    )
