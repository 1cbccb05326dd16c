"""The car's speed over ground, which every slip is measured against.

A ground-speed sensor's reading while it is fresh and plausible; otherwise an observer driven by
the accelerometer and corrected by the wheels: pulled towards their mean while they roll free,
under braking only up by two wheels faster than it (slowly, unless they stay faster: a released
tyre overshoots the car's speed) and down only when even the fastest wheel would slip more than
an ABS lets it (slowly); over a suspect sample carried by the accelerometer alone. `SpeedEstimate` is a
part of `frontend.FrontEnd` (its state, `_speed_estimate_mps`, `_speed_time_s`,
`_wheels_faster_since_s` and `_speed_restarted_braking`, is the front end's, where
`_frontcore.sample_physics` reads and writes it); the code here is the fallback without a C
compiler and the reference (tests compare).
"""
from __future__ import annotations

import math

from .samples import PhysicalSample

MAX_SPEED_MPS = 120.0
# No car brakes or gains speed faster than this: beyond it an acceleration input is broken, and an
# estimate pulled up by the wheels faster than this is following a corrupt wheel speed.
MAX_ABS_ACCEL_MPS2 = 30.0


class SpeedEstimate:
    """The speed estimate's update per sample (`_update_speed`) and over a suspect one
    (`_coast_speed`)."""

    def _update_speed(
        self, time_s: float, wheel_linear: list[float], accel_long: float, wheels_loaded: bool
    ) -> tuple[float, bool]:
        opts = self.options
        dt = 0.0 if self._speed_time_s is None else time_s - self._speed_time_s
        self._speed_time_s = time_s
        faster_since, self._wheels_faster_since_s = self._wheels_faster_since_s, None
        ref = self._value("vehicle_speed_ref", time_s) if self._has_ref_speed else None
        fastest = max(wheel_linear)
        if ref is not None and self._ref_fresh(time_s) and 0.0 <= ref <= MAX_SPEED_MPS and self._ref_plausible(ref, fastest):
            self._speed_estimate_mps = ref
            return ref, True
        mean = sum(wheel_linear) / 4.0
        v = self._speed_estimate_mps
        if v is None or dt <= 0.0 or dt > opts.max_gap:
            v = fastest
            # (under braking: from a slipping wheel, `_speed_correction_limit`)
            self._speed_restarted_braking = wheels_loaded
        else:
            v = v + accel_long * dt
            second = _second_fastest(wheel_linear)
            if not wheels_loaded:
                v += opts.speed_gain_free_rolling * (mean - v)
                self._speed_restarted_braking = False
            elif second > v:
                faster_since = time_s if faster_since is None else faster_since
                self._wheels_faster_since_s = faster_since
                v += min(opts.speed_gain_up * (second - v), self._speed_correction_limit(time_s - faster_since, dt))
            else:
                # Braked wheels all read low during ABS: even the least-braked one slips by
                # several percent, so pulling towards the fastest wheel biases the speed (and
                # every slip) low. Pull only when the estimate would put even the fastest wheel
                # beyond what an ABS lets it slip, and then no faster than `speed_correction_rate`:
                # that holds the drift of what free rolling left of the accelerometer's offset,
                # yet a threshold ABS dumping slowly, which holds every wheel past that slip for
                # seconds, cannot drag the estimate (and every slip) down with the wheels.
                ceiling = fastest / (1.0 - opts.min_braked_slip)
                if v > ceiling:
                    v -= min(opts.speed_gain_down * (v - ceiling), opts.speed_correction_rate * dt)
        v = min(max(v, 0.0), MAX_SPEED_MPS)
        self._speed_estimate_mps = v
        return v, False

    def _speed_correction_limit(self, faster_for_s: float, dt: float) -> float:
        """How far two wheels faster than the estimate may pull it up in one step while braking.

        Under braking the estimate runs on the accelerometer, whose offset is learnt while the car
        rolls free (its error ≈ 0.02 m/s², p90 0.04): it cannot fall behind the car faster than
        `speed_correction_rate`. A braked wheel reads faster than the car when a tyre whose force
        lags its slip carries it past the ground's speed after an ABS release (by up to 5–8 % for
        a few relaxation lengths of rolling), or when its signal is corrupt; followed, every such
        overshoot ratchets the estimate up, and nothing under ABS pulls it down again (every
        slip then reads high). Two wheels faster for longer than an overshoot lasts
        (`speed_correction_hold_s`) mean the estimate is low: then the full pull, no faster
        than a car can gain speed (one corrupt wheel must not carry it off). So too after a
        restart under braking (a gap in the wheel speeds, a clock step), until the car rolls free
        again: restarted from the fastest wheel, the estimate is as wrong as that wheel's slip,
        not as the accelerometer drifts, and only the releases can show the car's speed.
        """
        opts = self.options
        if faster_for_s >= opts.speed_correction_hold_s or self._speed_restarted_braking:
            return MAX_ABS_ACCEL_MPS2 * 0.5 * dt + 0.02
        return opts.speed_correction_rate * dt

    def _ref_plausible(self, ref: float, fastest_wheel: float) -> bool:
        """A ground-speed reading the wheels and the recent estimate can agree with.

        A braked wheel is slower than the ground, never much faster; and a single reading far
        from the running estimate is a glitch unless the next ones say the same (then the
        estimate was wrong and the sensor is followed again).
        """
        if ref + 1.0 < fastest_wheel * 0.95:
            return False
        if ref > fastest_wheel / (1.0 - self.options.max_all_wheel_slip) + 1.0 and fastest_wheel >= 0.5:
            return False
        v = self._speed_estimate_mps
        if v is not None and abs(ref - v) > 1.0 + 0.1 * v:
            self._ref_disagreements += 1
            return self._ref_disagreements > 10
        self._ref_disagreements = 0
        return True

    def _ref_fresh(self, time_s: float) -> bool:
        message = self._signal_message["vehicle_speed_ref"]
        h = self._history[message]
        return (time_s - h.last_arrival_s <= self.options.stale_periods * h.period_s + 1e-3
                or h.last_arrival_s >= time_s)

    def _coast_speed(self, before: tuple[float | None, float | None], sample: PhysicalSample) -> None:
        """The speed estimate carried over a suspect sample by the accelerometer alone: a
        corrupted or spoofed wheel speed pulls it up (a wheel faster than the estimate), and under
        ABS nothing pulls it down again for the rest of the stop (every slip would read high).

        While a second node sends the accelerometer's message, the wheels are trusted: the
        update made with the frame taken keeps their pull, and only its deceleration is
        exchanged for the one `_accel_of_two_senders` picks."""
        v, t = before
        time_s = sample.time_s
        if v is None or t is None or self._speed_time_s is None or self._speed_estimate_mps is None:
            return
        accel = self._value("accel_long", time_s)
        if accel is None or not math.isfinite(accel) or not 0.0 < time_s - t <= self.options.max_gap:
            return
        chosen = self._accel_of_two_senders(accel, sample)
        if chosen is not None:
            corrected = self._speed_estimate_mps + (chosen - accel) * (time_s - t)
            self._speed_estimate_mps = min(max(corrected, 0.0), MAX_SPEED_MPS)
            return
        coasted = min(max(v + (accel - self._accel_bias_mps2) * (time_s - t), 0.0), MAX_SPEED_MPS)
        # (only ever down to it: a reference sensor or a slower wheel may have said less)
        self._speed_estimate_mps = min(self._speed_estimate_mps, coasted)


def _second_fastest(speeds: list[float]) -> float:
    """The second-largest of the wheels' speeds (`_frontcore.c`'s `second_of`)."""
    return sorted(speeds)[-2]
