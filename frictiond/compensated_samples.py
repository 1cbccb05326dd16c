"""The samples the pipeline hands the estimator: each one sample late, corrected for the tyre's
relaxation lag.

`CompensatedSamples` is a part of `Pipeline` (its relaxation compensator, front end, config and
stats are the pipeline's): `_compensated` passes each front-end result's sample through
`relaxation.RelaxationCompensator`, and a sample held back meanwhile found to have used a spike
is not fitted (`_marked_if_tainted`).
"""
from __future__ import annotations

import math
from dataclasses import replace

from .frontend import FrontEndResult
from .samples import PhysicalSample


class CompensatedSamples:
    """The front end's results with the samples the estimator is to see."""

    def _compensated(self, time_s: float, result: FrontEndResult) -> FrontEndResult:
        """The front end's result with the sample the estimator is to see: each one sample late,
        corrected for the tyre's relaxation lag (`relaxation`); none at the first of a run."""
        if result.sample is None:
            held = self.relaxation.flush()
            # The last sample before a short gap still counts; after a silence it describes a
            # road the car has left (an estimate of it now would be a stale VALID).
            if (held is not None and not result.stale_messages and result.fault is None
                    and time_s - held.time_s <= self.config.frontend.max_gap):
                return replace(result, sample=self._marked_if_tainted(held))
            return result
        compensated = self.relaxation.push(result.sample)
        if compensated is None or time_s - compensated.time_s > self.config.frontend.max_gap:
            # (the first of a run: warming up; a held sample from before a silence is dropped)
            if result.fault is not None:
                self.stats.faults[result.fault] += 1
            return replace(result, sample=None, fault=None)
        if compensated is not result.sample:
            compensated = self._marked_if_tainted(compensated)
        return result if compensated is result.sample else replace(result, sample=compensated)

    def _marked_if_tainted(self, held: PhysicalSample) -> PhysicalSample:
        """A sample held back (`_compensated`): when meanwhile an input value it used was found to
        be a spike (`FrontEnd.tainted`), it is not fitted and gives no floor."""
        if not self.front_end.tainted(held.time_s):
            return held
        return replace(held, usable=(False, False, False, False), body_mu=math.nan)
