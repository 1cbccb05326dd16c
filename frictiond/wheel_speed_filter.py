"""The front end's derivative filter: the wheels' speeds and accelerations at one instant.

A quadratic in time fitted through the newest wheel-speed samples of all four wheels (a
Savitzky–Golay filter on the real timestamps, so that jitter and lost frames do not bias the
derivative), read at the window's centre: ω and ω̇ there, the weights with which the torques set
against ω̇ are averaged the same way, a sensor glitch told from a wheel's physics (one sample off
both its neighbours by more than a wheel's acceleration can change within a sample), and each
wheel's slips at the ends of that average; and the window's intake: its size for the trigger's
cycle time, each frame's speeds counted as repeats (a stuck sensor) and timed, the window
restarted after a gap. `WheelSpeedFilter` is a part of `frontend.FrontEnd` (its wheel-speed
window and settings are the front end's); `_frontcore.fit_wheels` is the same fit compiled, and
the code here the fallback and the reference (tests compare).
"""
from __future__ import annotations

import math
from operator import mul
from typing import Any

import numpy as np

from .samples import PhysicalSample

# Under ABS a wheel's acceleration changes by at most ~800 rad/s² within 10 ms (pressure moving a few
# thousand bar/s on ~25 N·m/bar over ~1.2 kg·m², and the tyre force past its peak): a sample further
# than this × dt² off its own trend is suspect until confirmed or repaired.
SUSPECT_JERK_RADPS3 = 80_000.0
MIN_SAMPLE_PERIOD_S = 0.004    # the per-sample constants are never set for a faster trigger than this


class WheelSpeedFilter:
    """The front end's wheel-speed window (`_wheel_times`, `_wheel_speeds`), the fit over it and
    what that yields besides ω and ω̇: the torque weights (`_torque_weights`), glitches, slip spreads."""

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
        # (each wheel's speed over its own rolling radius: `rolling_radius`)
        self._wheel_speeds.append(self._scaled_wheel_speeds(speeds))

    def _fit_wheels(self) -> tuple[float, list[float], list[float], bool]:
        """`_fit_window`, and when it finds a glitch (`_glitch_value`), the sample repaired in the
        window for good and the fit made again: (t_c, ω(t_c), dω/dt(t_c), glitch)."""
        fitted = self._fit_window()
        if not fitted[3]:
            return fitted
        k = len(self._wheel_times) - 3
        times, speeds = self._wheel_times, self._wheel_speeds
        threshold = self.glitch_threshold
        columns = list(zip(*speeds))
        repaired = []
        for y in columns:
            value = _glitch_value(times, y, k, threshold)
            repaired.append(y[k] if value is None else value)
        speeds[k] = tuple(repaired)
        t_c, omega, omega_dot, _ = self._fit_window()
        return t_c, omega, omega_dot, True

    def _fit_window(self) -> tuple[float, list[float], list[float], bool]:
        """Local quadratic fit at the window's centre: (t_c, ω(t_c), dω/dt(t_c), glitch), glitch
        when one wheel's third-newest sample is a sensor error (`_glitch_value`). Also the ω̇ the
        brake torques are set against (`_torque_omega_dot`: the same fit over the central
        `torque_window` samples) and the weights that average the torques as it averages ω̇.
        """
        times = self._wheel_times
        if self.core is not None:
            fitted = self.core.fit_wheels(times, self._wheel_speeds, self.glitch_threshold, self.torque_window)
            if fitted is None:
                self._torque_weights = self._torque_omega_dot = None
                return self._fit_wheels_numpy()
            t_c, omega, omega_dot, glitch, self._torque_weights, self._torque_omega_dot = fitted
            return t_c, omega, omega_dot, glitch
        n = len(times)
        t_c = float(times[n // 2])
        fitted = _quadratic_fit(times, self._wheel_speeds, t_c)
        if fitted is None:
            self._torque_weights = self._torque_omega_dot = None
            return self._fit_wheels_numpy()
        omega, omega_dot, self._torque_weights = fitted
        self._torque_omega_dot = omega_dot
        if self.torque_window < n:
            lo = (n - self.torque_window) // 2
            hi = lo + self.torque_window
            inner = _quadratic_fit(list(times)[lo:hi], list(self._wheel_speeds)[lo:hi], t_c)
            if inner is not None:
                _, self._torque_omega_dot, weights = inner
                self._torque_weights = [0.0] * lo + weights + [0.0] * (n - hi)
        threshold = self.glitch_threshold
        glitch = any(_glitch_value(times, y, n - 3, threshold) is not None for y in zip(*self._wheel_speeds))
        return t_c, omega, omega_dot, glitch

    def _fit_wheels_numpy(self) -> tuple[float, list[float], list[float], bool]:
        """The same fit by numpy's SVD least squares (for a degenerate spread of timestamps)."""
        times = np.fromiter(self._wheel_times, dtype=float, count=len(self._wheel_times))
        speeds = np.array(self._wheel_speeds, dtype=float)
        centre = len(times) // 2
        t_c = float(times[centre])
        tau = times - t_c
        design = np.empty((len(tau), 3))
        design[:, 0] = 1.0
        design[:, 1] = tau
        design[:, 2] = tau * tau
        coef, *_ = np.linalg.lstsq(design, speeds, rcond=None)
        k = len(times) - 3
        glitch = any(_glitch_value(self._wheel_times, y, k, self.glitch_threshold) is not None
                     for y in zip(*self._wheel_speeds))
        return t_c, [float(w) for w in coef[0]], [float(a) for a in coef[1]], glitch

    def _newest_suspect(self) -> bool:
        """Whether a wheel's newest sample, or the one before it, leaves the trend of the samples
        before it by more than `SUSPECT_JERK_RADPS3`·dt² (and, for the one before, its neighbours'
        interpolation too): a glitch that `_glitch_value` can only confirm two samples later."""
        times, speeds = self._wheel_times, self._wheel_speeds
        if self.core is not None:
            return self.core.newest_suspect(times, speeds, SUSPECT_JERK_RADPS3)
        n = len(times)
        if n < 4:
            return False
        t0, t1, t2, t3 = times[n - 4], times[n - 3], times[n - 2], times[n - 1]
        if not t0 < t1 < t2 < t3:
            return False
        limit = SUSPECT_JERK_RADPS3 * (t3 - t2) ** 2
        for y0, y1, y2, y3 in zip(speeds[n - 4], speeds[n - 3], speeds[n - 2], speeds[n - 1]):
            if abs(y3 - (y2 + (y2 - y1) * (t3 - t2) / (t2 - t1))) > limit:
                return True
            trend = y1 + (y1 - y0) * (t2 - t1) / (t1 - t0)
            between = y1 + (y3 - y1) * (t2 - t1) / (t3 - t1)
            if abs(y2 - trend) > limit and abs(y2 - between) > limit:
                return True
        return False

    def _attach_slip_spread(self, sample: PhysicalSample) -> None:
        """`sample.slip_spread`: each wheel's slip at the two ends of the window the torques and
        ω̇ were averaged over, with the weights that give that average's mean time and spread.

        Under ABS a wheel crosses its peak in one or two samples: μ read through the filter is
        the mean over that sweep, below the peak wherever the curve bends (10–25 % at 50 Hz on a
        sharp Magic Formula peak). The estimator counts what that mean takes off its fitted
        curve as uncertainty of the peak. The ends' slips come from their own wheel speeds
        against the wheel's ground speed carried back or forward by the body's deceleration."""
        weights = self._torque_weights
        v = sample.speed_mps
        if weights is None or not v > 1.0:
            return
        accel = self._sample_accel
        accel = accel - self._accel_bias_mps2 if accel is not None and math.isfinite(accel) else 0.0
        if self.core is not None:
            spread = self.core.slip_spread(weights, self._wheel_times, self._wheel_speeds, v, sample.slip, accel)
            if spread is not None:
                sample.slip_spread, sample.slip_spread_weights = spread
            return
        times = list(self._wheel_times)
        n = len(times)
        centre = n // 2
        t_c = times[centre]
        lo, hi = -1, -1
        mean = second = 0.0
        for k in range(n):
            w = weights[k]
            if w > 0.0:
                if lo < 0:
                    lo = k
                hi = k
                d = times[k] - t_c
                mean += w * d
                second += w * d * d
        if not 0 <= lo < centre < hi:
            return
        d_lo, d_hi = times[lo] - t_c, times[hi] - t_c
        det = d_lo * d_hi * (d_hi - d_lo)
        if not det < 0.0:
            return
        # Two weights at the ends that reproduce the filter's first two moments in time.
        a_lo = min(max((mean * d_hi * d_hi - second * d_hi) / det, 0.0), 0.5)
        a_hi = min(max((d_lo * second - d_lo * d_lo * mean) / det, 0.0), 0.5)
        ground_lo, ground_hi = 1.0 + accel * d_lo / v, 1.0 + accel * d_hi / v
        rows = self._wheel_speeds
        at_lo, at_c, at_hi = rows[lo], rows[centre], rows[hi]
        spread = []
        for i in range(4):
            slip = sample.slip[i]
            w_c = at_c[i]
            if not (w_c > 0.5 and 0.0 <= slip < 1.0):
                spread.append((slip, slip))
                continue
            rolling = (1.0 - slip) / w_c
            spread.append((max(0.0, 1.0 - rolling * at_lo[i] / ground_lo),
                           max(0.0, 1.0 - rolling * at_hi[i] / ground_hi)))
        sample.slip_spread = tuple(spread)
        sample.slip_spread_weights = (a_lo, a_hi)


def _glitch_value(times: Any, y: Any, k: int, threshold: float) -> float | None:
    """What sample `k` of one wheel's speeds `y` should read if it is a sensor glitch, else None.

    A glitch is one sample that disagrees, the same way and by more than `threshold`, with its
    neighbours' interpolation and with each side's own trend (the line through the two samples
    before it, and the two after it). A wheel cannot do that: it would need its acceleration to
    jump and jump back within a sample. A wheel running deep into slip and recovering (an ABS
    dumping late: 30-50 rad/s lost in 50 ms) turns around at the bottom, but each side of the
    turn follows its own trend, so it is no glitch; a jump too fast for the torques on the wheel
    never gets here (`plausibility.InputGate` rejects the frame).
    (`_frontcore.c`'s `glitch_value` is the same, line by line.)
    """
    if k < 2 or k + 2 >= len(y):
        return None
    t0, t1, t2, t3, t4 = times[k - 2], times[k - 1], times[k], times[k + 1], times[k + 2]
    if not t0 < t1 < t2 < t3 < t4:
        return None
    y0, y1, y2, y3, y4 = y[k - 2], y[k - 1], y[k], y[k + 1], y[k + 2]
    between = y1 + (y3 - y1) * (t2 - t1) / (t3 - t1)
    left = y1 + (y1 - y0) * (t2 - t1) / (t1 - t0)
    right = y3 - (y4 - y3) * (t3 - t2) / (t4 - t3)
    da, db, dc = y2 - between, y2 - left, y2 - right
    if (da > threshold and db > threshold and dc > threshold) or (da < -threshold and db < -threshold
                                                                   and dc < -threshold):
        return between
    return None


def _quadratic_fit(times: Any, rows: Any, t_c: float) -> tuple[list[float], list[float], list[float]] | None:
    """ω(t_c) and dω/dt(t_c) of each wheel by a local quadratic through `rows` (one 4-tuple of
    wheel speeds per time), and the weights that average a torque as it averages ω̇
    (`_matched_weights`); None for timestamps too degenerate for the closed form.

    Least squares in closed form on plain floats (the normal equations of a 3-parameter fit in the
    time offset scaled to [−1, 1], so they stay well conditioned): a handful of points and four
    wheels are far too small for numpy's per-call overhead. (`_frontcore.c`'s `quadratic_fit`.)
    """
    n = len(times)
    tau = [t - t_c for t in times]
    h = max(abs(tau[0]), abs(tau[-1])) or 1.0
    u = [x / h for x in tau]
    u2 = [x * x for x in u]
    # sum(map(mul, ...)): the same products summed in the same order as a generator of
    # a * b, without a Python frame per term.
    s1 = sum(u)
    s2 = sum(u2)
    s3 = sum(map(mul, u, u2))
    s4 = sum(map(mul, u2, u2))
    # Symmetric 3×3 normal matrix [[n, s1, s2], [s1, s2, s3], [s2, s3, s4]]: its adjugate.
    c00 = s2 * s4 - s3 * s3
    c01 = s2 * s3 - s1 * s4
    c02 = s1 * s3 - s2 * s2
    c11 = n * s4 - s2 * s2
    c12 = s1 * s2 - n * s3
    det = n * c00 + s1 * c01 + s2 * c02
    if not det > 1e-9 * max(n * s2 * s4, 1e-300):
        return None
    inv = 1.0 / det
    omega = []
    omega_dot = []
    for y in zip(*rows):   # each wheel's speeds over the window
        b0 = sum(y)
        b1 = sum(map(mul, u, y))
        b2 = sum(map(mul, u2, y))
        omega.append((c00 * b0 + c01 * b1 + c02 * b2) * inv)
        omega_dot.append((c01 * b0 + c11 * b1 + c12 * b2) * inv / h)
    return omega, omega_dot, _matched_weights(times, u, (c01 * inv / h, c11 * inv / h, c12 * inv / h))


def _matched_weights(times, u, coef) -> list[float]:
    """Weights w_k such that Σ w_k·T(t_k) is T averaged as the derivative filter averages ω̇.

    The filter's derivative is Σ c_k·ω(t_k) with c_k = coef₀ + coef₁·u_k + coef₂·u_k² and Σ c_k = 0;
    summed by parts it is Σ_j S_j·(ω(t_j) − ω(t_{j−1})) with S_j = Σ_{k≥j} c_k, i.e. the mean
    of ω̇ over each interval weighted by S_j·Δt_j (the weights sum to 1). Each interval's mean
    of T is taken by the trapezoid rule.
    """
    c = [coef[0] + coef[1] * a + coef[2] * a * a for a in u]
    n = len(c)
    tail = 0.0
    interval = [0.0] * (n + 1)
    for j in range(n - 1, 0, -1):
        tail += c[j]
        interval[j] = tail * (times[j] - times[j - 1])
    return [0.5 * (interval[k] + interval[k + 1]) for k in range(n)]
