"""μ_max from the car's total tyre force when its wheels run deep past their peaks: a free curve.

A threshold ABS on a car that sends its master cylinder's pressure alone drives each wheel to slip
0.6–1.0 every cycle, the four out of phase. There the body sum's static LuGre curve, its shape held
at the priors, cannot follow the tyres: past the peak a tyre falls to its sliding level, 5 % (a
Burckhardt dry tyre) to 55 % (a Magic Formula tyre with C = 2.5) below the peak, where that curve
falls about 12 %. So `body_sum_fit` leaves such rows out, and a window made mostly of them shows
nothing.

Here the curve has no shape: its values at fixed slips (`SLIP_KNOTS`, linear between them), one
curve for the four wheels, fitted by linear least squares to Σ share_i · μ(λ_i) = the body's μ,
its second differences held down a little. The four wheels' slips differ from row to row, so the
rows separate the knots. The curve shows the peak where its highest knot has knots with rows on
both sides and falls past it by more than `fall_z` of their standard errors: the tyres' force
measured falling past its top, not a shape's extrapolation. An ABS crosses the peak every cycle,
so the top and the knot it falls to must each hold rows in both halves of the window: a window
whose older rows sit at small slips on a grippy road and whose newer ones deep in slip on a
slippery one draws a "peak" from the two roads. A road changing within the window (or a peak
moving with the speed) also leaves the window's first and last thirds off the curve in opposite
directions, and shows nothing either. Pure numerics: nothing of CAN or of the front end.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# The slips the curve's values are fitted at (0 pinned to μ = 0): dense where tyres peak (0.05–0.4),
# sparse in the sliding range.
SLIP_KNOTS = np.array([0.0, 0.03, 0.06, 0.1, 0.15, 0.2, 0.3, 0.45, 0.65, 1.0])
# Verdicts: too few rows on the knots around the top, the top at the edge of the rows' slips, no
# fall past it beyond the noise, the window's older and newer rows on different curves.
FEW_ROWS = "too few rows around the curve's top"
AT_EDGE = "the curve's top at the edge of the slips"
NO_FALL = "the curve does not fall past its top"
DRIFTING = "the window's older and newer rows differ"
NOT_IN_BOTH_HALVES = "the top and the fall past it not in both halves of the window"


@dataclass(frozen=True)
class CurveSumOptions:
    smoothing: float = 0.02       # weight (per row) of the curve's second differences
    min_support: float = 3.0      # a knot counts with rows' load shares on it summing to this
    fall_z: float = 2.0           # past the top the curve falls by this many standard errors
    max_drift_share: float = 0.05  # the window's first and last thirds' residuals differ by less (of the peak)
    block_rows: int = 5           # the residuals' noise read over means of this many rows (neighbours correlate)


@dataclass(frozen=True)
class CurveSumFit:
    """The curve's values at `SLIP_KNOTS`, its peak (μ, λ) and the peak's standard error over μ,
    and why it does not show the peak ("" when it does)."""
    values: np.ndarray
    mu_max: float
    slip_star: float
    se_share: float
    verdict: str


def _hats(slips: np.ndarray) -> np.ndarray:
    """Each slip's weights on the knots past the first (linear interpolation): shape slips + knots − 1."""
    lam = np.clip(slips, 0.0, SLIP_KNOTS[-1])
    j = np.clip(np.searchsorted(SLIP_KNOTS, lam, side="right") - 1, 0, len(SLIP_KNOTS) - 2)
    f = (lam - SLIP_KNOTS[j]) / (SLIP_KNOTS[j + 1] - SLIP_KNOTS[j])
    weights = np.zeros(lam.shape + (len(SLIP_KNOTS),))
    np.put_along_axis(weights, j[..., None], (1.0 - f)[..., None], axis=-1)
    np.put_along_axis(weights, (j + 1)[..., None], f[..., None], axis=-1)
    return weights[..., 1:]


def _design(slips: np.ndarray, shares: np.ndarray) -> np.ndarray:
    """Rows × knots: each row's load-weighted weights of the four wheels on the knots."""
    return (shares[..., None] * _hats(slips)).sum(axis=1)


def curve_sum(values: np.ndarray, slips: np.ndarray, shares: np.ndarray) -> np.ndarray:
    """The body's μ the curve gives each row (rows × wheels of slips and load shares)."""
    return _design(slips, shares) @ values[1:]


def fit_curve_sum(slips: np.ndarray, shares: np.ndarray, body: np.ndarray,
                  options: CurveSumOptions | None = None) -> CurveSumFit:
    """The curve fitted to the rows (time order) and its verdict."""
    o = options or CurveSumOptions()
    design = _design(slips, shares)
    n_rows, n_knots = design.shape
    second = np.diff(np.eye(n_knots), 2, axis=0)
    normal = design.T @ design + o.smoothing ** 2 * n_rows * second.T @ second + 1e-6 * np.eye(n_knots)
    inverse = np.linalg.inv(normal)
    fitted = inverse @ (design.T @ body)
    values = np.concatenate(([0.0], fitted))
    residuals = body - design @ fitted
    covariance = _noise(residuals, o.block_rows) * inverse @ (design.T @ design) @ inverse
    errors = np.concatenate(([0.0], np.sqrt(np.maximum(np.diag(covariance), 0.0))))
    support = np.concatenate(([float(n_rows)], design.sum(axis=0)))
    half = n_rows // 2
    in_both_halves = np.concatenate(([True], (design[:half].sum(axis=0) >= 0.5 * o.min_support)
                                     & (design[half:].sum(axis=0) >= 0.5 * o.min_support)))
    read = np.flatnonzero(support[1:] >= o.min_support) + 1
    top = int(read[np.argmax(values[read])]) if len(read) else 0
    mu_max, slip_star = float(values[top]), float(SLIP_KNOTS[top])
    se_share = float(errors[top]) / max(mu_max, 1e-6)

    def verdict(why: str) -> CurveSumFit:
        return CurveSumFit(values, mu_max, slip_star, se_share, why)

    if len(read) < 3:
        return verdict(FEW_ROWS)
    past = read[read > top]
    if not len(past) or not (read < top).any():
        return verdict(AT_EDGE)
    past = past[in_both_halves[past]]
    if not in_both_halves[top] or not len(past):
        return verdict(NOT_IN_BOTH_HALVES)
    fall = max(values[top] - values[j] - o.fall_z * math.hypot(errors[top], errors[j]) for j in past)
    if fall <= 0.0:
        return verdict(NO_FALL)
    third = n_rows // 3
    if third and abs(float(residuals[-third:].mean() - residuals[:third].mean())) > o.max_drift_share * mu_max:
        return verdict(DRIFTING)
    return verdict("")


def _noise(residuals: np.ndarray, block: int) -> float:
    """A row's noise variance from the residuals' means over blocks of `block` rows (neighbouring
    rows share the accelerometer's filter and the ABS cycle's phase: their residuals correlate)."""
    n = len(residuals) - len(residuals) % block
    if n < 2 * block:
        return max(float(np.mean(residuals ** 2)), 1e-6)
    means = residuals[len(residuals) - n:].reshape(-1, block).mean(axis=1)
    return max(float(np.mean(means ** 2)) * block, 1e-6)
