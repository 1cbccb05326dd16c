"""Cycle times the DBC does not give, measured from a message's first frames (`CycleTimeProbe`).

A message's cycle time sizes the front end: the wheel-speed derivative filter's window, the
staleness limits, the estimator's per-sample evidence counts. Without a `GenMsgCycleTime` in the
DBC 100 Hz is assumed; a car that sends at 50 Hz then gets a filter twice as long in time as
meant and staleness limits a single lost frame passes. The pipeline measures such messages over
their first frames and, where they are off what was assumed, rebuilds its front end once with
what it measured.
"""
from __future__ import annotations

import math
import statistics
from collections.abc import Mapping

FRAMES_TO_MEASURE = 16     # a message's cycle is the median of its first intervals (of the messages seen) ...
MIN_FRAMES = 5             # ... or of at least this many, once
MAX_WAIT_S = 1.0           # ... this long has passed since the first probed frame
OFF_BY = 0.15              # a measured cycle this far from the assumed one replaces it


class CycleTimeProbe:
    """The cycle times of the messages the DBC gives none for, from their first frames."""

    def __init__(self, assumed: Mapping[str, float]) -> None:
        self.assumed = dict(assumed)
        self._times: dict[str, list[float]] = {name: [] for name in assumed}
        self._first_s: float | None = None

    def see(self, message: str, time_s: float) -> dict[str, float] | None:
        """Note a frame; once the cycles are known, those measured off the assumed ones by more
        than `OFF_BY` (possibly none), else None (keep calling)."""
        times = self._times.get(message)
        if times is None or not math.isfinite(time_s):
            return None           # (a message whose cycle the DBC gives; a time no clock reads)
        if len(times) < FRAMES_TO_MEASURE:
            times.append(time_s)
        if self._first_s is None:
            self._first_s = time_s
        # (a message not seen at all yet, an optional input this car may not send, is not waited for)
        if (min(len(t) for t in self._times.values() if t) < FRAMES_TO_MEASURE
                and time_s - self._first_s < MAX_WAIT_S):
            return None
        measured = {}
        for name, t in self._times.items():
            intervals = [b - a for a, b in zip(t, t[1:]) if b > a]
            if len(intervals) + 1 >= MIN_FRAMES:
                cycle = statistics.median(intervals)
                if abs(cycle - self.assumed[name]) > OFF_BY * self.assumed[name]:
                    measured[name] = round(cycle, 3)   # (whole ms, as a DBC gives them)
        return measured
