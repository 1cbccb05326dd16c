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
"""
from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass
from math import exp as _exp
from typing import Mapping, MutableMapping

from .second_source import RIVAL_CYCLES, SecondSource, flooded
from .vehicle import GRAVITY_MPS2, VehicleParams

# The most brake pressure a hydraulic unit produces [bar], and its fastest rise or fall [bar/s]
# (an ABS dump valve ~3000 bar/s): the wheel's torque bound and the pressures' rate limit.
MAX_BRAKE_PRESSURE_BAR = 250.0
MAX_PRESSURE_RATE_BAR_S = 6000.0
# No tyre on any road transmits more than this share of its load.
MAX_POSSIBLE_MU = 1.5
MAX_DRIVE_TORQUE_NM = 2000.0        # a drive line's torque at one wheel (traction spinning it up)
REANCHOR_FRAMES = 5                 # rejected frames in a row that agree with each other: a new level
# Body jerk [m/s³]: M Δa = Δ ΣF_x, and an ABS dumping every wheel takes the tyre forces from the
# peak (up to 1.5 g) to a fraction of it within ~20 ms: ~750 m/s³ (a brake onset alone is 50-100).
MAX_JERK_MPS3 = 750.0
FRAMES_TO_FOLLOW_A_CLOCK_STEP = 6   # consecutive frames that agree on a new time base
CLOCK_STEP_S = 0.25                 # a frame this far from the bus's time is a clock step
REORDER_S = 0.05                    # ... or this far behind its message's last frame
EARLY_SHARE_OF_PERIOD = 0.6         # sooner than this share of the cycle: a second source (±2 ms jitter at 10 ms)
SHARE_TIME_CONSTANT_S = 1.0         # `suspect_share` averages over about this long
# Kinds of rejection that are certain and carry no wrong value (an exact repeat, a frame of a
# regular stream arriving late, a frame the codec cannot read, a timestamp a second off):
# counted, not in the suspect share. What is left (out of range, rate, spike, second source,
# a wheel-speed glitch) says that values near the plausible are corrupted too, and some get through.
# A second node's frames told apart by their values and cycles are refused as surely; those that
# could not be told apart, and one taken before the genuine frame showed it up, are suspect
# (`_unsure`, `_revoke`): which of two plausible streams is genuine is then a judgement.
HARMLESS = frozenset({"duplicate", "out of order", "undecodable", "clock step", "second source"})
_EARLY_PAIR = 1.0 + EARLY_SHARE_OF_PERIOD     # (the early test's bound on two intervals, as `_clock` computes it)


@dataclass(frozen=True, slots=True)
class SignalLimit:
    """What one canonical input can be and do."""

    low: float
    high: float
    rate: float       # largest physical |dx/dt| [unit/s]
    noise: float      # allowance per frame on top (sensor noise, quantisation, jitter)
    spike: float = math.inf   # a value off both (agreeing) neighbours by more than this is a spike
    rise: float = math.nan    # largest dx/dt upwards when it differs from `rate` [unit/s]
    active: float = math.inf  # |value| above which a frame of zeros after it is an invalid marker


def wheel_accel_bound(vehicle: VehicleParams, wheel: int, up: bool = False) -> float:
    """|dω/dt| a wheel can reach [rad/s²]: J ω̇ = −T_b + R F_x + T_e with the largest force any
    road gives at the largest load the car can put on the wheel (1.5 g of braking, 1 g of
    cornering) and, slowing down, the largest brake torque the hydraulics give on top; speeding
    up, a brake only holds it back, a drive line adds at most `MAX_DRIVE_TORQUE_NM`."""
    loads = [vehicle.normal_forces(ax * GRAVITY_MPS2, ay * GRAVITY_MPS2)[wheel]
             for ax in (-1.5, 1.5) for ay in (-1.0, 1.0)]
    road = MAX_POSSIBLE_MU * max(loads) * vehicle.wheel_radius
    torque = road + (MAX_DRIVE_TORQUE_NM if up else vehicle.brake_gain(wheel) * MAX_BRAKE_PRESSURE_BAR)
    return torque / max(vehicle.wheel_inertia, 1e-3)


def signal_limits(vehicle: VehicleParams) -> dict[str, SignalLimit]:
    """The limits of every canonical input that has them (flags have none)."""
    limits = {
        "accel_long": SignalLimit(-30.0, 30.0, MAX_JERK_MPS3, 1.0, 2.0, active=0.5),
        "accel_lat": SignalLimit(-30.0, 30.0, MAX_JERK_MPS3, 1.0, 2.0),
        # (a car's yaw rate: at most ~1 rad/s, changing at most ~10 rad/s² in a spin)
        "yaw_rate": SignalLimit(-3.0, 3.0, 10.0, 0.05, 0.1),
        "vehicle_speed_ref": SignalLimit(0.0, 120.0, 2.0 * GRAVITY_MPS2, 0.5, 1.0),
        "brake_pressure_master": SignalLimit(-1.0, 350.0, MAX_PRESSURE_RATE_BAR_S, 3.0, 15.0),
    }
    for i, w in enumerate(("fl", "fr", "rl", "rr")):
        limits[f"wheel_speed_{w}"] = SignalLimit(0.0, 400.0, wheel_accel_bound(vehicle, i), 1.0,
                                                 rise=wheel_accel_bound(vehicle, i, up=True), active=1.0)
        limits[f"brake_pressure_{w}"] = SignalLimit(-1.0, 350.0, MAX_PRESSURE_RATE_BAR_S, 3.0, 15.0, active=5.0)
        # (a motor's torque steps within a few ms: the range, wild jumps, and one frame out and
        # back, which no drive line does within a cycle)
        limits[f"drive_torque_{w}"] = SignalLimit(-5000.0, 5000.0, 200_000.0, 200.0, 300.0)
    return limits


def _is_marker(values: Mapping[str, float], previous: Mapping[str, float], limits: Mapping[str, SignalLimit]) -> bool:
    """A frame of zeros (all bits 0, or all 1 in a signed signal: one step below zero) right after
    one that showed a moving, braking or decelerating car: the sender's "no value" marker. No live
    sensor reads exactly zero on every channel at once (four wheel speeds, four pressures, or
    the accelerometer's three axes), and no car stops or releases its brakes within one frame."""
    checked = False
    for name, x in values.items():    # (every frame passes here: out at its first live value)
        if name in limits:
            if abs(x) > 0.002:
                return False
            checked = True
    return checked and any(abs(previous.get(name, 0.0)) > limits[name].active for name in values if name in limits)


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


class InputGate(SecondSource):
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
        self._share_time_s = -math.inf
        self._share_all = self._share_bad = 0.0
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

    # -- the suspect share -------------------------------------------------------------------
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

    def _values(self, time_s: float, track: _Track, values: Mapping[str, float]) -> str | None:
        bounds = self._bounds
        previous = track.values
        dt = time_s - track.time_s
        live = False    # a value seen so far that is not zero: then the frame is no marker
        kind = None
        for name, x in values.items():
            b = bounds.get(name)
            if b is None:
                continue
            if x > 0.002 or x < -0.002:
                live = True
            low, high, rate, rise, noise = b
            if not low <= x <= high:      # (NaN: out)
                kind = "out of range"
                break
            last = previous.get(name)
            if last is not None and abs(x - last) > (rise if x > last else rate) * dt + noise:
                kind = "rate"
                break
        # A marker is told first: (only) a frame without a live value can be one.
        if not live and _is_marker(values, previous, self.limits):
            return "marker"
        return kind

    def _agrees(self, time_s: float, values: Mapping[str, float], earlier: tuple[float, dict] | None) -> bool:
        """Whether `values` are within the rate limits of an earlier rejected frame's."""
        if earlier is None or not time_s > earlier[0]:
            return False
        dt = time_s - earlier[0]
        for name, x in values.items():
            lim = self.limits.get(name)
            last = earlier[1].get(name)
            if lim is None or last is None:
                continue
            rate = lim.rise if x > last and lim.rise == lim.rise else lim.rate
            if not abs(x - last) <= rate * dt + lim.noise:
                return False
        return True

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

    # -- neighbours ---------------------------------------------------------------------------
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
