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
  message's cycle (a second node sending the same message).

A frame that breaks any of them is rejected whole (a random payload rarely breaks only one
signal) and counted by kind. After it is accepted, `repair_spike` looks back one frame: a value
that disagrees with both its neighbours, which agree with each other, is replaced by their
interpolation (wheel speeds are judged in the front end's derivative filter instead, where the
wheel's physics is known).

`suspect_share` is the share of input frames in about the last second that were rejected or
repaired (exact repeats and reordered frames of a regular stream excepted: they carry no wrong
value); the estimator turns it into confidence (`input_quality`).
"""
from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass
from typing import Mapping, MutableMapping

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
CONTEST_S = 0.15                    # samples this long after a second source's frame are not fitted (a 50 Hz window)
FLOOD_RATE_FACTOR = 2.25            # more frames than this many times the message's rate: a flood
SHARE_TIME_CONSTANT_S = 1.0         # `suspect_share` averages over about this long
# Kinds of rejection that are certain and carry no wrong value (an exact repeat, a frame of a
# regular stream arriving late, a frame the codec cannot read, a timestamp a second off):
# counted, not in the suspect share. What is left (out of range, rate, spike, second source,
# a wheel-speed glitch) says that values near the plausible are corrupted too, and some get through.
HARMLESS = frozenset({"duplicate", "out of order", "undecodable", "clock step", "second source"})


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
        # (a motor's torque steps within a few ms: only the range and wild jumps)
        limits[f"drive_torque_{w}"] = SignalLimit(-5000.0, 5000.0, 200_000.0, 200.0)
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
                 "recent", "arrivals", "rejected", "agreeing")

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.time_s = -math.inf                 # of the last accepted frame
        self.values: dict[str, float] = {}      # ... its values
        self.arrival_s = -math.inf              # of the last frame, accepted or not
        self.arrival_gap_s = period_s           # ... since the frame before it
        self.interval_s = period_s              # slow mean of the arrival intervals
        self.rejects = 0                        # consecutive rejected frames
        self.last_reject = ""
        self.recent: deque[float] = deque()     # times of the rejections of the last 0.1 s (not harmless)
        self.arrivals: deque[float] = deque()   # times of the frames of the last 0.1 s
        self.rejected: tuple[float, dict[str, float]] | None = None   # the last frame rejected for its rate
        self.agreeing = 0                       # ... and how many before it agreed, each with the next


class InputGate:
    """Admits or rejects each input frame (see the module's docstring); counts by kind."""

    def __init__(self, vehicle: VehicleParams, periods: Mapping[str, float]) -> None:
        self.limits = signal_limits(vehicle)
        # (the same as plain tuples, with the upward rate resolved: every input frame is checked)
        self._bounds = {name: (lim.low, lim.high, lim.rate, lim.rate if lim.rise != lim.rise else lim.rise, lim.noise)
                        for name, lim in self.limits.items()}
        self._spike = {name: lim.spike for name, lim in self.limits.items() if lim.spike != math.inf}
        self._tracks = {m: _Track(p) for m, p in periods.items()}
        self.counts: Counter[str] = Counter()
        self._bus_time_s = -math.inf
        self._step_base_s = math.nan
        self._step_frames = 0
        self._share_time_s = -math.inf
        self._share_all = self._share_bad = 0.0
        self._contested_s = -math.inf     # the last frame of a second source
        self.reanchored: set[str] = set()  # messages followed to a new level (the caller clears)

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
        """None to accept the frame, else the kind of rejection (already counted)."""
        track = self._tracks.get(message)
        if track is None:
            return None
        kind = self._clock(time_s, track, values)
        if kind is None:
            kind = self._values(time_s, track, values)
            if kind == "rate" and self._follows_new_level(time_s, track, values):
                kind = None
                self.reanchored.add(message)
        if math.isfinite(time_s) and time_s > track.arrival_s:
            # (all arrivals: a message really sent faster than its DBC says is not a second source)
            if track.arrival_s > -math.inf:
                gap = min(time_s - track.arrival_s, 4.0 * track.period_s)
                track.interval_s += (gap - track.interval_s) / 200.0
                track.arrival_gap_s = time_s - track.arrival_s
            track.arrival_s = time_s
        if kind is None:
            self._accept(time_s, message, track, values)
        elif kind == "second source":
            self._contested_s = max(self._contested_s, self._bus_time_s)
        else:
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
        return kind

    def _follows_new_level(self, time_s: float, track: _Track, values: Mapping[str, float]) -> bool:
        """A value rejected for its rate: whether enough rejected frames in a row agree with each
        other to say the last accepted one was wrong, or the sensor came back from a dead spell
        (followed; the front end restarts its filter)."""
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
                t.time_s = t.arrival_s = -math.inf
                t.values = {}
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

    def contested(self, time_s: float) -> bool:
        """Whether a second node sent one of the messages within `CONTEST_S` before `time_s`:
        which frames came from it is not certain (one may have been taken before the other
        was seen), so no sample that may include them is fitted."""
        return 0.0 <= time_s - self._contested_s <= CONTEST_S

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
        if len(track.arrivals) >= FLOOD_RATE_FACTOR * 0.1 / track.period_s:
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
        if repaired:
            self.counts["spike"] += 1
            # (the frame was counted as accepted: now it counts as suspect)
            self._share_bad += 1.0
