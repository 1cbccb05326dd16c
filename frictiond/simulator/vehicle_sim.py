"""Four-wheel braking dynamics with brake hydraulics and a rule-based ABS (truth side, no CAN).

Integrated at 1 kHz:

- body: `M dv/dt = −Σ F_x,i − B_v v − D_a v²` along the path; in a constant-radius (left) turn the
  yaw rate is `v/R_c`, the lateral acceleration `v²/R_c`, and wheel i's ground speed is
  `v ∓ ψ̇ d/2` (inner = left wheels slower);
- loads: model.md's load transfer with forward-positive `a_x`, but driven by `a_x` through a
  first-order pitch lag (50 ms), plus optional road roughness (load fluctuation per wheel);
- wheels: `J dω/dt = −T_b + R F_x + T_e` (here `T_e = 0`), solved semi-implicitly in ω because the
  tyre is stiff (for the dynamic LuGre truth the step is exact for the linear-in-slip update of the
  bristle state, so the recorded force is exactly the one the wheel felt);
- hydraulics: each wheel's pressure follows its valve command with a first-order lag
  (40 ms apply, 20 ms dump) and rate limits; `T_b = k_b,true · max(0, p − p_0)` with true gains
  that differ from the nominal ones by the scenario's factors (and ±1.5 % per wheel);
- ABS, one channel per wheel, run every 5 ms on the ECU's view (slip from the ground speed, wheel
  acceleration and brake force over the last cycle), see `AbsController`: it dumps when the slip
  still grows but the force no longer does (the peak has been passed), holds while the wheel
  re-accelerates, then re-applies from a fraction of the pressure that gave the most force and
  ramps slowly (at a rate proportional to it, so the cycle scales from dry asphalt to ice). The
  slip then cycles around the peak, roughly between 0.4 λ* and 1.5 λ*, with a deeper first cycle.
- driver: no pedal for the first second or more (free rolling), then a ramp to the scenario's
  master-cylinder demand, optionally released later.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..vehicle import GRAVITY_MPS2, VehicleParams
from .scenarios import Scenario
from .tyres import LugreDynamic, make_tyre, stack

DT_S = 0.001
PITCH_TIME_CONSTANT_S = 0.05
HYDRAULIC_TAU_APPLY_S = 0.040
HYDRAULIC_TAU_DUMP_S = 0.020
HYDRAULIC_MAX_RISE_BAR_S = 1500.0
HYDRAULIC_MAX_FALL_BAR_S = 3000.0
ROUGHNESS_CORRELATION_S = 0.04


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


@dataclass
class Trace:
    """1 kHz history of the simulated truth (one row per integration step)."""

    t: np.ndarray             # (N,)
    v: np.ndarray             # (N,) path speed at the CG
    ax: np.ndarray            # (N,) forward-positive acceleration
    ay: np.ndarray            # (N,) left-positive lateral acceleration
    yaw: np.ndarray           # (N,) yaw rate
    ground: np.ndarray        # (N,4) wheel ground speeds
    omega: np.ndarray         # (N,4)
    omega_dot: np.ndarray     # (N,4)
    pressure: np.ndarray      # (N,4) bar
    fx: np.ndarray            # (N,4) braking-positive tyre force
    fn: np.ndarray            # (N,4)
    pedal: np.ndarray         # (N,) driver's master-cylinder demand
    abs_active: np.ndarray    # (N,4) bool
    surface: np.ndarray       # (N,4) index into `surface_names`
    surface_names: tuple[str, ...]
    brake_gains: np.ndarray   # (4,) true N·m/bar
    radius: float

    @property
    def slip(self) -> np.ndarray:
        rw = self.omega * self.radius
        return (self.ground - rw) / np.maximum(np.maximum(self.ground, rw), 1e-6)


def _roughness(rng: np.random.Generator, n: int, level: float) -> np.ndarray:
    """(n,4) zero-mean load fluctuation factors, first-order correlated noise of std `level`."""
    if level <= 0.0:
        return np.zeros((n, 4))
    a = math.exp(-DT_S / ROUGHNESS_CORRELATION_S)
    w = rng.standard_normal((n, 4)) * math.sqrt(1.0 - a * a)
    out = np.empty((n, 4))
    x = rng.standard_normal(4)
    for k in range(n):  # cheap: done once, vectorised over wheels
        x = a * x + w[k]
        out[k] = x
    return np.clip(level * out, -0.5, 0.5)


ROUGH_ROAD_ABS = AbsParams(min_slip_rise_rel=0.10)


def _wheels_on_dynamic_lugre(tyre, ground: np.ndarray, omega: np.ndarray, z: np.ndarray, fn: np.ndarray,
                             tb: np.ndarray, R: float, J: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One step of the four wheels on a dynamic LuGre tyre (its bristle state `z`), semi-implicit
    in ω: (ω after the step, the tyre forces, z after the step)."""
    rw = omega * R
    s = ground - rw
    gs = tyre.g(s)
    a = tyre.theta * tyre.sigma0 * np.abs(s) / gs + tyre.kappa * np.abs(rw) + 1e-9
    dec = np.exp(-a * DT_S)
    zs = (1.0 - dec) / a                          # dz_new/ds
    z_pred = z * dec + s * zs
    c = tyre.sigma0 + tyre.sigma1 / DT_S
    mu0 = c * z_pred - tyre.sigma1 / DT_S * z + tyre.sigma2 * s
    dmu_ds = c * zs + tyre.sigma2
    stiff = R * R * fn * dmu_ds                   # −R·dFx/dω ≥ 0
    d_omega = (-tb + R * fn * mu0) * DT_S / (J + DT_S * stiff)
    omega_new = omega + d_omega
    locked = omega_new < 0.0
    if locked.any():
        omega_new = np.maximum(omega_new, 0.0)
    s_new = ground - omega_new * R
    z_old = z
    z = z_old * dec + s_new * zs
    mu = tyre.sigma0 * z + tyre.sigma1 * (z - z_old) / DT_S + tyre.sigma2 * s_new
    fx = mu * fn  # equals (J ω̇ + T_b)/R exactly unless the wheel locked
    return omega_new, fx, z


def _wheels_on_static_curve(tyre, ground: np.ndarray, omega: np.ndarray, fn: np.ndarray, tb: np.ndarray, R: float,
                            J: float) -> tuple[np.ndarray, np.ndarray]:
    """One step of the four wheels on a static μ(λ) curve, semi-implicit in ω through the curve's
    slope (explicit past the peak): (ω after the step, the tyre forces; a locked wheel slides)."""
    rw = omega * R
    denom = np.maximum(ground, rw)
    denom = np.maximum(denom, 1e-6)
    lam = (ground - rw) / denom
    mu0 = tyre.mu(lam, ground)
    slope = tyre.dmu_dslip(lam, ground)
    dlam = np.where(ground >= rw, -R / np.maximum(ground, 1e-6), -ground / (R * np.maximum(omega, 1e-6) ** 2))
    k_lin = R * fn * slope * dlam / J                # d(ω̇)/dω from the tyre
    d_omega = (-tb + R * fn * mu0) / J * DT_S / (1.0 - DT_S * np.minimum(k_lin, 0.0))
    omega_new = omega + d_omega
    locked = omega_new < 0.0
    if locked.any():
        omega_new = np.maximum(omega_new, 0.0)
        mu_lock = tyre.mu(np.ones(4), ground)
        fx = np.where(locked, mu_lock * fn, (J * d_omega / DT_S + tb) / R)
    else:
        fx = (J * d_omega / DT_S + tb) / R
    return omega_new, fx


def run_dynamics(scn: Scenario, vehicle: VehicleParams, family: str, rng: np.random.Generator,
                 abs_params: AbsParams | None = None) -> Trace:
    """Integrate one scenario with the given truth tyre family; `rng` draws the per-run details
    (brake-gain spread, brake onset, road roughness)."""
    if abs_params is None:
        abs_params = ROUGH_ROAD_ABS if scn.abs_rough_road else AbsParams()
    veh = vehicle
    R = veh.wheel_radius
    J = veh.wheel_inertia
    M = veh.mass
    g = GRAVITY_MPS2
    l = veh.wheelbase
    h = veh.cg_height
    half_track = np.array([veh.track_front, veh.track_front, veh.track_rear, veh.track_rear]) / 2.0
    side = np.array([-1.0, 1.0, -1.0, 1.0])  # left wheels inner in a left turn
    track = np.array([veh.track_front, veh.track_front, veh.track_rear, veh.track_rear])
    axle_front = np.array([1.0, 1.0, 0.0, 0.0])

    # --- surfaces and tyre models (one stacked model per distinct per-wheel surface tuple)
    names = tuple(dict.fromkeys(scn.surfaces + (scn.surfaces_after or ())))
    sidx_before = np.array([names.index(s) for s in scn.surfaces])
    sidx_after = np.array([names.index(s) for s in scn.surfaces_after]) if scn.surfaces_after else sidx_before
    singles = {s: make_tyre(family, s) for s in names}
    stacks: dict[tuple[int, ...], object] = {}

    def tyre_for(idx: np.ndarray):
        key = tuple(int(i) for i in idx)
        if key not in stacks:
            stacks[key] = stack([singles[names[i]] for i in key])
        return stacks[key]

    # --- brake gains (true), driver demand
    gf, gr = scn.brake_gain_factor
    kb_nom = np.array([veh.brake_gain_front] * 2 + [veh.brake_gain_rear] * 2)
    kb = kb_nom * np.array([gf, gf, gr, gr]) * (1.0 + rng.uniform(-0.015, 0.015, 4))
    p0 = veh.brake_pushout_pressure
    if scn.target_decel_mps2 is not None:
        # sized with the nominal gains, as a driver would feel for it
        demand = M * scn.target_decel_mps2 * R / float(np.sum(kb_nom)) + p0
    else:
        # a panic stop: at least enough for 1.6 g with the nominal gains, whatever the vehicle
        demand = max(scn.brake_pressure_bar, p0 + 1.6 * M * g * R / float(np.sum(kb_nom)))
    t_brake = scn.brake_start_s + float(rng.uniform(0.0, 0.2))
    t_release = scn.brake_release_s
    pedal_rate = scn.pedal_rate_bar_per_s

    def pedal(t: float) -> float:
        if t < t_brake:
            return 0.0
        p = min(demand, (t - t_brake) * pedal_rate)
        if t_release is not None and t > t_release:
            p = max(0.0, min(p, demand - (t - t_release) * pedal_rate))
        return p

    n_max = int(round(scn.duration_s / DT_S)) + 1
    rough = _roughness(rng, n_max, scn.road_roughness)
    curve = scn.curve_radius_m

    # --- allocate the trace
    T = np.empty(n_max); V = np.empty(n_max); AX = np.empty(n_max); AY = np.empty(n_max); YAW = np.empty(n_max)
    GND = np.empty((n_max, 4)); OM = np.empty((n_max, 4)); OMD = np.empty((n_max, 4)); P = np.empty((n_max, 4))
    FX = np.empty((n_max, 4)); FN = np.empty((n_max, 4)); PED = np.empty(n_max); ABS = np.zeros((n_max, 4), bool)
    SURF = np.empty((n_max, 4), dtype=np.int8)

    # --- state
    v = float(scn.initial_speed_mps)
    yaw = v / curve if curve else 0.0
    ground = v + side * yaw * half_track
    omega = ground / R
    pressure = np.zeros(4)
    p_cmd = np.zeros(4)
    a_lag = 0.0
    ax = 0.0
    z = np.zeros(4)
    abs_ctl = AbsController(abs_params, p0)
    omega_hist = omega.copy()
    p_sum = np.zeros(4)
    ap = abs_params
    x_travel = 0.0
    x_change = None

    sidx = sidx_before.copy()
    tyre = tyre_for(sidx)
    dyn = isinstance(tyre, LugreDynamic)
    n = 0
    for k in range(n_max):
        t = k * DT_S
        if v < scn.stop_speed_mps:
            break
        # surface change: front axle at surface_change_s, rear axle one wheelbase further on
        if scn.surface_change_s is not None:
            if x_change is None and t >= scn.surface_change_s:
                x_change = x_travel
            if x_change is not None:
                new = np.where(axle_front > 0, sidx_after, np.where(x_travel - x_change >= l, sidx_after, sidx_before))
                if not np.array_equal(new, sidx):
                    sidx = new
                    tyre = tyre_for(sidx)
        # lateral motion
        if curve:
            yaw = v / curve
            ay = v * yaw
        else:
            yaw = 0.0
            ay = 0.0
        ground = v + side * yaw * half_track
        # ABS (every period_steps) on the wheel deceleration over the last ECU cycle
        pd = pedal(t)
        if scn.abs_enabled and k % ap.period_steps == 0:
            rw = omega * R
            slip = (ground - rw) / np.maximum(np.maximum(ground, rw), 1e-6)
            wdot = (omega - omega_hist) / (ap.period_steps * DT_S)
            omega_hist = omega.copy()
            tb_ecu = kb * np.maximum(p_sum / ap.period_steps - p0, 0.0)
            p_sum = np.zeros(4)
            abs_ctl.step(slip, wdot * R - ax, (tb_ecu + J * wdot) / R, pd, pressure, p_cmd)
        elif not scn.abs_enabled:
            p_cmd[:] = pd
        # hydraulics: first-order lag with rate limits
        err = p_cmd - pressure
        rate = np.where(err > 0, err / HYDRAULIC_TAU_APPLY_S, err / HYDRAULIC_TAU_DUMP_S)
        rate = np.clip(rate, -HYDRAULIC_MAX_FALL_BAR_S, HYDRAULIC_MAX_RISE_BAR_S)
        pressure = np.maximum(pressure + rate * DT_S, 0.0)
        p_sum += pressure
        tb = kb * np.maximum(pressure - p0, 0.0)
        # loads: load transfer through the pitch lag, lateral transfer, road roughness
        front_axle = M * (g * veh.cg_to_rear_axle - h * a_lag) / l
        rear_axle = M * (g * veh.cg_to_front_axle + h * a_lag) / l
        axle = np.array([front_axle, front_axle, rear_axle, rear_axle])
        fn = axle * (0.5 + side * h * ay / (track * g)) * (1.0 + rough[k])
        # tyre + wheel, semi-implicit in omega
        if dyn:
            omega_new, fx, z = _wheels_on_dynamic_lugre(tyre, ground, omega, z, fn, tb, R, J)
        else:
            omega_new, fx = _wheels_on_static_curve(tyre, ground, omega, fn, tb, R, J)
        omega_dot = (omega_new - omega) / DT_S
        # body
        ax = (-float(np.sum(fx)) - veh.rolling_resistance * v - veh.drag_area_coefficient * v * v) / M
        # record the state at t with the forces acting over [t, t + dt]
        T[k] = t; V[k] = v; AX[k] = ax; AY[k] = ay; YAW[k] = yaw; GND[k] = ground; OM[k] = omega
        OMD[k] = omega_dot; P[k] = pressure; FX[k] = fx; FN[k] = fn; PED[k] = pd
        ABS[k] = abs_ctl.active; SURF[k] = sidx
        n = k + 1
        # advance
        omega = omega_new
        x_travel += v * DT_S
        v = v + ax * DT_S
        a_lag += (ax - a_lag) * (DT_S / PITCH_TIME_CONSTANT_S)

    return Trace(T[:n], V[:n], AX[:n], AY[:n], YAW[:n], GND[:n], OM[:n], OMD[:n], P[:n], FX[:n], FN[:n], PED[:n],
               ABS[:n], SURF[:n].astype(int), names, kb, R)
