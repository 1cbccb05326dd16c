"""Front end: from decoded input signals to time-aligned physical samples.

Per wheel-speed (trigger) frame the front end

1. keeps the last few wheel-speed samples and fits a local quadratic in time through them
   (a Savitzky–Golay filter that uses the real timestamps, so jitter and dropped frames do not
   bias the derivative); the derivative is taken at the centre of the window, so every other
   signal is evaluated at that same, delayed instant and all carry the same delay
   (`wheel_speed_filter`), each wheel's speed over its own tyre's rolling radius, learnt while
   the car rolls free (`rolling_radius`);
2. interpolates the other messages (accelerations, pressures, reference speed, drive torque),
   which arrive with their own phase, at that instant (`input_alignment`), each pressure less
   its sensor's zero point (`pressure_zeros`);
3. estimates the vehicle speed (reference sensor when present and fresh, otherwise an
   accelerometer-driven observer corrected by the wheels: `speed_estimate`), the accelerometer
   offset and a brake-gain correction from the body equation (pads move ±20 % in service:
   `body_equation`);
4. computes normal loads (model.md, physics signs), tyre forces from the wheel equation,
   utilised friction and slip, and gates each wheel's sample (`sample_physics`); a sample whose
   inputs are in doubt is not fitted (`doubtful_inputs`), and faulty sensors are reported
   (`sensor_faults`).

Those modules hold parts of `FrontEnd`; this one maps the messages, holds their histories and
routes each frame through the gate to a sample. Pure numerics: it knows canonical signal names
(`input_names`), not CAN.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Iterable, Mapping

try:
    # The derivative filter's fit, the inputs' interpolation and matched sums and the history
    # pushes compiled (setup.py builds it when a C compiler is there); the float code below is
    # the fallback and the reference (tests/test_frontcore.py compares).
    from . import _frontcore as compiled_front
except ImportError:  # pragma: no cover - depends on the install
    compiled_front = None

from .abs_activity import AbsActivity
from .body_equation import LEARNT_STATE, BodyEquation
from .doubtful_inputs import DoubtfulInputs
from .free_rolling_offset import UNLEARNT_ACCEL_TOLERANCE_MPS2
from .input_alignment import InputAlignment, MessageHistory, new_series
from .input_names import (ABS_FLAG_NAMES, DRIVE_TORQUE_NAMES, MASTER_PRESSURE_NAME, PRESSURE_NAMES, REQUIRED_INPUTS,
                          WHEEL_SPEED_NAMES)
from .plausibility import InputGate
from .pressure_noise import PressureNoise
from .pressure_zeros import PressureZeros
from .rolling_radius import RollingRadii
from .sample_physics import PHYSICS_TYPES as _PHYSICS_TYPES  # noqa: F401 (tests hand it to the compiled physics)
from .sample_physics import SamplePhysics
from .samples import FrontEndResult, PhysicalSample
from .sensor_faults import SensorFaults
from .speed_estimate import SpeedEstimate
from .vehicle import VehicleParams
from .wheel_speed_filter import WheelSpeedFilter

_FL, _FR, _RL, _RR = WHEEL_SPEED_NAMES

# Plausibility limits of physical inputs; beyond them a sensor is broken, not the road special.
MAX_WHEEL_SPEED_RADPS = 400.0


@dataclass(frozen=True, slots=True)
class FrontEndOptions:
    """Front-end tuning; field names are the config keys under `frontend:`."""

    # Wheel-speed samples in the local quadratic fit (odd); 0: as many as span
    # `derivative_span_s` at the wheel-speed message's cycle time (5 at 10 and at 20 ms, 9 at 5 ms).
    # The fit averages ω̇, and the torques matched to it, over its span: an ABS cycle's peak of
    # grip lasts a few tens of ms, and over 60 ms the μ measured at the top of the cycle read 10 %
    # under the tyre's (half of that over 40 ms), pulling the fitted peak down with it.
    derivative_window: int = 0
    derivative_span_s: float = 0.04
    min_speed: float = 3.0                # m/s; below it slip is ill-conditioned
    max_slip: float = 0.6                 # samples beyond it (near lock) are not used
    min_brake_pressure: float = 1.0       # bar above push-out for a wheel to count as braked
    # A wheel the ABS released (braked within `released_wheel_s`) spinning back up from deep
    # slip: the road's force alone turns it, J·ω̇ = r·F_x, a sample of its tyre's curve with no
    # brake torque to doubt. On ice a slow-dump ABS holds the wheels released for most of each
    # cycle; the spin-up lasts up to ~1 s there at speed (`accel_bias_settle_s`). Only from
    # `released_min_slip` up, past a low-μ road's peak, where the curve is flat in slip: nearer
    # the peak the spin-up sweeps the curve's steep side faster than the tyre's force follows
    # (its relaxation), and the samples read above the static curve (10 % of the peak over a
    # band of slips in the built-in `ice_fast` scenario, converging 0.9 s later with them).
    released_wheel_s: float = 1.0
    released_min_slip: float = 0.1
    stale_periods: float = 3.0            # an input older than this many periods is stale
    default_period: float = 0.01          # s, when the DBC gives no cycle time
    # rad/s a glitch sample is off its neighbours and both sides' trends, on top of what the wheel's
    # acceleration can change within a sample (`SUSPECT_JERK_RADPS3`·period²; see `wheel_speed_filter._glitch_value`)
    spike_threshold: float = 2.0
    max_gap: float = 0.25                 # s between wheel-speed frames before the filter restarts
    reorder_window: float = 0.05          # s; an older wheel-speed frame within this is skipped, not a restart
    # A wheel-speed frame's sample waits for the pressures and the acceleration to be received up
    # to its time, at most this many of their longest period (`trigger_hold`; 0: it does not wait)
    input_wait_periods: float = 2.0
    speed_gain_up: float = 0.3            # observer gain when wheels read faster than the estimate
    speed_gain_down: float = 0.02         # ... and when even the fastest wheel reads too slow
    # Under braking two wheels faster than the estimate pull it up by no more than this (m/s²: the
    # learnt accelerometer offset's error, with margin), unless they stay faster for longer than a
    # released tyre's overshoot lasts (`speed_estimate.SpeedEstimate._speed_correction_limit`);
    # wheels all beyond `min_braked_slip` pull it down by no more than this either
    speed_correction_rate: float = 0.1
    speed_correction_hold_s: float = 0.2
    # Under braking even the least-braked wheel slips less than this: only a bound against an
    # accelerometer gone wrong, not a speed reference (an ABS may hold every wheel at 30-40 %
    # slip on a road whose peak is there; a tighter bound drags the speed and every slip low).
    min_braked_slip: float = 0.5
    max_all_wheel_slip: float = 0.3       # ... and never all four wheels beyond this at once
    stuck_frames: int = 8                 # identical wheel-speed readings in a row that mean "stuck"
    unexplained_decel: float = 1.5        # m/s^2 of deceleration that zero brake pressure cannot explain
    speed_gain_free_rolling: float = 0.15
    accel_bias_time_constant: float = 3.0   # s, accelerometer offset learning while free rolling
    # Released wheels close their slip on the car's speed with a time constant J·v/(r²·C·F_z), up
    # to ~0.3 s for a low-grip tyre at motorway speed: until a few of those have passed since a
    # braked wheel last slipped (`SETTLE_SLIP`), their acceleration is not the car's and would
    # teach the offset a spin-up.
    accel_bias_settle_s: float = 1.0
    brake_gain_correction: bool = True
    brake_gain_time_constant: float = 2.0   # s
    brake_gain_min_decel: float = 0.25       # m/s^2 of deceleration before the body equation is used
    brake_gain_limits: float = 0.25         # correction stays within 1 ± this
    dead_wheel_ratio: float = 0.1           # a wheel this far below the others (share of their speed) ...
    dead_wheel_s: float = 0.2               # ... for longer than an ABS lets a braked wheel lock is dead
    dead_wheel_unbraked_s: float = 0.05     # ... or this long with no brake pressure that could lock it
    # Identify the pressure sensors' lag from the body equation and advance the brake torques by
    # it (`_learn_pressure_lag`); off: the pressures are taken as the brakes' at their instant.
    pressure_lag_compensation: bool = True
    # Learn the tyre's relaxation length from the μ–slip loops its lag draws under ABS and invert
    # the lag before the fit (`relaxation`; each sample reaches the estimator one sample late).
    relaxation_compensation: bool = True
    # The car brakes only on level ground (a test track, a simulator without grades): free rolling
    # then teaches the accelerometer's own offset, and the body equation takes it as known. Off (a
    # car on public roads): what free rolling teaches includes gravity's share on a grade, which
    # the brakes and the tyres' loads do not feel; the offset they see is told from the brakes'
    # gain by the body equation itself (`brake_gain.gain_and_sensor_offset`).
    level_road: bool = False
    # How far the longitudinal accelerometer may read off the contact and air forces, m/s² (its
    # offset and the tilt of its mounting: 1° is 0.17): the prior of the offset the body equation
    # fits. An offset beyond it is read as brake gain: on the campaign's dev stops an offset of
    # 0.4 put 2.3 % of the VALID outputs more than 20 % off (0.27 % as drawn, ≤ 0.3).
    accel_offset_tolerance: float = UNLEARNT_ACCEL_TOLERANCE_MPS2
    # Free rolling (no brake pressure, no drive torque sent) is coasting: the accelerometer then
    # reads the air's drag and the car's resistance only, and tells its own offset, gravity's
    # share on a grade not read (`_learn_rolling_offset`). A car driven under power that does not
    # send its drive torques (WHEEL_DRIVE_TORQUE; absent means none) must set it false: its
    # engine's push would pass for the offset.
    coasting_offset: bool = True


    def validate(self) -> None:
        """Called by the config loader: `ValueError` names the bad setting."""
        if self.derivative_window != 0 and (self.derivative_window < 3 or self.derivative_window % 2 == 0):
            raise ValueError(f"derivative_window: must be 0 (from derivative_span_s) or an odd number ≥ 3, "
                             f"got {self.derivative_window}")
        for name in ("min_speed", "default_period", "derivative_span_s", "stale_periods", "max_gap",
                     "spike_threshold", "accel_bias_time_constant", "brake_gain_time_constant",
                     "accel_offset_tolerance"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)!r}")
        if not 0 < self.max_slip < 1:
            raise ValueError(f"max_slip: must be in (0, 1), got {self.max_slip!r}")
        for name in ("accel_bias_settle_s", "speed_correction_rate", "speed_correction_hold_s", "input_wait_periods",
                     "released_wheel_s"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name}: must be ≥ 0, got {getattr(self, name)!r}")
        # A negative bound would let every released wheel through, a bound ≥ 1 none: both silently
        # change which samples count as torqued rather than saying the setting is wrong.
        if not 0 <= self.released_min_slip < 1:
            raise ValueError(f"released_min_slip: must be in [0, 1), got {self.released_min_slip!r}")


class FrontEnd(WheelSpeedFilter, SamplePhysics, SpeedEstimate, BodyEquation, DoubtfulInputs, InputAlignment,
               PressureZeros, RollingRadii, SensorFaults):
    """Turns decoded inputs into `PhysicalSample`s, one per trigger (wheel-speed) message."""

    def __init__(
        self,
        vehicle: VehicleParams,
        options: FrontEndOptions,
        message_signals: Mapping[str, Iterable[str]],
        message_periods: Mapping[str, float | None],
        trigger_message: str,
        pressures_are_master: bool = False,
    ) -> None:
        options.validate()
        # All wheel pressures read from one signal: the driver's demand, an upper bound of each
        # wheel's pressure while an ABS works (it only ever releases).
        self.pressures_are_master = pressures_are_master
        self.vehicle = vehicle
        self.options = options
        # The compiled derivative filter when installed; `None` runs the float code (tests compare).
        self.core = compiled_front
        self.trigger_message = trigger_message
        self._map_messages(message_signals, message_periods)
        self._size_filter()
        self._plan_sample_inputs()
        self._plan_physics()
        self.reset()

    def _map_messages(self, message_signals: Mapping[str, Iterable[str]],
                      message_periods: Mapping[str, float | None]) -> None:
        """Which message carries each canonical signal, and each message's history; `ValueError`
        when a required input is not mapped."""
        self._signal_message: dict[str, str] = {}
        for message, names in message_signals.items():
            for name in names:
                self._signal_message[name] = message
        self._message_signals = {message: tuple(names) for message, names in message_signals.items()}
        self._pressure_messages = frozenset(self._signal_message[n] for n in PRESSURE_NAMES if n in self._signal_message)
        self.required_messages = frozenset(
            self._signal_message[n] for n in REQUIRED_INPUTS if n in self._signal_message
        )
        missing = [n for n in REQUIRED_INPUTS if n not in self._signal_message]
        if missing:
            raise ValueError(f"required inputs not mapped: {', '.join(missing)}")
        self._history = {
            m: MessageHistory(p if p and p > 0 else self.options.default_period)
            for m, p in message_periods.items()
        }
        for m in message_signals:
            self._history.setdefault(m, MessageHistory(self.options.default_period))
        self._required_histories = tuple((m, self._history[m]) for m in sorted(self.required_messages))
        # What each required message is called in a fault (its first canonical signal's kind).
        self._fault_names = {m: _input_label(message_signals[m]) for m in self.required_messages}

    def _plan_sample_inputs(self) -> None:
        """What each sample reads and how: the optional inputs present, the lookups fetched in
        one call."""
        vehicle = self.vehicle
        # Each canonical signal's history, looked up once here rather than by message per value.
        self._source = {name: self._history[m] for name, m in self._signal_message.items()}
        # Per wheel: the side of the car (−1 left) and half its axle's track.
        half_front, half_rear = vehicle.track_front / 2, vehicle.track_rear / 2
        self._wheel_offsets = ((-1.0, half_front), (1.0, half_front), (-1.0, half_rear), (1.0, half_rear))
        self._has_ref_speed = "vehicle_speed_ref" in self._signal_message
        self._has_drive_torque = all(n in self._signal_message for n in DRIVE_TORQUE_NAMES)
        self._has_yaw_rate = "yaw_rate" in self._signal_message
        self._abs_activity = AbsActivity()
        self._pressure_noise = PressureNoise(PRESSURE_NAMES)
        # The signals each sample reads at the window's centre, fetched in one call
        # (`_values_at`): accelerations, pressures, then the optional drive torques and yaw rate.
        self._sample_inputs = (("accel_long", "accel_lat") + PRESSURE_NAMES
                               + (DRIVE_TORQUE_NAMES if self._has_drive_torque else ())
                               + (("yaw_rate",) if self._has_yaw_rate else ()))
        self._sample_lookups = self._lookups(self._sample_inputs)
        # The same for the filter-matched sums (`_matched_inputs`): pressures less the push-out
        # pressure, then the body's acceleration.
        pushout = vehicle.brake_pushout_pressure
        self._matched_lookups = tuple(
            (self._source[n].series, n, floor) if n in self._source else None
            for n, floor in [(name, pushout) for name in PRESSURE_NAMES] + [("accel_long", None)])
        self._brake_gains = [vehicle.brake_gain(i) for i in range(4)]
        # What the ABS activity reads (`_mark_abs_activity`), fetched in one call: the pressures,
        # the master cylinder's, the car's flag and the wheels' (None where not mapped).
        self._abs_inputs = PRESSURE_NAMES + (MASTER_PRESSURE_NAME,) + ABS_FLAG_NAMES
        self._abs_lookups = self._lookups(self._abs_inputs)

    # -- state -----------------------------------------------------------------------------
    def reset(self) -> None:
        n = self.derivative_window
        # Frame-level plausibility (issue 22): a corrupted frame never reaches the histories.
        self.gate = InputGate(self.vehicle, {m: h.period_s for m, h in self._history.items()})
        self._abs_activity.reset()
        self._pressure_noise.reset()
        self._abs_activity.set_noise(None)
        self._before_sample: tuple | None = None
        self._wheel_times: deque[float] = deque(maxlen=n)
        self._wheel_speeds: deque[tuple[float, float, float, float]] = deque(maxlen=n)
        self._speed_estimate_mps: float | None = None
        self._speed_time_s: float | None = None
        self._wheels_faster_since_s: float | None = None   # (under braking, two wheels faster than the estimate)
        self._speed_restarted_braking = False              # (the estimate restarted from the fastest wheel, braking)
        self._reset_body_equation()
        self._sample_accel: float | None = None   # the newest sample's longitudinal acceleration input
        self._reset_pressure_zeros()
        self._reset_rolling_radii()
        self._last_trigger_s = -math.inf
        self.skipped_triggers = 0
        self._ref_disagreements = 0
        self._repeats = [0, 0, 0, 0]
        self._previous_speeds: tuple[float, ...] = (math.nan,) * 4
        self._unexplained_s = 0.0
        self._last_sample_time_s: float | None = None
        self._low_since_s: list[float | None] = [None] * 4
        self._low_unbraked_s = [0.0] * 4
        self._braked_time_s = [-math.inf] * 4   # when each wheel was last braked (`released_wheel_s`)
        self._dead = [False] * 4
        self._torque_weights: list[float] | None = None
        self._torque_omega_dot: list[float] | None = None   # the ω̇ those weights go with
        self._trigger_period_s = 0.0
        self._triggers_timed = 0

    def period_of(self, message: str) -> float:
        return self._history[message].period_s

    # -- main entry --------------------------------------------------------------------------
    def push(self, time_s: float, message: str, values: Mapping[str, float]) -> FrontEndResult | None:
        """Feed one decoded message; returns a result only for the trigger message."""
        history = self._history.get(message)
        if history is None:
            return None
        is_trigger = message == self.trigger_message
        if is_trigger:
            dt = time_s - self._last_trigger_s
            if -self.options.reorder_window < dt < 1e-4:
                # A repeated or slightly out-of-order wheel-speed frame (gateways and log
                # splices do this): skip it rather than restart the derivative filter.
                self.skipped_triggers += 1
                self.gate.note(time_s, "duplicate" if dt == 0.0 else "out of order")
                return None
        rejected = self.gate.admit(time_s, message, values)
        if self.gate.revoked:
            for taken, taken_s in self.gate.revoked.items():
                self._take_back(taken, taken_s)
            self.gate.revoked.clear()
        if rejected is not None:
            # Rejected: no sample from a wheel-speed frame that cannot be true (the last estimate
            # is repeated), a fault when they keep coming; nothing at all for a frame whose time
            # is not the bus's (an output must not carry it). Without a fault, an input that has
            # gone silent is still stale at this frame's time: a refused trigger must not hide it.
            if not is_trigger or rejected in _NO_OUTPUT:
                return None
            fault = self._persistent_fault()
            return FrontEndResult(None, () if fault is not None else self.stale_messages(time_s), fault)
        if message in self.gate.reanchored:
            # Followed to a new level the physics could not reach (a sensor back from a dead
            # spell): the derivative window must not straddle the step.
            self.gate.reanchored.discard(message)
            if is_trigger:
                self._wheel_times.clear()
                self._wheel_speeds.clear()
        if message in self._pressure_messages:
            if self._pressure_noise.push(time_s, values):
                self._abs_activity.set_noise(self._pressure_noise.sigma())
            values = self._zeroed_pressures(values)
        core = self.core
        if core is not None and type(time_s) is float and type(values) is dict and time_s >= history.last_arrival_s:
            # `MessageHistory.push`'s compiled path, without its call (once per input frame)
            core.push_values(history.series, history.merged, time_s, values, new_series)
            history.last_arrival_s = time_s
        else:
            history.push(time_s, values, core)
        if not is_trigger:
            self.gate.repair_spike(message, history.series)
            return None
        return self._on_trigger(time_s, history)

    def _on_trigger(self, time_s: float, history: MessageHistory) -> FrontEndResult:
        stale = self.stale_messages(time_s)
        values = history.merged
        # (the four wheels spelt out: this runs at the bus rate, and loops cost a frame each)
        try:
            speeds = fl, fr, rl, rr = (float(values[_FL]), float(values[_FR]), float(values[_RL]), float(values[_RR]))
        except KeyError:
            return FrontEndResult(None, stale, None)
        top = MAX_WHEEL_SPEED_RADPS
        if not (0.0 <= fl <= top and 0.0 <= fr <= top and 0.0 <= rl <= top and 0.0 <= rr <= top):   # (NaN: out)
            self._wheel_times.clear()
            self._wheel_speeds.clear()
            return FrontEndResult(None, stale, "wheel speed out of range")
        self._push_wheel_speeds(time_s, speeds)
        if len(self._wheel_times) < self.derivative_window:
            return FrontEndResult(None, stale, None)
        return self._sample_at(time_s, stale)

    def _sample_at(self, time_s: float, stale: tuple[str, ...]) -> FrontEndResult:
        """The sample of a full derivative window: a persistent fault or stale inputs give none;
        inputs in doubt give a suspect one (`_suspect_sample`), the rest `_compute_sample`'s."""
        fault = self._persistent_fault()
        if fault is not None:
            return FrontEndResult(None, (), fault)
        if stale:
            return FrontEndResult(None, stale, None)
        # (what this sample will teach, as it was: put back if its frame is revoked, `_take_back`)
        self._before_sample = (time_s, self._speed_estimate_mps, self._speed_time_s, self._wheels_faster_since_s,
                               self._speed_restarted_braking, self._last_sample_time_s,
                               [getattr(self, name) for name in LEARNT_STATE])
        if (self._newest_suspect() or self._input_lost(time_s)
                or (self.gate.contested(time_s) and not self._wheel_senders_told_apart(time_s))):
            result = self._suspect_sample(stale)
        else:
            free_rolling_before = self._accel_bias_samples
            result = self._compute_sample(stale)
            if result.sample is not None and result.sample.braking:
                self._attach_slip_spread(result.sample)
                self._learn_resistance_doubt(result.sample.speed_mps, sum(result.sample.tyre_force_n))
            elif result.sample is not None and self._accel_bias_samples > free_rolling_before:
                self._learn_pressure_zeros()
            if result.sample is not None:
                self._learn_rolling_radii(result.sample, self._free_rolling_sample)
        if result.fault == "wheel speed glitch":
            self.gate.count_repair(result.fault)
        if result.sample is not None:
            self._mark_abs_activity(result.sample)
            self._mark_body_mu(result.sample)
            self._mark_lateral_mu(result.sample)
            result.sample.brake_gain_doubt = math.hypot(self._brake_gain_doubt, self.resistance_doubt_share)
            result.sample.accel_offset_doubt_mps2 = self.accel_offset_doubt_mps2
            result.sample.input_suspect_share = self.gate.suspect_share()
        return result

    @property
    def pressure_noise_bar(self) -> float | None:
        """The brake-pressure sensors' noise σ as measured (`pressure_noise`), None until known."""
        return self._pressure_noise.sigma()

    def pressure_noise_note(self) -> str | None:
        """A line for the user when the pressure sensors are too noisy for the usual ABS-release
        threshold (`AbsActivity.noise_note`); None otherwise."""
        return self._abs_activity.noise_note(self._pressure_noise.sigma())

    def _mark_abs_activity(self, sample: PhysicalSample) -> None:
        """`sample.abs_active`: the wheels an ABS is working (see `abs_activity`), from the
        pressures, the master-cylinder pressure and the car's ABS flags at the sample's instant."""
        t = sample.time_s
        if self.core is not None:
            v = self.core.values_at(self._abs_lookups, t)
        else:
            v = tuple([self._value(n, t) for n in self._abs_inputs])
        sample.abs_active = self._abs_activity.update(t, v[:4], v[4], v[5], v[6:])

# Rejections of a trigger frame that give no output at all (its time is not the bus's).
_NO_OUTPUT = frozenset({"clock step", "out of order", "duplicate"})


def _input_label(signals: Iterable[str]) -> str:
    """'wheel speed', 'brake pressure' or 'acceleration': what a required message carries."""
    names = tuple(signals)
    for prefix, label in (("wheel_speed", "wheel speed"), ("brake_pressure", "brake pressure"),
                          ("accel", "acceleration")):
        if any(n.startswith(prefix) for n in names):
            return label
    return names[0] if names else "input"


def make_front_end(
    vehicle: VehicleParams,
    options: FrontEndOptions,
    messages: Iterable[Any],
    trigger_message: str,
    pressures_are_master: bool = False,
) -> FrontEnd:
    """Build from message descriptions having `name`, `period_s` and `signals` (canonical names);
    `pressures_are_master`: the four wheel pressures are one signal (see `FrontEnd`)."""
    messages = list(messages)
    return FrontEnd(
        vehicle,
        options,
        {m.name: tuple(m.signals) for m in messages},
        {m.name: m.period_s for m in messages},
        trigger_message,
        pressures_are_master,
    )
