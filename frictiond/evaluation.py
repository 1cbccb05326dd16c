"""Accuracy metrics of a friction estimate against a simulator's truth (issue: estimation accuracy).

Definitions (shared by `benchmarks/accuracy.py` and the accuracy regression tests):

- *excitation onset*: the first truth row where any wheel's slip exceeds 5 %;
- *evaluated span*: from 0.5 s after the onset to the end of braking (last truth row with the
  brakes applied);
- *MAE*: mean |MuMax − true μ_max| over VALID outputs inside the span;
- *valid share*: VALID outputs in the span / all outputs in the span;
- *convergence time*: from the onset until the estimate is VALID and within 10 % of the truth
  and stays so for 0.3 s;
- *re-convergence time*: the same, measured from a jump of the true μ_max (> 10 % within 50 ms);
- *false valid*: VALID outputs anywhere that are more than 20 % off the truth;
- *confidence calibration*: every output with a confidence > 0, as (confidence, |relative error|),
  for `calibration_table`: when the estimator says 0.9, the error should be small.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .samples import FrictionEstimate, Status

ONSET_SLIP = 0.05
SPAN_DELAY_S = 0.5
CONVERGED_REL = 0.10
HOLD_S = 0.3
FALSE_VALID_REL = 0.20


@dataclass
class AccuracyReport:
    mae: float
    mae_rel: float
    valid_share: float
    convergence_s: float
    reconvergence_s: float | None
    false_valid_count: int
    valid_count: int
    output_count: int
    mean_truth: float
    confidence_errors: list[tuple[float, float]] = field(default_factory=list)
    # The outputs in the evaluated span that are not VALID, and how many of them are within
    # FALSE_VALID_REL of the truth: what a consumer reading MuMax regardless of status would get.
    unvalid_count: int = 0
    unvalid_within_count: int = 0

    @property
    def false_valid_share(self) -> float:
        return self.false_valid_count / self.valid_count if self.valid_count else 0.0


def _truth_arrays(truth_rows: Sequence[dict[str, float]]) -> dict[str, np.ndarray]:
    keys = truth_rows[0].keys()
    return {k: np.array([r[k] for r in truth_rows], dtype=float) for k in keys}


def _time_to_converge(times, mu, truth, valid, start_s: float) -> float:
    """Seconds from `start_s` until VALID-and-within-10 % holds for HOLD_S; inf if never."""
    ok = valid & (np.abs(mu - truth) <= CONVERGED_REL * np.maximum(truth, 1e-3))
    run_start = None
    for t, good in zip(times, ok):
        if t < start_s:
            continue
        if good:
            if run_start is None:
                run_start = t
            if t - run_start >= HOLD_S:
                return run_start - start_s
        else:
            run_start = None
    return math.inf


def evaluate(estimates: Sequence[FrictionEstimate], truth_rows: Sequence[dict[str, float]]) -> AccuracyReport:
    tr = _truth_arrays(truth_rows)
    t_truth = tr["time_s"]
    slips = np.vstack([tr[f"slip_{w}"] for w in ("fl", "fr", "rl", "rr")])
    braking = tr["braking"] > 0.5
    excited = np.nonzero(np.max(slips, axis=0) > ONSET_SLIP)[0]
    onset = float(t_truth[excited[0]]) if len(excited) else math.inf
    braked_rows = np.nonzero(braking)[0]
    end_braking = float(t_truth[braked_rows[-1]]) if len(braked_rows) else -math.inf

    times = np.array([e.time_s for e in estimates], dtype=float)
    mu = np.array([e.mu_max for e in estimates], dtype=float)
    valid = np.array([e.status == Status.VALID for e in estimates], dtype=bool)
    idx = np.clip(np.searchsorted(t_truth, times), 0, len(t_truth) - 1)
    truth_mu = tr["mu_max"][idx]

    in_span = (times >= onset + SPAN_DELAY_S) & (times <= end_braking)
    span_valid = in_span & valid
    err = np.abs(mu - truth_mu)
    mae = float(np.mean(err[span_valid])) if span_valid.any() else math.inf
    mae_rel = float(np.mean(err[span_valid] / truth_mu[span_valid])) if span_valid.any() else math.inf
    valid_share = float(span_valid.sum() / in_span.sum()) if in_span.any() else 0.0

    convergence = _time_to_converge(times, mu, truth_mu, valid, onset) if math.isfinite(onset) else math.inf

    reconvergence = None
    mu_truth_series = tr["mu_max"]
    jumps = np.nonzero(np.abs(mu_truth_series[5:] - mu_truth_series[:-5]) > 0.1 * mu_truth_series[:-5])[0]
    if len(jumps) and math.isfinite(onset):
        jump_t = float(t_truth[jumps[0] + 5])
        if jump_t > onset:
            reconvergence = _time_to_converge(times, mu, truth_mu, valid, jump_t)

    tolerance = FALSE_VALID_REL * np.maximum(truth_mu, 1e-3)
    false_valid = valid & (err > tolerance)
    confidence = np.array([e.confidence for e in estimates], dtype=float)
    rated = confidence > 0
    rel_err = err / np.maximum(truth_mu, 1e-3)
    confidence_errors = list(zip(confidence[rated].tolist(), rel_err[rated].tolist()))
    return AccuracyReport(
        mae=mae,
        mae_rel=mae_rel,
        valid_share=valid_share,
        convergence_s=convergence,
        reconvergence_s=reconvergence,
        false_valid_count=int(false_valid.sum()),
        valid_count=int(valid.sum()),
        output_count=len(estimates),
        mean_truth=float(np.mean(truth_mu[in_span])) if in_span.any() else math.nan,
        confidence_errors=confidence_errors,
        unvalid_count=int((in_span & ~valid).sum()),
        unvalid_within_count=int((in_span & ~valid & (err <= tolerance)).sum()),
    )


CONFIDENCE_BINS = (0.0, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0 + 1e-9)


@dataclass
class CalibrationRow:
    low: float
    high: float
    count: int
    median_error: float     # |relative error|
    p90_error: float
    share_over_10: float    # share of outputs more than 10 % off
    share_over_20: float


def calibration_table(pairs: Sequence[tuple[float, float]]) -> list[CalibrationRow]:
    """(confidence, |relative error|) pairs binned by confidence (`CONFIDENCE_BINS`)."""
    conf = np.array([c for c, _ in pairs], dtype=float)
    err = np.array([e for _, e in pairs], dtype=float)
    rows = []
    for low, high in zip(CONFIDENCE_BINS[:-1], CONFIDENCE_BINS[1:]):
        sel = err[(conf >= low) & (conf < high) & (conf > 0)]
        if len(sel) == 0:
            rows.append(CalibrationRow(low, min(high, 1.0), 0, math.nan, math.nan, math.nan, math.nan))
            continue
        rows.append(CalibrationRow(low, min(high, 1.0), len(sel), float(np.median(sel)),
                                   float(np.quantile(sel, 0.9)), float(np.mean(sel > 0.1)), float(np.mean(sel > 0.2))))
    return rows
