"""Frame-level plausibility of the inputs (issue 22): what physics and a signal's own history allow.

Input frames carry no CRC: a corrupted or spoofed frame decodes to numbers that are each within
their DBC range. Before a frame's values reach the front end's histories (and from there the
fit), `InputGate.admit` checks them against

- the signal's physical range (`SignalLimit.low`/`high`);
- what the signal can do since its last accepted value: a rate limit from physics plus a
  per-frame allowance for noise (`SignalLimit.rate`, `noise`), e.g. a wheel cannot accelerate
  faster than its brake and the road's largest possible force can turn it, a brake pressure
  cannot rise or fall faster than a hydraulic unit moves it;
- the message's own clock: a frame older than the message's last one (reordered, or a single
  frame stepped back), a frame far from the bus's time (a clock step, either way: followed only
  once enough frames agree on it), an exact repeat, and a frame arriving much sooner than the
  message's cycle (a second node sending the same message). Then the two senders' frames are
  told apart by their values and cycles (`_choose_source`): the genuine one is followed, the
  other's frames are rejected, and a frame taken before the other showed it up is revoked
  (`revoked`: the front end takes it out of its histories). Two senders whose first frames
  matched (a replay of a flat stretch) were never told apart: once their values part, every
  frame is a judgement (`contested`) for as long as both send; `contested_senders` names the
  messages in doubt and the other sender's values (the front end can tell wheel-speed senders
  apart by the car's speed, which the gate does not know).

A frame that breaks any of them is rejected whole (a random payload rarely breaks only one
signal) and counted by kind. After it is accepted, `repair_spike` looks back one frame: a value
that disagrees with both its neighbours, which agree with each other, is replaced by their
interpolation (wheel speeds are judged in the front end's derivative filter instead, where the
wheel's physics is known). A spike within the rate limit of the frame before it makes the
genuine frame after it look too fast: that frame is rejected for its rate, but when it fits the
frame before the spike, the spike is revoked instead (`_revoke_spike`). Both note the span a
sample may have taken the wrong value from (`repaired`).

`suspect_share` is the share of input frames in about the last second that were rejected or
repaired (exact repeats and reordered frames of a regular stream excepted: they carry no wrong
value); the estimator turns it into confidence (`input_quality`).

`InputGate` holds the tracks and the admission; its parts, each in its own module, are the
message's clock (`message_clock`), the values against the signals' limits (`signal_limits`), a
second sender (`second_source`), spikes and new levels (`spike_repair`) and the suspect share
(`suspect_share`).
"""
from __future__ import annotations

import math
from collections import Counter, deque
from math import exp as _exp
from typing import Mapping

from .message_clock import _EARLY_PAIR, CLOCK_STEP_S, EARLY_SHARE_OF_PERIOD, MessageClock
from .second_source import RIVAL_CYCLES, SecondSource, flooded
from .signal_limits import SignalLimit, ValueChecks, signal_limits, wheel_accel_bound  # noqa: F401 (re-exported)
from .spike_repair import SpikeRepair
from .suspect_share import HARMLESS, SHARE_TIME_CONSTANT_S, SuspectShare
from .vehicle import VehicleParams


class _Track:
    """One message's accepted history as the gate sees it."""

    __slots__ = ("period_s", "time_s", "values", "arrival_s", "arrival_gap_s", "interval_s", "rejects", "last_reject",
                 "recent", "arrivals", "rejected", "agreeing", "accepted", "rival", "rival_s", "cadence_s",
                 "identified", "rival_last", "doubted_s")

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.time_s = -math.inf                 # of the last accepted frame
        self.values: dict[str, float] = {}      # ... its values
        self.arrival_s = -math.inf              # of the last frame, accepted or not
        # ... since the frame before it; unknown (inf) for the first frame, so that the second
        # frame of a message, however soon, is never judged early: a sender's first frames come
        # as jittery as its start-up or a player's makes them, and there is no cycle to hold yet.
        self.arrival_gap_s = math.inf
        self.interval_s = period_s              # slow mean of the arrival intervals
        self.rejects = 0                        # consecutive rejected frames
        self.last_reject = ""
        self.recent: deque[float] = deque()     # times of the rejections of the last 0.1 s (not harmless)
        self.arrivals: deque[float] = deque()   # times of the frames of the last 0.1 s
        self.rejected: tuple[float, dict[str, float]] | None = None   # the last frame rejected for its rate
        self.agreeing = 0                       # ... and how many before it agreed, each with the next
        self.accepted: deque[tuple[float, dict[str, float]]] = deque(maxlen=3)   # the last accepted frames
        self.rival: deque[tuple[float, dict[str, float]]] = deque(maxlen=2)      # a second source's last frames
        self.rival_s = -math.inf                # (bus time) of its last frame
        self.cadence_s = period_s               # the sender's own cycle, as measured before a second one came
        # Whether the genuine sender was told apart from a second one when that one's first frame
        # came: a replay of a flat stretch matches the genuine frames, so which track is followed
        # is then chance, and when the two part later each continues its own track.
        self.identified = True
        # The second source's newest frame (kept when it falls silent), and when a frame of this
        # message last left which sender sent it in doubt (`InputGate._unsure`), bus time.
        self.rival_last: tuple[float, dict[str, float]] | None = None
        self.doubted_s = -math.inf

    def to_rival(self, frame: tuple[float, dict[str, float]], now_s: float) -> None:
        """A frame judged the second source's."""
        self.rival.append(frame)
        self.rival_last = frame
        self.rival_s = now_s


class InputGate(SecondSource, MessageClock, ValueChecks, SpikeRepair, SuspectShare):
    """Admits or rejects each input frame (see the module's docstring); counts by kind."""

    def __init__(self, vehicle: VehicleParams, periods: Mapping[str, float]) -> None:
        self.limits = signal_limits(vehicle)
        # (the same as plain tuples, with the upward rate resolved: every input frame is checked)
        self._bounds = {name: (lim.low, lim.high, lim.rate, lim.rate if lim.rise != lim.rise else lim.rise, lim.noise)
                        for name, lim in self.limits.items()}
        self._spike = {name: lim.spike for name, lim in self.limits.items() if lim.spike != math.inf}
        self._active = {name: lim.active for name, lim in self.limits.items() if lim.active != math.inf}
        self._tracks = {m: _Track(p) for m, p in periods.items()}
        self.counts: Counter[str] = Counter()
        self._bus_time_s = -math.inf
        self._step_base_s = math.nan
        self._step_frames = 0
        self._reset_suspect_share()
        self._contested_s = -math.inf     # the last frame of a second source whose values could not tell it
        self._doubt = False               # ... and whether the frame being admitted was one
        self.reanchored: set[str] = set()  # messages followed to a new level (the caller clears)
        # An accepted frame found to be a second source's once the genuine one arrived (message:
        # its time): the caller takes it out of its histories and clears the entry.
        self.revoked: dict[str, float] = {}
        # (before, after): the times of the neighbours of a value found wrong after it was taken
        # (a spike repaired or revoked): a sample between them may have used it (the front end
        # drops spans older than a second, `FrontEnd.tainted`).
        self.repaired: deque[tuple[float, float]] = deque(maxlen=64)

    # -- admission ---------------------------------------------------------------------------
    def admit(self, time_s: float, message: str, values: Mapping[str, float]) -> str | None:
        """None to accept the frame, else the kind of rejection (already counted).

        Most frames are plain: one sender, on time, plausible values. They are accepted here, with
        `_clock`'s, `_values`'s, `_accept`'s and `note`'s work for such a frame written out in one
        place (every input frame passes: the calls and attribute lookups were most of the gate's
        cost). Any other frame goes, before anything is changed, to `_admit_judged`, the reference:
        both give the same verdict and leave the same state."""
        track = self._tracks.get(message)
        if track is None:
            return None
        bus = self._bus_time_s
        dt = time_s - track.time_s
        # Plain so far: one sender, no rate rejections pending, near the bus's time, after the
        # message's last frame (a NaN or infinite time fails a test; the first frame has no bus).
        if (track.rival or track.rejected is not None
                or not -CLOCK_STEP_S <= time_s - bus <= CLOCK_STEP_S or not dt > 0.0):
            return self._admit_judged(time_s, message, track, values)
        period = track.period_s
        interval = track.interval_s
        # (min and max written out, picking as they do: their calls were a sixth of this path's time)
        held = 0.5 * period if 0.5 * period > interval else interval      # max(interval, period / 2)
        cycle = held if held < period else period                          # min(period, held)
        if (dt < EARLY_SHARE_OF_PERIOD * cycle
                and (time_s - track.arrival_s) + track.arrival_gap_s < _EARLY_PAIR * cycle):   # (early: `_clock`)
            return self._admit_judged(time_s, message, track, values)
        # The values (`_values`): in range, within the rate limits, and not the sender's marker.
        bounds = self._bounds
        previous = track.values
        live = False
        for name, x in values.items():
            b = bounds.get(name)
            if b is None:
                continue
            if x > 0.002 or x < -0.002:
                live = True
            if not b[0] <= x <= b[1]:
                return self._admit_judged(time_s, message, track, values)
            last = previous.get(name)
            if last is not None and abs(x - last) > (b[3] if x > last else b[2]) * dt + b[4]:
                return self._admit_judged(time_s, message, track, values)
        # A frame of zeros after a live one may be a marker (`_is_marker`): only signals with an
        # `active` level can show the live one (a drive torque's frames, all zeros when coasting,
        # have none: they pass without the look).
        if not live and not self._active.keys().isdisjoint(values):
            active = self._active
            for name in values:
                a = active.get(name)
                if a is not None and abs(previous.get(name, 0.0)) > a:
                    return self._admit_judged(time_s, message, track, values)
        self._accept_plain(time_s, track, values, held)
        return None

    def _accept_plain(self, time_s: float, track: _Track, values: Mapping[str, float], held: float) -> None:
        """A plain frame accepted (`admit`): the updates `_admit_judged` makes for it, in its order.
        `held` is max(interval, period / 2) as `admit` found it."""
        period = track.period_s
        interval = track.interval_s
        track.cadence_s = held if held < 2.0 * period else 2.0 * period    # min(2 period, held)
        arrival = track.arrival_s
        if time_s > arrival:
            if arrival > -math.inf:
                gap = time_s - arrival
                gap = 4.0 * period if 4.0 * period < gap else gap                # min(gap, 4 periods)
                track.interval_s = interval + (gap - interval) / 200.0
                track.arrival_gap_s = time_s - arrival
            track.arrival_s = time_s
        track.time_s = time_s
        track.values = kept = dict(values)
        track.accepted.append((time_s, kept))
        track.rejects = track.agreeing = 0
        self._step_frames = 0
        bus = self._bus_time_s
        if time_s > bus:
            self._bus_time_s = bus = time_s
        recent = track.recent
        while recent and not bus - 0.1 < recent[0] <= bus:
            recent.popleft()
        arrivals = track.arrivals
        arrivals.append(bus)
        while arrivals and not bus - 0.1 < arrivals[0] <= bus:
            arrivals.popleft()
        # (`note` for an accepted frame, on the bus's time, which is finite here)
        since = bus - self._share_time_s
        if since > 0.0:
            keep = _exp(-since / SHARE_TIME_CONSTANT_S)
            self._share_all *= keep
            self._share_bad *= keep
            self._share_time_s = bus
        elif since < -CLOCK_STEP_S:
            self._share_time_s = bus
        self._share_all += 1.0

    def _admit_judged(self, time_s: float, message: str, track: _Track, values: Mapping[str, float]) -> str | None:
        """`admit` for every frame that is not plainly the one sender's next, plausible frame."""
        kind = self._clock(time_s, track, values)
        if track.rival and self._bus_time_s - track.rival_s > RIVAL_CYCLES * track.period_s:
            track.rival.clear()     # (the second node has stopped: one sender again)
        if not track.rival:
            track.cadence_s = min(2.0 * track.period_s, max(track.interval_s, 0.5 * track.period_s))
        if kind == "second source" or (kind is None and track.rival):
            kind = self._choose_source(time_s, message, track, values, kind)
        if kind is None:
            kind = self._values(time_s, track, values)
            if kind == "rate" and self._revoke_spike(message, track, time_s, values):
                kind = self._values(time_s, track, values)
            # (zeros that go on are what the sensors read, not a marker: four wheels locked
            # below an ABS's cut-out speed, the car skidding to rest)
            if kind in ("rate", "marker") and self._follows_new_level(time_s, track, values):
                kind = None
                self.reanchored.add(message)
        if math.isfinite(time_s) and time_s > track.arrival_s:
            # (all arrivals: a message really sent faster than its DBC says is not a second source;
            # but not while two nodes send it: the cycle measured is the genuine sender's)
            if track.arrival_s > -math.inf:
                if not track.rival:
                    gap = min(time_s - track.arrival_s, 4.0 * track.period_s)
                    track.interval_s += (gap - track.interval_s) / 200.0
                track.arrival_gap_s = time_s - track.arrival_s
            track.arrival_s = time_s
        if kind is None:
            self._accept(time_s, message, track, values)
        elif kind != "second source":
            track.rejects += 1
            track.last_reject = kind
            if kind not in HARMLESS:
                track.recent.append(self._bus_time_s)
        # (on the bus's time: a frame stepped back or ahead still arrived now)
        now = self._bus_time_s
        track.arrivals.append(now)
        for times in (track.recent, track.arrivals):
            while times and not now - 0.1 < times[0] <= now:
                times.popleft()
        self.note(time_s, kind)
        if self._doubt:
            self._doubt = False
            if kind is None or kind in HARMLESS:
                self._share_bad += 1.0
        return kind

    def _accept(self, time_s: float, message: str, track: _Track, values: Mapping[str, float]) -> None:
        if track.rejected is not None and self._values(track.time_s + track.period_s, track, values) is not None:
            # Accepted after frames rejected for their rate, and further from the last accepted
            # value than one cycle allows: a step (the time since only made it admissible).
            self.reanchored.add(message)
        track.time_s = time_s
        track.values = dict(values)
        track.accepted.append((time_s, track.values))
        track.rejects = track.agreeing = 0
        track.rejected = None
        self._bus_time_s = max(self._bus_time_s, time_s)

    def persistent(self, message: str) -> str | None:
        """The kind of rejection when a message's frames keep being rejected (5 in a row, or 8
        in 0.1 s), or arrive at more than twice the message's rate (a flood; a second node at
        the same rate is rejected frame by frame): the input is broken, not corrupted now and then."""
        track = self._tracks.get(message)
        if track is None:
            return None
        if track.rejects >= 5 and track.last_reject not in HARMLESS:
            return track.last_reject
        if len(track.recent) >= 8:
            return track.last_reject or "rate"
        if flooded(track):
            return "second source"
        return None

    def faulty_messages(self) -> list[tuple[str, str]]:
        """(message, kind) of every message whose frames keep being rejected."""
        out = []
        for message in self._tracks:
            kind = self.persistent(message)
            if kind is not None:
                out.append((message, kind))
        return out
