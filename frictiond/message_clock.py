"""A frame's time against its message's clock and the bus's (`MessageClock`, a part of
`plausibility.InputGate`; its state is the gate's): a clock step (followed once enough frames
agree on the new time base), a reordered frame, an exact repeat, a frame too early for the
message's cycle (a second source)."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Mapping

if TYPE_CHECKING:
    from .plausibility import _Track

FRAMES_TO_FOLLOW_A_CLOCK_STEP = 6   # consecutive frames that agree on a new time base
CLOCK_STEP_S = 0.25                 # a frame this far from the bus's time is a clock step
REORDER_S = 0.05                    # ... or this far behind its message's last frame
EARLY_SHARE_OF_PERIOD = 0.6         # sooner than this share of the cycle: a second source (±2 ms jitter at 10 ms)
_EARLY_PAIR = 1.0 + EARLY_SHARE_OF_PERIOD     # (the early test's bound on two intervals, as `_clock` computes it)


class MessageClock:
    """`_clock`: the kind of a frame's timing fault, or None."""

    def _clock(self, time_s: float, track: _Track, values: Mapping[str, float]) -> str | None:
        if not math.isfinite(time_s):
            return "clock step"
        bus = self._bus_time_s
        if bus > -math.inf and (abs(time_s - bus) > CLOCK_STEP_S or track.time_s - time_s > REORDER_S):
            # Far from every other message's time, or well behind the message's own last frame:
            # one stepped frame, or the clock stepped. Followed once enough frames in a row
            # agree on the new time base.
            if self._step_frames and abs(time_s - self._step_base_s) <= CLOCK_STEP_S:
                self._step_frames += 1
            else:
                self._step_frames = 1
            self._step_base_s = time_s
            if self._step_frames < FRAMES_TO_FOLLOW_A_CLOCK_STEP:
                return "clock step"
            self._bus_time_s = time_s
            for t in self._tracks.values():     # a new time base: the old histories mean nothing
                t.time_s = t.arrival_s = t.rival_s = t.doubted_s = -math.inf
                t.arrival_gap_s = math.inf
                t.rival_last = None
                t.values = {}
                t.accepted.clear()
                t.rival.clear()
            return None
        self._step_frames = 0
        dt = time_s - track.time_s
        if dt == 0.0 and dict(values) == track.values:
            return "duplicate"
        if dt <= 0.0 and track.time_s > -math.inf:
            return "out of order"
        cycle = min(track.period_s, max(track.interval_s, 0.5 * track.period_s))
        # Early, and with the frame before it less than a cycle and a half apart: an extra frame.
        # (An early frame right after a late one is the bus's jitter, as a gateway's buffer or a
        # busy sender delivers them: the two still span two cycles.)
        if (dt < EARLY_SHARE_OF_PERIOD * cycle
                and (time_s - track.arrival_s) + track.arrival_gap_s < (1.0 + EARLY_SHARE_OF_PERIOD) * cycle):
            return "second source"
        return None
