"""The pressure sensors' lag behind the brakes, told by the body equation.

A pressure sensor (and its signal's filtering) trails the brakes by a few tens of ms: under ABS the
wheels' torque balance read μ high while the pressure fell and low while it rose. The body's
torque N = ΣR·F_x − ΣJ·ω̇ is what the brakes gave at each instant, so a fit of N on the pressures'
torque B and its rate Ḃ tells the lag (`_learn_pressure_lag`); the brake gain is then fitted to the
pressures as read against N passed through that lag (`_needed_as_sensed`). `PressureLag` is a part
of `body_equation.BodyEquation` (its state, `_lag_state` and `_sensed_needed_*`, lives on the front
end, where the compiled `_frontcore.sample_physics` reads and writes it by these names; the code
here is the fallback without a C compiler and the reference).
"""
from __future__ import annotations

import math

# While the brakes' torque moves, what a pressure sensor trailing it by this long misses (a pedal
# applied at 1,500 bar/s, an ABS dump: tens of bar): the body check allows for that much.
PRESSURE_SENSOR_LAG_S = 0.04
# The pressure sensors' own lag, identified from the body equation (`_learn_pressure_lag`), is
# taken as at most this (a first-order lag of a few tens of ms; more would be a broken sensor),
# learnt over about this much braking, with a prior of "no lag" weighing like ten samples of a
# pressure moving 10 kN·m/s. (Also in _frontcore.c.)
MAX_PRESSURE_LAG_S = 0.05
# ... and below this, not told from none: a lag-free sensor's fit wanders by up to ~1 ms (the
# body equation's noise, the torques' rates being finite differences), and advancing the torques
# by that only adds noise.
MIN_PRESSURE_LAG_S = 0.002
PRESSURE_LAG_TIME_CONSTANT_S = 5.0
_PRESSURE_LAG_PRIOR = 10 * 10_000.0**2
# What the lag's learning keeps from sample to sample (in `body_equation.LEARNT_STATE`).
PRESSURE_LAG_STATE = ("_sensed_needed_nm", "_sensed_needed_time_s", "_lag_state")


class PressureLag:
    """The pressure sensors' lag: learnt (`_learn_pressure_lag`), the brake torques' rates it is
    learnt from (`_brake_torque_rates`), and the body's torque as the lagging sensors see it."""

    def _reset_pressure_lag(self) -> None:
        """No lag learnt yet."""
        # N as a pressure sensor with the learnt lag would read it (`_needed_as_sensed`), and the
        # time of the sample it was last brought to
        self._sensed_needed_nm = math.nan
        self._sensed_needed_time_s = -math.inf
        # The pressure-lag regression (`_learn_pressure_lag`): Σ B², Σ B·Ḃ, Σ Ḃ², Σ B·N, Σ Ḃ·N, the
        # lag it gives, then the time and the four matched brake torques of the last sample (their
        # rates). One tuple, replaced whole, so that a suspect sample's state is put back as is.
        self._lag_state: tuple[float, ...] = (0.0,) * 6 + (math.nan, 0.0, 0.0, 0.0, 0.0)

    @property
    def pressure_lag_s(self) -> float:
        """The pressure sensors' lag behind the brakes, as learnt from the body equation."""
        return self._lag_state[5]

    def _needed_as_sensed(self, needed: float) -> float:
        """The torque the body needs, through the pressure sensors' first-order lag as learnt: what
        the pressures read, times the gain, less the offset's torque. The gain is fitted to the
        pressures as read against this, not to the pressures advanced by the lag (B + τ·Ḃ) against
        N: Ḃ is a difference of noisy readings, and noise in the regressor biases a least-squares
        slope towards 0 (at a 36 ms lag, 0.25 bar of noise and an ABS from 157 km/h a whole stop's
        fit gave the gain 0.94 for 1.05 and the offset −0.43 m/s² for +0.30; the lag taken off N
        instead, 1.00).
        Restarted from N after a gap in the samples the gain learns from."""
        lag, now = self._lag_state[5], self._lag_state[6]
        last, elapsed = self._sensed_needed_nm, now - self._sensed_needed_time_s
        if lag > 0.0 and math.isfinite(last) and 0.0 < elapsed <= 1.5 * self.sample_period_s:
            needed = last + (needed - last) * -math.expm1(-elapsed / lag)
        self._sensed_needed_nm, self._sensed_needed_time_s = needed, now
        return needed

    def _brake_torque_rates(self, time_s: float, torques: list[float]) -> list[float]:
        """Each wheel's matched brake torque's rate since the last sample (0 after a gap, and
        where either torque is not finite: one bad sample must not spoil the next one's torque)."""
        state = self._lag_state
        dt = time_s - state[6]            # (NaN before the first sample: no rate)
        self._lag_state = state[:6] + (time_s, *torques)
        if not 0.0 < dt <= self.options.max_gap:
            return [0.0, 0.0, 0.0, 0.0]
        rates = [(b - b0) / dt for b, b0 in zip(torques, state[7:])]
        return [r if math.isfinite(r) else 0.0 for r in rates]

    def _learn_pressure_lag(self, brake: float, rate: float, needed: float) -> None:
        """The pressure sensors' lag τ from the body equation: the brakes' torque the body needs,
        N = ΣR·F_x − ΣJ·ω̇, is k·(B + τ·Ḃ) at every instant, B the torque the pressures say; a
        least-squares fit of N on B and Ḃ gives k and k·τ (each sample as it comes, with forgetting,
        and a prior of no lag). The wheels' torque balance sees the same lag: under ABS it read μ
        30 % high while the pressure fell and 25 % low while it rose (the peak read high)."""
        s_bb, s_bd, s_dd, s_bn, s_dn, lag = self._lag_state[:6]
        keep = 1.0 - min(1.0, self.sample_period_s / PRESSURE_LAG_TIME_CONSTANT_S)
        s_bb = keep * s_bb + brake * brake
        s_bd = keep * s_bd + brake * rate
        s_dd = keep * s_dd + rate * rate
        s_bn = keep * s_bn + brake * needed
        s_dn = keep * s_dn + rate * needed
        if not all(map(math.isfinite, (s_bb, s_bd, s_dd, s_bn, s_dn))):
            return      # a NaN here would stay in the sums for good
        dd = s_dd + _PRESSURE_LAG_PRIOR
        det = s_bb * dd - s_bd * s_bd
        if det > 0.0:
            k = (s_bn * dd - s_bd * s_dn) / det
            k_lag = (s_bb * s_dn - s_bd * s_bn) / det
            # (a gain k far from 1 is a body equation that does not hold: no lag from it)
            if 0.5 < k < 2.0:
                lag = min(max(k_lag / k, 0.0), MAX_PRESSURE_LAG_S)
                lag = lag if lag >= MIN_PRESSURE_LAG_S else 0.0
        self._lag_state = (s_bb, s_bd, s_dd, s_bn, s_dn, lag) + self._lag_state[6:]
