"""Scores of one campaign stop: both estimators through the real pipeline, against the truth.

Per estimator, the metrics of `frictiond.evaluation` (MAE over VALID outputs in the evaluated
span, VALID share of the span, convergence, false VALID), plus what the campaign's targets need
beyond them: FAULT outputs, a crash of the pipeline (recorded, never raised), and the
calibration counts — VALID outputs with confidence ≥ c, and how many of them are within 10 % of
the truth, for c in `CALIBRATION_LEVELS` (summed over stops by the report) — and the braking time
the estimator kept from VALID, by its reason (`not_valid`).
Per stop, from the truth: the highest utilisation any wheel reached while braking 1 m/s above
the ABS cut-out speed (`max_utilisation`; |F_x| / (μ_max F_z), with in a turn the lateral force's
share of the tyre's lateral grip added by the friction ellipse): a stop that stayed below 0.8
never showed the peak; and how long some wheel's slip was past its own peak slip there
(`past_peak_s`).
"""
from __future__ import annotations

import json
import math
import time
import traceback
from typing import Any, Sequence

import numpy as np

from ..evaluation import CONVERGED_REL, evaluate
from ..replay import estimates_of
from ..samples import FrictionEstimate, Status
from .draw import StopSpec, Stress, draw_stop
from .simulate import CampaignStop, simulate_stop

ESTIMATORS = {"lugre": "lugre-tr", "rls": "burckhardt-rls"}   # row prefix → estimator.kind
CALIBRATION_LEVELS = (0.5, 0.6, 0.7, 0.8, 0.9)
UTILISATION_SHOWN = 0.8
MOVING_MPS = 2.0     # FAULTs above this true speed are counted apart (`faults_moving`)
WHEELS = ("fl", "fr", "rl", "rr")


def truth_summary(stop: CampaignStop) -> dict[str, float]:
    """Stop-level truth figures for the tables and the 'never near the peak' target."""
    rows = stop.truth
    braking = [r for r in rows if r["braking"] > 0.5 and r["speed_mps"] > 1.0]
    # Above the ABS's cut-out: below it every wheel runs through its peak to lock-up in the
    # last metre, which shows the peak to no estimator.
    fast = [r for r in braking if r["speed_mps"] > stop.spec.abs_cutout_mps + 1.0]
    util = max((max(r[f"utilisation_{w}"] for w in WHEELS) for r in fast), default=0.0)
    slip = max((max(r[f"slip_{w}"] for w in WHEELS) for r in fast), default=0.0)
    # How long some wheel ran past its own peak slip: data that never do bound the peak's height
    # from below only (a slip target short of it, an ABS releasing before it), closely only where
    # the curve is flat-topped and the wheels came within a few % of their grip.
    times = [r["time_s"] for r in fast]
    past = sum(t1 - t0 for t0, t1, r in zip(times, times[1:], fast)
               if any(r[f"slip_{w}"] > r[f"slip_at_mu_max_{w}"] for w in WHEELS))
    return {
        "max_utilisation": float(util),
        "max_slip": float(slip),
        "past_peak_s": round(float(past), 3),
        "truth_mu_mean": float(np.mean([r["mu_max"] for r in braking])) if braking else math.nan,
        "end_speed_mps": float(rows[-1]["speed_mps"]),
        "duration_s": float(rows[-1]["time_s"]),
    }


def estimator_scores(estimates: Sequence[FrictionEstimate], truth: list[dict[str, float]]) -> dict[str, Any]:
    rep = evaluate(estimates, truth)
    t_truth = np.array([r["time_s"] for r in truth])
    mu_truth = np.array([r["mu_max"] for r in truth])
    out: dict[str, Any] = {
        "mae": rep.mae, "mae_rel": rep.mae_rel, "valid_share": rep.valid_share, "conv_s": rep.convergence_s,
        "reconv_s": math.nan if rep.reconvergence_s is None else rep.reconvergence_s,
        "false_valid": rep.false_valid_count, "valid": rep.valid_count, "outputs": rep.output_count,
        "span_truth": rep.mean_truth, "unvalid": rep.unvalid_count, "unvalid_within": rep.unvalid_within_count,
        "faults": sum(1 for e in estimates if e.status == Status.FAULT), "crash": "",
    }
    speed = np.array([r["speed_mps"] for r in truth])
    fault_t = [e.time_s for e in estimates if e.status == Status.FAULT]
    at = np.clip(np.searchsorted(t_truth, fault_t), 0, len(t_truth) - 1)
    out["faults_moving"] = int((speed[at] > MOVING_MPS).sum()) if fault_t else 0
    valid = [e for e in estimates if e.status == Status.VALID]
    if valid:
        idx = np.clip(np.searchsorted(t_truth, [e.time_s for e in valid]), 0, len(t_truth) - 1)
        truth_v = np.maximum(mu_truth[idx], 1e-3)
        rel = np.abs(np.array([e.mu_max for e in valid]) - truth_v) / truth_v
        conf = np.array([e.confidence for e in valid])
    else:
        rel = conf = np.zeros(0)
    for c in CALIBRATION_LEVELS:
        sel = conf >= c
        out[f"cal_n_{int(c * 100)}"] = int(sel.sum())
        out[f"cal_ok_{int(c * 100)}"] = int((rel[sel] <= CONVERGED_REL).sum())
    return out


def not_valid_json(pipeline: Any) -> str:
    """The braking time the estimator kept from VALID, by its own reason (`frictiond.not_valid`),
    as JSON {reason: seconds}: one string column, in the JSON and the Parquet results alike."""
    period = pipeline.front_end.sample_period_s
    return json.dumps({k: round(n * period, 3) for k, n in pipeline.stats.estimator_not_valid.most_common()})


def _crashed(exc: BaseException) -> dict[str, Any]:
    last = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    where = f" at {last.filename.rsplit('/', 1)[-1]}:{last.lineno}" if last else ""
    out: dict[str, Any] = {"mae": math.inf, "mae_rel": math.inf, "valid_share": 0.0, "conv_s": math.inf,
                           "reconv_s": math.nan, "false_valid": 0, "valid": 0, "outputs": 0, "span_truth": math.nan,
                           "unvalid": 0, "unvalid_within": 0,
                           "faults": 0, "faults_moving": 0, "crash": f"{type(exc).__name__}: {exc}"[:200] + where,
                           "not_valid": "{}"}
    for c in CALIBRATION_LEVELS:
        out[f"cal_n_{int(c * 100)}"] = out[f"cal_ok_{int(c * 100)}"] = 0
    return out


def spec_fields(spec: StopSpec) -> dict[str, Any]:
    """The draw's fields a failure analysis filters on."""
    car, sensors = spec.car, spec.sensors
    return {
        "seed": spec.seed, "family": spec.family, "abs": spec.abs_family, "tyre": spec.tyre_family,
        "manoeuvre": spec.manoeuvre, "surfaces": spec.surface_labels, "jump": spec.jump_kind,
        "speed0_kmh": round(spec.speed0_mps * 3.6, 1), "demand_bar": round(spec.demand_bar, 1),
        "mass_kg": round(car.mass_kg, 0), "payload_kg": round(car.payload_kg, 0),
        "gain_err_front": round(car.brake_gain_front / car.config_brake_gain_front - 1.0, 3),
        "gain_err_rear": round(car.brake_gain_rear / car.config_brake_gain_rear - 1.0, 3),
        "relaxation_m": round(spec.relaxation_m, 3), "speed_slope": round(spec.surfaces[0].speed_slope, 3),
        "wheel_hz": sensors.wheel_hz, "resolution_kmh": sensors.wheel_resolution_kmh,
        "drop_rate": round(sensors.drop_rate, 4), "accel_offset": round(sensors.accel_offset_mps2, 3),
        "master_only": sensors.master_only, "reference_speed": sensors.reference_speed,
        "abs_flags": sensors.abs_flags, "wind_mps": round(spec.wind_mps, 2), "grade": round(spec.grade, 4),
        "wheel_messages": sensors.wheel_messages, "cycle_times_in_dbc": sensors.cycle_times_in_dbc,
    }


def score_stop(stop: CampaignStop) -> dict[str, Any]:
    """One row: the draw's fields, the truth's summary, then `lugre_*` and `rls_*` scores."""
    row: dict[str, Any] = {**spec_fields(stop.spec), **truth_summary(stop), "frames": len(stop.frames)}
    for prefix, kind in ESTIMATORS.items():
        t0 = time.process_time()
        try:
            pipeline, estimates = estimates_of(stop.config(kind), stop.frames)
            scores = estimator_scores(estimates, stop.truth)
            scores["not_valid"] = not_valid_json(pipeline)
        except Exception as exc:   # a crash is a result of the campaign, not the campaign's end
            scores = _crashed(exc)
        scores["cpu_s"] = time.process_time() - t0
        row.update({f"{prefix}_{k}": v for k, v in scores.items()})
    return row


def run_seed(seed: int, family: str | None = None, stress: Stress | None = None) -> dict[str, Any]:
    """Draw (with `stress`'s settings in place of the draw's), simulate and score one seed (the
    unit of work a campaign worker runs)."""
    t0 = time.process_time()
    spec = draw_stop(seed, family, stress)
    try:
        stop = simulate_stop(spec)
    except Exception as exc:   # a generator bug must show as such, with its seed
        return {**spec_fields(spec), "sim_error": f"{type(exc).__name__}: {exc}"[:200]}
    sim_s = time.process_time() - t0
    row = score_stop(stop)
    row["sim_cpu_s"] = sim_s
    row["sim_error"] = ""
    return row


def run_seeds(seeds: Sequence[int], family: str | None = None, stress: Stress | None = None) -> list[dict[str, Any]]:
    """A chunk of seeds in one task (fewer, larger Dask tasks: the scheduler's cost per task
    is comparable to a short stop's)."""
    return [run_seed(s, family, stress) for s in seeds]
