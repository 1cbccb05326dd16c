"""What `frictiond monitor` knows about the bus: the model behind the screen and `--json`.

No curses here (the view is `monitor_tui.py`) and no python-can (frames come in as `Frame`s,
from a bus or a log, through `busio`). The model:

* decodes frictiond's output frames (FRICTION_ESTIMATE, FRICTION_WHEEL multiplexed by
  WheelIndex) with the output DBC and checks their E2E protection;
* keeps a rolling history of `MuMax`;
* tracks, per input message of the config, when it was last seen (freshness) and its measured
  rate, and counts input frames the input codec cannot decode;
* counts other, error and undecodable frames;
* runs the front end's plausibility gate (`plausibility.InputGate`) over the decoded inputs: the
  input frames it would reject, by kind, and their share of about the last second, which is why
  an estimate leaves VALID when corruption is high (`input_quality.LEAVE_VALID_SHARE`).

Times are in the frames' own time base (log time, or the bus's receive timestamps); callers that
want ages pass `now` in that time base (see `FrameClock`).
"""
from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass
from typing import Any, Iterable, Iterator, Sequence

from .frames import Frame, frame_key
from .samples import WHEELS, Status

RATE_WINDOW_S = 1.0
DEFAULT_HISTORY = 600
WHEEL_SIGNALS = ("Slip", "MuUsed", "MuMaxWheel", "NormalForce")
ESTIMATE_SIGNALS = ("MuMax", "SlipAtMuMax", "Theta", "Confidence")


def status_name(value: Any) -> str:
    """`EstimatorStatus` as a name, whether cantools gave a choice name or a raw number."""
    if isinstance(value, str):
        return value
    try:
        return Status(int(value)).name
    except (TypeError, ValueError):
        return f"UNKNOWN({value})"


def _clean(value: Any, digits: int = 6) -> Any:
    if isinstance(value, float):
        if not math.isfinite(value):
            return None
        return round(value, digits)
    return value


class RateTracker:
    """Last-seen time and measured rate of one message, over a sliding window of frame times."""

    __slots__ = ("name", "frame_id", "period_s", "count", "last_s", "first_s", "_times", "window_s")

    def __init__(self, name: str, frame_id: int, period_s: float | None = None,
                 window_s: float = RATE_WINDOW_S) -> None:
        self.name = name
        self.frame_id = frame_id
        self.period_s = period_s
        self.window_s = window_s
        self.reset()

    def reset(self) -> None:
        self.count = 0
        self.last_s: float | None = None
        self.first_s: float | None = None
        self._times: deque[float] = deque()

    def seen(self, time_s: float) -> None:
        self.count += 1
        if self.first_s is None:
            self.first_s = time_s
        if self.last_s is not None and time_s < self.last_s - self.window_s:
            self._times.clear()  # time went backwards (spliced log, clock step): start over
            self.first_s = time_s
        self.last_s = time_s
        self._times.append(time_s)
        self._prune(time_s)

    def _prune(self, now_s: float) -> None:
        times = self._times
        limit = now_s - self.window_s
        while times and times[0] <= limit:
            times.popleft()

    def age(self, now_s: float) -> float | None:
        if self.last_s is None:
            return None
        return max(0.0, now_s - self.last_s)

    def rate(self, now_s: float) -> float | None:
        """Frames per second over the last window; None before two frames were seen."""
        if self.last_s is None:
            return None
        self._prune(max(now_s, self.last_s))
        n = len(self._times)
        observed = max(now_s, self.last_s) - (self.first_s if self.first_s is not None else now_s)
        if observed >= self.window_s:
            return n / self.window_s
        if n >= 2:
            span = self._times[-1] - self._times[0]
            return (n - 1) / span if span > 0 else None
        return None

    def is_stale(self, now_s: float, periods: float = 5.0) -> bool:
        age = self.age(now_s)
        if age is None:
            return True
        if self.period_s:
            return age > max(periods * self.period_s, 0.05)
        return age > 1.0


@dataclass
class WheelValues:
    time_s: float
    slip: float
    mu_used: float
    mu_max_wheel: float
    normal_force: float
    e2e: str

    def as_json(self) -> dict[str, Any]:
        return {
            "time_s": _clean(self.time_s), "Slip": _clean(self.slip), "MuUsed": _clean(self.mu_used),
            "MuMaxWheel": _clean(self.mu_max_wheel), "NormalForce": _clean(self.normal_force), "e2e": self.e2e,
        }


@dataclass
class EstimateValues:
    time_s: float
    status: str
    mu_max: float
    slip_at_mu_max: float
    theta: float
    confidence: float
    e2e: str


@dataclass
class InputRow:
    name: str
    frame_id: int
    period_s: float | None
    count: int
    age_s: float | None
    rate_hz: float | None
    stale: bool
    is_output: bool = False


@dataclass
class MonitorSnapshot:
    """Everything the screen shows at one instant (plain values, safe to keep while paused)."""

    now_s: float | None
    frames_total: int
    estimate: EstimateValues | None
    wheels: list[WheelValues | None]
    history: list[float]
    history_status: list[str]
    inputs: list[InputRow]
    outputs: list[InputRow]
    e2e: dict[str, int]
    undecodable: dict[str, int]
    undecodable_total: int
    other_frames: int
    error_frames: int
    source: str = ""
    finished: bool = False
    rejected: dict[str, int] | None = None   # input frames the plausibility gate refuses, by kind
    suspect_share: float = 0.0               # ... share of the last second's input (rejected or repaired)
    not_valid_reason: str = ""               # why the estimate cannot be VALID now ("" when it can)


class MonitorModel:
    """Consumes frames; keeps what the monitor shows. `feed` returns the JSON object of an estimate."""

    def __init__(self, output_codec: Any, input_codec: Any = None, input_messages: Sequence[Any] | None = None,
                 history: int = DEFAULT_HISTORY, vehicle: Any = None) -> None:
        self.output_codec = output_codec
        self.input_codec = input_codec
        if input_messages is None and input_codec is not None:
            input_messages = input_codec.input_messages()
        from .plausibility import InputGate
        from .vehicle import VehicleParams

        # The front end's own gate over what the monitor sees (the vehicle's limits when given).
        self.input_gate = InputGate(vehicle or VehicleParams(),
                                    {m.name: (m.period_s or 0.01) for m in (input_messages or ())})
        self.inputs: dict[int, RateTracker] = {}
        for m in sorted(input_messages or (), key=lambda m: m.frame_id):
            key = frame_key(int(m.frame_id), bool(getattr(m, "is_extended", False)))
            self.inputs[key] = RateTracker(m.name, int(m.frame_id), m.period_s)
        est_msg, wheel_msg = output_codec.estimate_message, output_codec.wheel_message
        self.outputs: dict[int, RateTracker] = {
            output_codec.estimate_id: RateTracker(est_msg.name, output_codec.estimate_id,
                                                  (est_msg.cycle_time or 0) / 1000.0 or None),
            # one FRICTION_WHEEL frame per wheel (multiplexer page) each cycle
            output_codec.wheel_id: RateTracker(wheel_msg.name, output_codec.wheel_id,
                                               (wheel_msg.cycle_time or 0) / 1000.0 / len(WHEELS) or None),
        }
        self.history: deque[float] = deque(maxlen=max(1, history))
        self.history_status: deque[str] = deque(maxlen=max(1, history))
        self.estimate: EstimateValues | None = None
        self.wheels: list[WheelValues | None] = [None] * len(WHEELS)
        self.frames_total = 0
        self.other_frames = 0
        self.error_frames = 0
        self.undecodable: Counter[str] = Counter()
        self.last_time_s: float | None = None
        self._pending: EstimateValues | None = None
        self._pending_wheels: set[int] = set()

    # ------------------------------------------------------------------------------------------
    def feed(self, frame: Frame) -> dict[str, Any] | None:
        """Take one frame; returns the JSON object of an estimate when one is complete (else None).

        frictiond sends each update as FRICTION_ESTIMATE followed by the FRICTION_WHEEL frames of
        the same update, so an estimate's object is completed by the four wheel frames after it
        (or, when wheel frames are sent less often, by the next estimate, or by `flush`): its
        per-wheel values are then those of the same update.
        """
        self.frames_total += 1
        self.last_time_s = frame.time_s
        if frame.is_error:
            self.error_frames += 1
            return None
        if frame.is_remote:
            self.other_frames += 1
            return None
        cid = frame.can_id
        if not frame.is_extended and cid in self.outputs:
            self.outputs[cid].seen(frame.time_s)
            return self._feed_output(frame)
        tracker = self.inputs.get(frame_key(cid, frame.is_extended))
        if tracker is None:
            self.other_frames += 1
            return None
        tracker.seen(frame.time_s)
        if self.input_codec is not None:
            from .codec import DecodeFailure

            try:
                decoded = self.input_codec.decode(frame)
            except DecodeFailure as exc:
                self.undecodable[f"{tracker.name}: {exc.reason}"] += 1
                self.input_gate.note(frame.time_s, "undecodable")
            else:
                if decoded is not None:
                    self.input_gate.admit(decoded.time_s, decoded.message, decoded.values)
        return None

    def not_valid_reason(self) -> str:
        """Why an estimate now cannot be VALID, as the pipeline decides it ("" when it can)."""
        from .input_quality import LEAVE_VALID_SHARE, REASON

        share = self.input_gate.suspect_share()
        return f"{REASON}: {share:.0%} of the input rejected (above {LEAVE_VALID_SHARE:.0%})" \
            if share > LEAVE_VALID_SHARE else ""

    def feed_all(self, frames: Iterable[Frame]) -> Iterator[dict[str, Any]]:
        """The JSON objects of all estimates among `frames` (the last one flushed at the end)."""
        for frame in frames:
            obj = self.feed(frame)
            if obj is not None:
                yield obj
        obj = self.flush()
        if obj is not None:
            yield obj

    def _feed_output(self, frame: Frame) -> dict[str, Any] | None:
        codec = self.output_codec
        decoded = codec.decode_output(frame)
        if decoded is None:  # not reached: the ID is an output's
            self.other_frames += 1
            return None
        verdict = decoded.get("e2e", "")
        name = decoded.get("message", "?")
        if verdict in ("length", "undecodable"):
            self.undecodable[f"{name}: {'wrong length' if verdict == 'length' else 'undecodable'}"] += 1
            return None
        if frame.can_id == codec.estimate_id:
            try:
                est = EstimateValues(
                    frame.time_s, status_name(decoded.get("EstimatorStatus")), float(decoded["MuMax"]),
                    float(decoded["SlipAtMuMax"]), float(decoded["Theta"]), float(decoded["Confidence"]), verdict,
                )
            except (KeyError, TypeError, ValueError):
                self.undecodable[f"{name}: undecodable"] += 1
                return None
            self.estimate = est
            if verdict != "crc":  # a corrupt frame's number is not history
                self.history.append(est.mu_max)
                self.history_status.append(est.status)
            done = self.flush()
            self._pending = est
            self._pending_wheels = set()
            return done
        index = decoded.get("WheelIndex")
        if isinstance(index, str):
            index = WHEELS.index(index) if index in WHEELS else None
        try:
            i = int(index) if index is not None else -1
            values = WheelValues(frame.time_s, float(decoded["Slip"]), float(decoded["MuUsed"]),
                                 float(decoded["MuMaxWheel"]), float(decoded["NormalForce"]), verdict)
        except (KeyError, TypeError, ValueError):
            i = -1
        if not 0 <= i < len(WHEELS):
            self.undecodable[f"{name}: bad WheelIndex"] += 1
            return None
        self.wheels[i] = values
        if self._pending is not None:
            self._pending_wheels.add(i)
            if len(self._pending_wheels) == len(WHEELS):
                return self.flush()
        return None

    def flush(self) -> dict[str, Any] | None:
        """The JSON object of an estimate still waiting for its wheel frames (end of log, idle bus)."""
        est, self._pending = self._pending, None
        return None if est is None else self.estimate_json(est)

    def estimate_json(self, est: EstimateValues) -> dict[str, Any]:
        return {
            "time_s": _clean(est.time_s),
            "status": est.status,
            "MuMax": _clean(est.mu_max),
            "Confidence": _clean(est.confidence),
            "SlipAtMuMax": _clean(est.slip_at_mu_max),
            "Theta": _clean(est.theta),
            "e2e": est.e2e,
            "wheels": {w: (v.as_json() if v is not None else None) for w, v in zip(WHEELS, self.wheels)},
            "input_rejected": dict(self.input_gate.counts),
            "input_suspect_share": _clean(self.input_gate.suspect_share()),
            "not_valid_reason": self.not_valid_reason(),
        }

    # ------------------------------------------------------------------------------------------
    def reset_counters(self) -> None:
        """The `r` key: E2E counters, frame counts, undecodable counts and rates start again."""
        self.output_codec.e2e.reset()
        self.undecodable.clear()
        self.input_gate.counts.clear()
        self.frames_total = self.other_frames = self.error_frames = 0
        for tracker in (*self.inputs.values(), *self.outputs.values()):
            last = tracker.last_s
            tracker.reset()
            tracker.last_s = last  # freshness is a fact about the bus, not a counter

    def e2e_counts(self) -> dict[str, int]:
        e = self.output_codec.e2e
        return {
            "ok": int(e.frames_ok), "crc_failures": int(e.crc_failures), "counter_jumps": int(e.counter_jumps),
            "frames_lost": int(e.frames_lost), "repeated": int(e.repeated),
        }

    def snapshot(self, now_s: float | None = None, source: str = "", finished: bool = False) -> MonitorSnapshot:
        if now_s is None:
            now_s = self.last_time_s

        def rows(trackers: dict[int, RateTracker], is_output: bool) -> list[InputRow]:
            out = []
            for t in trackers.values():
                if now_s is None:
                    out.append(InputRow(t.name, t.frame_id, t.period_s, t.count, None, None, True, is_output))
                else:
                    out.append(InputRow(t.name, t.frame_id, t.period_s, t.count, t.age(now_s), t.rate(now_s),
                                        t.is_stale(now_s), is_output))
            return out

        return MonitorSnapshot(
            now_s=now_s,
            frames_total=self.frames_total,
            estimate=self.estimate,
            wheels=list(self.wheels),
            history=list(self.history),
            history_status=list(self.history_status),
            inputs=rows(self.inputs, False),
            outputs=rows(self.outputs, True),
            e2e=self.e2e_counts(),
            undecodable=dict(self.undecodable),
            undecodable_total=sum(self.undecodable.values()),
            other_frames=self.other_frames,
            error_frames=self.error_frames,
            source=source,
            finished=finished,
            rejected=dict(self.input_gate.counts),
            suspect_share=self.input_gate.suspect_share(),
            not_valid_reason=self.not_valid_reason(),
        )


# ---------------------------------------------------------------------------------------------
@dataclass
class FrameClock:
    """"Now" in the frames' time base: the last frame's time plus the wall time since, × speed.

    Works for any time base (epoch receive stamps, log times starting at 0). `speed` 0 means
    "as fast as possible": time only moves with the frames.
    """

    speed: float = 1.0
    last_frame_s: float | None = None
    _wall_at_last: float = 0.0
    frozen: bool = False

    def observe(self, frame_time_s: float, wall_s: float) -> None:
        self.last_frame_s = frame_time_s
        self._wall_at_last = wall_s

    def now(self, wall_s: float) -> float | None:
        if self.last_frame_s is None:
            return None
        if self.frozen or self.speed <= 0:
            return self.last_frame_s
        return self.last_frame_s + max(0.0, wall_s - self._wall_at_last) * self.speed

    def shift(self, seconds: float) -> None:
        """Pauses: the wall time spent paused does not age anything."""
        self._wall_at_last += seconds


class LogPlayer:
    """Paces a log's frames against the wall clock.

    `speed` 1 is real time, N is N× faster, 0 as fast as possible. Timestamps that go backwards
    (spliced logs) do not wait; long gaps are kept as they are.
    """

    def __init__(self, frames: Iterable[Frame], speed: float = 1.0) -> None:
        self._frames = iter(frames)
        self.speed = float(speed)
        self._next: Frame | None = None
        self._log_elapsed = 0.0
        self._prev_time: float | None = None
        self._wall_start: float | None = None
        self.finished = False
        self.paused_at: float | None = None

    def _peek(self) -> Frame | None:
        if self._next is None and not self.finished:
            try:
                self._next = next(self._frames)
            except StopIteration:
                self.finished = True
        return self._next

    def _due(self, frame: Frame) -> float:
        delta = 0.0 if self._prev_time is None else max(0.0, frame.time_s - self._prev_time)
        return (self._wall_start or 0.0) + (self._log_elapsed + delta) / self.speed

    def pause(self, wall_s: float) -> None:
        if self.paused_at is None:
            self.paused_at = wall_s

    def resume(self, wall_s: float) -> float:
        """Leave pause; returns how long it lasted (to shift clocks by)."""
        if self.paused_at is None:
            return 0.0
        paused = max(0.0, wall_s - self.paused_at)
        self.paused_at = None
        if self._wall_start is not None:
            self._wall_start += paused
        return paused

    def due_frames(self, wall_s: float, limit: int = 10_000) -> list[Frame]:
        """Frames whose time has come (at most `limit`, so a screen keeps up with fast replays)."""
        if self.paused_at is not None:
            return []
        out: list[Frame] = []
        if self._wall_start is None:
            self._wall_start = wall_s
        while len(out) < limit:
            frame = self._peek()
            if frame is None:
                break
            if self.speed > 0 and self._due(frame) > wall_s:
                break
            if self._prev_time is not None:
                self._log_elapsed += max(0.0, frame.time_s - self._prev_time)
            self._prev_time = frame.time_s
            self._next = None
            out.append(frame)
        return out

    def seconds_to_next(self, wall_s: float) -> float | None:
        """Wall seconds until the next frame is due (0 when one is due, None at the end)."""
        frame = self._peek()
        if frame is None:
            return None
        if self.speed <= 0 or self._wall_start is None or self.paused_at is not None:
            return 0.0
        return max(0.0, self._due(frame) - wall_s)


# ---------------------------------------------------------------------------------------------
class LogSource:
    """A log file as a frame source, paced by `LogPlayer`, with its own clock."""

    def __init__(self, frames: Iterable[Frame], speed: float = 1.0, description: str = "log",
                 batch: int = 2000) -> None:
        self.player = LogPlayer(frames, speed)
        self.clock = FrameClock(speed=speed)
        self.description = description
        self.batch = batch
        self.error: str | None = None

    @property
    def finished(self) -> bool:
        return self.error is not None or self.player.finished and self.player._next is None

    def poll(self, max_wait_s: float, wall: Any) -> list[Frame]:
        """Frames due now; waits up to `max_wait_s` (with `wall.sleep`) when none is."""
        if self.finished:
            self.clock.frozen = True
            wall.sleep(max_wait_s)
            return []
        try:
            frames = self.player.due_frames(wall.monotonic(), self.batch)
            if not frames and self.player.paused_at is None:
                wait = self.player.seconds_to_next(wall.monotonic())
                if wait is not None:
                    wall.sleep(min(max_wait_s, wait))
                    frames = self.player.due_frames(wall.monotonic(), self.batch)
            elif not frames:
                wall.sleep(max_wait_s)
        except (OSError, ValueError, EOFError) as exc:  # a corrupt log, mid-way
            self.error = f"log unreadable: {exc}"
            return []
        if frames:
            self.clock.observe(frames[-1].time_s, wall.monotonic())
        if self.finished:
            self.clock.frozen = True
        return frames

    def now(self, wall_s: float) -> float | None:
        return self.clock.now(wall_s)

    def pause(self, wall_s: float) -> None:
        self.player.pause(wall_s)
        self.clock.frozen = True

    def resume(self, wall_s: float) -> None:
        self.clock.shift(self.player.resume(wall_s))
        self.clock.frozen = self.finished


class BusSource:
    """A bus as a frame source: anything with `recv(timeout)`, plus a converter to `Frame`."""

    def __init__(self, bus: Any, to_frame: Any, description: str = "bus", batch: int = 5000) -> None:
        self.bus = bus
        self.to_frame = to_frame
        self.clock = FrameClock(speed=1.0)
        self.description = description
        self.batch = batch
        self.error: str | None = None
        self.finished = False

    def poll(self, max_wait_s: float, wall: Any) -> list[Frame]:
        frames: list[Frame] = []
        try:
            msg = self.bus.recv(timeout=max_wait_s)
            while msg is not None:
                frames.append(self.to_frame(msg))
                if len(frames) >= self.batch:
                    break
                msg = self.bus.recv(timeout=0)
        except Exception as exc:  # interface went down (ip link set vcan0 down, USB unplugged)
            self.error = f"bus error: {exc}"
            wall.sleep(max_wait_s)
        if frames:
            self.error = None
            self.clock.observe(frames[-1].time_s, wall.monotonic())
        return frames

    def now(self, wall_s: float) -> float | None:
        return self.clock.now(wall_s)

    def pause(self, wall_s: float) -> None:
        pass  # a bus cannot be paused: frames keep being counted, the screen freezes

    def resume(self, wall_s: float) -> None:
        pass
