"""ABS controller families of the campaign, each with the signature the estimator must live with.

Every controller runs on its own cycle (`cycle_s`, 5–10 ms) on the true wheel speeds and the true
vehicle speed (a real ABS estimates the latter; the error it makes is not what is tested here),
and returns per wheel a hydraulic command: the pressure to move to and the rate to move at
[bar/s]. `simulate.py` moves the wheel pressures accordingly between cycles. Below `cutout_mps`
every ABS hands the wheels back to the driver's pressure, as real ones do.

Families (`ABS_FAMILIES`):
- "a-threshold": slip thresholds with a *slow* dump: when slip > `slip_high` the pressure
  decays exponentially (time constant `dump_tau_s`, 40–100 ms, against a few ms for a fast
  dump) until slip < `slip_low`, then re-applies fast. The slow dump lets the slip run deep
  (0.6–1.0 briefly, tens of ms, on a peaky curve): old or cheap systems, and a stress test of
  the estimator's handling of the far side of the curve.
- "b-decel": wheel-deceleration triggered: fast dump when the wheel's circumferential
  deceleration exceeds the car's by `decel_dump` with slip > `slip_min` (or slip > `slip_guard`);
  the deceleration alone, at smaller slip, only holds the pressure; hold while the wheel
  spins up, then slow re-apply (`reapply_rate`) until the next trigger: the classic Bosch-style
  cycle (its "−a" threshold, relative to the reference deceleration).
- "c-slip": continuous slip control holding `target_frac` × the true peak slip (capped at
  `target_cap`, ≤ 0.12): a modern system that rarely crosses the peak; on flat-topped dry curves
  the slip stays ≤ ~0.12 and μ within a few per cent of the peak.
- "d-none": no ABS intervention: the driver's moderate pressure all the way to standstill.

Any family may regulate the rear axle "select-low" (`params["rear_select_low"]` ≥ 0.5, the stress
run `Stress.rear_select_low`): one valve for both rear wheels, which get the command of the wheel
asking for less pressure, as most production ABS does to keep the car straight. The rear wheel on
more grip is then braked short of its limit, and the axle's two wheels see one pressure.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

ABS_FAMILIES = ("a-threshold", "b-decel", "c-slip", "d-none")

APPLY, DUMP, HOLD, REAPPLY, HOLD_A = range(5)


@dataclass
class WheelCommand:
    target_bar: float
    rate_bps: float
    active: bool = False       # the ABS is modulating this wheel (for the ABS flags)


@dataclass
class AbsController:
    """One controller of `family` with its drawn `params` (see the module docstring)."""

    family: str
    params: dict[str, float]
    cycle_s: float = 0.007
    cutout_mps: float = 2.0
    _mode: list[int] = field(default_factory=lambda: [APPLY] * 4)
    _seen_spin_up: list[bool] = field(default_factory=lambda: [False] * 4)
    _mode_since: list[float] = field(default_factory=lambda: [0.0] * 4)
    _last_omega: list[float] | None = None
    _wheel_accel: list[float] = field(default_factory=lambda: [0.0] * 4)
    _p_ctrl: list[float] = field(default_factory=lambda: [0.0] * 4)
    _controlling: list[bool] = field(default_factory=lambda: [False] * 4)
    _ever_active: list[bool] = field(default_factory=lambda: [False] * 4)
    _last_speed: float | None = None
    _car_accel: float = 0.0

    def update(self, t: float, speed_mps: float, omega: Sequence[float], slip: Sequence[float],
               pressure_bar: Sequence[float], driver_bar: float, radius_m: float,
               peak_slip: Sequence[float]) -> list[WheelCommand]:
        """One controller cycle: a command per wheel."""
        self._measure_accel(omega, radius_m, speed_mps)
        if self.family == "d-none" or speed_mps < self.cutout_mps or driver_bar < 1.0:
            # ABS off (or idle): the wheels see the driver's pressure through the hydraulics.
            self._mode = [APPLY] * 4
            self._controlling = [False] * 4
            return [WheelCommand(driver_bar, self.params.get("apply_rate", 1500.0)) for _ in range(4)]
        step = {"a-threshold": self._threshold, "b-decel": self._decel, "c-slip": self._slip_control}[self.family]
        commands = [step(i, t, slip[i], pressure_bar[i], driver_bar, peak_slip[i]) for i in range(4)]
        if self.params.get("rear_select_low", 0.0) >= 0.5:
            commands[2] = commands[3] = _select_low(commands[2], commands[3])
        return commands

    def _measure_accel(self, omega: Sequence[float], radius_m: float, speed_mps: float) -> None:
        """Circumferential wheel accelerations relative to the car's [m/s²], differenced over the
        cycle and smoothed once (an ABS never differentiates a raw wheel speed)."""
        if self._last_omega is not None and self._last_speed is not None:
            car = (speed_mps - self._last_speed) / self.cycle_s
            self._car_accel = 0.5 * self._car_accel + 0.5 * car
            for i in range(4):
                raw = radius_m * (omega[i] - self._last_omega[i]) / self.cycle_s - car
                self._wheel_accel[i] = 0.5 * self._wheel_accel[i] + 0.5 * raw
        self._last_omega = list(omega)
        self._last_speed = speed_mps

    def _set(self, i: int, mode: int, t: float) -> None:
        if self._mode[i] != mode:
            self._mode[i] = mode
            self._mode_since[i] = t

    def _threshold(self, i: int, t: float, slip: float, p: float, driver: float, _peak: float) -> WheelCommand:
        prm = self.params
        if self._mode[i] != DUMP and slip > prm["slip_high"]:
            self._set(i, DUMP, t)
            self._ever_active[i] = True
        elif self._mode[i] == DUMP and slip < prm["slip_low"]:
            self._set(i, APPLY, t)
        if self._mode[i] == DUMP:
            return WheelCommand(0.0, max(p / prm["dump_tau_s"], 20.0), True)
        return WheelCommand(driver, prm["apply_rate"], self._ever_active[i])

    def _decel(self, i: int, t: float, slip: float, p: float, driver: float, _peak: float) -> WheelCommand:
        prm = self.params
        acc = self._wheel_accel[i]
        mode = self._mode[i]
        # −a alone holds the pressure; −a with slip beyond `slip_min` (or slip beyond the guard)
        # dumps (Bosch's phases 2 and 3): a soft tyre decelerates its wheel hard on a pressure
        # rise long before its peak, and a relaxing tyre does for a few ms on every step.
        decelerating = acc < -prm["decel_dump"]
        if mode in (APPLY, REAPPLY, HOLD_A) and (decelerating and slip > prm["slip_min"] or slip > prm["slip_guard"]):
            self._set(i, DUMP, t)
            self._ever_active[i] = True
            self._seen_spin_up[i] = False
        elif mode in (APPLY, REAPPLY) and decelerating:
            self._set(i, HOLD_A, t)
            self._ever_active[i] = True
        elif mode == HOLD_A and acc > -0.3 * prm["decel_dump"]:
            self._set(i, REAPPLY, t)
        elif mode == DUMP and acc > -0.3 * prm["decel_dump"] and slip < prm["slip_guard"]:
            self._set(i, HOLD, t)
        elif mode == HOLD:
            if acc > prm["spin_up"]:
                self._seen_spin_up[i] = True
            recovered = self._seen_spin_up[i] and acc < prm["spin_up"]
            if recovered or t - self._mode_since[i] > prm["hold_max_s"]:
                self._set(i, REAPPLY, t)
        mode = self._mode[i]
        if mode == DUMP:
            return WheelCommand(0.0, prm["dump_rate"], True)
        if mode in (HOLD, HOLD_A):
            return WheelCommand(p, 0.0, True)
        if mode == REAPPLY:
            return WheelCommand(driver, prm["reapply_rate"], True)
        return WheelCommand(driver, prm["apply_rate"], False)

    def _slip_control(self, i: int, t: float, slip: float, p: float, driver: float, peak: float) -> WheelCommand:
        prm = self.params
        target = min(prm["target_frac"] * peak, prm["target_cap"])
        if not self._controlling[i]:
            # Pre-control: the pedal's fast rise is taken over before the target, not after it.
            if slip <= 0.5 * target:
                return WheelCommand(driver, prm["apply_rate"], False)
            self._controlling[i] = True
            self._ever_active[i] = True
            self._p_ctrl[i] = p
        # Integral action in the log of the pressure: the same relative correction on ice (a few
        # bar) as on dry asphalt (100+ bar).
        err = target - slip
        pc = self._p_ctrl[i] * math.exp(max(min(prm["gain"] * err * self.cycle_s, 0.3), -0.5))
        if slip > target + 0.04:       # well past the target: halve at once (a safety dump)
            pc = 0.5 * p
        self._p_ctrl[i] = min(max(pc, 1.0), driver)
        return WheelCommand(self._p_ctrl[i], prm["valve_rate"], True)


def _select_low(left: WheelCommand, right: WheelCommand) -> WheelCommand:
    """One valve for an axle: the command asking for the lower pressure, active if either is."""
    low = left if left.target_bar <= right.target_bar else right
    return WheelCommand(low.target_bar, low.rate_bps, left.active or right.active)
