"""The whole chain for one bus: frames → decoded signals → physical samples → estimate → frames.

Shared by `replay`, `run` and `demo`, so the live daemon and the offline replay compute the
same thing from the same frames.
"""
from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field, replace
from typing import Any, Callable

from . import input_quality
from .codec import DecodedInput, DecodeFailure, InputCodec, InputMessage, OutputCodec, load_databases
from .compensated_samples import CompensatedSamples
from .config import Config
from .cycle_times import CycleTimeProbe
from .frames import Frame
from .frontend import PRESSURE_NAMES, FrontEnd, FrontEndResult, make_front_end
from .relaxation import RelaxationCompensator
from .samples import FrictionEstimate, PhysicalSample, Status
from .trigger_hold import TriggerHold
from .wheel_speed_join import WheelSpeedJoin

_new_tuple = tuple.__new__


# This many repaired input faults within the window turn the status to FAULT.
FAULTS_FOR_STATUS = 15
FAULT_WINDOW_S = 0.5
# With a dead wheel-speed sensor the estimate goes on from the other wheels, but it has lost
# a wheel's data and the redundancy behind the speed estimate: never VALID, confidence capped.
DEAD_WHEEL_CONFIDENCE = 0.3


def make_estimator(config: Config, sample_period_s: float = 0.01) -> Any:
    """The estimator named by `estimator.kind`, for samples `sample_period_s` apart."""
    kind = config.estimator.kind
    if kind == "lugre-tr":
        from .estimator import LugreTrustRegionEstimator

        return LugreTrustRegionEstimator(config.estimator.lugre_tr, config.vehicle, sample_period_s)
    if kind == "burckhardt-rls":
        from .baseline_rls import BurckhardtRLSEstimator

        return BurckhardtRLSEstimator(config.estimator.burckhardt_rls, config.vehicle)
    raise ValueError(f"estimator.kind: unknown estimator {kind!r}")


# Why a master-cylinder-only car has no wheel μ under ABS (`PipelineStats.unmeasured`).
WHEEL_TORQUES_UNKNOWN = ("wheel brake torques unknown (one master-cylinder pressure for all wheels, "
                         "and an ABS released wheels)")


@dataclass
class PipelineStats:
    frames_read: int = 0
    input_frames: int = 0
    ignored: Counter = field(default_factory=Counter)   # frames that are not inputs, by kind
    error_frames: int = 0
    undecodable: Counter = field(default_factory=Counter)
    updates: int = 0
    frames_out: int = 0
    status_updates: Counter = field(default_factory=Counter)
    faults: Counter = field(default_factory=Counter)
    # Updates whose estimate would have been VALID, by the reason it was not (input_quality).
    not_valid: Counter = field(default_factory=Counter)
    # Braking updates the estimator kept from VALID, by its own reason (`not_valid`).
    estimator_not_valid: Counter = field(default_factory=Counter)
    # Braking updates at which no wheel's μ could be measured, by the reason.
    unmeasured: Counter = field(default_factory=Counter)

    @property
    def ignored_frames(self) -> int:
        return sum(self.ignored.values())

    @property
    def undecodable_total(self) -> int:
        return sum(self.undecodable.values())


class Pipeline(CompensatedSamples):
    """Feeds frames through codec, front end and estimator; returns the frames to send."""

    def __init__(self, config: Config, estimator: Any | None = None) -> None:
        self.config = config
        input_db = load_databases(config.can.dbc, strict=config.can.dbc_strict)
        output_db = load_databases([config.can.output_dbc], strict=True)
        self.input_codec = InputCodec(input_db, config.signals, config.vehicle.wheel_radius)
        self._input_ids = self.input_codec.input_ids
        self.output_codec = OutputCodec(output_db)
        messages = self.input_codec.input_messages()
        self.trigger_message = self.input_codec.trigger_message
        self._own_estimator = estimator is None
        self.estimator = estimator
        self._build(messages)
        # Cycle times the DBC does not give: measured from the first frames (`cycle_times`), and
        # the front end rebuilt with them where they are off the default assumed.
        undeclared = {m.name: config.frontend.default_period for m in messages if not m.period_s}
        self._cycle_probe = CycleTimeProbe(undeclared) if undeclared else None
        self.measured_cycle_times: dict[str, float] = {}
        self.stats = PipelineStats()
        self.last_estimate: FrictionEstimate | None = None
        self.last_sample: PhysicalSample | None = None
        self.last_result: FrontEndResult | None = None
        # Called with each estimate sent and its sample (replay's recorder): one frame may release
        # more than one update where the wheel speeds come from several messages (`wheel_join`).
        self.on_estimate: Callable[[FrictionEstimate, PhysicalSample | None], None] | None = None
        self._last_valid: FrictionEstimate | None = None
        self._last_output_s = -math.inf
        self._last_trigger_s = -math.inf
        # The frame times of the wheel-speed inputs `trigger_hold` holds, oldest first.
        self._trigger_stamps: deque[float] = deque()
        self._wheel_divider = max(1, int(config.output.wheel_divider))
        self._recent_faults: deque[float] = deque()
        self._first_update_s: float | None = None
        self._corrupt_input = False   # the share of corrupted input keeps the status from VALID
        self.relaxation = RelaxationCompensator(config.frontend.relaxation_compensation)

    def _build(self, messages: list[InputMessage]) -> None:
        """The parts sized by the messages' cycle times: the wheel-speed join, the front end and
        (unless given) the estimator."""
        config, trigger = self.config, self.trigger_message
        partners = self.input_codec.wheel_partners
        # Wheel speeds of messages apart from the trigger's, completed at its instants.
        self.wheel_join: WheelSpeedJoin | None = None
        if partners:
            self.wheel_join = WheelSpeedJoin(trigger, partners, {m.name: m.period_s for m in messages})
            messages = WheelSpeedJoin.front_end_messages(messages, trigger, partners)
        # A car that sends only its master-cylinder pressure maps it to all four wheels.
        pressure_sources = {(config.signals[n].message, config.signals[n].signal)
                            for n in PRESSURE_NAMES if n in config.signals}
        # Each wheel-speed input held until the pressures and the acceleration its sample is
        # matched with have been received up to its time (`trigger_hold`).
        held = self.trigger_hold.flush() if hasattr(self, "trigger_hold") else []
        self.trigger_hold = TriggerHold.for_messages(trigger, messages, config.frontend.input_wait_periods,
                                                     config.frontend.default_period)
        for item in held:   # (rebuilt at the measured cycle times: they wait for the partners again)
            self.trigger_hold.push(item)
        before: FrontEnd | None = getattr(self, "front_end", None)
        self.front_end: FrontEnd = make_front_end(config.vehicle, config.frontend, messages, trigger,
                                                  pressures_are_master=len(pressure_sources) == 1)
        if before is not None:
            # (rebuilt at the measured cycle times: what coasting showed of the accelerometer so
            # far is the sensor's, whatever the period its samples were taken at)
            self.front_end.take_coasting_from(before)
        if self._own_estimator:
            learnt = self.estimator.state() if self.estimator is not None else None
            self.estimator = make_estimator(config, self.front_end.sample_period_s)
            if learnt is not None:
                self.estimator.load_state(learnt)

    def _measure_cycle(self, message: str, time_s: float) -> None:
        """A frame of a message without a DBC cycle time, while those are being measured; the
        front end rebuilt once they are known, if any is off what was assumed."""
        measured = self._cycle_probe.see(message, time_s)  # type: ignore[union-attr]
        if measured is None:
            return
        self._cycle_probe = None
        if measured:
            self.measured_cycle_times = measured
            self._build([m._replace(period_s=measured.get(m.name, m.period_s))
                         for m in self.input_codec.input_messages()])

    # ------------------------------------------------------------------------------------------
    def process(self, frame: Frame) -> list[Frame]:
        """One received frame in; the output frames it causes (empty for most frames)."""
        stats = self.stats
        stats.frames_read += 1
        if frame.can_id not in self._input_ids or frame.is_error or frame.is_remote:
            # Most of a bus is other ECUs' traffic: counted and dropped before anything else.
            self._ignore(frame)
            return []
        try:
            decoded = self.input_codec.decode(frame)
        except DecodeFailure as exc:
            stats.undecodable[str(exc.reason if hasattr(exc, "reason") else exc)] += 1
            # (an input frame that could not be read is corruption too: it counts in the share)
            self.front_end.gate.note(frame.time_s, "undecodable")
            return []
        if decoded is None:   # an extended frame that shares a standard input's ID
            self._ignore(frame)
            return []
        stats.input_frames += 1
        if self._cycle_probe is not None:
            self._measure_cycle(decoded.message, decoded.time_s)
        out: list[Frame] = []
        for part in (self.wheel_join.push(decoded) if self.wheel_join is not None else (decoded,)):
            if part.message == self.trigger_message:
                self._last_trigger_s = frame.time_s
                self._trigger_stamps.append(frame.time_s)
            for item in self.trigger_hold.push(part):
                out.extend(self._feed(item))
        return out

    def flush(self) -> list[Frame]:
        """The end of the input (a log's last frame): the wheel-speed inputs still waiting for
        their partners' frames (`trigger_hold`) go to the front end as they are."""
        out: list[Frame] = []
        for item in self.trigger_hold.flush():
            out.extend(self._feed(item))
        return out

    def _feed(self, item: DecodedInput) -> list[Frame]:
        """One decoded input to the front end; the output frames of the update a wheel-speed
        input causes, stamped with the time of the frame that brought it (can-contract.md)."""
        stamps = self._trigger_stamps
        stamp = stamps.popleft() if item.message == self.trigger_message and stamps else item.time_s
        result = self.front_end.push(item.time_s, item.message, item.values)
        return [] if result is None else self._update(stamp, result)

    def count_unrelated(self, frames: int) -> None:
        """Count standard-ID data frames of other IDs that a reader dropped before `process`."""
        self.stats.frames_read += frames
        if frames:
            self.stats.ignored["unrelated IDs"] += frames

    def _ignore(self, frame: Frame) -> None:
        """Count a frame that is not an input, by kind."""
        if frame.is_error:
            self.stats.error_frames += 1
        else:
            self.stats.ignored["remote frames" if frame.is_remote else
                               "extended IDs" if frame.is_extended else "unrelated IDs"] += 1

    def tick(self, now_s: float) -> list[Frame]:
        """Call when no frame has arrived for a while: the wheel-speed inputs that have waited
        their longest for their partners go on (`trigger_hold`), and a stale trigger input is
        reported."""
        released: list[Frame] = []
        for item in self.trigger_hold.due(now_s):
            released.extend(self._feed(item))
        if released:
            return released
        period = self.front_end.period_of(self.trigger_message)
        limit = self.config.frontend.stale_periods * period
        if now_s - self._last_trigger_s <= limit or now_s - self._last_output_s < period:
            return []
        stale = self.front_end.stale_messages(now_s)
        if not stale:
            return []
        # (what was last said: the trigger frames after the gap warm the filter up, and they must
        # not repeat a VALID from before it, whether the loop ticked before them or not)
        self.last_estimate = self._held_estimate(now_s, Status.INPUT_STALE)
        return self._emit(now_s, self.last_estimate, None)

    # ------------------------------------------------------------------------------------------
    def _held_estimate(self, time_s: float, status: Status) -> FrictionEstimate:
        """The last known estimate, relabelled: MuMax must not be trusted under this status."""
        prev = self._last_valid or self.last_estimate
        if prev is None:
            return FrictionEstimate(time_s, status, 0.0, 0.0, 1.0, 0.0)
        return FrictionEstimate(
            time_s, status, prev.mu_max, prev.slip_at_mu_max, prev.theta, 0.0, prev.wheel_mu_max, math.inf
        )

    def _update(self, time_s: float, result: FrontEndResult) -> list[Frame]:
        self.last_result = result
        result = self._compensated(time_s, result)
        if self._first_update_s is None:
            self._first_update_s = time_s
        if result.stale_messages:
            # Right after start a message may simply not have had its first turn yet: that is
            # INIT, not a timeout. It becomes INPUT_STALE once its timeout has really passed.
            slowest = max(self.front_end.period_of(m) for m in self.front_end.required_messages)
            starting = (time_s - self._first_update_s <= self.config.frontend.stale_periods * slowest
                        and self._last_valid is None)
            estimate = self._held_estimate(time_s, Status.INIT if starting else Status.INPUT_STALE)
        elif result.fault is not None and result.sample is None:
            self.stats.faults[result.fault] += 1
            estimate = self._held_estimate(time_s, Status.FAULT)
        elif result.sample is None:
            # Filter warming up (start, or after a gap): repeat what we last said.
            prev = self.last_estimate
            # (not after a silence: a VALID from before it is no estimate of the road now)
            silent = time_s - self._last_output_s > self.config.frontend.max_gap
            if prev is None or prev.status in (Status.INPUT_STALE, Status.FAULT) or silent:
                estimate = self._held_estimate(
                    time_s, Status.INIT if self._last_valid is None else Status.NOT_EXCITED
                )
            else:
                estimate = replace(prev, time_s=time_s)
        else:
            estimate = self._estimate_from_sample(time_s, result)
        self.last_estimate = estimate
        frames = self._emit(time_s, estimate, self.last_sample)
        if frames and self.on_estimate is not None:
            self.on_estimate(estimate, self.last_sample)
        return frames

    def _estimate_from_sample(self, time_s: float, result: FrontEndResult) -> FrictionEstimate:
        """The estimator's update on the front end's sample, its status lowered where the input is
        in doubt: many repaired faults (FAULT), a dead wheel-speed sensor or much corrupt input."""
        if result.fault is not None:
            self.stats.faults[result.fault] += 1
            self._recent_faults.append(time_s)
        self.last_sample = result.sample
        if result.sample.braking and self.front_end.wheel_torques_unknown:
            self.stats.unmeasured[WHEEL_TORQUES_UNKNOWN] += 1
        estimate = self.estimator.update(result.sample)
        while self._recent_faults and self._recent_faults[0] < time_s - FAULT_WINDOW_S:
            self._recent_faults.popleft()
        if result.dead_wheels:
            self.stats.faults["wheel speed dead"] += 1
        self._corrupt_input = input_quality.leaves_valid(result.sample.input_suspect_share, self._corrupt_input)
        if len(self._recent_faults) >= FAULTS_FOR_STATUS:
            # Glitches the front end could repair, but so many that the input itself is
            # suspect (a failing sensor, a spoofing node): say so instead of VALID.
            estimate = replace(estimate, status=Status.FAULT, confidence=0.0)
        elif result.dead_wheels:
            # A wheel-speed sensor reads zero while the car rolls: that wheel is out of the
            # fit; what the others give is reported, but not promised (not VALID).
            estimate = replace(estimate, status=Status.CONVERGING if estimate.status == Status.VALID
                               else estimate.status, confidence=min(estimate.confidence, DEAD_WHEEL_CONFIDENCE))
        elif self._corrupt_input and estimate.status == Status.VALID:
            # Too much of the input was rejected as corrupt: what got through may bend the
            # estimate (the summary and the monitor say so).
            self.stats.not_valid[input_quality.REASON] += 1
            estimate = replace(estimate, status=Status.CONVERGING,
                               confidence=min(estimate.confidence, input_quality.CAPPED_CONFIDENCE))
        elif estimate.status == Status.VALID:
            self._last_valid = estimate
        elif result.sample.braking:
            self._count_not_valid(estimate)
        return estimate

    @property
    def not_valid_reason(self) -> str:
        """Why the last estimate is CONVERGING or NOT_EXCITED, in words ("" for the other
        statuses, which say why themselves): too much corrupt input, or the estimator's reason."""
        est = self.last_estimate
        if est is None or est.status not in (Status.CONVERGING, Status.NOT_EXCITED):
            return ""
        if self._corrupt_input:
            return input_quality.REASON
        return getattr(self.estimator, "not_valid_reason", "")

    def _count_not_valid(self, estimate: FrictionEstimate) -> None:
        """A braking update the estimator itself kept from VALID, by its reason (`not_valid`):
        the replay summary's answer to "why did this stop stay CONVERGING?"."""
        if estimate.status in (Status.CONVERGING, Status.NOT_EXCITED):
            reason = getattr(self.estimator, "not_valid_reason", "")
            if reason:
                self.stats.estimator_not_valid[reason] += 1

    def _emit(self, time_s: float, estimate: FrictionEstimate, sample: PhysicalSample | None) -> list[Frame]:
        stats = self.stats
        stats.updates += 1
        stats.status_updates[estimate.status] += 1
        self._last_output_s = time_s
        codec = self.output_codec
        # tuple.__new__: a Frame without its Python-level __new__ (five frames an update)
        frames = [_new_tuple(Frame, (time_s, codec.estimate_id, codec.encode_estimate(estimate), False, False, False))]
        if sample is not None and stats.updates % self._wheel_divider == 0:
            wheel_id = codec.wheel_id
            for payload in codec.encode_wheels(estimate, sample):
                frames.append(_new_tuple(Frame, (time_s, wheel_id, payload, False, False, False)))
        stats.frames_out += len(frames)
        return frames
