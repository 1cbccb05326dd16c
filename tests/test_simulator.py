"""The braking simulator: physics sanity, ABS behaviour, sensor/bus timing, determinism, API."""
from __future__ import annotations

import csv
import time

import numpy as np
import pytest

from frictiond.simulator import (
    SCENARIOS,
    TRUTH_MODELS,
    MessageSchedule,
    SensorEvent,
    SimulationResult,
    Truth,
    simulate,
)
from frictiond.vehicle import GRAVITY_MPS2, VehicleParams

VEH = VehicleParams()
W = ("fl", "fr", "rl", "rr")
WHEEL_SPEEDS = tuple(f"wheel_speed_{w}" for w in W)
PRESSURES = tuple(f"brake_pressure_{w}" for w in W)
DRIVE = tuple(f"drive_torque_{w}" for w in W)
SCHEDULES = [
    MessageSchedule("WHEEL_SPEEDS", 0.01, WHEEL_SPEEDS),
    MessageSchedule("ACCELERATIONS", 0.01, ("accel_long", "accel_lat", "yaw_rate")),
    MessageSchedule("BRAKE_PRESSURES", 0.02, PRESSURES),
    MessageSchedule("VEHICLE_SPEED_REF", 0.01, ("vehicle_speed_ref",)),
    MessageSchedule("WHEEL_DRIVE_TORQUE", 0.05, DRIVE),
]
ABS_SCENARIOS = [n for n in SCENARIOS if not n.startswith("moderate")]
REQUIRED_TRUTH_KEYS = (
    ["time_s", "speed_mps", "mu_max", "slip_at_mu_max", "braking"]
    + [f"{k}_{w}" for k in ("slip", "mu", "mu_max", "fx", "fn", "omega_dot") for w in W]
)

_cache: dict[tuple, SimulationResult] = {}


def run(name: str, seed: int = 0, **kw) -> SimulationResult:
    key = (name, seed, tuple(sorted(kw.items())))
    if key not in _cache:
        _cache[key] = simulate(name, VEH, SCHEDULES, seed=seed, **kw)
    return _cache[key]


def wheels(truth: Truth, key: str) -> np.ndarray:
    return np.column_stack([truth[f"{key}_{w}"] for w in W])


def braking_rows(truth: Truth, settle_s: float = 0.3) -> np.ndarray:
    """Rows with the brake applied, from `settle_s` after the pedal went down."""
    b = truth["braking"] > 0.5
    t0 = truth.time_s[b][0]
    return b & (truth.time_s >= t0 + settle_s)


# ------------------------------------------------------------------ API and scenario set
def test_public_api_and_scenarios():
    assert set(TRUTH_MODELS) == {"burckhardt", "magic-formula", "lugre"}
    for name in ("dry", "wet", "snow", "ice", "ice_fast", "cobblestone_wet", "dry_to_wet", "split_mu",
                 "moderate", "moderate_wet", "cornering", "loaded", "noisy"):
        scn = SCENARIOS[name]
        assert scn.name == name
        assert scn.description and "\n" not in scn.description
        assert scn.truth_model in TRUTH_MODELS
        assert 12.0 <= scn.initial_speed_mps <= 40.0
        assert scn.duration_s <= 8.0
        assert scn.brake_start_s >= 1.0
    # the defaults mix the truth families
    assert len({s.truth_model for s in SCENARIOS.values()}) == 3


def test_result_structure():
    r = run("wet")
    assert isinstance(r, SimulationResult)
    assert r.scenario is SCENARIOS["wet"]
    assert all(isinstance(e, SensorEvent) for e in r.events)
    times = [e.time_s for e in r.events]
    assert times == sorted(times)
    assert times[0] >= 0.0 and times[-1] <= r.truth.time_s[-1] + 1e-9
    tr = r.truth
    assert np.allclose(np.diff(tr.time_s), 0.01)
    assert tr.time_s[0] == 0.0
    rows = tr.rows()
    assert len(rows) == len(tr.time_s)
    for k in REQUIRED_TRUTH_KEYS:
        assert k in rows[0]
    row = tr.at(2.004)
    assert row["time_s"] == pytest.approx(2.0)
    assert tr.at(-5.0)["time_s"] == 0.0
    assert tr.at(1e9)["time_s"] == tr.time_s[-1]


def test_truth_csv(tmp_path):
    r = run("dry")
    path = tmp_path / "truth.csv"
    r.truth_csv(path)
    with open(path) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(r.truth)
    for k in REQUIRED_TRUTH_KEYS:
        assert k in rows[0]
    i = len(rows) // 2
    assert float(rows[i]["mu_max"]) == pytest.approx(r.truth["mu_max"][i], rel=1e-6)
    assert float(rows[i]["speed_mps"]) == pytest.approx(r.truth["speed_mps"][i], rel=1e-6)


def test_bad_arguments():
    with pytest.raises(ValueError):
        simulate("no_such_road", VEH, SCHEDULES)
    with pytest.raises(ValueError):
        simulate("dry", VEH, SCHEDULES, truth_model="pacejka2002")
    with pytest.raises(ValueError):
        simulate("dry", VEH, [MessageSchedule("X", 0.01, ("wheel_speed_fl", "tyre_temperature"))])
    with pytest.raises(ValueError):
        simulate("dry", VEH, [MessageSchedule("X", 0.0, ("wheel_speed_fl",))])


# ------------------------------------------------------------------ physics sanity
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_speed_falls_while_braking_and_forces_are_consistent(name):
    r = run(name)
    tr = r.truth
    v = tr["speed_mps"]
    b = tr["braking"] > 0.5
    assert b.any()
    # free rolling first (>= 1 s), at the scenario's initial speed
    assert tr.time_s[b][0] >= 1.0
    assert v[0] == pytest.approx(SCENARIOS[name].initial_speed_mps)
    # braking only ever slows the car down
    dv = np.diff(v)
    assert np.all(dv[b[:-1]] <= 1e-9)
    assert v[-1] < v[0] - 2.5
    # the body equation holds for the recorded tyre forces: M dv/dt = -ΣFx - Bv v - Da v²
    fx_sum = wheels(tr, "fx").sum(axis=1)
    mass = VEH.mass * SCENARIOS[name].load_factor      # the car as loaded, not as configured
    accel = -(fx_sum + VEH.rolling_resistance * v + VEH.drag_area_coefficient * v * v) / mass
    assert np.allclose(tr["accel_long"], accel, rtol=1e-9, atol=1e-9)
    # and integrating it reproduces the speed (10 ms rows of a 1 kHz integration)
    v_int = v[0] + np.concatenate([[0.0], np.cumsum(accel[:-1] * np.diff(tr.time_s))])
    assert np.max(np.abs(v_int - v)) < 0.02 * v[0]
    # loads: the four normal forces carry the car's weight
    fn = wheels(tr, "fn")
    weight = mass * GRAVITY_MPS2
    rough = SCENARIOS[name].road_roughness
    assert np.allclose(fn.sum(axis=1), weight, rtol=4 * rough + 1e-9)
    # braking: the front axle is loaded (pitch lag aside), left/right only differ in a turn
    assert np.mean(fn[b, 0] + fn[b, 1]) > weight * VEH.cg_to_rear_axle / VEH.wheelbase


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_utilised_mu_stays_below_the_peak_in_steady_parts(name):
    tr = run(name).truth
    mu = wheels(tr, "mu")
    mu_max = wheels(tr, "mu_max")
    # quasi-steady: the wheel accelerates with the car (no spin-up or spin-down transient)
    excess = wheels(tr, "omega_dot") * VEH.wheel_radius - tr["accel_long"][:, None]
    steady = np.abs(excess) < 1.0
    assert steady.sum() > 100
    assert np.max(mu[steady] - mu_max[steady]) < 0.01
    # the dynamic LuGre bristles may overshoot a little in transients, the static models never
    slack = 0.08 if run(name).truth_model == "lugre" else 0.01
    assert np.max(mu / mu_max) < 1.0 + slack


@pytest.mark.parametrize("model", sorted(TRUTH_MODELS))
def test_truth_model_override(model):
    r = run("wet", truth_model=model)
    assert r.truth_model == model
    tr = r.truth
    mu = wheels(tr, "mu")
    mu_max = wheels(tr, "mu_max")
    excess = wheels(tr, "omega_dot") * VEH.wheel_radius - tr["accel_long"][:, None]
    steady = np.abs(excess) < 1.0
    assert np.max(mu[steady] - mu_max[steady]) < 0.01
    assert 0.3 < np.median(tr["mu_max"]) < 0.9


def test_true_brake_gains_differ_from_nominal():
    r = run("dry")
    front, rear = SCENARIOS["dry"].brake_gain_factor
    g = np.array(r.brake_gains)
    nominal = np.array([VEH.brake_gain_front] * 2 + [VEH.brake_gain_rear] * 2)
    ratio = g / nominal
    assert np.allclose(ratio[:2], front, rtol=0.02)
    assert np.allclose(ratio[2:], rear, rtol=0.02)
    assert abs(ratio[0] - 1.0) > 0.03


# ------------------------------------------------------------------ ABS
@pytest.mark.parametrize("name", ["dry", "wet", "snow", "ice", "split_mu", "cornering", "dry_to_wet"])
def test_abs_keeps_slip_bounded(name):
    tr = run(name).truth
    slip = wheels(tr, "slip")
    b = braking_rows(tr)
    # no wheel stays locked: slip beyond 0.5 is rare, and never for long
    assert np.mean(slip[b].max(axis=1) > 0.5) < 0.02
    assert np.mean(slip[b] > 0.3) < 0.05
    # the ABS cycles: every wheel dumps and re-applies several times
    active = wheels(tr, "abs")
    assert np.all(active[b].mean(axis=0) > 0.5)


@pytest.mark.parametrize("name", ABS_SCENARIOS)
def test_peak_region_is_visited(name):
    tr = run(name).truth
    ratio = wheels(tr, "slip") / wheels(tr, "slip_at_mu_max")
    b = braking_rows(tr)
    # some wheel goes past 0.8 λ* and the utilised friction gets close to the peak
    assert np.max(ratio[b]) > 0.8
    assert np.mean(ratio[b].max(axis=1) > 0.8) > 0.1
    mu_ratio = wheels(tr, "mu") / wheels(tr, "mu_max")
    assert np.max(mu_ratio[b]) > 0.95
    # cycling around the peak, not parked far below it
    assert 0.3 < np.median(ratio[b]) < 1.2


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("name, decel_range, max_utilisation", [("moderate", (2.5, 3.5), 0.5),
                                                                ("moderate_wet", (3.0, 4.0), 0.8)])
def test_moderate_braking_stays_far_from_the_peak(seed, name, decel_range, max_utilisation):
    tr = run(name, seed=seed).truth
    ratio = wheels(tr, "slip") / wheels(tr, "slip_at_mu_max")
    assert np.max(ratio) < 0.5
    assert np.max(wheels(tr, "mu") / wheels(tr, "mu_max")) < max_utilisation
    assert not wheels(tr, "abs").any()
    b = tr["braking"] > 0.5
    decel = -tr["accel_long"][braking_rows(tr, 0.5) & b]
    assert decel_range[0] < np.median(decel) < decel_range[1]
    # released before the end: free rolling again
    assert tr["braking"][-1] == 0.0


# ------------------------------------------------------------------ scenario specifics
def test_split_mu_sides_differ():
    tr = run("split_mu").truth
    left = (tr["mu_max_fl"] + tr["mu_max_rl"]) / 2
    right = (tr["mu_max_fr"] + tr["mu_max_rr"]) / 2
    assert np.all(left > 1.5 * right)
    assert np.allclose(tr["mu_max"], (left + right) / 2)


def test_dry_to_wet_jump():
    tr = run("dry_to_wet").truth
    scn = SCENARIOS["dry_to_wet"]
    t = tr.time_s
    before = tr["mu_max"][(t > scn.surface_change_s - 0.3) & (t < scn.surface_change_s - 0.05)]
    after = tr["mu_max"][(t > scn.surface_change_s + 0.4) & (t < scn.surface_change_s + 0.7)]
    assert after.max() < 0.8 * before.min()
    # the front axle changes first, the rear a wheelbase later
    i_f = np.argmax(tr["mu_max_fl"] < 0.8 * before.min())
    i_r = np.argmax(tr["mu_max_rl"] < 0.8 * before.min())
    assert 0.05 < t[i_r] - t[i_f] < 0.3


def test_cornering_kinematics():
    r = run("cornering")
    tr = r.truth
    radius = SCENARIOS["cornering"].curve_radius_m
    v = tr["speed_mps"]
    assert np.allclose(tr["yaw_rate"], v / radius)
    assert np.allclose(tr["accel_lat"], v * v / radius)
    assert 3.0 < tr["accel_lat"][0] < 4.0
    # left turn: right wheels faster and more loaded
    assert np.all(tr["ground_speed_fr"] > tr["ground_speed_fl"])
    half = VEH.track_front / 2
    assert np.allclose(tr["ground_speed_fr"] - tr["ground_speed_fl"], 2 * half * v / radius)
    assert np.all(tr["fn_fr"] > tr["fn_fl"])
    lat = [e.values["accel_lat"] for e in r.events if e.message == "ACCELERATIONS" and e.time_s < 1.0]
    assert np.mean(lat) == pytest.approx(tr["accel_lat"][0], abs=0.15)


def test_a_turn_leaves_the_brakes_what_the_combined_slip_envelope_allows():
    # Each tyre carries a_y/g of its load sideways; braking gets (1 − u^2.5)^(1/2.5) of its curve,
    # u = a_y / (g μ_max): at 3.5 m/s² on dry 3 % less than straight ahead, and no more.
    from frictiond.simulator.vehicle_sim import COMBINED_SLIP_EXPONENT

    tr = run("cornering").truth
    wheels = ("fl", "fr", "rl", "rr")
    braking = (tr["braking"] > 0.5) & (tr["speed_mps"] > 5.0)
    use = tr["accel_lat"][braking] / (9.81 * np.array([tr[f"mu_max_{w}"][braking] for w in wheels]))
    left = (1.0 - use**COMBINED_SLIP_EXPONENT) ** (1.0 / COMBINED_SLIP_EXPONENT)
    mu = np.abs(np.array([tr[f"mu_{w}"][braking] for w in wheels]))
    peak = np.array([tr[f"mu_max_{w}"][braking] for w in wheels])
    assert use.max() > 0.3                                # (the premise: a turn that takes a share)
    assert (mu <= 1.01 * left * peak).all()
    assert (mu > 0.98 * left * peak).any()


# ------------------------------------------------------------------ sensors and bus timing
@pytest.mark.parametrize("name", ["dry", "noisy"])
def test_event_rates_match_schedules(name):
    r = run(name, reference_speed=True)
    duration = r.truth.time_s[-1]
    drop = SCENARIOS[name].drop_rate
    for m in SCHEDULES:
        times = np.array([e.time_s for e in r.events if e.message == m.name])
        n_sent = duration / m.period_s
        expected = n_sent * (1.0 - drop)
        # ±2 %, or the binomial spread of the lost frames for slow messages (few frames)
        tolerance = max(0.02 * expected, 3.0 * np.sqrt(n_sent * drop * (1.0 - drop)) + 1.0)
        assert abs(len(times) - expected) <= tolerance, m.name
        gaps = np.diff(times)
        # ±1 ms jitter around the period; a lost frame doubles a gap
        assert np.all(gaps > m.period_s - 0.0021)
        k = np.round(gaps / m.period_s)
        assert np.all(np.abs(gaps - k * m.period_s) < 0.0021)
        assert np.any(np.abs(gaps - m.period_s) > 1e-4)  # jitter is there


def test_events_carry_only_their_signals():
    r = run("wet", reference_speed=True)
    sig = {m.name: set(m.signals) for m in SCHEDULES}
    for e in r.events[:500]:
        assert set(e.values) == sig[e.message]
        assert all(isinstance(x, float) and np.isfinite(x) for x in e.values.values())


def test_reference_speed_switch():
    default = run("dry")
    assert not default.reference_speed
    assert "VEHICLE_SPEED_REF" not in {e.message for e in default.events}
    on = run("dry", reference_speed=True)
    ref = [e for e in on.events if e.message == "VEHICLE_SPEED_REF"]
    assert len(ref) > 0.9 * on.truth.time_s[-1] / 0.01
    err = [e.values["vehicle_speed_ref"] - on.truth.at(e.time_s)["speed_mps"] for e in ref]
    assert abs(np.mean(err)) < 0.1
    # a mixed message keeps its other signals
    mixed = [MessageSchedule("BODY", 0.01, ("accel_long", "vehicle_speed_ref"))]
    off = simulate("dry", VEH, mixed, reference_speed=False)
    assert off.events and all(set(e.values) == {"accel_long"} for e in off.events)
    # the physics does not depend on the message layout
    assert np.array_equal(off.truth["speed_mps"], default.truth["speed_mps"])


def test_sensor_models():
    r = run("wet", reference_speed=True)
    tr = r.truth
    ws = np.array([[e.values[s] for s in WHEEL_SPEEDS] for e in r.events if e.message == "WHEEL_SPEEDS"])
    t = np.array([e.time_s for e in r.events if e.message == "WHEEL_SPEEDS"])
    assert np.allclose(ws * 100, np.round(ws * 100), atol=1e-6)  # 0.01 rad/s resolution
    true_w = np.interp(t, tr.time_s, tr["wheel_speed_fl"])
    free = t < 1.0  # free rolling: smooth, interpolation exact enough
    assert 0.01 < np.std(ws[free, 0] - true_w[free]) < 0.04
    acc = np.array([e.values["accel_long"] for e in r.events if e.message == "ACCELERATIONS"])
    ta = np.array([e.time_s for e in r.events if e.message == "ACCELERATIONS"])
    resid = acc - np.interp(ta, tr.time_s, tr["accel_long"])
    free = ta < 1.0
    assert 0.03 < np.std(resid[free]) < 0.08
    assert 0.02 < abs(np.mean(resid)) < 0.1  # a small constant bias
    noisy = run("noisy", reference_speed=True)
    accn = np.array([e.values["accel_long"] for e in noisy.events if e.message == "ACCELERATIONS"])
    tn = np.array([e.time_s for e in noisy.events if e.message == "ACCELERATIONS"])
    residn = accn - np.interp(tn, noisy.truth.time_s, noisy.truth["accel_long"])
    assert np.std(residn[tn < 1.0]) > 2 * np.std(resid[free])
    p = np.array([[e.values[s] for s in PRESSURES] for e in r.events if e.message == "BRAKE_PRESSURES"])
    assert np.all(p >= 0.0)
    assert p.max() > 30.0
    d = [e.values["drive_torque_fl"] for e in r.events if e.message == "WHEEL_DRIVE_TORQUE"]
    assert d and all(x == 0.0 for x in d)


# ------------------------------------------------------------------ determinism and speed
def test_deterministic_per_seed():
    a = simulate("snow", VEH, SCHEDULES, seed=7)
    b = simulate("snow", VEH, SCHEDULES, seed=7)
    assert a.events == b.events
    assert a.truth.rows() == b.truth.rows()
    c = simulate("snow", VEH, SCHEDULES, seed=8)
    assert a.events != c.events
    assert not np.array_equal(a.truth["slip_fl"], c.truth["slip_fl"])


def test_runtime():
    t0 = time.perf_counter()
    simulate("ice", VEH, SCHEDULES, seed=3)  # the longest run: 8 s of braking
    assert time.perf_counter() - t0 < 5.0  # ~0.4 s on a laptop; loose for loaded CI machines


def test_load_factor_makes_the_true_car_heavier_than_the_configured_one():
    config_mass = VehicleParams().mass
    light = simulate("wet", VehicleParams(), SCHEDULES, seed=0).truth.rows()
    heavy = simulate("loaded", VehicleParams(), SCHEDULES, seed=0).truth.rows()
    def static_load(rows):
        return sum(rows[5][f"fn_{w}"] for w in ("fl", "fr", "rl", "rr"))   # before braking
    assert static_load(light) == pytest.approx(config_mass * GRAVITY_MPS2, rel=0.02)
    assert static_load(heavy) == pytest.approx(1.25 * config_mass * GRAVITY_MPS2, rel=0.02)


# ------------------------------------------------------------------ a road on a grade
def test_a_grade_slows_the_car_by_gravity_s_share_the_accelerometer_does_not_read():
    flat, up, down = run("snow", 0), run("snow", 0, grade=0.06), run("snow", 0, grade=-0.06)
    share = GRAVITY_MPS2 * np.sin(np.arctan(0.06))
    for r, sign in ((up, 1.0), (down, -1.0)):
        t, v, ax = r.truth.time_s, r.truth["speed_mps"], r.truth["accel_long"]
        # the speed changes by the accelerometer's reading less gravity's share along the road
        dv = np.diff(v) / np.diff(t)
        steady = slice(50, len(dv) - 50)
        assert np.median(dv[steady] - ax[:-1][steady]) == pytest.approx(-sign * share, abs=0.03)
    # free rolling alone: downhill the car gains speed, uphill it loses it
    assert down.truth["speed_mps"][90] > flat.truth["speed_mps"][90] > up.truth["speed_mps"][90]
    with pytest.raises(ValueError, match="grade"):
        simulate("snow", VEH, SCHEDULES, grade=0.5)


def test_a_grade_the_front_end_is_told_nothing_of_keeps_snow_right(default_config, level_config):
    # The built-in simulator's snow stop on a 6 % grade either way. Free rolling teaches the
    # accelerometer's offset with gravity's share (0.59 m/s², a quarter of snow's deceleration);
    # the default front end takes the sensor's own offset from the brake gain's fit instead and
    # stays right. A front end told the roads are level (`frontend.level_road`) takes gravity's
    # share for brake torque: the premise, hundreds of VALID outputs more than 20 % off.
    from frictiond.evaluation import evaluate
    from frictiond.replay import estimates_of
    from frictiond.sim_frames import simulate_frames

    for grade in (0.06, -0.06):
        frames, sim = simulate_frames(default_config, "snow", seed=2, grade=grade)
        _, estimates = estimates_of(default_config, frames)
        report = evaluate(estimates, sim.truth.rows())
        assert report.false_valid_count == 0 and report.mae < 0.015 and report.valid_share > 0.9, grade
        _, told_level = estimates_of(level_config, frames)
        assert evaluate(told_level, sim.truth.rows()).false_valid_count > 100, grade
