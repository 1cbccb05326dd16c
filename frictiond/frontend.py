"""Front end: from decoded input signals to time-aligned physical samples.

Per wheel-speed (trigger) frame the front end

1. keeps the last few wheel-speed samples and fits a local quadratic in time through them
   (a Savitzky–Golay filter that uses the real timestamps, so jitter and dropped frames do not
   bias the derivative); the derivative is taken at the centre of the window, so every other
   signal is evaluated at that same, delayed instant and all carry the same delay
   (`wheel_speed_filter`);
2. interpolates the other messages (accelerations, pressures, reference speed, drive torque),
   which arrive with their own phase, at that instant (`input_alignment`), each pressure less
   its sensor's zero point (`pressure_zeros`);
3. estimates the vehicle speed (reference sensor when present and fresh, otherwise an
   accelerometer-driven observer corrected by the wheels: `speed_estimate`), the accelerometer
   offset and a brake-gain correction from the body equation (pads move ±20 % in service:
   `body_equation`);
4. computes normal loads (model.md, physics signs), tyre forces from the wheel equation,
   utilised friction and slip, and gates each wheel's sample; a sample whose inputs are in
   doubt is not fitted (`doubtful_inputs`), and faulty sensors are reported (`sensor_faults`).

Those modules hold parts of `FrontEnd`; this one holds the histories and the sample's physics
with the faults it finds. Pure numerics: it knows canonical signal names (`input_names`), not CAN.
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
from .input_alignment import InputAlignment, MessageHistory, new_series
from .input_names import (ABS_FLAG_NAMES, DRIVE_TORQUE_NAMES, MASTER_PRESSURE_NAME, PRESSURE_NAMES, REQUIRED_INPUTS,
                          WHEEL_SPEED_NAMES)
from .plausibility import InputGate
from .pressure_zeros import PressureZeros
from .samples import PhysicalSample
from .sensor_faults import SensorFaults, stood_in_for
from .speed_estimate import MAX_ABS_ACCEL_MPS2, SpeedEstimate
from .vehicle import GRAVITY_MPS2, VehicleParams
from .wheel_speed_filter import SUSPECT_JERK_RADPS3, WheelSpeedFilter

_FL, _FR, _RL, _RR = WHEEL_SPEED_NAMES

# Plausibility limits of physical inputs; beyond them a sensor is broken, not the road special.
MAX_WHEEL_SPEED_RADPS = 400.0
FREE_ROLLING_SPREAD = 0.04     # relative wheel-speed spread a curve can explain without any slip
FREE_ROLLING_ACCEL_MPS2 = 2.0  # a free-rolling wheel's acceleration follows the body's within this
SETTLE_SLIP = 0.01             # a braked wheel slipping more has a spin-up to settle (`accel_bias_settle_s`)
MAX_PRESSURE_BAR = 350.0
MIN_SAMPLE_PERIOD_S = 0.004    # the per-sample constants are never set for a faster trigger than this
BODY_WHEELS_TOLERANCE = 0.25   # the body's and the wheels' total force agree within this (pad friction ±20 %)


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
    stale_periods: float = 3.0            # an input older than this many periods is stale
    default_period: float = 0.01          # s, when the DBC gives no cycle time
    # rad/s a glitch sample is off its neighbours and both sides' trends, on top of what the wheel's
    # acceleration can change within a sample (`SUSPECT_JERK_RADPS3`·period²; see `wheel_speed_filter._glitch_value`)
    spike_threshold: float = 2.0
    max_gap: float = 0.25                 # s between wheel-speed frames before the filter restarts
    reorder_window: float = 0.05          # s; an older wheel-speed frame within this is skipped, not a restart
    speed_gain_up: float = 0.3            # observer gain when wheels read faster than the estimate
    speed_gain_down: float = 0.02         # ... and when even the fastest wheel reads too slow
    # Under braking two wheels faster than the estimate pull it up by no more than this (m/s²: the
    # learnt accelerometer offset's error, with margin), unless they stay faster for longer than a
    # released tyre's overshoot lasts (`speed_estimate.SpeedEstimate._speed_correction_limit`)
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


    def validate(self) -> None:
        """Called by the config loader: `ValueError` names the bad setting."""
        if self.derivative_window != 0 and (self.derivative_window < 3 or self.derivative_window % 2 == 0):
            raise ValueError(f"derivative_window: must be 0 (from derivative_span_s) or an odd number ≥ 3, "
                             f"got {self.derivative_window}")
        for name in ("min_speed", "default_period", "derivative_span_s", "stale_periods", "max_gap",
                     "spike_threshold", "accel_bias_time_constant", "brake_gain_time_constant"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)!r}")
        if not 0 < self.max_slip < 1:
            raise ValueError(f"max_slip: must be in (0, 1), got {self.max_slip!r}")
        for name in ("accel_bias_settle_s", "speed_correction_rate", "speed_correction_hold_s"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name}: must be ≥ 0, got {getattr(self, name)!r}")


@dataclass(slots=True)
class FrontEndResult:
    """Outcome of one trigger frame."""

    sample: PhysicalSample | None       # None while the filter warms up or after a fault
    stale_messages: tuple[str, ...] = ()
    fault: str | None = None
    # Wheels whose speed sensor reads (near) zero while the car rolls on: excluded from the
    # sample; the estimate goes on with the others, but must not be called VALID.
    dead_wheels: tuple[int, ...] = ()


class FrontEnd(WheelSpeedFilter, SpeedEstimate, BodyEquation, DoubtfulInputs, InputAlignment, PressureZeros,
               SensorFaults):
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

    def _size_filter(self) -> None:
        """The per-sample constants, for the trigger's cycle time."""
        options, trigger = self.options, self.trigger_message
        # One wheel-speed sample per trigger: the per-sample constants (the derivative window,
        # the forgetting of the brake-gain and accelerometer-offset learning) are set for the
        # trigger's cycle time, not for 10 ms. A 7-sample window at 20 ms spans 0.12 s, over
        # which an ABS cycle's wheel speed is no quadratic: every other sample was a "glitch".
        # (Not below 4 ms: the daemon's flood guard passes at most 250 updates/s by default, and a
        # DBC claiming 1 ms would otherwise size a 61-sample window for frames that come slower.)
        self.declared_period_s = (self._history[trigger].period_s if trigger in self._history
                                  else options.default_period)
        self.sample_period_s = max(MIN_SAMPLE_PERIOD_S, self.declared_period_s)
        # A glitch is off its neighbours by more than noise and more than a wheel's acceleration
        # can change within a sample: at 20 ms (50 Hz wheel speeds) a wheel recovering from deep
        # slip and overshooting is sampled as a zig-zag of ~10 rad/s on both front wheels alike.
        self.glitch_threshold = options.spike_threshold + SUSPECT_JERK_RADPS3 * self.sample_period_s ** 2
        # The wheels' fit spans `derivative_span_s` but takes at least 5 samples (the glitch test
        # needs two on each side); the ω̇ the torques are set against in μ spans only the samples
        # within `derivative_span_s` (3 at 20 ms): averaged over 80 ms, the top of an ABS cycle
        # read μ 0.038 low at 50 Hz, over 40 ms 0.016.
        span_samples = max(3, 2 * round(options.derivative_span_s / self.sample_period_s / 2) + 1)
        self.derivative_window = options.derivative_window or max(5, span_samples)
        self.torque_window = options.derivative_window or span_samples

    def _plan_sample_inputs(self) -> None:
        """What each sample reads and how: the optional inputs present, the lookups fetched in
        one call, the constants of the compiled physics."""
        vehicle, options = self.vehicle, self.options
        # Each canonical signal's history, looked up once here rather than by message per value.
        self._source = {name: self._history[m] for name, m in self._signal_message.items()}
        # Per wheel: the side of the car (−1 left) and half its axle's track.
        half_front, half_rear = vehicle.track_front / 2, vehicle.track_rear / 2
        self._wheel_offsets = ((-1.0, half_front), (1.0, half_front), (-1.0, half_rear), (1.0, half_rear))
        self._has_ref_speed = "vehicle_speed_ref" in self._signal_message
        self._has_drive_torque = all(n in self._signal_message for n in DRIVE_TORQUE_NAMES)
        self._has_yaw_rate = "yaw_rate" in self._signal_message
        self._abs_activity = AbsActivity()
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
        # `_compute_sample`'s compiled part reads its settings as one tuple of numbers, in the
        # order of `_frontcore.c`'s K_ constants.
        self._physics_constants = tuple(float(x) for x in (
            options.stuck_frames, pushout, options.min_brake_pressure, options.min_speed,
            options.dead_wheel_ratio, options.dead_wheel_s, options.dead_wheel_unbraked_s, options.max_gap,
            options.unexplained_decel, vehicle.wheel_radius, options.speed_gain_free_rolling,
            options.speed_gain_up, options.speed_gain_down, options.min_braked_slip, options.max_all_wheel_slip,
            self.sample_period_s, options.accel_bias_time_constant, vehicle.mass, vehicle.cg_height,
            vehicle.cg_to_front_axle, vehicle.cg_to_rear_axle, vehicle.track_front, vehicle.track_rear,
            vehicle.wheel_inertia, options.brake_gain_correction, options.brake_gain_min_decel,
            vehicle.rolling_resistance, vehicle.drag_area_coefficient, options.brake_gain_limits,
            options.brake_gain_time_constant, options.max_slip, self._has_drive_torque, self._has_yaw_rate,
            float(self.pressures_are_master), *self._brake_gains, options.pressure_lag_compensation,
            options.accel_bias_settle_s, options.speed_correction_rate, options.speed_correction_hold_s))

    # -- state -----------------------------------------------------------------------------
    def reset(self) -> None:
        n = self.derivative_window
        # Frame-level plausibility (issue 22): a corrupted frame never reaches the histories.
        self.gate = InputGate(self.vehicle, {m: h.period_s for m, h in self._history.items()})
        self._abs_activity.reset()
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
        self._last_trigger_s = -math.inf
        self.skipped_triggers = 0
        self._ref_disagreements = 0
        self._repeats = [0, 0, 0, 0]
        self._previous_speeds: tuple[float, ...] = (math.nan,) * 4
        self._unexplained_s = 0.0
        self._last_sample_time_s: float | None = None
        self._low_since_s: list[float | None] = [None] * 4
        self._low_unbraked_s = [0.0] * 4
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

    def _push_wheel_speeds(self, time_s: float, speeds: tuple[float, float, float, float]) -> None:
        """The wheel speeds of a trigger frame into the derivative window: counted as repeats
        (a stuck sensor), timed (the trigger's measured cycle), the window restarted after a
        gap or a jump back in time."""
        opts = self.options
        fl, fr, rl, rr = speeds
        # A sensor that repeats exactly the same reading frame after frame while the car
        # changes speed is stuck (quantised noise makes exact repeats rare on a live sensor).
        repeats, previous = self._repeats, self._previous_speeds
        repeats[0] = repeats[0] + 1 if fl == previous[0] and fl > 1.0 else 0
        repeats[1] = repeats[1] + 1 if fr == previous[1] and fr > 1.0 else 0
        repeats[2] = repeats[2] + 1 if rl == previous[2] and rl > 1.0 else 0
        repeats[3] = repeats[3] + 1 if rr == previous[3] and rr > 1.0 else 0
        self._previous_speeds = speeds
        dt = time_s - self._last_trigger_s
        if 0.0 < dt <= opts.max_gap:
            # The trigger's actual cycle time (a slow mean: lost frames barely move it), set
            # against the DBC's, which the per-sample constants were sized for.
            self._triggers_timed += 1
            self._trigger_period_s += (dt - self._trigger_period_s) / min(self._triggers_timed, 100)
        if dt <= 0.0 or dt > opts.max_gap:
            # A gap or a jump back in time: the derivative window must not straddle it.
            self._wheel_times.clear()
            self._wheel_speeds.clear()
            self._speed_time_s = None
        self._last_trigger_s = time_s
        self._wheel_times.append(time_s)
        self._wheel_speeds.append(speeds)  # type: ignore[arg-type]

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
            elif result.sample is not None and self._accel_bias_samples > free_rolling_before:
                self._learn_pressure_zeros()
        if result.fault == "wheel speed glitch":
            self.gate.count_repair(result.fault)
        if result.sample is not None:
            self._mark_abs_activity(result.sample)
            self._mark_body_mu(result.sample)
            result.sample.input_suspect_share = self.gate.suspect_share()
        return result

    def _mark_body_mu(self, sample: PhysicalSample) -> None:
        """`sample.body_mu`: the car's total longitudinal tyre force over its weight, from the
        accelerometer (offset removed) less drag and rolling resistance, where the wheels' own
        sum agrees (the smaller of the two).

        An accelerometer reads the contact and air forces over the mass, not gravity, so this
        holds on a slope, and the mass cancels (a loaded car reads the same). No road gives less
        grip than the tyres just used: the load-weighted μ_max is at least this.
        """
        if not sample.braking:
            return
        accel = self._value("accel_long", sample.time_s)
        if accel is None or not math.isfinite(accel):
            return
        veh = self.vehicle
        v = sample.speed_mps
        resistance = veh.resistance_force(v) / veh.mass
        body = (-(accel - self._accel_bias_mps2) - resistance) / GRAVITY_MPS2
        # The same total from the wheels (brake torques, inertia): a bound must not rest on one
        # sensor alone. Beyond what brake-gain error explains, one of them is wrong: no bound.
        load = sum(sample.normal_force_n)
        wheels = sum(sample.tyre_force_n) / load if load > 0.0 else math.nan
        if abs(body - wheels) <= BODY_WHEELS_TOLERANCE * abs(wheels) + 0.05:
            sample.body_mu = min(body, wheels)

    def _mark_abs_activity(self, sample: PhysicalSample) -> None:
        """`sample.abs_active`: the wheels an ABS is working (see `abs_activity`), from the
        pressures, the master-cylinder pressure and the car's ABS flags at the sample's instant."""
        t = sample.time_s
        if self.core is not None:
            v = self.core.values_at(self._abs_lookups, t)
        else:
            v = tuple([self._value(n, t) for n in self._abs_inputs])
        sample.abs_active = self._abs_activity.update(t, v[:4], v[4], v[5], v[6:])

    # -- the physics ---------------------------------------------------------------------------
    def _compute_sample(self, stale: tuple[str, ...]) -> FrontEndResult:
        opts = self.options
        veh = self.vehicle
        t_c, omega, omega_dot, glitch = self._fit_wheels()

        inputs = self._values_at(t_c)
        self._sample_accel = inputs[0]   # (`_attach_slip_spread`)
        if self.core is not None:
            # The rest in one compiled call on this object's state (the code below, line by line).
            ref, ref_fresh = None, False
            if self._has_ref_speed:
                ref = self._value("vehicle_speed_ref", t_c)
                ref_fresh = ref is not None and self._ref_fresh(t_c)
            return self.core.sample_physics(self, self._physics_constants, _PHYSICS_TYPES, t_c, omega, omega_dot,
                                            glitch, inputs, stale, self._matched_lookups, self._wheel_times,
                                            self._torque_weights, ref, ref_fresh, self._torque_omega_dot)
        accel_long_raw, accel_lat = inputs[0], inputs[1]
        pressures = list(inputs[2:6])
        if accel_long_raw is None or accel_lat is None or None in pressures:
            return FrontEndResult(None, stale, None)
        if abs(accel_long_raw) > MAX_ABS_ACCEL_MPS2 or abs(accel_lat) > MAX_ABS_ACCEL_MPS2:
            return FrontEndResult(None, stale, "acceleration out of range")
        if any(not (-1.0 <= p <= MAX_PRESSURE_BAR) for p in pressures):  # type: ignore[operator]
            return FrontEndResult(None, stale, "brake pressure out of range")
        drive = [0.0, 0.0, 0.0, 0.0]
        if self._has_drive_torque:
            for i in range(4):
                v = inputs[6 + i]
                drive[i] = v if v is not None and math.isfinite(v) else 0.0

        radius = veh.wheel_radius
        wheel_linear = [radius * float(w) for w in omega]
        stuck = [n >= opts.stuck_frames for n in self._repeats] if abs(accel_long_raw) > 0.5 else [False] * 4
        braked = [p - veh.brake_pushout_pressure > opts.min_brake_pressure for p in pressures]  # type: ignore[operator]
        dead = self._dead_wheels(t_c, wheel_linear, braked)
        wheel_linear = stood_in_for([st or d for st, d in zip(stuck, dead)], wheel_linear)
        braking = any(braked)
        if not braking:
            self._brake_released = False    # (a new stop: the master pressure is the wheels' again)
        driving = self._has_drive_torque and any(abs(d) > 20.0 for d in drive)

        accel_long = accel_long_raw - self._accel_bias_mps2
        if self._deceleration_unexplained(t_c, braking or driving, accel_long, omega_dot):
            return FrontEndResult(None, stale, "brake pressure implausible")
        speed, from_ref = self._speed_and_offset(t_c, wheel_linear, omega_dot, accel_long, accel_long_raw,
                                                 braking or driving)

        yaw_rate = inputs[-1] if self._has_yaw_rate else None
        if yaw_rate is None or not math.isfinite(yaw_rate):
            yaw_rate = accel_lat / speed if speed > opts.min_speed else 0.0

        loads = veh.normal_forces(accel_long, accel_lat)
        brake_torques, accel_long_matched = self._matched_inputs(pressures, accel_long_raw)
        brake_rates = self._brake_torque_rates(t_c, brake_torques)
        torque_omega_dot = omega_dot if self._torque_omega_dot is None else self._torque_omega_dot
        inertia_torques = [veh.wheel_inertia * float(a) for a in torque_omega_dot]
        if opts.brake_gain_correction and not glitch:
            # The body's deceleration through the same filter as the torques it is compared with.
            self._update_brake_gain(accel_long_matched - self._accel_bias_mps2,
                                    speed, inertia_torques, brake_torques, drive, wheel_linear, brake_rates, braking)
        gain = self._brake_gain_factor
        # A sensor lagging by τ reads p(t) − τ·ṗ(t): the brakes' torque is the reading advanced by τ.
        lag = self._lag_state[5]
        brake_torques = [max(b + lag * r, 0.0) for b, r in zip(brake_torques, brake_rates)]   # (NaN stays NaN)

        forces = [(inertia_torques[i] + gain * brake_torques[i] - drive[i]) / radius for i in range(4)]
        mus = [force / load if load > 50.0 else 0.0 for force, load in zip(forces, loads)]
        slips = self._slips(speed, yaw_rate, wheel_linear)
        for i in range(4):
            if braked[i] and slips[i] > SETTLE_SLIP:
                self._slipping_time_s = t_c
        good = (speed >= opts.min_speed and not glitch and self._brake_model_holds and not self._brake_released)
        usable = [
            good
            and abs(slips[i]) <= opts.max_slip
            and (braked[i] or (self._has_drive_torque and abs(drive[i]) > 20.0))
            and loads[i] > 50.0
            and not stuck[i]
            and not dead[i]
            and math.isfinite(mus[i])
            for i in range(4)
        ]

        sample = PhysicalSample(
            time_s=t_c,
            speed_mps=speed,
            slip=tuple(slips),  # type: ignore[arg-type]
            mu_used=tuple(mus),  # type: ignore[arg-type]
            normal_force_n=tuple(loads),
            tyre_force_n=tuple(forces),  # type: ignore[arg-type]
            usable=tuple(usable),  # type: ignore[arg-type]
            braking=braking,
            speed_from_reference=from_ref,
        )
        fault = ("wheel speed glitch" if glitch else "wheel speed stuck" if any(stuck)
                 else None if self._brake_model_holds or not braking or speed < opts.min_speed
                 else "brake pressure disagrees with deceleration")
        return FrontEndResult(sample, stale, fault, tuple(i for i in range(4) if dead[i]))

    def _speed_and_offset(self, t_c: float, wheel_linear: list[float], omega_dot: list[float],
                          accel_long: float, accel_long_raw: float, torqued: bool) -> tuple[float, bool]:
        """The ground speed (and whether from the car's reference) after this sample; while the
        wheels roll free, settled since their last braked slip, the accelerometer's offset learnt."""
        # No pressure is not yet free rolling: wheels released by the ABS (pressure below the
        # threshold on a low-μ road) may still be spinning back up from deep slip, all together.
        # Only wheels that agree with each other (within what a curve explains) and accelerate
        # with the body read the ground speed.
        radius = self.vehicle.wheel_radius
        fastest = max(wheel_linear)
        free_rolling = (not torqued
                        and fastest - min(wheel_linear) <= FREE_ROLLING_SPREAD * fastest + 0.3
                        and all(abs(radius * a - accel_long) < FREE_ROLLING_ACCEL_MPS2 for a in omega_dot))
        speed, from_ref = self._update_speed(t_c, wheel_linear, accel_long, not free_rolling)
        if free_rolling and t_c - self._slipping_time_s >= self.options.accel_bias_settle_s:
            self._learn_accel_bias(t_c, omega_dot, accel_long_raw)
        return speed, from_ref

    def _slips(self, speed: float, yaw_rate: float, wheel_linear: list[float]) -> list[float]:
        """Each wheel's slip against its own ground speed: in a turn the outer wheels travel faster."""
        slips = []
        for i, (side, half_track) in enumerate(self._wheel_offsets):
            ground = speed + side * yaw_rate * half_track
            denom = max(ground, wheel_linear[i])
            slips.append((ground - wheel_linear[i]) / denom if denom > 0.1 else 0.0)
        return slips

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


# What `_frontcore.sample_physics` builds its results from: the two result types, then the
# fault messages it can give (those of `_compute_sample`, in this order).
_PHYSICS_TYPES = (PhysicalSample, FrontEndResult, "acceleration out of range", "brake pressure out of range",
                  "brake pressure implausible", "wheel speed glitch", "wheel speed stuck",
                  "brake pressure disagrees with deceleration")


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
