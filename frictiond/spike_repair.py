"""A wrong value the gate let through, found by the frames after it (`SpikeRepair`, a part of
`plausibility.InputGate`; its state is the gate's): a spike revoked when the genuine frame after
it was rejected for its rate, a new level followed once enough rejected frames agree on it, and
a value off both its (agreeing) neighbours repaired to their interpolation."""
from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, MutableMapping

if TYPE_CHECKING:
    from .plausibility import _Track

REANCHOR_FRAMES = 5                 # rejected frames in a row that agree with each other: a new level


class SpikeRepair:
    """`_revoke_spike`, `_follows_new_level` and `repair_spike`; the spans a sample may have
    taken a wrong value from go to `repaired`."""

    def _revoke_spike(self, message: str, track: _Track, time_s: float, values: Mapping[str, float]) -> bool:
        """A frame rejected for its rate against the last accepted one, but within the rate
        limits of the one before: when the last accepted frame leaves both its neighbours (a
        spike within the rate limit of its predecessor, which made the genuine frame after it
        look too fast), it is revoked (counted as a spike; the caller takes it out of its
        histories) and the track goes on from the frame before it. True when it was."""
        accepted = track.accepted
        if track.rival or len(accepted) < 2 or accepted[-1][0] != track.time_s:
            return False
        before_time, before_values = accepted[-2]
        last_time, last_values = accepted[-1]
        if not before_time < last_time < time_s or not self._agrees(time_s, values, accepted[-2]):
            return False
        spike = False
        for name, b in last_values.items():
            a, c = before_values.get(name), values.get(name)
            tolerance = self._spike.get(name)
            if a is None or c is None or tolerance is None:
                continue
            # (off both neighbours, each by more than they are apart: the one frame that does not fit)
            if min(abs(b - a), abs(b - c)) > max(tolerance, abs(c - a)):
                spike = True
                break
        if not spike:
            return False
        self._drop_last_accepted(message, track, "spike")
        self.repaired.append((before_time, time_s))
        return True

    def _follows_new_level(self, time_s: float, track: _Track, values: Mapping[str, float]) -> bool:
        """A frame rejected for its rate or as a marker: whether enough rejected frames in a row
        agree with each other to say the last accepted one was wrong, the sensor came back from a
        dead spell, or its zeros are what it reads (followed; the front end restarts its filter)."""
        agrees = self._agrees(time_s, values, track.rejected)
        track.rejected = (time_s, dict(values))
        track.agreeing = track.agreeing + 1 if agrees else 0
        return track.agreeing >= REANCHOR_FRAMES - 1

    def repair_spike(self, message: str, series: MutableMapping[str, tuple]) -> None:
        """The frame before the newest of `message`: a value off both its neighbours (which agree)
        by more than the signal's `spike` tolerance is replaced by their interpolation."""
        spikes = self._spike
        repaired = False
        for name, (times, values) in series.items():
            spike = spikes.get(name)
            if spike is None or len(values) < 3:
                continue
            a, b, c = values[-3], values[-2], values[-1]
            ta, tb, tc = times[-3], times[-2], times[-1]
            if not ta < tb < tc:
                continue
            mid = a + (c - a) * (tb - ta) / (tc - ta)
            if abs(b - mid) > spike and abs(c - a) < 0.5 * spike and (b - a) * (b - c) > 0.0:
                values[-2] = mid
                repaired = True
                if not self.repaired or self.repaired[-1] != (ta, tc):   # (once per frame, not per signal)
                    self.repaired.append((ta, tc))
        if repaired:
            self.counts["spike"] += 1
            # (the frame was counted as accepted: now it counts as suspect)
            self._share_bad += 1.0
