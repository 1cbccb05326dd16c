"""One campaign stop: integrate the truth car at 1 kHz, then put it on the bus as frames.

`simulate_stop(spec)` → `CampaignStop` with the input `frames` (encoded through this car's own
DBC and signal map, exactly as frictiond decodes them), the `truth` rows every 10 ms (the
columns `frictiond.evaluation` reads, plus per-wheel forces, loads and utilisation), and
`config(kind)`, the frictiond config of the car as configured.

Integration: per 1 ms step the driver's pedal, the ABS (on its own cycle), the hydraulics (rate
limited), load transfer (pitch-lagged a_x, lateral from the curve), the lateral force the curve
needs (each tyre's share in proportion to its load, which lowers its longitudinal curve by the
friction ellipse: `lateral_use`), then each wheel by
linearly implicit Euler — the tyre's slope dF/dω enters the step's denominator where it
stabilises (below the peak), so a stiff tyre at low speed does not need a smaller step — with
the optional relaxation lag integrated in the same implicit step; then the body.
"""
from __future__ import annotations

import hashlib
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..codec import InputCodec, load_databases
from ..config import Config, parse_config
from ..frames import Frame
from .abs_control import AbsController, WheelCommand
from .draw import StopSpec
from .sensors import bus_dbc_text, sensor_events, signal_map
from .tyres import scalar_model, scalar_speed_factor
from .vehicle import GRAVITY_MPS2, normal_loads

WHEELS = ("fl", "fr", "rl", "rr")
TRUTH_EVERY = 10                 # truth rows every 10 steps (10 ms at 1 kHz)
V_EPS_MPS = 1.0                  # slip's denominator floor for the force (regularised near standstill)
STANDSTILL_MPS = 0.05
RELAXATION_MIN_SPEED_MPS = 5.0  # the relaxation time σ/v is σ/5 m/s at most
# The path is prescribed: where a turn would ask more of a tyre than its grip, it is held at this
# share of its lateral grip (a real car would run wide instead).
MAX_LATERAL_USE = 0.95
BRAKING_MIN_SPEED_MPS = 0.5      # `braking` in the truth: pedal applied and the car still rolling
AFTER_STOP_S = 0.3
AFTER_RELEASE_S = 0.5
PEDAL_RELEASE_BPS = 1000.0


@dataclass
class Trace:
    """The 1 kHz truth trace (arrays; (N, 4) per wheel)."""

    t: np.ndarray
    v: np.ndarray
    x: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    yaw: np.ndarray
    omega: np.ndarray
    omega_dot: np.ndarray
    pressure: np.ndarray
    master: np.ndarray
    fx: np.ndarray
    fz: np.ndarray
    slip: np.ndarray
    ground: np.ndarray
    mu_max: np.ndarray
    slip_at_mu_max: np.ndarray
    abs_active: np.ndarray
    braking: np.ndarray
    lateral_use: np.ndarray      # F_y / (lateral grip · F_z) per wheel


@dataclass
class CampaignStop:
    spec: StopSpec
    frames: list[Frame]
    truth: list[dict[str, float]]
    dbc_path: Path
    trace: Trace | None = field(default=None, repr=False)

    def config_data(self, kind: str = "lugre-tr") -> dict[str, Any]:
        return config_data(self.spec, self.dbc_path, kind)

    def config(self, kind: str = "lugre-tr") -> Config:
        """The frictiond config of the car as configured, with estimator `kind`."""
        return parse_config(self.config_data(kind), None)


def config_data(spec: StopSpec, dbc_path: Path | str, kind: str = "lugre-tr") -> dict[str, Any]:
    """The YAML mapping of the stop's frictiond config (`dbc_path` as given)."""
    return {
        "can": {"interface": "virtual", "channel": "campaign", "dbc": str(dbc_path)},
        "vehicle": spec.car.config_vehicle(),
        "estimator": {"kind": kind},
        "signals": signal_map(spec.sensors),
    }


def dbc_file(spec: StopSpec, directory: Path | None = None) -> Path:
    """This car's DBC, written once per content into a cache folder (workers share it)."""
    text = bus_dbc_text(spec.sensors)
    folder = directory or Path(tempfile.gettempdir()) / "frictiond-campaign-dbc"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{hashlib.sha1(text.encode()).hexdigest()[:16]}.dbc"
    if not path.exists():
        tmp = path.with_suffix(f".{np.random.default_rng().integers(1 << 30)}.tmp")
        tmp.write_text(text)
        tmp.replace(path)   # atomic: a parallel worker never reads half a file
    return path


class _Integrator:
    """The 1 kHz truth simulation of one stop (state in plain floats: four wheels a step)."""

    def __init__(self, spec: StopSpec) -> None:
        self.spec = spec
        car = spec.car
        self.car = car
        self.dt = spec.dt_s
        self.models = [scalar_model(c) for c in spec.surfaces]
        self.peaks = [c.peak for c in spec.surfaces]
        self.speed_factor = [scalar_speed_factor(c) for c in spec.surfaces]
        self.abs = AbsController(spec.abs_family, dict(spec.abs_params), spec.abs_cycle_s, spec.abs_cutout_mps)
        self.abs_every = max(1, int(round(spec.abs_cycle_s / spec.dt_s)))
        self.v = spec.speed0_mps
        self.x = 0.0
        self.radii = car.radii()
        self.omega = [self.v / r for r in self.radii]
        self.force = [0.0] * 4
        self.pressure = [0.0] * 4
        self.driver = 0.0
        self.ax = 0.0
        angle = math.atan(spec.grade)
        self.gravity_along, self.gravity_normal = GRAVITY_MPS2 * math.sin(angle), GRAVITY_MPS2 * math.cos(angle)
        self.ax_lagged = 0.0
        self.commands = [WheelCommand(0.0, 1500.0)] * 4
        self.brake_on_s = spec.pre_roll_s
        self.end_s: float | None = None
        self.stopped = False
        self.rows: list[tuple] = []

    # -- road ---------------------------------------------------------------------------------
    def surface_of(self, wheel: int) -> int:
        spec = self.spec
        if len(spec.surfaces) == 1:
            return 0
        if spec.manoeuvre == "split":
            return 0 if wheel in (0, 2) else 1
        # a jump: the front axle crosses first, the rear one wheelbase later
        pos = self.x - (self.car.wheelbase_m if wheel >= 2 else 0.0)
        return 1 if spec.jump_at_m is not None and pos >= spec.jump_at_m else 0

    # -- driver ---------------------------------------------------------------------------------
    def pedal_target(self, t: float) -> float:
        spec = self.spec
        since = t - self.brake_on_s
        if since < 0.0 or since > spec.max_brake_s:
            return 0.0      # before the stop, or the driver gives up (the car still rolls)
        if spec.release_at_s is not None and spec.release_at_s <= since < spec.release_at_s + spec.release_for_s:
            return 0.0
        return spec.demand_bar

    def step_driver(self, t: float) -> None:
        target = self.pedal_target(t)
        up, down = self.spec.pedal_rate_bps * self.dt, PEDAL_RELEASE_BPS * self.dt
        self.driver = min(self.driver + up, target) if target > self.driver else max(self.driver - down, target)

    # -- hydraulics -----------------------------------------------------------------------------
    def step_hydraulics(self, k: int, t: float, ground: list[float], slip: list[float], mu_peak_slip: list[float]) -> None:
        if k % self.abs_every == 0:
            self.commands = self.abs.update(t, self.v, self.omega, slip, self.pressure, self.driver,
                                            self.car.wheel_radius_m, mu_peak_slip)
        for i, cmd in enumerate(self.commands):
            p = self.pressure[i]
            step = cmd.rate_bps * self.dt
            self.pressure[i] = max(cmd.target_bar, p - step) if cmd.target_bar < p else min(cmd.target_bar, p + step)

    # -- wheels and body --------------------------------------------------------------------------
    def ground_speeds(self) -> tuple[list[float], float, float]:
        """Each wheel's ground speed, a_y and yaw rate (a left turn: right wheels run outside)."""
        radius = self.spec.turn_radius_m
        if radius <= 0.0:
            return [self.v] * 4, 0.0, 0.0
        yaw = self.v / radius
        half = 0.5 * self.car.track_m
        return [self.v - yaw * half, self.v + yaw * half] * 2, self.v * yaw, yaw

    def lateral_use(self, ground: list[float], ay: float, surfaces: list[int]) -> list[float]:
        """Each tyre's lateral force over its lateral grip. The tyres carry m·a_y in proportion
        to their loads, so each carries a_y/g of its load, against a lateral grip of
        `lateral_capacity` × its longitudinal peak at its speed."""
        if ay == 0.0:
            return [0.0] * 4
        need = abs(ay) / GRAVITY_MPS2
        grip = [self.spec.lateral_capacity * self.peaks[s][0] * self.speed_factor[s](g)
                for g, s in zip(ground, surfaces)]
        return [min(need / max(c, 1e-6), MAX_LATERAL_USE) for c in grip]

    def step_wheels(self, ground: list[float], fz: list[float], surfaces: list[int],
                    lateral_use: list[float]) -> list[float]:
        """Linearly implicit Euler per wheel; returns ω̇. Updates ω and the tyre forces.

        Combined slip by the friction ellipse: a tyre using the share u of its lateral grip has
        √(1 − u²) of its longitudinal curve left, at every slip."""
        car, dt = self.car, self.dt
        j = car.wheel_inertia_kgm2
        gains = car.gains()
        relax = self.spec.relaxation_m
        omega_dot = [0.0] * 4
        for i in range(4):
            r = self.radii[i]
            g, w = ground[i], self.omega[i]
            den = max(g, r * w, V_EPS_MPS)
            lam = (g - r * w) / den
            mu, dmu = self.models[surfaces[i]](lam, g)
            left = math.sqrt(1.0 - lateral_use[i] ** 2)
            mu, dmu = mu * left, dmu * left
            f_ss = mu * fz[i]
            k = fz[i] * dmu * (-r / den)                  # dF/dω
            # σ/v grows without bound towards standstill; real tyres stop relaxing there (the
            # patch sticks), and a lag of seconds would make the wheel an undamped oscillator.
            a = dt * max(g, RELAXATION_MIN_SPEED_MPS) / relax if relax > 0.0 else math.inf
            if math.isinf(a):
                f_eff, k_eff = f_ss, k
            else:
                f_eff, k_eff = (self.force[i] + a * f_ss) / (1.0 + a), a * k / (1.0 + a)
            torque = gains[i] * max(0.0, self.pressure[i] - car.pushout_bar)
            # Past the peak the slope destabilises: it stays explicit there (k_eff > 0 dropped).
            denom = 1.0 - dt * r * min(k_eff, 0.0) / j
            dw = dt * (-torque + r * f_eff) / j / denom
            w_new = w + dw
            if w_new < 0.0:          # a locked wheel: the brake holds it, it does not turn back
                w_new = 0.0
            dw = w_new - w
            force = f_eff + k_eff * dw
            if relax > 0.0:
                # The lag is the carcass's; the patch still slides at the road's limit (a wheel
                # that runs onto ice loses its force at once, not over σ of travel).
                limit = self.peaks[surfaces[i]][0] * self.speed_factor[surfaces[i]](g) * fz[i] * left
                force = min(max(force, -limit), limit)
            self.force[i] = force
            self.omega[i] = w_new
            omega_dot[i] = dw / dt
        return omega_dot

    def step_body(self, t: float) -> None:
        car, dt = self.car, self.dt
        # (the car's speed through the air; a car at rest is held by its brakes and tyres, not
        # blown along by a tail wind)
        air = self.v + self.spec.wind_mps if self.v > 0.0 else 0.0
        drag = car.drag_area_coefficient * air * abs(air)
        driven = self.spec.driven_until_s
        if driven is not None and t < driven:
            # Driven at a steady speed: the engine's force holds off the drag (put on the body:
            # the driven wheels' traction slip, a few tenths of a %, is left out).
            drag = 0.0
        # `ax` is what an accelerometer reads, the contact and air forces over the mass; on a
        # grade the car's speed changes by that less gravity's share along the road.
        self.ax = -(sum(self.force) + drag) / car.true_mass_kg
        accel = self.ax - self.gravity_along
        if self.v <= 0.0 and self.driver > 1.0:
            # At rest on its brakes: the tyres' static grip holds the car against gravity's share
            # (the draw keeps the grade within what the road's grip holds), and that is what the
            # accelerometer reads.
            self.ax, accel = self.gravity_along, 0.0
        self.v = max(self.v + accel * dt, 0.0)
        self.x += self.v * dt
        self.ax_lagged += (self.ax - self.ax_lagged) * dt / max(car.pitch_lag_s, dt)

    # -- the run ----------------------------------------------------------------------------------
    def run(self) -> Trace:
        spec, dt = self.spec, self.dt
        n_max = int((spec.pre_roll_s + spec.max_brake_s + AFTER_RELEASE_S + 0.5) / dt)
        for k in range(n_max):
            t = k * dt
            ground, ay, yaw = self.ground_speeds()
            surfaces = [self.surface_of(i) for i in range(4)]
            slip = [_slip(g, r * w) for g, w, r in zip(ground, self.omega, self.radii)]
            self.step_driver(t)
            self.step_hydraulics(k, t, ground, slip, [self.peaks[s][1] for s in surfaces])
            fz = normal_loads(self.car, self.ax_lagged, ay, self.gravity_normal)
            lateral = self.lateral_use(ground, ay, surfaces)
            omega_dot = self.step_wheels(ground, fz, surfaces, lateral)
            braking = 1.0 if self.driver > 1.0 and self.v > BRAKING_MIN_SPEED_MPS else 0.0
            self.rows.append((t, self.v, self.x, self.ax, ay, yaw, self.driver, braking, *self.omega, *omega_dot,
                              *self.pressure, *self.force, *fz, *slip, *ground, *surfaces,
                              *(1.0 if c.active else 0.0 for c in self.commands), *lateral))
            self.step_body(t)
            self._check_end(t)
            if self.end_s is not None and t >= self.end_s:
                break
        return self._trace()

    def _check_end(self, t: float) -> None:
        if not self.stopped and self.v <= STANDSTILL_MPS and t > self.brake_on_s:
            # At rest: the wheels stop with the car (the regularised tyre would creep otherwise).
            self.stopped = True
            self.v, self.omega, self.force = 0.0, [0.0] * 4, [0.0] * 4
            self.end_s = t + AFTER_STOP_S
        elif self.end_s is None and t - self.brake_on_s > self.spec.max_brake_s:
            self.end_s = t + AFTER_RELEASE_S

    def _trace(self) -> Trace:
        a = np.array(self.rows, dtype=float)
        col = iter(range(a.shape[1]))
        one = {name: a[:, next(col)] for name in ("t", "v", "x", "ax", "ay", "yaw", "master", "braking")}
        quad = {name: a[:, [next(col) for _ in range(4)]]
                for name in ("omega", "omega_dot", "pressure", "fx", "fz", "slip", "ground", "surface", "abs_active",
                             "lateral_use")}
        surface = quad.pop("surface").astype(int)
        mu_max = np.zeros_like(quad["ground"])
        slip_at = np.zeros_like(quad["ground"])
        for s, curve in enumerate(self.spec.surfaces):
            on = surface == s
            mu_max[on] = curve.peak[0] * curve.speed_factor(quad["ground"][on])
            slip_at[on] = curve.peak[1]
        return Trace(mu_max=mu_max, slip_at_mu_max=slip_at, **one, **quad)


def _slip(ground: float, rw: float) -> float:
    """model.md's slip, 0 when neither the road nor the wheel moves."""
    top = max(ground, rw)
    return (ground - rw) / top if top > 0.1 else 0.0


def truth_rows(trace: Trace) -> list[dict[str, float]]:
    """Every 10th step as a truth row; `mu_max` is the mean of the four wheels' peaks (the
    road's peak on a uniform road, the mean of both sides on split-μ; the road's grip, of which
    a turn leaves less to braking), as frictiond's own
    simulator writes it and `frictiond.evaluation` reads it."""
    sel = slice(0, len(trace.t), TRUTH_EVERY)
    fz = trace.fz[sel]
    mu = trace.fx[sel] / np.maximum(fz, 1.0)
    mu_max = trace.mu_max[sel]
    cols: dict[str, np.ndarray] = {
        "time_s": trace.t[sel], "speed_mps": trace.v[sel],
        "mu_max": mu_max.mean(axis=1), "slip_at_mu_max": trace.slip_at_mu_max[sel].mean(axis=1),
        "braking": trace.braking[sel], "accel_long": trace.ax[sel], "accel_lat": trace.ay[sel],
        "yaw_rate": trace.yaw[sel], "brake_pressure_master": trace.master[sel],
    }
    per_wheel = {"slip": trace.slip[sel], "mu": mu, "mu_max": mu_max, "slip_at_mu_max": trace.slip_at_mu_max[sel],
                 "fx": trace.fx[sel], "fn": fz, "omega_dot": trace.omega_dot[sel], "wheel_speed": trace.omega[sel],
                 "ground_speed": trace.ground[sel], "brake_pressure": trace.pressure[sel],
                 "abs": trace.abs_active[sel],
                 # (of the friction ellipse: the longitudinal share and the lateral share together)
                 "utilisation": np.hypot(np.abs(mu) / np.maximum(mu_max, 1e-3), trace.lateral_use[sel])}
    for name, values in per_wheel.items():
        for i, w in enumerate(WHEELS):
            cols[f"{name}_{w}"] = values[:, i]
    names = list(cols)
    return [dict(zip(names, row)) for row in zip(*(cols[n].tolist() for n in names))]


def encode_frames(spec: StopSpec, trace: Trace, dbc_path: Path) -> list[Frame]:
    """The stop's input frames through its DBC and signal map (the codec frictiond decodes with)."""
    config = parse_config(config_data(spec, dbc_path), None)
    codec = InputCodec(load_databases([dbc_path]), config.signals, config.vehicle.wheel_radius)
    ids = {m.name: (m.frame_id, m.is_extended) for m in codec.input_messages()}
    rng = np.random.default_rng([spec.seed, 7])
    frames = []
    for ev in sensor_events(spec.sensors, trace, config.vehicle.wheel_radius, rng):
        payloads = codec.encode_input(ev.message, ev.values)
        frame_id, extended = ids[ev.message]
        frames.append(Frame(ev.time_s, frame_id, payloads[0], extended))
    return frames


def simulate_stop(spec: StopSpec, *, keep_trace: bool = False, dbc_dir: Path | None = None) -> CampaignStop:
    """Integrate the stop and encode it; deterministic in `spec` (hence in its seed)."""
    trace = _Integrator(spec).run()
    dbc_path = dbc_file(spec, dbc_dir)
    frames = encode_frames(spec, trace, dbc_path)
    return CampaignStop(spec, frames, truth_rows(trace), dbc_path, trace if keep_trace else None)
