"""A second node sending an input message's ID (`SecondSource`, a part of
`plausibility.InputGate`; its state is the gate's): each frame goes to the sender whose trend it
fits, an accepted frame found to be the second node's is taken back, and samples whose sender
stayed in doubt are contested (docs/corruption.md, "Two senders")."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Mapping

if TYPE_CHECKING:
    from .plausibility import _Track

CONTEST_S = 0.15                    # samples this long after a second source's frame are not fitted (a 50 Hz window)
RIVAL_CYCLES = 3.0                  # a second source silent this many cycles has stopped: one track again
# Two sources' frames fit the genuine track clearly better or worse when their misfits (squared
# deviations in each signal's noise allowance and in the bus's jitter) differ by more than this.
SOURCES_DIFFER = 1.0
FITS = 9.0                          # ... and a frame fits a track within 3 allowances (in one signal, or in time)
JITTER_SHARE = 0.15                 # a sender's frames keep its cycle within this share of it (the timing's allowance)
FLOOD_RATE_FACTOR = 2.25            # more frames than this many times the message's rate: a flood


def flooded(track: _Track) -> bool:
    """More frames of the message in the last 0.1 s than `FLOOD_RATE_FACTOR` times its rate."""
    return len(track.arrivals) >= FLOOD_RATE_FACTOR * 0.1 / track.period_s


def _clear(a: float, b: float) -> bool:
    """Whether two misfits tell which sender a frame is from: both fit (the same values: either
    will do), or one fits and the other clearly does not."""
    return max(a, b) <= SOURCES_DIFFER or _told_apart(a, b)


def _told_apart(a: float, b: float) -> bool:
    """Whether one of two misfits fits and the other clearly does not."""
    return min(a, b) <= FITS and abs(a - b) > SOURCES_DIFFER


def _predict(frames, time_s: float, period_s: float) -> dict[str, float] | None:
    """A track's values at `time_s`: on the line through its last two frames (a signal's trend),
    held at the last when they are closer than half a cycle or more than a few cycles apart, or
    old (extrapolated far, the line says nothing); None without a frame."""
    if not frames:
        return None
    t1, v1 = frames[-1]
    if len(frames) < 2:
        return v1
    t0, v0 = frames[-2]
    if not 0.5 * period_s <= t1 - t0 <= 3.0 * period_s or not 0.0 <= time_s - t1 <= 3.0 * period_s:
        return v1   # (two frames much closer than a cycle: their slope is mostly noise)
    w = (time_s - t1) / (t1 - t0)
    return {name: x + w * (x - v0[name]) if name in v0 else x for name, x in v1.items()}


class SecondSource:
    """The gate's handling of two senders of one message."""

    def _choose_source(self, time_s: float, message: str, track: _Track, values: Mapping[str, float],
                       kind: str | None) -> str | None:
        """A frame of a message that two nodes send: None when it continues the genuine track
        (its values checked after), else "second source".

        A second node's frames are each plausible, and it sends at the message's own rate. What
        tells the two apart: the genuine sensor's signal continues its own trend (a wheel, a
        pressure, a car's acceleration cannot jump between frames; a replayed or foreign stream
        does not), and each node keeps its own cycle (a frame is due one cycle after its
        sender's last). Each frame goes to the track it fits better by both (`_misfit`). Only
        when neither fits and they fit about as badly are the next samples not fitted.
        """
        now = self._bus_time_s
        if not track.rival:     # (early after the last accepted frame: a second node)
            return self._first_rival_frame(time_s, message, track, values)
        if time_s - track.time_s > RIVAL_CYCLES * track.period_s and not flooded(track):
            # The track followed has gone silent: the source still sending is the message's
            # (taken over with its frames; the front end restarts its filter at the step).
            # Not in a flood: there no sender can be followed (a FAULT, `persistent`).
            track.accepted.clear()
            track.accepted.extend(track.rival)
            track.time_s, track.values = track.accepted[-1]
            track.rival.clear()
            self.reanchored.add(message)
            return None
        rival = self._misfit(track, track.rival, time_s, values)
        accepted = track.accepted
        if time_s - track.time_s < 0.5 * track.cadence_s and len(accepted) >= 3:
            # The accepted frame of this cycle and this one: one node's each. Judged as a pair
            # against each sender's frames before them, so that one frame taken wrongly (a wheel
            # under ABS can leave its trend as far as a replay does) is put right a frame later.
            last_time, last_values = accepted[-1]
            before = list(accepted)[:-1]
            keep = self._misfit(track, before, last_time, last_values) + rival
            swap = self._misfit(track, before, time_s, values) + self._misfit(track, track.rival, last_time, last_values)
            if self._newer_is_genuine(message, track, keep, swap):
                self._doubt_unidentified(track, values, None)
                return None
            kind = "second source"
        else:
            genuine = self._misfit(track, accepted, time_s, values)
            kind = None if genuine <= rival else "second source"
            if not _clear(genuine, rival):
                self._unsure(track)
        self._doubt_unidentified(track, values, kind)
        if kind is not None:
            track.to_rival((time_s, dict(values)), now)
        return kind

    def _doubt_unidentified(self, track: _Track, values: Mapping[str, float], kind: str | None) -> None:
        """Two senders never told apart (`_Track.identified`) whose values have parted: each
        frame fits its own track, so which one is genuine is a judgement (`_unsure`) as long
        as both send: a replay of a flat accelerometer, followed by chance, stays flat through
        a brake onset that the genuine frames show."""
        if track.identified:
            return
        other = track.values if kind is not None else track.rival[-1][1] if track.rival else None
        if other is None or self._distance(values, other) > SOURCES_DIFFER:
            self._unsure(track)

    def _newer_is_genuine(self, message: str, track: _Track, keep: float, swap: float) -> bool:
        """The accepted frame and a newer one, one of them a second node's: `keep` the misfit of
        the senders as taken, `swap` with the two frames exchanged. When the exchange fits clearly
        better (and fits at all), the accepted frame is revoked and the newer one is genuine;
        when the misfits cannot tell, the frame is a judgement (`_unsure`)."""
        if not _clear(keep, swap):
            self._unsure(track)
        if keep - swap > SOURCES_DIFFER and swap <= FITS:
            self._revoke(message, track, self._bus_time_s)
            return True
        return False

    def _revoke(self, message: str, track: _Track, now: float) -> None:
        """The last accepted frame was the second node's: out of the track (back to the one
        before), to the rival's, counted; the caller takes it out of its histories (`revoked`)."""
        track.to_rival(self._drop_last_accepted(message, track, "second source"), now)

    def _drop_last_accepted(self, message: str, track: _Track, kind: str) -> tuple[float, dict[str, float]]:
        """The last accepted frame out of the track (back to the one before), counted as `kind`
        and as suspect (it was counted as accepted); the caller takes it out of its histories
        (`revoked`). Returns it."""
        last = track.accepted.pop()
        track.time_s, track.values = track.accepted[-1]
        self.revoked[message] = last[0]
        self.counts[kind] += 1
        self._share_bad += 1.0
        return last

    def _unsure(self, track: _Track) -> None:
        """Which of two sources sent a frame of `track`'s message is not certain: the next
        samples are not fitted, and the frame counts as suspect."""
        self._contested_s = max(self._contested_s, self._bus_time_s)
        track.doubted_s = self._bus_time_s
        self._doubt = True

    def _first_rival_frame(self, time_s: float, message: str, track: _Track, values: Mapping[str, float]) -> str | None:
        """The first frame seen early after the message's last accepted one: one of the two is a
        second node's. The one that fits the frames before them is genuine; when that is the
        newer, the accepted one is revoked (counted as the second source's)."""
        track.rival_s = self._bus_time_s
        accepted = track.accepted
        if len(accepted) < 2 or accepted[-1][0] != track.time_s:
            track.identified = False
            track.to_rival((time_s, dict(values)), self._bus_time_s)
            return "second source"
        before = list(accepted)[:-1]
        last_time, last_values = accepted[-1]
        last = self._misfit(track, before, last_time, last_values)
        new = self._misfit(track, before, time_s, values)
        track.identified = _told_apart(last, new)
        if self._newer_is_genuine(message, track, last, new):
            return None
        track.to_rival((time_s, dict(values)), self._bus_time_s)
        return "second source"

    def _misfit(self, track: _Track, frames, time_s: float, values: Mapping[str, float]) -> float:
        """How badly a frame fits a sender's frames: its values off their trend (`_distance`)
        plus its time off their cycle, in the bus's jitter (a lost frame: the next cycle)."""
        cycle = track.cadence_s
        since = time_s - frames[-1][0]
        late = since - max(1.0, round(since / cycle)) * cycle
        return self._distance(values, _predict(frames, time_s, track.period_s)) + (late / (JITTER_SHARE * cycle)) ** 2

    def _distance(self, values: Mapping[str, float], predicted: Mapping[str, float] | None) -> float:
        """How far a frame's values are from a prediction: the sum of each signal's squared
        deviation in its noise allowance (each signal is evidence; a replay is off in most of
        them); inf without a prediction or for a non-finite value."""
        if predicted is None:
            return math.inf
        bounds = self._bounds
        total = 0.0
        for name, x in values.items():
            b = bounds.get(name)
            p = predicted.get(name)
            if b is not None and p is not None:
                total += ((x - p) / b[4]) ** 2
        return total if total == total else math.inf

    def contested(self, time_s: float) -> bool:
        """Whether a second node sent one of the messages within `CONTEST_S` before `time_s`:
        which frames came from it is not certain (one may have been taken before the other
        was seen), so no sample that may include them is fitted."""
        return 0.0 <= time_s - self._contested_s <= CONTEST_S

    def second_source_value(self, name: str, time_s: float) -> float | None:
        """Signal `name` in the last frame of a second node that sent within `CONTEST_S` before
        `time_s` (None when none did): with the frame taken, the two candidates for its value."""
        for track in self._tracks.values():
            if track.rival and 0.0 <= time_s - track.rival_s <= CONTEST_S:
                value = track.rival[-1][1].get(name)
                if value is not None and math.isfinite(value):
                    return value
        return None

    def contested_senders(self, time_s: float) -> dict[str, dict[str, float] | None]:
        """The messages whose sender was in doubt within `CONTEST_S` before `time_s` (what makes
        `contested` true), each with the other sender's newest values (None if not known)."""
        return {message: None if track.rival_last is None else track.rival_last[1]
                for message, track in self._tracks.items() if 0.0 <= time_s - track.doubted_s <= CONTEST_S}
