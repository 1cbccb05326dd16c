"""What the front end does with inputs in doubt.

The gate (`plausibility.InputGate`) judges each frame; what reaches the front end may still be in
doubt, and this is what it does then: a frame the gate later finds to be a second node's is
taken out of the histories and the wheel-speed window; a sample whose inputs are suspect (a
wheel off its own trend, a second sender, a frame overdue) is computed but not fitted, teaches
nothing, and the speed estimate coasts over it; of two senders, the car's own speed or its tyre
forces tell which one is genuine where they can; and a required message whose frames keep being
rejected becomes a fault that names it. `DoubtfulInputs` is a part of `frontend.FrontEnd`.
"""
from __future__ import annotations

import math

from .body_equation import LEARNT_STATE
from .input_names import WHEEL_SPEED_NAMES
from .samples import FrontEndResult, PhysicalSample

# A braked wheel turns no faster than the car moves, but for: its tyre's rolling radius against
# the configured one (this share of the speed), the wheel speeds' noise and the speed estimate's
# error (this much), and a curve's outer track (half the track times the yaw rate, |a_y|/v).
WHEEL_RADIUS_SPREAD = 0.01
WHEEL_SPEED_NOISE_MPS = 0.15
# Braking harder than this, a wheel speed sender is told from another by the car's speed
# (`_wheel_senders_told_apart`): wheels drive no car that decelerates.
MIN_TELLING_DECEL_MPS2 = 1.0
# The fault a required input's persistently rejected frames give, by kind of rejection.
_REJECTION_FAULTS = {"out of range": "out of range", "rate": "implausible", "second source": "from a second source",
                     "clock step": "clock step"}


class DoubtfulInputs:
    """Second senders, suspect samples, overdue frames and persistent rejections."""

    def _take_back(self, message: str, time_s: float) -> None:
        """A frame already pushed that the gate has since found to be a second node's (`revoked`):
        out of the message's histories, and out of the wheel-speed window, so that no later
        sample's derivative or interpolation includes it. (A sample made from it alone is gone.)"""
        history = self._history.get(message)
        if history is None or time_s != time_s:
            return
        merged = history.merged
        for name, (times, values) in history.series.items():
            if times and times[-1] == time_s:
                times.pop()
                values.pop()
                if values:
                    merged[name] = values[-1]
        if message == self.trigger_message and self._wheel_times and self._wheel_times[-1] == time_s:
            self._wheel_times.pop()
            self._wheel_speeds.pop()
            self._last_trigger_s = self._wheel_times[-1] if self._wheel_times else -math.inf
            before = self._before_sample
            if before is not None and before[0] == time_s:
                # Its sample taught the speed observer and the learnt state: back as they were
                # (the next sample has the same window centre: the observer would restart at
                # the fastest wheel, every slip zero for the rest of the stop).
                (_, self._speed_estimate_mps, self._speed_time_s, self._wheels_faster_since_s,
                 self._speed_restarted_braking, self._last_sample_time_s, learnt) = before
                for name, value in zip(LEARNT_STATE, learnt):
                    setattr(self, name, value)

    def _persistent_fault(self) -> str | None:
        """A fault naming the required message whose frames keep being rejected, if any."""
        for message, kind in self.gate.faulty_messages():
            label = self._fault_names.get(message)
            if label is not None:
                return f"{label} {_REJECTION_FAULTS.get(kind, 'implausible')}"
        return None

    def _input_lost(self, now_s: float) -> bool:
        """Whether a required message's next frame is overdue (lost, or rejected by the gate):
        the sample's inputs are averaged over the derivative window, which reaches to now, and
        past the message's last frame its value would be the last one held, not what the brakes
        or the body did then (a pressure under ABS moves by tens of bar in a cycle)."""
        trigger = self.trigger_message
        for m, h in self._required_histories:
            if m != trigger and now_s - h.last_arrival_s > 1.25 * h.period_s:
                return True
        return False

    def _suspect_sample(self, stale: tuple[str, ...]) -> FrontEndResult:
        """`_compute_sample` for a suspect sample: a wheel's newest samples are off its own trend
        by more than a wheel's acceleration can change (maybe a glitch not yet confirmed: that
        takes two more samples; its weight in the derivative is largest now), a second node
        sends one of the inputs, or an input's frame for the sample's instant is overdue. Not
        fitted, and it teaches the front end nothing: the learnt state is put back and the speed
        estimate coasts on the accelerometer."""
        speed_before = (self._speed_estimate_mps, self._speed_time_s)
        learnt = [getattr(self, name) for name in LEARNT_STATE]
        result = self._compute_sample(stale)
        for name, value in zip(LEARNT_STATE, learnt):
            setattr(self, name, value)
        if result.sample is not None:
            result.sample.usable = (False, False, False, False)
            self._coast_speed(speed_before, result.sample)
        return result

    def _wheel_senders_told_apart(self, time_s: float) -> bool:
        """While only wheel speeds have a second sender in doubt: whether the car's speed tells
        which one is genuine. Braking, no wheel turns faster than the car moves (its slip is
        ≥ 0), so a sender whose fastest wheel is faster than the speed estimate (carried on the
        accelerometer alone while the senders are in doubt) by more than the wheels' radii,
        noise and a curve's outer track allow is not the car's: a replay of an earlier, faster
        moment of the stop, or of the cruise before it, flat through the brake onset. The frames
        taken are then the other sender's, and when each one in the derivative window fits the
        car's speed as well, the sample is fitted."""
        v = self._speed_estimate_mps
        at = self._speed_time_s
        accel = self._value("accel_long", time_s)
        if v is None or at is None or accel is None or not accel - self._accel_bias_mps2 <= -MIN_TELLING_DECEL_MPS2:
            return False
        veh = self.vehicle
        lateral = self._value("accel_lat", time_s)
        if lateral is None or not math.isfinite(lateral):
            return False
        outer = 0.5 * max(veh.track_front, veh.track_rear) * abs(lateral) / max(v, 1.0)

        def faster_than_the_car(wheel_mps: float, car_mps: float) -> bool:
            return wheel_mps > car_mps * (1.0 + WHEEL_RADIUS_SPREAD) + WHEEL_SPEED_NOISE_MPS + outer

        radius = veh.wheel_radius
        for message, rival in self.gate.contested_senders(time_s).items():
            names = self._message_signals.get(message, ())
            if rival is None or not names or not set(names) <= set(WHEEL_SPEED_NAMES):
                return False
            if not faster_than_the_car(max(rival.get(name, 0.0) for name in names) * radius, v):
                return False
        decel = self._accel_bias_mps2 - accel
        for t, speeds in zip(self._wheel_times, self._wheel_speeds):
            # (the car was faster before the estimate's time)
            if faster_than_the_car(max(speeds) * radius, v + decel * max(at - t, 0.0)):
                return False
        return True

    def _accel_of_two_senders(self, taken: float, sample: PhysicalSample) -> float | None:
        """While a second node sends the accelerometer's message (None when none does): of the
        value taken and the other sender's, the one nearer the car's deceleration by its tyre
        forces (the brakes' and the wheels' inertia torques, with drag and rolling resistance:
        the body equation the brake gain is learnt from). The frame taken may be the second
        node's: a replay flat at brake onset while the pressures rise and the car decelerates."""
        other = self.gate.second_source_value("accel_long", self._last_trigger_s)
        if other is None:
            return None
        veh = self.vehicle
        forces = sum(sample.tyre_force_n) + veh.resistance_force(sample.speed_mps)
        if not math.isfinite(forces):
            return None
        by_forces = -forces / veh.mass + self._sensor_offset_mps2
        return other if abs(other - by_forces) < abs(taken - by_forces) else taken

