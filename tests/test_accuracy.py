"""Accuracy regression: the benchmark's metrics per scenario, pinned with a margin.

Seed 0 of every case in `benchmarks/accuracy.py`, through the full pipeline (frames encoded with
the default DBC). Limits are the achieved figures with a margin, never looser than issue 3's
targets where the estimator meets them: MAE ≤ 0.05 and ≤ 12 %, VALID ≥ 80 % of the evaluated
span, converged within 0.3 s, re-converged within 0.5 s after a μ jump, false VALID ≤ 1 %.
VALID is entered at confidence 0.685 (a false VALID unlikely, not only a 10 % error): where that
took VALID outputs the limits say so.
"""
from __future__ import annotations

import dataclasses
import math
import statistics

import numpy as np
import pytest

from frictiond.config import default_config_path, load_config
from frictiond.evaluation import calibration_table, evaluate
from frictiond.pipeline import Pipeline
from frictiond.replay import ReplayRecorder, replay_frames
from frictiond.sim_frames import simulate_frames

from .conftest import load_benchmark

_bench = load_benchmark("accuracy")
CASES = {c[0]: c[1:] for c in _bench.CASES}

# case: (max MAE, max relative MAE, min VALID share, max convergence s, max re-convergence s)
LIMITS = {
    "dry": (0.035, 0.04, 0.95, 0.3, None),
    # A runaway must run on to lock-up (or an ABS release it) before it counts: the first evidence
    # a cycle later moves the fits after it by 0.0002 (MAE 0.0299 → 0.0301 over the same outputs).
    # (VALID from σ ≤ 0.099, the threshold's: 0.922 of the span, was 0.95.)
    # (A change of road found at 3.4 m/s, not there, leaves the last 0.4 s CONVERGING: below
    # 5 m/s no wheel shows the new road's peak. 0.873 of the span.)
    "dry/burckhardt": (0.031, 0.035, 0.87, 0.3, None),
    "dry/ref": (0.035, 0.04, 0.95, 0.3, None),
    "wet": (0.03, 0.05, 0.95, 0.3, None),
    # The MF curve on wet asphalt: a late jump of the fit (~6 % at 3 s, low speed) costs ~0.1 s of VALID.
    "wet/mf": (0.035, 0.045, 0.88, 0.3, None),
    "wet/ref": (0.035, 0.06, 0.95, 0.3, None),
    "snow": (0.012, 0.05, 0.95, 0.3, None),
    "snow/burckhardt": (0.008, 0.04, 0.95, 0.3, None),
    # Burckhardt ice: μ_max 0.034, already 96 % of it at 1 % slip (a plateau, ABS holds 1-2 %).
    # VALID's threshold of confidence comes 0.34 s after the onset: issue 3's 0.3 s missed.
    "ice": (0.005, 0.08, 0.9, 0.36, None),
    # The same ice at 35 m/s (μ_max 0.026): the ABS holds the wheels past the peak at nearly
    # constant slip, which stays evidence of the peak once the stop has shown it. (A VALID once
    # withdrawn is not held again when no sample is usable: 0.955 → 0.941 here.)
    "ice_fast": (0.004, 0.08, 0.93, 0.3, None),
    # A car 25 % heavier than configured: the body equation's brake-gain check absorbs it.
    "loaded": (0.025, 0.035, 0.95, 0.3, None),
    # Rough road: noisier wheel speeds and μ samples; VALID over nearly all the stop.
    # Below 7 m/s this ABS holds half the peak slip (utilisation 0.93-0.98), where μ still rises
    # at 0.4-0.7 of its secant: not at the peak, so CONVERGING there, short of issue 3's 80 %.
    # (Each wheel-speed sample waiting for the pressures of its window's end, `trigger_hold`: 0.62
    # of the span, 0.65 before; over seeds 1-4 of the case 1,867 VALID outputs against 1,883.)
    "cobblestone_wet": (0.025, 0.05, 0.6, 0.3, None),
    "dry_to_wet": (0.02, 0.03, 0.85, 0.3, 0.5),
    # After the change of road the MF fit's spread keeps the confidence below VALID's threshold
    # a few cycles longer. (With `trigger_hold` 0.72 of the span, 0.80 before; over seeds 1-4
    # of the case 1,045 VALID outputs against 1,062, 2 false in both.)
    "dry_to_wet/mf": (0.05, 0.065, 0.7, 0.3, None),
    "split_mu": (0.01, 0.025, 0.95, 0.3, None),
    # (VALID from σ ≤ 0.099, the threshold's: 0.914 of the span.)
    "noisy": (0.015, 0.025, 0.9, 0.3, None),
    "noisy/ref": (0.02, 0.03, 0.95, 0.3, None),
    # (The same: the first VALID 0.06 s later, 0.36 s after the slip first passes 5 %.)
    "cornering": (0.025, 0.025, 0.95, 0.4, None),
}
# The built-in simulator's roads are level, and the front end is told so (`level_road`): free
# rolling then teaches the accelerometer's own offset, which on ice is most of what the brakes'
# torque is known to. (With the default, where a grade may hide in that offset, the low-μ cases
# stay CONVERGING: `test_a_grade_the_front_end_is_not_told_of_costs_validity_not_accuracy`.)
DEFAULT = load_config(default_config_path())
BASE = dataclasses.replace(DEFAULT, frontend=dataclasses.replace(DEFAULT.frontend, level_road=True))


def run_case(label: str, kind: str):
    scenario, model, ref = CASES[label]
    config = dataclasses.replace(BASE, estimator=dataclasses.replace(BASE.estimator, kind=kind))
    frames, sim = simulate_frames(config, scenario, seed=0, truth_model=model, reference_speed=ref)
    recorder = ReplayRecorder()
    replay_frames(Pipeline(config), frames, None, recorder)
    return evaluate(recorder.estimates, sim.truth.rows())


@pytest.fixture(scope="module")
def reports():
    return {(label, kind): run_case(label, kind) for label in CASES for kind in ("lugre-tr", "burckhardt-rls")}


@pytest.mark.parametrize("label", ["dry", "wet", "snow", "ice", "split_mu", "cornering", "loaded"])
def test_a_grade_the_front_end_is_not_told_of_costs_validity_not_accuracy(label):
    # The default front end does not take the roads as level: what free rolling teaches of the
    # accelerometer may be a grade, and the offset the brakes' check uses is only told from their
    # gain as the stop goes (`brake_gain.gain_and_sensor_offset`). On the simulator's level
    # roads that costs no accuracy and no false VALID; VALID over most of the span where the
    # deceleration is large against the sensor's tolerance (0.3 m/s²), none on ice (0.3 m/s²).
    scenario, model, ref = CASES[label]
    frames, sim = simulate_frames(DEFAULT, scenario, seed=0, truth_model=model, reference_speed=ref)
    recorder = ReplayRecorder()
    replay_frames(Pipeline(DEFAULT), frames, None, recorder)
    r = evaluate(recorder.estimates, sim.truth.rows())
    assert r.false_valid_count == 0
    if label == "ice":
        assert r.valid_count == 0
    else:
        level = LIMITS[label]
        assert r.valid_share >= 0.9 and r.mae <= level[0] + 0.005, r


@pytest.mark.parametrize("label", sorted(LIMITS))
def test_lugre_accuracy_is_pinned(reports, label):
    r = reports[(label, "lugre-tr")]
    mae, mae_rel, valid, conv, reconv = LIMITS[label]
    assert r.mae <= mae, f"MAE {r.mae:.4f}"
    assert r.mae_rel <= mae_rel, f"relative MAE {r.mae_rel:.4f}"
    assert r.valid_share >= valid, f"VALID share {r.valid_share:.3f}"
    assert r.convergence_s <= conv, f"convergence {r.convergence_s:.3f} s"
    if reconv is not None:
        assert r.reconvergence_s is not None and r.reconvergence_s <= reconv, f"re-convergence {r.reconvergence_s}"
    assert r.false_valid_count <= 0.02 * max(r.valid_count, 1), f"false VALID {r.false_valid_count}/{r.valid_count}"


@pytest.mark.parametrize("label", ["moderate", "moderate_wet", "moderate_wet/burckhardt"])
def test_moderate_braking_never_claims_valid(reports, label):
    # The peak is never approached (30 % of the grip on dry; 65 % on wet, where a LuGre-like
    # tyre's curve already bends, and the driver's release bends the data more): no VALID at all.
    assert reports[(label, "lugre-tr")].valid_count == 0


def test_ice_magic_formula(reports):
    # Magic Formula ice: the peak at ~39 % slip, every wheel held at 26-60 %, all released
    # together; the speed observer must not take released wheels spinning back up for free
    # rolling. The early fits (wheels locking within 0.1 s) are off by 7-10 %, and their spread
    # (6-9 % of μ_max from 60 samples of one ABS cycle) is that of one piece of evidence: VALID
    # once further ABS cycles have added samples nearer the peak: VALID's
    # threshold, 1.22 s after the onset (0.86 of the span).
    r = reports[("ice/mf", "lugre-tr")]
    assert r.mae_rel <= 0.06, f"relative MAE {r.mae_rel:.4f}"
    assert r.valid_share >= 0.84, f"VALID share {r.valid_share:.3f}"
    assert r.convergence_s <= 1.3, f"convergence {r.convergence_s:.3f} s"
    assert r.false_valid_count <= 0.03 * r.valid_count, f"false VALID {r.false_valid_count}/{r.valid_count}"


def test_false_valid_overall_and_lugre_beats_baseline(reports):
    lugre = [reports[(c, "lugre-tr")] for c in CASES]
    false_valid = sum(r.false_valid_count for r in lugre)
    valid = sum(r.valid_count for r in lugre)
    assert false_valid <= 0.01 * valid, f"false VALID {false_valid}/{valid}"
    scored = [c for c in CASES if math.isfinite(reports[(c, "lugre-tr")].mae) and math.isfinite(reports[(c, "burckhardt-rls")].mae)]
    mean_lugre = statistics.mean(reports[(c, "lugre-tr")].mae for c in scored)
    mean_rls = statistics.mean(reports[(c, "burckhardt-rls")].mae for c in scored)
    assert mean_lugre < 0.8 * mean_rls, f"lugre {mean_lugre:.4f} vs rls {mean_rls:.4f}"
    # ... including the cases whose truth is the baseline's own model (Burckhardt).
    burckhardt_cases = ["wet", "wet/ref", "snow/burckhardt", "dry/burckhardt"]
    assert statistics.mean(reports[(c, "lugre-tr")].mae for c in burckhardt_cases) < statistics.mean(
        reports[(c, "burckhardt-rls")].mae for c in burckhardt_cases)


def test_confidence_means_something(reports):
    """Binned by confidence, the error falls as the confidence rises: when lugre-tr says ≥ 0.8,
    its μ_max is within a few per cent (issue 3: "when it says 0.9, the error is small")."""
    pairs = [p for c in CASES for p in reports[(c, "lugre-tr")].confidence_errors]
    rows = {round(r.low, 1): r for r in calibration_table(pairs)}
    confident = [e for c, e in pairs if c >= 0.8]
    assert len(confident) > 1000
    assert float(np.quantile(confident, 0.9)) <= 0.06
    assert max(confident) <= 0.2
    # Monotone: the 0.6–0.7 bin errs more than the ≥ 0.8 ones.
    assert rows[0.6].count > 100 and rows[0.6].p90_error > float(np.quantile(confident, 0.9))


def run_at_cycle_time(tmp_path, label: str, cycle_ms: int):
    """`label` with every input message at `cycle_ms` (a vehicle DBC with other cycle times)."""
    import re

    from frictiond.config import package_data_path

    text = package_data_path("frictiond.dbc").read_text()
    dbc = tmp_path / f"every_{cycle_ms}_ms.dbc"
    dbc.write_text(re.sub(r'(BA_ "GenMsgCycleTime" BO_ (?:176|192|208|224)) 10;', rf"\1 {cycle_ms};", text))
    config = dataclasses.replace(BASE, can=dataclasses.replace(BASE.can, dbc=(dbc,)))
    scenario, model, ref = CASES[label]
    frames, sim = simulate_frames(config, scenario, seed=0, truth_model=model, reference_speed=ref)
    period = np.median(np.diff([f.time_s for f in frames if f.can_id == 176]))
    assert abs(period - cycle_ms / 1000) < 0.1 * cycle_ms / 1000
    recorder = ReplayRecorder()
    pipeline = Pipeline(config)
    replay_frames(pipeline, frames, None, recorder)
    return pipeline, evaluate(recorder.estimates, sim.truth.rows())


@pytest.mark.parametrize("label", ["dry", "wet"])
def test_a_car_whose_inputs_come_every_20_ms(tmp_path, label):
    """A vehicle DBC with 20 ms cycle times (50 Hz): the front end's derivative window and the
    estimator's sample counts follow the cycle time. With them fixed for 10 ms, every other ABS
    sample was a wheel-speed "glitch" and convergence took 0.62 s (dry) and 0.77 s (wet)."""
    pipeline, r = run_at_cycle_time(tmp_path, label, 20)
    assert pipeline.stats.faults.get("wheel speed glitch", 0) <= 6   # (31 with a 7-sample window)
    assert r.mae_rel <= 0.05 and r.valid_share >= 0.95, r
    assert r.convergence_s <= 0.35, f"convergence {r.convergence_s:.3f} s"
    assert r.false_valid_count == 0


def test_firm_braking_applied_briskly_is_no_run_away(tmp_path):
    """Firm braking at 65 % of the grip, inputs every 5 ms: the pedal's application moves the slip
    at ~0.3 /s, as fast as a wheel running away, but in the linear region, where μ rises with it.
    Counted as a run-away, it made 265 of 302 outputs VALID with μ_max 40 % low."""
    _, r = run_at_cycle_time(tmp_path, "moderate_wet/burckhardt", 5)
    assert r.valid_count == 0


def test_the_outputs_that_are_not_valid_are_counted_in_the_span_with_those_near_the_truth():
    """`evaluate` counts the span's non-VALID outputs (from 0.5 s after some slip first exceeds
    5 % to the end of braking) and how many are within 20 % of the truth; VALID ones and those
    outside the span are not counted."""
    from frictiond.samples import FrictionEstimate, Status

    truth = [{"time_s": k / 100, "braking": float(0.4 <= k / 100 < 1.9), "mu_max": 0.5,
              **{f"slip_{w}": (0.1 if k / 100 >= 0.5 else 0.0) for w in ("fl", "fr", "rl", "rr")}}
             for k in range(200)]
    kinds = [(Status.VALID, 0.5), (Status.CONVERGING, 0.55), (Status.CONVERGING, 0.7), (Status.NOT_EXCITED, 0.41)]
    estimates = [FrictionEstimate(k / 20, kinds[k % 4][0], kinds[k % 4][1], 0.1, 1.0, 0.7) for k in range(40)]
    span = [e for e in estimates if 1.0 <= e.time_s <= 1.89]
    rep = evaluate(estimates, truth)
    assert rep.unvalid_count == sum(e.status != Status.VALID for e in span) == 13
    assert rep.unvalid_within_count == sum(e.status != Status.VALID and e.mu_max in (0.55, 0.41) for e in span) == 9
