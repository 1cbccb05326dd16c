"""The simulated car's brakes (truth side, no CAN): the driver's pedal, each wheel's hydraulics
and a rule-based ABS (`AbsController`), stepped together by `BrakeSystem` at the integration rate.

- driver: no pedal for the first second or more (free rolling), then a ramp to the scenario's
  master-cylinder demand, optionally released later;
- hydraulics: each wheel's pressure follows its valve command with a first-order lag
  (40 ms apply, 20 ms dump) and rate limits; `T_b = k_b,true · max(0, p − p_0)` with true gains
  that differ from the nominal ones by the scenario's factors (and ±1.5 % per wheel);
- ABS: see `AbsController` and `vehicle_sim`'s docstring.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..vehicle import GRAVITY_MPS2, VehicleParams
from .scenarios import Scenario
from .timestep import DT_S

HYDRAULIC_TAU_APPLY_S = 0.040
HYDRAULIC_TAU_DUMP_S = 0.020
HYDRAULIC_MAX_RISE_BAR_S = 1500.0
HYDRAULIC_MAX_FALL_BAR_S = 3000.0


@dataclass(frozen=True)
class AbsParams:
    period_steps: int = 5              # ECU cycle: 5 ms
    slip_gate: float = 0.008           # no intervention below this slip
    slip_max: float = 0.45             # dump whatever else the signals say
    window_cycles: int = 3             # force/slip trend over this many ECU cycles (15 ms)
    min_slip_rise: float = 0.002       # slip must have grown this much over the window ...
    min_slip_rise_rel: float = 0.04    # ... and this fraction of itself
    elasticity_threshold: float = 0.03  # d ln F / d ln λ below this: at or past the peak
    reaccel_threshold: float = 0.8     # m/s²: the wheel re-accelerates → stop dumping
    settle_threshold: float = 0.3      # m/s²: re-acceleration over → re-apply
    reapply_slip_fraction: float = 0.7  # ... or slip back below this fraction of the peak's slip
    reapply_fraction: float = 0.85     # jump to this fraction of the pressure at the last peak ...
    reapply_rate: float = 1.6          # ... then ramp at this fraction of it per second
    lock_memory: float = 0.85          # a new peak pressure is at least this fraction of the last


APPLY, DUMP, HOLD = 0, 1, 2


class AbsController:
    """Four independent rule-based ABS channels (apply / dump / hold / re-apply cycle).

    Each ECU cycle it gets, per wheel, the slip (from the ground speed), the wheel's circumferential
    acceleration minus the vehicle's (`excess`, negative when the wheel decelerates faster than the
    car) and the brake force the ECU infers from its own pressure and the wheel deceleration,
    `F = (k_b p + J ω̇)/R` (averaged over the cycle; the ECU is idealised: it knows its true brake
    gains). It writes the valve commands.

    - APPLY: pressure follows the driver (inside a cycle: jump to a fraction of the pressure that
      gave the most force before the last dump, then ramp at a rate proportional to it, so the
      cycle scales from dry to ice).
      The peak is recognised when the slip grows but the force no longer does: the elasticity
      `Δ ln F / Δ ln λ` over the last few cycles falls below a small threshold → DUMP.
    - DUMP: outlet valve open until the wheel re-accelerates → HOLD.
    - HOLD: until the re-acceleration is over → APPLY (cycling).
    Independently of the trend, slip beyond `slip_max` dumps.
    """

    def __init__(self, params: AbsParams, pushout_bar: float = 0.0) -> None:
        self.p = params
        self.p0 = pushout_bar
        self.state = [APPLY] * 4
        self.cycling = [False] * 4
        self.p_lock = [0.0] * 4
        self.active = [False] * 4
        self.dumps = [0] * 4
        self.f_max = [0.0] * 4           # best force of the current apply phase ...
        self.p_at_f_max = [0.0] * 4      # ... the pressure and slip where it was seen
        self.slip_at_f_max = [0.0] * 4
        n = params.window_cycles + 1
        self._slip_hist = [[0.0] * n for _ in range(4)]
        self._force_hist = [[0.0] * n for _ in range(4)]

    def step(self, slip, excess, force, pd: float, pressure, p_cmd) -> None:
        ap = self.p
        dt = ap.period_steps * DT_S
        for i in range(4):
            lam = float(slip[i])
            e = float(excess[i])
            p = float(pressure[i])
            f = float(force[i])
            sh, fh = self._slip_hist[i], self._force_hist[i]
            sh.pop(0); sh.append(lam)
            fh.pop(0); fh.append(f)
            st = self.state[i]
            if pd <= self.p0 + 1.0:  # driver off the brake: ABS idle
                self.state[i], self.cycling[i] = APPLY, False
                p_cmd[i] = pd
                self.active[i] = False
                continue
            if st == APPLY:
                if f > self.f_max[i]:
                    self.f_max[i], self.p_at_f_max[i], self.slip_at_f_max[i] = f, p, lam
                rise = lam - sh[0]
                past_peak = False
                if lam > ap.slip_gate and rise > max(ap.min_slip_rise, ap.min_slip_rise_rel * lam) and f > 0.0:
                    elasticity = ((f - fh[0]) / max(abs(f), 1.0)) / (rise / lam)
                    past_peak = elasticity < ap.elasticity_threshold
                if past_peak or lam > ap.slip_max:
                    st = self._dump(i, p, p_cmd)
                elif self.cycling[i]:
                    p_cmd[i] = min(pd, p_cmd[i] + ap.reapply_rate * self.p_lock[i] * dt)
                    if p_cmd[i] >= pd:
                        self.cycling[i] = False
                else:
                    p_cmd[i] = pd
            elif st == DUMP:
                if e > ap.reaccel_threshold or lam < ap.slip_gate:
                    st = HOLD
                    p_cmd[i] = p
                else:
                    p_cmd[i] = 0.0
            else:  # HOLD
                if lam > ap.slip_max:
                    st = self._dump(i, p, p_cmd)
                elif e < ap.settle_threshold or lam < ap.reapply_slip_fraction * self.slip_at_f_max[i]:
                    st, self.cycling[i] = APPLY, True
                    p_cmd[i] = max(p, ap.reapply_fraction * self.p_lock[i])
                    self.f_max[i] = 0.0
            self.state[i] = st
            p_cmd[i] = min(p_cmd[i], pd)
            self.active[i] = self.cycling[i] or st != APPLY

    def _dump(self, i: int, p: float, p_cmd) -> int:
        # the pressure that gave the most force in this apply phase (the peak), not the overshoot
        p_peak = self.p_at_f_max[i] if self.f_max[i] > 0.0 else p
        if self.p_lock[i] > 0.0:  # one cycle moves the memory by a bounded step (rough roads fake peaks)
            p_peak = max(p_peak, self.p.lock_memory * self.p_lock[i])
        self.p_lock[i] = p_peak
        self.dumps[i] += 1
        p_cmd[i] = 0.0
        return DUMP


ROUGH_ROAD_ABS = AbsParams(min_slip_rise_rel=0.10)


class BrakeSystem:
    """Pedal, ABS and hydraulics of one run: each step's pressures (`pressure`) and brake torques.

    Its random draws (the true gains' spread, then the brake onset) are made on construction, in
    that order: the caller draws the road's roughness after them."""

    def __init__(self, scn: Scenario, veh: VehicleParams, rng: np.random.Generator, abs_params: AbsParams,
                 omega: np.ndarray) -> None:
        R = veh.wheel_radius
        M = veh.mass
        g = GRAVITY_MPS2
        gf, gr = scn.brake_gain_factor
        kb_nom = np.array([veh.brake_gain_front] * 2 + [veh.brake_gain_rear] * 2)
        self.gains = kb_nom * np.array([gf, gf, gr, gr]) * (1.0 + rng.uniform(-0.015, 0.015, 4))   # true
        self.pushout = p0 = veh.brake_pushout_pressure
        if scn.target_decel_mps2 is not None:
            # sized with the nominal gains, as a driver would feel for it
            self._demand = M * scn.target_decel_mps2 * R / float(np.sum(kb_nom)) + p0
        else:
            # a panic stop: at least enough for 1.6 g with the nominal gains, whatever the vehicle
            self._demand = max(scn.brake_pressure_bar, p0 + 1.6 * M * g * R / float(np.sum(kb_nom)))
        self._t_brake = scn.brake_start_s + float(rng.uniform(0.0, 0.2))
        self._t_release = scn.brake_release_s
        self._pedal_rate = scn.pedal_rate_bar_per_s
        self._abs_enabled = scn.abs_enabled
        self._radius = R
        self._inertia = veh.wheel_inertia
        self.pressure = np.zeros(4)
        self._p_cmd = np.zeros(4)
        self.abs = AbsController(abs_params, p0)
        self._abs_params = abs_params
        self._omega_hist = omega.copy()   # the wheel speeds at the last ECU cycle
        self._p_sum = np.zeros(4)         # the pressures summed over this ECU cycle

    def pedal(self, t: float) -> float:
        """The driver's master-cylinder demand at `t` [bar]."""
        if t < self._t_brake:
            return 0.0
        p = min(self._demand, (t - self._t_brake) * self._pedal_rate)
        if self._t_release is not None and t > self._t_release:
            p = max(0.0, min(p, self._demand - (t - self._t_release) * self._pedal_rate))
        return p

    def step(self, k: int, t: float, omega: np.ndarray, ground: np.ndarray, ax: float) -> tuple[float, np.ndarray]:
        """Step `k` at `t`: the pedal's demand, and the brake torques over the step."""
        R, J, ap, p0 = self._radius, self._inertia, self._abs_params, self.pushout
        pd = self.pedal(t)
        if self._abs_enabled and k % ap.period_steps == 0:
            # ABS (every period_steps) on the wheel deceleration over the last ECU cycle
            rw = omega * R
            slip = (ground - rw) / np.maximum(np.maximum(ground, rw), 1e-6)
            wdot = (omega - self._omega_hist) / (ap.period_steps * DT_S)
            self._omega_hist = omega.copy()
            tb_ecu = self.gains * np.maximum(self._p_sum / ap.period_steps - p0, 0.0)
            self._p_sum = np.zeros(4)
            self.abs.step(slip, wdot * R - ax, (tb_ecu + J * wdot) / R, pd, self.pressure, self._p_cmd)
        elif not self._abs_enabled:
            self._p_cmd[:] = pd
        # hydraulics: first-order lag with rate limits
        err = self._p_cmd - self.pressure
        rate = np.where(err > 0, err / HYDRAULIC_TAU_APPLY_S, err / HYDRAULIC_TAU_DUMP_S)
        rate = np.clip(rate, -HYDRAULIC_MAX_FALL_BAR_S, HYDRAULIC_MAX_RISE_BAR_S)
        self.pressure = np.maximum(self.pressure + rate * DT_S, 0.0)
        self._p_sum += self.pressure
        return pd, self.gains * np.maximum(self.pressure - p0, 0.0)
