"""The share of input frames of about the last second rejected or repaired as implausible
(`SuspectShare`, a part of `plausibility.InputGate`; its state is the gate's); the estimator
turns it into confidence (`input_quality`)."""
from __future__ import annotations

import math

from .message_clock import CLOCK_STEP_S

SHARE_TIME_CONSTANT_S = 1.0         # `suspect_share` averages over about this long
# Kinds of rejection that are certain and carry no wrong value (an exact repeat, a frame of a
# regular stream arriving late, a frame the codec cannot read, a timestamp a second off):
# counted, not in the suspect share. What is left (out of range, rate, spike, second source,
# a wheel-speed glitch) says that values near the plausible are corrupted too, and some get through.
# A second node's frames told apart by their values and cycles are refused as surely; those that
# could not be told apart, and one taken before the genuine frame showed it up, are suspect
# (`_unsure`, `_revoke`): which of two plausible streams is genuine is then a judgement.
HARMLESS = frozenset({"duplicate", "out of order", "undecodable", "clock step", "second source"})


class SuspectShare:
    """An exponentially forgotten count of all input frames and of the suspect ones."""

    def _reset_suspect_share(self) -> None:
        self._share_time_s = -math.inf
        self._share_all = self._share_bad = 0.0

    def note(self, time_s: float, kind: str | None) -> None:
        """One input frame seen at `time_s`: accepted (`kind` None) or rejected/repaired as `kind`.
        Also for frames refused before the front end (the codec's `DecodeFailure`)."""
        if kind is not None:
            self.counts[kind] += 1
        # (on the bus's time: a frame stepped a second ahead must not age the share by a second)
        if math.isfinite(self._bus_time_s):
            time_s = self._bus_time_s
        elif not math.isfinite(time_s):
            return
        dt = time_s - self._share_time_s
        if dt > 0.0:
            keep = math.exp(-dt / SHARE_TIME_CONSTANT_S)
            self._share_all *= keep
            self._share_bad *= keep
            self._share_time_s = time_s
        elif dt < -CLOCK_STEP_S:
            self._share_time_s = time_s    # (the clock stepped back: go on from here)
        self._share_all += 1.0
        if kind is not None and kind not in HARMLESS:
            self._share_bad += 1.0

    def count_repair(self, kind: str) -> None:
        """A value the front end repaired after admitting its frame (a wheel-speed glitch)."""
        self.counts[kind] += 1
        self._share_bad += 1.0

    def suspect_share(self) -> float:
        """Rejected or repaired input frames over all input frames, over about the last second."""
        return self._share_bad / self._share_all if self._share_all >= 1.0 else 0.0
