"""Random braking stops, each fully determined by its seed: `draw_stop(seed, family=None)`.

Development seeds are 0 … N−1, held-out seeds 1,000,000 … 1,000,000 + N − 1 (`seeds_for`):
tune on the first, report on both. Every draw below uses one `numpy.random.default_rng(seed)`
in a fixed order, so a seed is a stop; forcing a family (`family="a-threshold/burckhardt"`)
replaces those choices after the draw, leaving every other number as the seed drew it.

Ranges (uniform unless stated; "a–b" inclusive):

Vehicle (true car; the frictiond config describes it as configured)
- mass 900–2,800 kg (configured); payload 0–120 kg on top, not in the config
- wheelbase 2.3–3.2 m, CG at 38–55 % of it from the front axle; CG height 0.45–0.80 m; track 1.40–1.70 m
- wheel radius 0.28–0.40 m, wheel inertia 0.7–2.5 kg·m²
- configured front brake gain such that the front axle locks at μ = 1 with 70–130 bar;
  rear gain 0.30–0.60 × front; true gains 0.8–1.2 × configured, each axle independently
- push-out pressure 0–1 bar, ½ρC_dA 0.30–0.60 kg/m, pitch lag of the load transfer 30–120 ms

Tyres (never LuGre: the estimator's own model is not a truth)
- family "burckhardt" (½): one of the tabulated surfaces (dry/wet asphalt, cobblestone dry/wet,
  snow, ice) with c1 × 0.88–1.12, c2 × 0.8–1.2, c3 × 0.8–1.2
- family "magic-formula" (½): B 4–14, C 1.2–2.5, D 0.08–1.2, E −1…1; combinations whose curve
  is not a tyre (peak slip outside 0.02–0.5, or past the peak below 25 % of D) are redrawn
- speed dependence m(v) = 1 + k (v − 15 m/s)/15, k −0.25…+0.15 (either sign), m within 0.6–1.2
- relaxation (35 % of stops): first-order lag of the force, relaxation length 0.10–0.60 m

ABS (see abs_control.py): "a-threshold" 27 %, "b-decel" 27 %, "c-slip" 27 %, "d-none" 19 %;
controller cycle 5–10 ms, cut-out below 1.5–3 m/s
- a: slip_high 0.20–0.35, slip_low 0.05–0.12, slow dump (exponential, τ 40–100 ms), apply
  800–2,000 bar/s
- b: wheel decel beyond the car's by 6–14 m/s² with slip > 0.05–0.10 (the decel alone
  holds), slip guard 0.20–0.35, dump 1,500–3,000 bar/s,
  spin-up 1–4 m/s² (relative to the car),
  hold ≤ 50–150 ms, slow re-apply 100–400 bar/s
- c: target 0.70–0.95 × the true peak slip, capped at 0.09–0.12, log-pressure gain 60–150
- ABS stops: driver demand 1.3–2.0 × the pressure that locks the harder-to-lock axle on the
  grippiest surface (≤ 280 bar), pedal 300–1,500 bar/s
- d: moderate braking to standstill, on roads whose every peak is ≥ 0.15 (redrawn otherwise):
  the demand that uses 25–60 % of the lowest peak (at least 0.1 g when 60 % allows), and
  never more than the curve gives at 3.5 % slip; pedal 50–200 bar/s; the initial speed is
  lowered (not below 20 km/h) so that the stop takes ≤ 12 s at that deceleration

Manoeuvres: "straight" 35 %, "jump" 20 % (dry→wet, wet→dry or any→ice, at 10–40 % of the
stopping distance, front axle first), "split" 15 % (a high-μ side and a low-μ side), "cornering"
15 % (a_y 1.5–4 m/s² at the start, ≤ 0.35 μ g, on a constant radius), "release" 15 % (the driver
releases 0.8–2.0 s into the stop for 0.3–0.8 s and brakes again)
- combined slip in a turn: the lateral force the curve needs lowers each tyre's longitudinal curve
  by the friction ellipse, lateral grip 0.85–1.10 × the longitudinal (see simulate.py)
- wind along the road ± 0–5 m/s (a head wind positive): the air drag is ½ρC_dA·(v + w)|v + w|,
  while the car's config gives ½ρC_dA alone, as a user knows it
- the road's grade: flat for a third of the stops, else uphill or downhill 0–8 % (rise over run;
  at most half the lowest peak μ, so that the brakes can stop and hold the car).
  The accelerometer reads the contact and air forces, so on a grade it differs from the wheels'
  deceleration by gravity's share, and free rolling teaches the front end that share together
  with the sensor's offset
- initial speed 20–160 km/h; 0.8–1.2 s of free rolling first (`pre_roll_s` sets it: the front end
  learns the accelerometer's offset while rolling free); braking for at most 8 s (14 s
  without ABS; then the driver releases), 0.3 s recorded after standstill, 0.5 s after a release

Sensors (see sensors.py)
- wheel speeds at 50, 83 or 100 Hz, km/h with resolution 0.01, 0.015625, 0.02, 0.03125, 0.05 or
  0.0625, noise σ 0–0.1 km/h; accelerations and pressures at 50 or 100 Hz each
- reception jitter ± 0–2 ms, frame loss 0–2 % per message
- accelerometer offset ± 0–0.3 m/s² (lateral ± 0–0.2), noise σ 0.02–0.15 m/s²
- pressure sensor lag 0–40 ms, offset ± 0–1 bar, noise σ 0.1–0.6 bar
- 20 % of cars send only the master-cylinder pressure (no per-wheel pressures)
- 15 % have a ground-speed sensor; ABS flags: none 40 %, global 30 %, per wheel 30 %
- 30 % send the rear wheel speeds in a message of their own (big-endian, at the same rate with
  their own phase, jitter and losses), drawn last: the other draws are those of before
- 25 % have a DBC without cycle times (no GenMsgCycleTime), drawn after that
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .abs_control import ABS_FAMILIES
from .sensors import SensorSpec
from .tyres import BURCKHARDT_SURFACES, TyreCurve, magic_formula_plausible, slip_for_force, tmeasy_like
from .vehicle import GRAVITY_MPS2, CarSpec, lock_pressure_bar

HELD_OUT_BASE = 1_000_000
TYRE_FAMILIES = ("burckhardt", "magic-formula")
MANOEUVRES = ("straight", "jump", "split", "cornering", "release")
WHEEL_RATES_HZ = (50, 83, 100)
WHEEL_RESOLUTIONS_KMH = (0.01, 0.015625, 0.02, 0.03125, 0.05, 0.0625)
JUMPS = ("dry-wet", "wet-dry", "to-ice")
D_MIN_PEAK = 0.15
GRADED_SHARE = 2.0 / 3.0     # of the stops on a grade (the rest on the flat)
MAX_GRADE = 0.08             # rise over run, either way: a steep main road
MAX_GRADE_SET = 0.3          # ... and what a stress run may set (`Stress.grade`)
MAX_PAYLOAD_SET_KG = 2000.0  # what a stress run may put aboard (`Stress.payload_kg`)
MAX_ACCEL_OFFSET_SET = 2.0   # ... and the accelerometer's offset it may set (`Stress.accel_offset_mps2`)
STRESS_TYRE_MODELS = ("tmeasy",)   # the truth tyres a stress run may put in place of the draw's
TMEASY_STREAM = 0x7E           # (the TMeasy shapes' random stream, apart from the draw's six)
RADII_STREAM = 0x7F            # (the tyre radii's, `Stress.tyre_radii`)
RADIUS_SCALE_STREAM = 0x80     # (the common radius error's, `Stress.radius_scale`)
MAX_RADIUS_SCALE_SET = 0.05    # how far off a stress run may draw all four tyres' radius together
MAX_TYRE_RADII_SET = 0.08      # how far off a stress run may draw a tyre's radius (a space-saver spare)


@dataclass(frozen=True)
class StopSpec:
    """Everything that makes one stop. `surfaces[0]` is the road at the start (and the left
    side on split-μ); `surfaces[1]` the road after the jump (the right side on split-μ)."""

    seed: int
    abs_family: str
    tyre_family: str
    manoeuvre: str
    car: CarSpec
    surfaces: tuple[TyreCurve, ...]
    relaxation_m: float
    sensors: SensorSpec
    abs_params: dict[str, float] = field(hash=False)
    abs_cycle_s: float = 0.007
    abs_cutout_mps: float = 2.0
    speed0_mps: float = 20.0
    demand_bar: float = 100.0
    pedal_rate_bps: float = 800.0
    pre_roll_s: float = 1.0
    max_brake_s: float = 8.0
    jump_at_m: float | None = None
    jump_kind: str = ""
    turn_radius_m: float = 0.0          # 0: straight ahead; > 0 a left turn
    # The tyres' lateral grip over their longitudinal grip: the friction ellipse's other axis.
    lateral_capacity: float = 1.0
    wind_mps: float = 0.0               # along the road, a head wind positive (the air drag's speed is v + w)
    grade: float = 0.0                  # the road's rise over its run along the travel, uphill positive
    # Driven at a steady speed until then (s from the start; None: the car coasts from the start):
    # an engine's force on the body equal to the air's drag, no drive torque on the bus.
    driven_until_s: float | None = None
    release_at_s: float | None = None   # after the brake onset
    release_for_s: float = 0.0
    dt_s: float = 0.001

    @property
    def family(self) -> str:
        return f"{self.abs_family}/{self.tyre_family}/{self.manoeuvre}"

    @property
    def surface_labels(self) -> str:
        return "|".join(s.label for s in self.surfaces)


def seeds_for(which: str, n: int) -> list[int]:
    """The n seeds of the "dev" or "held-out" set."""
    if which == "dev":
        return list(range(n))
    if which == "held-out":
        return list(range(HELD_OUT_BASE, HELD_OUT_BASE + n))
    raise ValueError(f"unknown seed set {which!r} (dev or held-out)")


def _pick(rng: np.random.Generator, options: tuple[str, ...], weights: tuple[float, ...]) -> str:
    return options[int(rng.choice(len(options), p=np.asarray(weights) / sum(weights)))]


def _match(choice: str, options: tuple[str, ...], wanted: str | None) -> str:
    """`wanted` (a prefix of one option, "" or "*" for any) overrides the drawn `choice`."""
    if not wanted or wanted == "*":
        return choice
    hits = [o for o in options if o.startswith(wanted)]
    if len(hits) != 1:
        raise ValueError(f"family part {wanted!r} matches {hits or 'nothing'} of {', '.join(options)}")
    return hits[0]


# ------------------------------------------------------------------------------------ vehicle
def _draw_car(rng: np.random.Generator) -> CarSpec:
    mass = rng.uniform(900.0, 2800.0)
    wheelbase = rng.uniform(2.3, 3.2)
    front_share = rng.uniform(0.38, 0.55)          # CG distance from the front axle / wheelbase
    h = rng.uniform(0.45, 0.80)
    radius = rng.uniform(0.28, 0.40)
    lf, lr = front_share * wheelbase, (1.0 - front_share) * wheelbase
    # Brake gains "to match": the front axle locks at μ = 1 with 70–130 bar, whatever the car.
    front_wheel_load = 0.5 * mass * GRAVITY_MPS2 * (lr + h) / wheelbase
    kf = front_wheel_load * radius / rng.uniform(70.0, 130.0)
    kr = kf * rng.uniform(0.30, 0.60)
    return CarSpec(
        mass_kg=mass, cg_to_front_m=lf, cg_to_rear_m=lr, cg_height_m=h, track_m=rng.uniform(1.40, 1.70),
        wheel_radius_m=radius, wheel_inertia_kgm2=rng.uniform(0.7, 2.5),
        brake_gain_front=kf * rng.uniform(0.8, 1.2), brake_gain_rear=kr * rng.uniform(0.8, 1.2),
        config_brake_gain_front=kf, config_brake_gain_rear=kr,
        payload_kg=rng.uniform(0.0, 120.0), pushout_bar=rng.uniform(0.0, 1.0),
        drag_area_coefficient=rng.uniform(0.30, 0.60), pitch_lag_s=rng.uniform(0.03, 0.12),
    )


# -------------------------------------------------------------------------------------- tyres
_MF_CLASS_D = {"dry": (0.8, 1.2), "wet": (0.4, 0.8), "snow": (0.15, 0.4), "ice": (0.08, 0.15)}
_BURCKHARDT_CLASS = {"dry": ("dry_asphalt", "cobblestone_dry"), "wet": ("wet_asphalt", "cobblestone_wet"),
                     "snow": ("snow",), "ice": ("ice",)}


def _burckhardt(rng: np.random.Generator, surface: str, slope: float) -> TyreCurve:
    c1, c2, c3 = BURCKHARDT_SURFACES[surface]
    params = (c1 * rng.uniform(0.88, 1.12), c2 * rng.uniform(0.8, 1.2), c3 * rng.uniform(0.8, 1.2))
    return TyreCurve("burckhardt", params, slope, surface)


def _magic_formula(rng: np.random.Generator, d_range: tuple[float, float], slope: float) -> TyreCurve:
    for _ in range(200):
        params = (rng.uniform(4.0, 14.0), rng.uniform(1.2, 2.5), rng.uniform(*d_range), rng.uniform(-1.0, 1.0))
        if magic_formula_plausible(params):
            break
    else:   # pragma: no cover - the acceptance rate is ~40 %
        params = (10.0, 1.9, 0.5 * sum(d_range), 0.97)
    d = params[2]
    label = "mf-dry" if d >= 0.8 else "mf-wet" if d >= 0.4 else "mf-snow" if d >= 0.15 else "mf-ice"
    return TyreCurve("magic-formula", params, slope, label)


def _curve(rng: np.random.Generator, family: str, road_class: str | None, slope: float) -> TyreCurve:
    """A curve of `family` on a road class (dry/wet/snow/ice), or on any road (None)."""
    if family == "burckhardt":
        options = tuple(BURCKHARDT_SURFACES) if road_class is None else _BURCKHARDT_CLASS[road_class]
        return _burckhardt(rng, options[int(rng.integers(len(options)))], slope)
    return _magic_formula(rng, (0.08, 1.2) if road_class is None else _MF_CLASS_D[road_class], slope)


def _draw_surfaces(rng: np.random.Generator, family: str, manoeuvre: str) -> tuple[tuple[TyreCurve, ...], str]:
    slope = rng.uniform(-0.25, 0.15)
    if manoeuvre == "jump":
        kind = JUMPS[int(rng.integers(len(JUMPS)))]
        first, second = {"dry-wet": ("dry", "wet"), "wet-dry": ("wet", "dry"),
                         "to-ice": (("dry", "wet", "snow")[int(rng.integers(3))], "ice")}[kind]
        return (_curve(rng, family, first, slope), _curve(rng, family, second, slope)), kind
    if manoeuvre == "split":
        high = ("dry", "wet")[int(rng.integers(2))]
        low = ("snow", "ice") if high == "wet" else ("wet", "snow", "ice")
        pair = (_curve(rng, family, high, slope), _curve(rng, family, low[int(rng.integers(len(low)))], slope))
        return (pair if rng.random() < 0.5 else pair[::-1]), "split"
    return (_curve(rng, family, None, slope),), ""


# ------------------------------------------------------------------------------------ ABS, sensors
def _draw_abs_params(rng: np.random.Generator) -> dict[str, dict[str, float]]:
    """Parameters of every family (drawn always, in one order: forcing a family keeps the rest)."""
    u = rng.uniform
    return {
        "a-threshold": {"slip_high": u(0.20, 0.35), "slip_low": u(0.05, 0.12), "dump_tau_s": u(0.04, 0.10),
                        "apply_rate": u(800.0, 2000.0)},
        "b-decel": {"decel_dump": u(6.0, 14.0), "slip_min": u(0.05, 0.10), "slip_guard": u(0.20, 0.35), "dump_rate": u(1500.0, 3000.0),
                    "spin_up": u(1.0, 4.0), "hold_max_s": u(0.05, 0.15), "reapply_rate": u(100.0, 400.0),
                    "apply_rate": u(800.0, 2000.0)},
        "c-slip": {"target_frac": u(0.70, 0.95), "target_cap": u(0.09, 0.12), "gain": u(60.0, 150.0),
                   "valve_rate": u(1500.0, 3000.0), "apply_rate": u(800.0, 2000.0)},
        "d-none": {"apply_rate": u(200.0, 600.0)},
    }


def _draw_sensors(rng: np.random.Generator) -> SensorSpec:
    u = rng.uniform
    sign = [float(x) for x in rng.choice([-1.0, 1.0], size=3)]   # plain floats: the spec prints and dumps cleanly
    return SensorSpec(
        wheel_hz=int(rng.choice(WHEEL_RATES_HZ)), accel_hz=int(rng.choice((50, 100))),
        pressure_hz=int(rng.choice((50, 100))),
        wheel_resolution_kmh=float(rng.choice(WHEEL_RESOLUTIONS_KMH)), wheel_noise_kmh=u(0.0, 0.1),
        jitter_s=u(0.0, 0.002), drop_rate=u(0.0, 0.02),
        accel_offset_mps2=sign[0] * u(0.0, 0.3), accel_lat_offset_mps2=sign[1] * u(0.0, 0.2),
        accel_noise_mps2=u(0.02, 0.15),
        pressure_lag_s=u(0.0, 0.04), pressure_offset_bar=sign[2] * u(0.0, 1.0), pressure_noise_bar=u(0.1, 0.6),
        master_only=bool(rng.random() < 0.20), reference_speed=bool(rng.random() < 0.15),
        abs_flags=("none", "global", "wheel")[int(rng.choice(3, p=[0.4, 0.3, 0.3]))],
        wheel_messages="axles" if rng.random() < 0.3 else "one",
        cycle_times_in_dbc=bool(rng.random() >= 0.25),
    )


def clean(sensors: SensorSpec) -> SensorSpec:
    """The car's sensors without their imperfections: no noise, jitter, frame loss, offsets or
    pressure lag, the wheel speeds at the finest resolution. What the car sends (its rates, a
    master-cylinder pressure, a ground-speed sensor, ABS flags) stays. Another simulator's
    signals may be this clean: what the noise hides (a stop whose evidence never passes its
    gates) shows there."""
    return replace(sensors, wheel_resolution_kmh=min(WHEEL_RESOLUTIONS_KMH), wheel_noise_kmh=0.0, jitter_s=0.0,
                   drop_rate=0.0, accel_offset_mps2=0.0, accel_lat_offset_mps2=0.0, accel_noise_mps2=0.0,
                   pressure_lag_s=0.0, pressure_offset_bar=0.0, pressure_noise_bar=0.0)


# ------------------------------------------------------------------------------------ driver
def _peak_mu(curve: TyreCurve, speed_mps: float) -> float:
    return curve.peak[0] * float(curve.speed_factor(speed_mps))


def _abs_demand(rng: np.random.Generator, car: CarSpec, surfaces: tuple[TyreCurve, ...], v0: float) -> float:
    grip = max(max(_peak_mu(s, v) for v in (0.0, v0)) for s in surfaces)
    lock = max(lock_pressure_bar(car, grip, front=True), lock_pressure_bar(car, grip, front=False))
    return min(lock * rng.uniform(1.3, 2.0), 280.0)


def _moderate_demand(rng: np.random.Generator, car: CarSpec, surfaces: tuple[TyreCurve, ...],
                     v0: float) -> tuple[float, float]:
    """(pressure, μ used): 25–60 % of the lowest peak, and no more than 3.5 % slip gives."""
    use = rng.uniform(0.25, 0.60)
    # at least 0.1 g where 60 % of the peak allows it: firm enough for the pressures to matter
    mu_t = min(min(min(max(use * _peak_mu(s, v), min(0.1, 0.6 * _peak_mu(s, v))),
                       float(s.mu(0.035, v))) for v in (0.0, 0.5 * v0, v0)) for s in surfaces)
    m, g, h, l, r = car.true_mass_kg, GRAVITY_MPS2, car.cg_height_m, car.wheelbase_m, car.wheel_radius_m
    front_wheel = 0.5 * m * (g * car.cg_to_rear_m + h * mu_t * g) / l
    rear_wheel = 0.5 * m * (g * car.cg_to_front_m - h * mu_t * g) / l
    return car.pushout_bar + mu_t * r * min(front_wheel / car.brake_gain_front, rear_wheel / car.brake_gain_rear), mu_t


def _apply_family(choices: list[str], family: str | None) -> list[str]:
    if not family:
        return choices
    parts = (family.split("/") + ["", ""])[:3]
    options = (ABS_FAMILIES, TYRE_FAMILIES, MANOEUVRES)
    return [_match(c, o, w) for c, o, w in zip(choices, options, parts)]


@dataclass(frozen=True)
class Stress:
    """What a stress run sets on every stop in place of what the stop drew (None: as drawn):
    `clean_sensors`, its sensors' imperfections taken off (`clean`); `pre_roll_s`, the brake
    applied this soon after the start (`with_pre_roll`); `grade` (rise over run, uphill
    positive); `payload_kg`, the load aboard that the config does not know; `accel_offset_mps2`,
    the size of the accelerometer's offset (its drawn sign kept). The last two probe beyond the
    draw's ranges (0–120 kg, 0–0.3 m/s²): a loaded car, a sensor mounted tilted. `cruise_lift_s`:
    the car driven at a steady speed (no drive torque on the bus) until this long before the brakes,
    where the draw has it coast (`StopSpec.driven_until_s`). `tyre_model`: "tmeasy", every road's
    tyre replaced by a TMeasy curve of the same peak μ (`tyres.tmeasy_like`, its shape drawn from
    the seed), a shape the estimator was never developed on. `rear_select_low`: the ABS regulates
    the rear axle select-low (`abs_control`), one pressure for both rear wheels. `tyre_radii`: every
    wheel's true rolling radius off the configured one by a share drawn within ± this, each wheel
    its own (worn, soft or mixed tyres; drawn: none off). `radius_scale`: all four true radii off the
    configured one by one share drawn within ± this (a radius configured from the tyre's size, not
    as measured rolling; with `tyre_radii`, the two multiply). `averaged_wheel_speeds`: every wheel
    speed the mean over its frame period before the frame (`SensorSpec.wheel_average_s`), as an ECU
    counting a toothed ring's edges sends it, not the speed at the frame's instant."""

    clean_sensors: bool = False
    pre_roll_s: float | None = None
    grade: float | None = None
    payload_kg: float | None = None
    accel_offset_mps2: float | None = None
    cruise_lift_s: float | None = None
    tyre_model: str | None = None
    rear_select_low: bool = False
    tyre_radii: float | None = None
    radius_scale: float | None = None
    averaged_wheel_speeds: bool = False

    def __post_init__(self) -> None:
        if self.pre_roll_s is not None and not self.pre_roll_s >= 0.0:
            raise ValueError(f"pre_roll_s must be ≥ 0, not {self.pre_roll_s}")
        if self.grade is not None and not abs(self.grade) <= MAX_GRADE_SET:
            raise ValueError(f"grade must be within ±{MAX_GRADE_SET}, not {self.grade}")
        if self.payload_kg is not None and not 0.0 <= self.payload_kg <= MAX_PAYLOAD_SET_KG:
            raise ValueError(f"payload_kg must be within 0…{MAX_PAYLOAD_SET_KG:g}, not {self.payload_kg}")
        if self.accel_offset_mps2 is not None and not 0.0 <= self.accel_offset_mps2 <= MAX_ACCEL_OFFSET_SET:
            raise ValueError(f"accel_offset_mps2 must be within 0…{MAX_ACCEL_OFFSET_SET:g}, "
                             f"not {self.accel_offset_mps2}")
        if self.cruise_lift_s is not None and not self.cruise_lift_s >= 0.0:
            raise ValueError(f"cruise_lift_s must be ≥ 0, not {self.cruise_lift_s}")
        if self.tyre_radii is not None and not 0.0 <= self.tyre_radii <= MAX_TYRE_RADII_SET:
            raise ValueError(f"tyre_radii must be within 0…{MAX_TYRE_RADII_SET:g}, not {self.tyre_radii}")
        if self.radius_scale is not None and not 0.0 <= self.radius_scale <= MAX_RADIUS_SCALE_SET:
            raise ValueError(f"radius_scale must be within 0…{MAX_RADIUS_SCALE_SET:g}, not {self.radius_scale}")
        if self.tyre_model not in (None,) + STRESS_TYRE_MODELS:
            raise ValueError(f"tyre_model must be one of {', '.join(STRESS_TYRE_MODELS)}, not {self.tyre_model!r}")

    def apply(self, spec: StopSpec) -> StopSpec:
        """`spec` with these settings (`clean_sensors` is `draw_stop`'s, before the drive is drawn)."""
        if self.grade is not None:
            spec = replace(spec, grade=float(self.grade))
        if self.payload_kg is not None:
            spec = replace(spec, car=replace(spec.car, payload_kg=float(self.payload_kg)))
        if self.accel_offset_mps2 is not None:
            drawn = spec.sensors.accel_offset_mps2
            offset = math.copysign(float(self.accel_offset_mps2), drawn if drawn != 0.0 else 1.0)
            spec = replace(spec, sensors=replace(spec.sensors, accel_offset_mps2=offset))
        spec = spec if self.pre_roll_s is None else with_pre_roll(spec, self.pre_roll_s)
        if self.cruise_lift_s is not None:
            spec = replace(spec, driven_until_s=max(spec.pre_roll_s - float(self.cruise_lift_s), 0.0))
        if self.tyre_model == "tmeasy":
            shapes = np.random.default_rng([spec.seed, TMEASY_STREAM])
            spec = replace(spec, tyre_family="tmeasy", surfaces=tuple(tmeasy_like(c, shapes) for c in spec.surfaces))
        if self.rear_select_low:
            spec = replace(spec, abs_params={**spec.abs_params, "rear_select_low": 1.0})
        if self.tyre_radii is not None:
            off = np.random.default_rng([spec.seed, RADII_STREAM]).uniform(-self.tyre_radii, self.tyre_radii, 4)
            spec = replace(spec, car=replace(spec.car, radius_factors=tuple(float(1.0 + x) for x in off)))
        if self.radius_scale is not None:
            common = 1.0 + np.random.default_rng([spec.seed, RADIUS_SCALE_STREAM]).uniform(-self.radius_scale,
                                                                                             self.radius_scale)
            factors = tuple(float(f * common) for f in spec.car.radius_factors)
            spec = replace(spec, car=replace(spec.car, radius_factors=factors))
        if self.averaged_wheel_speeds:
            spec = replace(spec, sensors=replace(spec.sensors, wheel_average_s=1.0 / spec.sensors.wheel_hz))
        return spec

    def flags(self) -> str:
        """The options of `benchmarks/campaign.py` that set these (each with a leading space)."""
        return "".join([" --clean-sensors" if self.clean_sensors else "",
                        f" --pre-roll {self.pre_roll_s:g}" if self.pre_roll_s is not None else "",
                        f" --grade {self.grade:g}" if self.grade is not None else "",
                        f" --payload {self.payload_kg:g}" if self.payload_kg is not None else "",
                        f" --accel-offset {self.accel_offset_mps2:g}" if self.accel_offset_mps2 is not None else "",
                        f" --cruise-lift {self.cruise_lift_s:g}" if self.cruise_lift_s is not None else "",
                        f" --tyre-model {self.tyre_model}" if self.tyre_model is not None else "",
                        " --rear-select-low" if self.rear_select_low else "",
                        f" --tyre-radii {self.tyre_radii:g}" if self.tyre_radii is not None else "",
                        f" --radius-scale {self.radius_scale:g}" if self.radius_scale is not None else "",
                        " --averaged-wheel-speeds" if self.averaged_wheel_speeds else ""])

    def describe(self) -> str:
        """These settings for a report's title (", clean sensors, on a grade of 0.04", or "")."""
        return "".join([", clean sensors" if self.clean_sensors else "",
                        f", braked {self.pre_roll_s:g} s after the start" if self.pre_roll_s is not None else "",
                        f", on a grade of {self.grade:g}" if self.grade is not None else "",
                        f", {self.payload_kg:g} kg aboard" if self.payload_kg is not None else "",
                        f", accelerometer offset ±{self.accel_offset_mps2:g} m/s²"
                        if self.accel_offset_mps2 is not None else "",
                        f", driven until {self.cruise_lift_s:g} s before the brakes"
                        if self.cruise_lift_s is not None else "",
                        f", every tyre a {self.tyre_model} curve" if self.tyre_model is not None else "",
                        ", the rear axle's ABS select-low" if self.rear_select_low else "",
                        f", tyre radii within ±{self.tyre_radii:g} of the configured"
                        if self.tyre_radii is not None else "",
                        f", all four radii within ±{self.radius_scale:g} of the configured together"
                        if self.radius_scale is not None else "",
                        ", wheel speeds averaged over their frame period" if self.averaged_wheel_speeds else ""])


def draw_stop(seed: int, family: str | None = None, stress: Stress | None = None, **settings: Any) -> StopSpec:
    """The stop of `seed`. `family`: "ABS[/TYRE[/MANOEUVRE]]", each part a prefix of one of
    `ABS_FAMILIES`, `TYRE_FAMILIES`, `MANOEUVRES` or "*" (e.g. "c", "a/magic", "*/*/split").
    `stress` (or its fields as keywords, e.g. `grade=0.04`): what to set in place of the draw."""
    stress = replace(stress or Stress(), **settings)
    streams = [np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(6)]
    pick, car_rng, tyre_rng, abs_rng, sensor_rng, drive_rng = streams
    choices = [_pick(pick, ABS_FAMILIES, (27, 27, 27, 19)), _pick(pick, TYRE_FAMILIES, (1, 1)),
               _pick(pick, MANOEUVRES, (35, 20, 15, 15, 15))]
    abs_family, tyre_family, manoeuvre = _apply_family(choices, family)
    car = _draw_car(car_rng)
    surfaces, jump_kind = _draw_surfaces(tyre_rng, tyre_family, manoeuvre)
    while abs_family == "d-none" and min(s.peak[0] for s in surfaces) < D_MIN_PEAK:
        # A moderate stop on ice is a few bar on the pedal, below the pressure sensors' offset.
        surfaces, jump_kind = _draw_surfaces(tyre_rng, tyre_family, manoeuvre)
    relaxation = tyre_rng.uniform(0.10, 0.60) if tyre_rng.random() < 0.35 else 0.0
    abs_params = _draw_abs_params(abs_rng)[abs_family]
    abs_cycle, cutout = abs_rng.uniform(0.005, 0.010), abs_rng.uniform(1.5, 3.0)
    sensors = _draw_sensors(sensor_rng)
    if stress.clean_sensors:
        sensors = clean(sensors)
    spec = _draw_drive(drive_rng, StopSpec(
        seed=int(seed), abs_family=abs_family, tyre_family=tyre_family, manoeuvre=manoeuvre, car=car,
        surfaces=surfaces, relaxation_m=relaxation, sensors=sensors, abs_params=abs_params,
        abs_cycle_s=abs_cycle, abs_cutout_mps=cutout, jump_kind=jump_kind))
    return stress.apply(spec)


def with_pre_roll(spec: StopSpec, pre_roll_s: float) -> StopSpec:
    """The same stop with the brake applied `pre_roll_s` after the start instead of 0.8–1.2 s: the
    front end has had that little free rolling to learn the accelerometer's offset (another
    simulator, or a daemon started just before a stop, may give it none). A change of road stays
    where it was along the braking distance."""
    if not pre_roll_s >= 0.0:
        raise ValueError(f"pre_roll_s must be ≥ 0, not {pre_roll_s}")
    jump = None if spec.jump_at_m is None else spec.jump_at_m - spec.speed0_mps * (spec.pre_roll_s - pre_roll_s)
    return replace(spec, pre_roll_s=float(pre_roll_s), jump_at_m=jump)


def _draw_drive(rng: np.random.Generator, spec: StopSpec) -> StopSpec:
    """Speed, pedal and the manoeuvre's geometry (they depend on the car and the road)."""
    v0 = rng.uniform(20.0, 160.0) / 3.6
    pre_roll = rng.uniform(0.8, 1.2)
    abs_demand = _abs_demand(rng, spec.car, spec.surfaces, v0)
    moderate, mu_moderate = _moderate_demand(rng, spec.car, spec.surfaces, v0)
    pedal_panic, pedal_soft = rng.uniform(300.0, 1500.0), rng.uniform(50.0, 200.0)
    mu_first = _peak_mu(spec.surfaces[0], v0)
    mu_low = min(_peak_mu(s, v0) for s in spec.surfaces)
    stop_s = v0 / (0.9 * mu_first * GRAVITY_MPS2)
    jump_frac, a_y0 = rng.uniform(0.10, 0.40), rng.uniform(1.5, 4.0)
    release_frac, release_for = rng.uniform(0.25, 0.5), rng.uniform(0.3, 0.8)
    changes: dict[str, Any] = {"speed0_mps": v0, "pre_roll_s": pre_roll}
    if spec.abs_family == "d-none":
        v0 = max(20.0 / 3.6, min(v0, 12.0 * 0.8 * mu_moderate * GRAVITY_MPS2))
        changes.update(demand_bar=moderate, pedal_rate_bps=pedal_soft, max_brake_s=14.0, speed0_mps=v0)
    else:
        changes.update(demand_bar=abs_demand, pedal_rate_bps=pedal_panic)
    if spec.manoeuvre == "jump":
        braking_m = min(0.5 * v0 * stop_s, v0 * spec.max_brake_s * 0.6)
        changes["jump_at_m"] = v0 * pre_roll + jump_frac * braking_m
    elif spec.manoeuvre == "cornering":
        changes["turn_radius_m"] = v0 ** 2 / min(a_y0, 0.35 * mu_low * GRAVITY_MPS2)
    elif spec.manoeuvre == "release":
        changes.update(release_at_s=float(np.clip(release_frac * stop_s, 0.4, 2.0)), release_for_s=release_for)
    # (drawn last, and for every stop: the draws above stay what each seed drew before)
    changes["lateral_capacity"] = rng.uniform(0.85, 1.10)
    changes["wind_mps"] = rng.uniform(-5.0, 5.0)
    # (a road steeper than half its grip allows is one no car stops on: a stop must end)
    graded, grade = rng.random() < GRADED_SHARE, rng.uniform(-1.0, 1.0) * min(MAX_GRADE, 0.5 * mu_low)
    changes["grade"] = grade if graded else 0.0
    return replace(spec, **changes)
