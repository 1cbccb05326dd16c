"""The simulator's manoeuvres: straight-line and curved ABS stops on several surfaces.

A `Scenario` is plain data; `vehicle_sim.simulate` turns it into a trajectory. Every scenario starts
with at least one second of free rolling (so the front end's filters and speed observer warm up)
before the driver applies the brake.

Surfaces are given per wheel in the order FL, FR, RL, RR. With `surface_change_s` set, the front
axle reaches `surfaces_after` at that time and the rear axle one wheelbase later (the road changes at
a place, not at an instant).

The true brake gains differ from the nominal `VehicleParams.brake_gain_*` by `brake_gain_factor`
(front, rear): pad friction moves with temperature and wear, and the estimator must cope with it.
"""
from __future__ import annotations

from dataclasses import dataclass

from .tyres import FAMILIES, SURFACES

Surfaces = tuple[str, str, str, str]
MAX_GRADE = 0.3          # rise over run, either way (a very steep street is 0.2)


def _all(surface: str) -> Surfaces:
    return (surface, surface, surface, surface)


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str                      # one line
    surfaces: Surfaces                    # per wheel FL, FR, RL, RR
    truth_model: str                      # default truth tyre family (see tyres.FAMILIES)
    initial_speed_mps: float = 25.0
    duration_s: float = 8.0               # hard end; the run also ends below stop_speed_mps
    stop_speed_mps: float = 2.0
    brake_start_s: float = 1.2            # free rolling before (plus up to 0.2 s seeded offset)
    brake_release_s: float | None = None  # None: brake until the end
    brake_pressure_bar: float = 120.0     # driver's master-cylinder demand (panic stop)
    target_decel_mps2: float | None = None  # if set, the demand is sized for this deceleration instead
    pedal_rate_bar_per_s: float = 700.0
    abs_enabled: bool = True
    surfaces_after: Surfaces | None = None
    surface_change_s: float | None = None  # front axle crosses the change at this time
    curve_radius_m: float | None = None    # constant-radius left turn (positive yaw rate)
    brake_gain_factor: tuple[float, float] = (1.08, 0.94)  # true / nominal gain, front and rear
    road_roughness: float = 0.0            # relative std of the wheels' normal-load fluctuation
    abs_rough_road: bool = False           # the ABS's rough-road mode (slower to call a peak)
    noise_scale: float = 1.0               # multiplies every sensor noise
    drop_rate: float = 0.005               # probability that a frame is lost
    reference_speed: bool = False          # whether a ground-speed sensor is fitted
    load_factor: float = 1.0               # true mass / configured mass (passengers, luggage)
    grade: float = 0.0                     # the road's rise over its run along the travel, uphill positive

    def __post_init__(self) -> None:
        if self.truth_model not in FAMILIES:
            raise ValueError(f"scenario {self.name}: unknown truth model {self.truth_model!r}")
        for s in self.surfaces + (self.surfaces_after or ()):
            if s not in SURFACES:
                raise ValueError(f"scenario {self.name}: unknown surface {s!r}")
        if (self.surfaces_after is None) != (self.surface_change_s is None):
            raise ValueError(f"scenario {self.name}: surfaces_after and surface_change_s go together")
        if not 0.5 <= self.load_factor <= 2.0:
            raise ValueError(f"scenario {self.name}: load_factor must lie within [0.5, 2]")
        if not abs(self.grade) <= MAX_GRADE:
            raise ValueError(f"scenario {self.name}: grade must lie within ±{MAX_GRADE:g}, not {self.grade!r}")
        if self.brake_start_s < 1.0:
            raise ValueError(f"scenario {self.name}: at least 1 s of free rolling before braking")


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario("dry", "ABS stop on dry asphalt from 27 m/s (Magic Formula truth)",
                 _all("dry"), "magic-formula", initial_speed_mps=27.0),
        Scenario("wet", "ABS stop on wet asphalt from 25 m/s (Burckhardt truth)",
                 _all("wet"), "burckhardt", initial_speed_mps=25.0, brake_gain_factor=(0.93, 1.05)),
        Scenario("snow", "ABS stop on packed snow from 22 m/s (dynamic LuGre truth)",
                 _all("snow"), "lugre", initial_speed_mps=22.0, brake_gain_factor=(1.10, 0.95)),
        Scenario("ice", "ABS braking on ice from 20 m/s, 8 s (Burckhardt truth)",
                 _all("ice"), "burckhardt", initial_speed_mps=20.0, brake_gain_factor=(1.05, 0.92)),
        Scenario("cobblestone_wet", "ABS stop on wet cobblestones from 22 m/s, rough road (Magic Formula truth)",
                 _all("cobblestone_wet"), "magic-formula", initial_speed_mps=22.0, road_roughness=0.04,
                 abs_rough_road=True, brake_gain_factor=(0.95, 1.04)),
        Scenario("dry_to_wet", "ABS stop from 28 m/s, dry asphalt turning wet mid-stop at 2.4 s (dynamic LuGre truth)",
                 _all("dry"), "lugre", initial_speed_mps=28.0, surfaces_after=_all("wet"),
                 surface_change_s=2.4),
        Scenario("split_mu", "ABS stop from 25 m/s, left wheels on wet asphalt, right wheels on snow (Burckhardt truth)",
                 ("wet", "snow", "wet", "snow"), "burckhardt", initial_speed_mps=25.0,
                 brake_gain_factor=(1.06, 0.96)),
        Scenario("moderate", "Moderate braking at ~3 m/s^2 on dry asphalt, far from the peak, ABS idle (LuGre truth)",
                 _all("dry"), "lugre", initial_speed_mps=25.0, target_decel_mps2=3.0, brake_release_s=6.0,
                 duration_s=7.5, pedal_rate_bar_per_s=60.0),
        Scenario("moderate_wet", "Firm braking at ~3.5 m/s^2 on wet asphalt (~65 % of the grip, ABS idle), released at 6 s (LuGre truth)",
                 _all("wet"), "lugre", initial_speed_mps=25.0, target_decel_mps2=3.5, brake_release_s=6.0,
                 duration_s=7.5, pedal_rate_bar_per_s=60.0),
        Scenario("cornering", "ABS stop in a 115 m radius left turn from 20 m/s (~3.5 m/s^2 lateral) on dry (Magic Formula truth)",
                 _all("dry"), "magic-formula", initial_speed_mps=20.0, curve_radius_m=115.0,
                 brake_gain_factor=(1.04, 0.97)),
        Scenario("ice_fast", "ABS braking on ice from 35 m/s, 8 s: μ_max ~0.026 (Burckhardt truth)",
                 _all("ice"), "burckhardt", initial_speed_mps=35.0, brake_gain_factor=(1.03, 0.95)),
        Scenario("loaded", "ABS stop on wet asphalt from 25 m/s in a car 25 % heavier than configured (Magic Formula truth)",
                 _all("wet"), "magic-formula", initial_speed_mps=25.0, load_factor=1.25,
                 brake_gain_factor=(1.05, 0.97)),
        Scenario("noisy", "ABS stop on wet asphalt from 25 m/s with heavy sensor noise and 3 % lost frames (LuGre truth)",
                 _all("wet"), "lugre", initial_speed_mps=25.0, noise_scale=4.0, drop_rate=0.03),
    )
}
