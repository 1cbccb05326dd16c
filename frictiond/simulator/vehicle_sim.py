"""Four-wheel braking dynamics with brake hydraulics and a rule-based ABS (truth side, no CAN).

Integrated at 1 kHz:

- body: `M dv/dt = −Σ F_x,i − B_v v − D_a v² − M g sin θ` along the path, θ the road's grade
  (`Scenario.grade`, uphill positive), while the accelerometer (`Trace.ax`) reads the contact and
  air forces over the mass, not gravity; the loads carry `g cos θ`. In a constant-radius (left) turn the
  yaw rate is `v/R_c`, the lateral acceleration `v²/R_c`, and wheel i's ground speed is
  `v ∓ ψ̇ d/2` (inner = left wheels slower);
- loads: model.md's load transfer with forward-positive `a_x`, but driven by `a_x` through a
  first-order pitch lag (50 ms), plus optional road roughness (load fluctuation per wheel);
- combined slip: in a turn each tyre carries a_y/g of its load sideways, and what is left of its
  curve to braking follows a super-ellipse, `(1 − u^2.5)^(1/2.5)` with u = a_y/(g μ_max) (a
  squarer envelope than the estimator's friction circle);
- wheels: `J dω/dt = −T_b + R F_x + T_e` (here `T_e = 0`), solved semi-implicitly in ω because the
  tyre is stiff (for the dynamic LuGre truth the step is exact for the linear-in-slip update of the
  bristle state, so the recorded force is exactly the one the wheel felt);
- hydraulics (`brakes`): each wheel's pressure follows its valve command with a first-order lag
  (40 ms apply, 20 ms dump) and rate limits; `T_b = k_b,true · max(0, p − p_0)` with true gains
  that differ from the nominal ones by the scenario's factors (and ±1.5 % per wheel);
- ABS (`brakes`), one channel per wheel, run every 5 ms on the ECU's view (slip from the ground speed, wheel
  acceleration and brake force over the last cycle), see `AbsController`: it dumps when the slip
  still grows but the force no longer does (the peak has been passed), holds while the wheel
  re-accelerates, then re-applies from a fraction of the pressure that gave the most force and
  ramps slowly (at a rate proportional to it, so the cycle scales from dry asphalt to ice). The
  slip then cycles around the peak, roughly between 0.4 λ* and 1.5 λ*, with a deeper first cycle.
- driver (`brakes`): no pedal for the first second or more (free rolling), then a ramp to the scenario's
  master-cylinder demand, optionally released later.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..vehicle import GRAVITY_MPS2, VehicleParams
from .brakes import ROUGH_ROAD_ABS, AbsController, AbsParams, BrakeSystem  # noqa: F401 (AbsController re-exported)
from .scenarios import Scenario
from .timestep import DT_S
from .tyres import LugreDynamic, make_tyre, stack

PITCH_TIME_CONSTANT_S = 0.05
ROUGHNESS_CORRELATION_S = 0.04


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


class _Surfaces:
    """The road under each wheel (`idx`, indices into `names`) and the truth tyre model on it
    (`tyre`: one stacked model per distinct per-wheel surface tuple, made when first needed)."""

    def __init__(self, scn: Scenario, family: str, wheelbase: float) -> None:
        self.names = names = tuple(dict.fromkeys(scn.surfaces + (scn.surfaces_after or ())))
        self.before = np.array([names.index(s) for s in scn.surfaces])
        self.after = np.array([names.index(s) for s in scn.surfaces_after]) if scn.surfaces_after else self.before
        self._singles = {s: make_tyre(family, s) for s in names}
        self._stacks: dict[tuple[int, ...], object] = {}
        self._change_s = scn.surface_change_s
        self._wheelbase = wheelbase
        self._x_change: float | None = None   # the distance travelled when the front axle reached the new road
        self.idx = self.before.copy()
        self.tyre = self.tyre_for(self.idx)

    def follow(self, t: float, x_travel: float) -> None:
        """The surface change: front axle at `surface_change_s`, rear axle one wheelbase further on."""
        if self._change_s is None:
            return
        if self._x_change is None and t >= self._change_s:
            self._x_change = x_travel
        if self._x_change is not None:
            new = self.after_change(x_travel - self._x_change)
            if not np.array_equal(new, self.idx):
                self.idx = new
                self.tyre = self.tyre_for(new)

    def tyre_for(self, idx: np.ndarray):
        key = tuple(int(i) for i in idx)
        if key not in self._stacks:
            self._stacks[key] = stack([self._singles[self.names[i]] for i in key])
        return self._stacks[key]

    def after_change(self, travelled_since_m: float) -> np.ndarray:
        """The surfaces once the front axle has reached the new road, `travelled_since_m` ago:
        the rear axle reaches it one wheelbase further on."""
        return np.where(_AXLE_FRONT > 0, self.after,
                        np.where(travelled_since_m >= self._wheelbase, self.after, self.before))


class _TraceRecorder:
    """The trace's arrays, allocated for the longest run and filled one step at a time."""

    def __init__(self, n_max: int) -> None:
        self.t = np.empty(n_max); self.v = np.empty(n_max); self.ax = np.empty(n_max)
        self.ay = np.empty(n_max); self.yaw = np.empty(n_max)
        self.ground = np.empty((n_max, 4)); self.omega = np.empty((n_max, 4)); self.omega_dot = np.empty((n_max, 4))
        self.pressure = np.empty((n_max, 4)); self.fx = np.empty((n_max, 4)); self.fn = np.empty((n_max, 4))
        self.pedal = np.empty(n_max); self.abs_active = np.zeros((n_max, 4), bool)
        self.surface = np.empty((n_max, 4), dtype=np.int8)

    def record(self, k: int, t: float, v: float, ax: float, ay: float, yaw: float, ground: np.ndarray,
               omega: np.ndarray, omega_dot: np.ndarray, pressure: np.ndarray, fx: np.ndarray, fn: np.ndarray,
               pedal: float, abs_active: np.ndarray, surface: np.ndarray) -> None:
        self.t[k] = t; self.v[k] = v; self.ax[k] = ax; self.ay[k] = ay; self.yaw[k] = yaw
        self.ground[k] = ground; self.omega[k] = omega; self.omega_dot[k] = omega_dot
        self.pressure[k] = pressure; self.fx[k] = fx; self.fn[k] = fn; self.pedal[k] = pedal
        self.abs_active[k] = abs_active; self.surface[k] = surface

    def trace(self, n: int, surface_names: tuple[str, ...], brake_gains: np.ndarray, radius: float) -> Trace:
        """The first `n` steps."""
        return Trace(self.t[:n], self.v[:n], self.ax[:n], self.ay[:n], self.yaw[:n], self.ground[:n],
                     self.omega[:n], self.omega_dot[:n], self.pressure[:n], self.fx[:n], self.fn[:n],
                     self.pedal[:n], self.abs_active[:n], self.surface[:n].astype(int), surface_names,
                     brake_gains, radius)


_SIDE = np.array([-1.0, 1.0, -1.0, 1.0])  # left wheels inner in a left turn
_AXLE_FRONT = np.array([1.0, 1.0, 0.0, 0.0])


class _NormalLoads:
    """Each wheel's load: load transfer through the pitch lag, lateral transfer, road roughness."""

    def __init__(self, veh: VehicleParams) -> None:
        self._veh = veh
        self._wheelbase = veh.wheelbase
        self._track = np.array([veh.track_front, veh.track_front, veh.track_rear, veh.track_rear])

    def __call__(self, a_lag: float, ay: float, roughness: np.ndarray, g: float = GRAVITY_MPS2) -> np.ndarray:
        veh = self._veh
        M = veh.mass
        l = self._wheelbase
        h = veh.cg_height
        front_axle = M * (g * veh.cg_to_rear_axle - h * a_lag) / l
        rear_axle = M * (g * veh.cg_to_front_axle + h * a_lag) / l
        axle = np.array([front_axle, front_axle, rear_axle, rear_axle])
        return axle * (0.5 + _SIDE * h * ay / (self._track * g)) * (1.0 + roughness)


COMBINED_SLIP_EXPONENT = 2.5
MAX_LATERAL_USE = 0.95   # (the path is prescribed: a turn asking more of a tyre holds it here)


def _longitudinal_share(tyre, ground: np.ndarray, ay: float) -> np.ndarray:
    """What a turn leaves of each tyre's longitudinal curve (1 straight ahead)."""
    use = np.minimum(abs(ay) / (GRAVITY_MPS2 * np.maximum(tyre.mu_max(ground), 1e-6)), MAX_LATERAL_USE)
    n = COMBINED_SLIP_EXPONENT
    return (1.0 - use**n) ** (1.0 / n)


def _turn(v: float, curve_radius_m: float | None) -> tuple[float, float]:
    """Yaw rate and lateral acceleration in a constant-radius (left) turn; none on a straight."""
    if curve_radius_m:
        yaw = v / curve_radius_m
        return yaw, v * yaw
    return 0.0, 0.0


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
    half_track = np.array([veh.track_front, veh.track_front, veh.track_rear, veh.track_rear]) / 2.0
    surfaces = _Surfaces(scn, family, veh.wheelbase)
    curve = scn.curve_radius_m
    v = float(scn.initial_speed_mps)
    yaw, _ = _turn(v, curve)
    ground = v + _SIDE * yaw * half_track
    omega = ground / R
    brakes = BrakeSystem(scn, veh, rng, abs_params, omega)   # (its draws come before the roughness's)
    n_max = int(round(scn.duration_s / DT_S)) + 1
    rough = _roughness(rng, n_max, scn.road_roughness)
    recorder = _TraceRecorder(n_max)
    normal_loads = _NormalLoads(veh)

    a_lag = 0.0
    ax = 0.0
    slope = math.atan(scn.grade)
    gravity_along, gravity_normal = GRAVITY_MPS2 * math.sin(slope), GRAVITY_MPS2 * math.cos(slope)
    z = np.zeros(4)
    x_travel = 0.0
    dyn = isinstance(surfaces.tyre, LugreDynamic)
    n = 0
    for k in range(n_max):
        t = k * DT_S
        if v < scn.stop_speed_mps:
            break
        surfaces.follow(t, x_travel)
        yaw, ay = _turn(v, curve)
        ground = v + _SIDE * yaw * half_track
        pd, tb = brakes.step(k, t, omega, ground, ax)
        fn = normal_loads(a_lag, ay, rough[k], gravity_normal)
        # tyre + wheel, semi-implicit in omega; in a turn on the load a turn leaves to braking
        fn_braking = fn * _longitudinal_share(surfaces.tyre, ground, ay) if ay else fn
        if dyn:
            omega_new, fx, z = _wheels_on_dynamic_lugre(surfaces.tyre, ground, omega, z, fn_braking, tb, R, J)
        else:
            omega_new, fx = _wheels_on_static_curve(surfaces.tyre, ground, omega, fn_braking, tb, R, J)
        omega_dot = (omega_new - omega) / DT_S
        # body: `ax` is what an accelerometer reads (the contact and air forces over the mass); on a
        # grade the speed changes by gravity's share along the road too
        ax = (-float(np.sum(fx)) - veh.rolling_resistance * v - veh.drag_area_coefficient * v * v) / M
        # record the state at t with the forces acting over [t, t + dt]
        recorder.record(k, t, v, ax, ay, yaw, ground, omega, omega_dot, brakes.pressure, fx, fn, pd,
                        brakes.abs.active, surfaces.idx)
        n = k + 1
        # advance
        omega = omega_new
        x_travel += v * DT_S
        v = v + (ax - gravity_along) * DT_S
        a_lag += (ax - a_lag) * (DT_S / PITCH_TIME_CONSTANT_S)

    return recorder.trace(n, surfaces.names, brakes.gains, R)
