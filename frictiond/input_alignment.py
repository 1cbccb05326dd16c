"""The inputs at a sample's instant: each message's recent values (`MessageHistory`), read by
interpolation at the derivative window's centre (`InputAlignment._values_at`) or averaged over
the window with the derivative filter's own weights (`InputAlignment._matched_inputs`).

`InputAlignment` is a part of `frontend.FrontEnd` (its state, `_source`, `_sample_lookups`,
`_matched_lookups`, `_wheel_times` and `_torque_weights`, is the front end's); the compiled
`_frontcore` does the same sums when built, and the float code here is the fallback and the
reference (tests/test_frontcore.py compares).
"""
from __future__ import annotations

import math
from collections import deque
from typing import Any, Mapping

from .input_names import PRESSURE_NAMES


def new_series() -> tuple[deque[float], deque[float]]:
    """A signal's (times, values) history: the newest 16 of each."""
    return deque(maxlen=16), deque(maxlen=16)


class MessageHistory:
    """The last few values of one input message, for interpolation and staleness.

    Each signal keeps its own (time, value) series: a multiplexed message carries only some of
    its signals per frame, and a page's value must keep the time of the frame that carried it.
    """

    __slots__ = ("series", "period_s", "last_arrival_s", "merged")

    def __init__(self, period_s: float) -> None:
        self.series: dict[str, tuple[deque[float], deque[float]]] = {}
        self.period_s = period_s
        self.last_arrival_s = -math.inf
        self.merged: dict[str, float] = {}

    def push(self, time_s: float, values: Mapping[str, float], core: Any = None) -> None:
        series = self.series
        if time_s < self.last_arrival_s:
            # Time went backwards (log splice, clock step): the old history means nothing now.
            series.clear()
        if core is not None and type(time_s) is float and type(values) is dict:
            core.push_values(series, self.merged, time_s, values, new_series)
            self.last_arrival_s = time_s
            return
        merged = self.merged
        for name, value in values.items():
            merged[name] = value
            pair = series.get(name)
            if pair is None:
                pair = series[name] = new_series()
            pair[0].append(time_s)
            pair[1].append(value)
        self.last_arrival_s = time_s

    def value_at(self, time_s: float, name: str) -> float | None:
        pair = self.series.get(name)
        if pair is None:
            return None
        times, values = pair
        if time_s >= times[-1]:
            return values[-1]
        for k in range(len(times) - 1, 0, -1):
            t0 = times[k - 1]
            if t0 <= time_s:
                t1 = times[k]
                v0 = values[k - 1]
                w = (time_s - t0) / (t1 - t0) if t1 > t0 else 1.0
                return v0 + w * (values[k] - v0)
        return values[0]


def interpolation_plan(ts: list[float], times: list[float], weights: list[float],
                       slopes: bool = False) -> list[tuple[int, float]]:
    """(series index, coefficient) pairs with Σ coefficient·value = Σ_k weights_k·value(times_k),
    value interpolated linearly in the series (held beyond its ends) as `MessageHistory.value_at`;
    with `slopes`, = Σ_k weights_k·(the series' slope at times_k): its slope between the values
    around each time, 0 beyond its ends (held) and across a repeated time."""
    coefficients: dict[int, float] = {}
    get = coefficients.get
    last = len(ts) - 1
    k = last
    for t, w in zip(reversed(times), reversed(weights)):
        if t >= ts[last]:
            if not slopes:
                coefficients[last] = get(last, 0.0) + w
            continue
        while k > 0 and ts[k - 1] > t:
            k -= 1
        if k == 0:
            if not slopes:
                coefficients[0] = get(0, 0.0) + w
            continue
        t0, t1 = ts[k - 1], ts[k]
        if slopes:
            if t1 > t0:
                coefficients[k - 1] = get(k - 1, 0.0) - w / (t1 - t0)
                coefficients[k] = get(k, 0.0) + w / (t1 - t0)
            continue
        f = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
        coefficients[k - 1] = get(k - 1, 0.0) + w * (1.0 - f)
        coefficients[k] = get(k, 0.0) + w * f
    return list(coefficients.items())


def plan_total(plan: list[tuple[int, float]], values, floor: float | None) -> float:
    """Σ coefficient·value over an `interpolation_plan` (`max(0, value − floor)` per value when
    `floor` is given)."""
    if floor is None:
        return sum(a * values[j] for j, a in plan)
    total = 0.0
    for j, a in plan:
        v = values[j]
        if v > floor:
            total += a * (v - floor)
    return total


class InputAlignment:
    """The front end's reading of its inputs at a sample's instant."""

    # The wheel's angular acceleration comes from the derivative filter, which averages ω̇ over
    # its window; the torques and the body acceleration it is set against in the wheel and body
    # equations are averaged by the same kernel (`wheel_speed_filter._matched_weights`). Against
    # point values, a fast pressure swing (ABS on ice, where most of the brake torque goes into the
    # wheel's inertia) left the two out of step: μ read 50 % low while the pressure rose, then as
    # much high.
    def _matched_brake_torques(self, pressures: list[float]) -> list[float]:
        veh = self.vehicle
        if self._torque_weights is None:
            return [veh.brake_torque_nm(i, p) for i, p in enumerate(pressures)]
        plans: dict = {}
        pushout = veh.brake_pushout_pressure
        return [veh.brake_gain(i) * self._matched(name, p, plans, pushout)
                for i, (name, p) in enumerate(zip(PRESSURE_NAMES, pressures))]

    def _matched_brake_rates(self) -> list[float | None]:
        """Each wheel's matched brake torque's rate at the sample's instant: the pressure series'
        slopes (linear between its frames, 0 beyond them) averaged over the derivative window with
        the filter's weights, times the wheel's gain; None where the series has no two frames.

        The rate the sensors' lag is compensated with (`_tyre_forces`) and learnt from
        (`_learn_pressure_lag`). The matched torques' difference from the previous sample is the
        rate half a wheel period earlier (5–10 ms), late by that much while an ABS dumps or builds
        hundreds of bar per second. (`_frontcore.c`'s `matched_slopes`.)"""
        weights = self._torque_weights
        if weights is None:
            return [None] * 4
        pushout = self.vehicle.brake_pushout_pressure
        times = list(self._wheel_times)
        rates: list[float | None] = []
        for i, name in enumerate(PRESSURE_NAMES):
            pair = self._series(name)
            if pair is None or len(pair[0]) < 2:
                rates.append(None)
                continue
            plan = interpolation_plan(list(pair[0]), times, weights, slopes=True)
            rates.append(self.vehicle.brake_gain(i) * plan_total(plan, pair[1], pushout))
        return rates

    def _matched_inputs(self, pressures: list[float], accel_long_raw: float) -> tuple[list[float], float]:
        """`_matched_brake_torques` and `_matched_value("accel_long", …)` (one compiled call when built)."""
        if self.core is None or self._torque_weights is None:
            return self._matched_brake_torques(pressures), self._matched_value("accel_long", accel_long_raw)
        matched = self.core.matched_many(self._matched_lookups, self._wheel_times, self._torque_weights)
        pushout = self.vehicle.brake_pushout_pressure
        torques = [gain * (m if m is not None else max(0.0, p - pushout))
                   for gain, m, p in zip(self._brake_gains, matched, pressures)]
        return torques, (matched[4] if matched[4] is not None else accel_long_raw)

    def _matched_value(self, name: str, fallback: float) -> float:
        return fallback if self._torque_weights is None else self._matched(name, fallback, {}, None)

    def _matched(self, name: str, fallback: float, plans: dict, floor: float | None) -> float:
        """Σ w_k·x(t_k) over the derivative window's times, x interpolated in its series like
        `value_at` (`max(0, x − floor)` per series value when `floor` is given). The
        interpolation plan depends only on the series' timestamps: signals of one message share it."""
        pair = self._series(name)
        if pair is None:
            return fallback if floor is None else max(0.0, fallback - floor)
        ts, vs = pair
        if self.core is not None:
            return self.core.matched(ts, vs, self._wheel_times, self._torque_weights, floor)
        key = (len(ts), ts[0], ts[-1])
        plan = plans.get(key)
        if plan is None:
            plan = plans[key] = interpolation_plan(list(ts), list(self._wheel_times), self._torque_weights)
        return plan_total(plan, vs, floor)

    def _series(self, name: str) -> tuple | None:
        """The (times, values) series of input `name` as received; None before its first frame."""
        history = self._source.get(name)
        return history.series.get(name) if history is not None else None

    def _value(self, name: str, time_s: float) -> float | None:
        history = self._source.get(name)
        if history is None:
            return None
        return history.value_at(time_s, name)

    def _lookups(self, names: tuple[str, ...]) -> tuple[tuple[dict, str] | None, ...]:
        """Per name, (its message's series, name) for `_frontcore.values_at`; None where unmapped."""
        return tuple((self._source[n].series, n) if n in self._source else None for n in names)

    def _values_at(self, time_s: float) -> tuple[float | None, ...]:
        """`_value` of each of `_sample_inputs` at one time."""
        if self.core is not None:
            return self.core.values_at(self._sample_lookups, time_s)
        return tuple([self._value(name, time_s) for name in self._sample_inputs])
