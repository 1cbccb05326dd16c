"""Truth tyre models of the campaign, independent of the estimator's (no LuGre here, on purpose).

A tyre curve is separable: μ(λ, v) = base(λ) · m(v), with `base` a Burckhardt or Magic Formula
curve in slip (or, for the stress run `Stress.tyre_model`, Rill's TMeasy curve: `tmeasy_like`)
and `m(v)` a linear speed factor of either sign. Separable
keeps the truth cheap: the peak over slip at any speed is the base curve's peak times m(v), and
its slip does not move with speed. The estimator's LuGre model makes the peak move with speed;
a truth that does not is one of the mismatches the campaign is there to show.

The speed factor is clipped to [0.6, 1.2]: grip that grows with speed exists (some wet
surfaces, drainage) but not by half again.

An optional relaxation length σ turns the steady-state force into a first-order lag
(σ / v) dF/dt + F = F_ss, which `simulate.py` integrates with the wheel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

# Burckhardt (c1, c2, c3) per surface: Burckhardt 1993 as tabulated by Kiencke & Nielsen (2000),
# the values the literature and frictiond's docs use.
BURCKHARDT_SURFACES: dict[str, tuple[float, float, float]] = {
    "dry_asphalt": (1.2801, 23.99, 0.52),
    "wet_asphalt": (0.857, 33.822, 0.347),
    "cobblestone_dry": (1.3713, 6.4565, 0.6691),
    "cobblestone_wet": (0.4004, 33.708, 0.1204),
    "snow": (0.1946, 94.129, 0.0646),
    "ice": (0.05, 306.39, 0.0),
}

SPEED_REF_MPS = 15.0           # the speed where m(v) = 1
SPEED_FACTOR_MIN, SPEED_FACTOR_MAX = 0.6, 1.2
SLIP_GRID = np.linspace(0.0, 1.0, 1001)


@dataclass(frozen=True, slots=True)
class TyreCurve:
    """One tyre on one surface: `kind` is "burckhardt", "magic-formula" or "tmeasy"; `params` its
    coefficients, (c1, c2, c3), (B, C, D, E) or (dF0, s_M, F_M, s_S, F_S) (`tmeasy_base`);
    `speed_slope` k of m(v) = 1 + k (v − 15)/15; `label` names the surface it was drawn around (for
    the tables)."""

    kind: str
    params: tuple[float, ...]
    speed_slope: float = 0.0
    label: str = ""

    def base(self, slip: np.ndarray | float) -> np.ndarray:
        lam = np.clip(np.asarray(slip, dtype=float), 0.0, 1.0)
        if self.kind == "burckhardt":
            c1, c2, c3 = self.params
            return c1 * (1.0 - np.exp(-c2 * lam)) - c3 * lam
        if self.kind == "magic-formula":
            b, c, d, e = self.params
            x = b * lam
            return d * np.sin(c * np.arctan(x - e * (x - np.arctan(x))))
        if self.kind == "tmeasy":
            return tmeasy_base(lam, *self.params)
        raise ValueError(f"unknown tyre kind {self.kind!r}")

    def speed_factor(self, speed_mps: np.ndarray | float) -> np.ndarray:
        m = 1.0 + self.speed_slope * (np.asarray(speed_mps, dtype=float) - SPEED_REF_MPS) / SPEED_REF_MPS
        return np.clip(m, SPEED_FACTOR_MIN, SPEED_FACTOR_MAX)

    def mu(self, slip: np.ndarray | float, speed_mps: np.ndarray | float) -> np.ndarray:
        """Utilised friction at braking slip λ ≥ 0 (the sign is applied by the caller)."""
        return self.base(slip) * self.speed_factor(speed_mps)

    @property
    def peak(self) -> tuple[float, float]:
        """(μ_peak of the base curve, slip at the peak), on a 0.001 slip grid."""
        return _peak(self)


_PEAK_CACHE: dict[TyreCurve, tuple[float, float]] = {}


def _peak(curve: TyreCurve) -> tuple[float, float]:
    hit = _PEAK_CACHE.get(curve)
    if hit is None:
        mu = curve.base(SLIP_GRID)
        k = int(np.argmax(mu))
        hit = (float(mu[k]), float(SLIP_GRID[k]))
        if len(_PEAK_CACHE) > 4096:   # a worker runs thousands of stops: bound the memo
            _PEAK_CACHE.clear()
        _PEAK_CACHE[curve] = hit
    return hit


def magic_formula_plausible(params: tuple[float, float, float, float]) -> bool:
    """A drawn (B, C, D, E) is kept when its curve is a tyre: single rise to the peak and, past
    it, never below 25 % of D up to full lock (C near 2.5 with E < 0 turns sin(·) negative)."""
    b, c, d, e = params
    curve = TyreCurve("magic-formula", params)
    mu = curve.base(SLIP_GRID)
    k = int(np.argmax(mu))
    if mu[k] < 0.9 * d or SLIP_GRID[k] < 0.02 or SLIP_GRID[k] > 0.5:
        return False
    return bool(np.min(mu[k:]) >= 0.25 * d and np.all(np.diff(mu[: k + 1]) >= -1e-9))


def tmeasy_base(slip: np.ndarray, d_f0: float, s_m: float, f_m: float, s_s: float, f_s: float) -> np.ndarray:
    """Rill's TMeasy longitudinal curve over F_z (G. Rill, "Road Vehicle Dynamics", 2012, ch. 3):
    from the initial slope `d_f0` a rational rise to the peak `f_m` at slip `s_m`, where its
    slope is 0; a cubic fall to the sliding level `f_s`, reached with zero slope at `s_s`; then
    flat. Its pieces are none of the estimator's or the campaign's other shapes: a tyre the
    estimator was never tuned on."""
    lam = np.asarray(slip, dtype=float)
    sigma = lam / s_m
    rise = d_f0 * lam / (1.0 + sigma * (sigma + d_f0 * s_m / f_m - 2.0))
    u = np.clip((lam - s_m) / (s_s - s_m), 0.0, 1.0)
    fall = f_m - (f_m - f_s) * u * u * (3.0 - 2.0 * u)
    return np.where(lam <= s_m, rise, fall)


def tmeasy_like(curve: TyreCurve, rng: np.random.Generator) -> TyreCurve:
    """A TMeasy tyre with `curve`'s peak μ, speed factor and label (prefixed "tm-"), its shape
    drawn: the peak's slip that of `curve` within 0.05–0.30 (0.05–0.15 for a curve still rising at
    lock, Burckhardt's ice); the initial slope the tyre's longitudinal stiffness over its load,
    12–30 whatever the road (a property of the tyre), at least 1.5 times the secant to the peak (a
    round top; on ice a sharp knee far below the peak's slip); the sliding level 55–95 % of the
    peak, reached at slip 0.35–0.9."""
    f_m, s_peak = curve.peak
    s_m = float(np.clip(s_peak, 0.05, 0.30)) if s_peak < 0.9 else float(rng.uniform(0.05, 0.15))
    d_f0 = max(float(rng.uniform(12.0, 30.0)), 1.5 * f_m / s_m)
    s_s = float(rng.uniform(max(1.5 * s_m + 0.05, 0.35), 0.9))
    f_s = float(rng.uniform(0.55, 0.95)) * f_m
    return TyreCurve("tmeasy", (d_f0, s_m, f_m, s_s, f_s), curve.speed_slope, "tm-" + curve.label)


def slip_for_force(curve: TyreCurve, mu_wanted: float, speed_mps: float) -> float:
    """Smallest slip where the curve reaches `mu_wanted` (the peak's slip if it never does)."""
    mu = curve.mu(SLIP_GRID, speed_mps)
    idx = np.nonzero(mu >= mu_wanted)[0]
    return float(SLIP_GRID[idx[0]]) if len(idx) else curve.peak[1]


def scalar_speed_factor(curve: TyreCurve) -> Callable[[float], float]:
    """m(v) in plain floats."""
    k_v = curve.speed_slope

    def factor(v: float) -> float:
        return min(max(1.0 + k_v * (v - SPEED_REF_MPS) / SPEED_REF_MPS, SPEED_FACTOR_MIN), SPEED_FACTOR_MAX)

    return factor


def scalar_model(curve: TyreCurve) -> Callable[[float, float], tuple[float, float]]:
    """(λ, v) → (μ, dμ/dλ) in plain floats for the 1 kHz integration (numpy on four numbers a
    step costs more than the arithmetic). Odd in λ: traction slip gives a driving force."""
    factor = scalar_speed_factor(curve)

    if curve.kind == "burckhardt":
        c1, c2, c3 = curve.params

        def base(lam: float) -> tuple[float, float]:
            e = math.exp(-c2 * lam)
            return c1 * (1.0 - e) - c3 * lam, c1 * c2 * e - c3
    elif curve.kind == "tmeasy":
        d_f0, s_m, f_m, s_s, f_s = curve.params
        knee = d_f0 * s_m / f_m - 2.0

        def base(lam: float) -> tuple[float, float]:
            if lam <= s_m:
                sigma = lam / s_m
                den = 1.0 + sigma * (sigma + knee)
                return d_f0 * lam / den, d_f0 * (1.0 - sigma * sigma) / (den * den)
            if lam >= s_s:
                return f_s, 0.0
            u = (lam - s_m) / (s_s - s_m)
            return f_m - (f_m - f_s) * u * u * (3.0 - 2.0 * u), -(f_m - f_s) * 6.0 * u * (1.0 - u) / (s_s - s_m)
    else:
        b, c, d, e_ = curve.params

        def base(lam: float) -> tuple[float, float]:
            x = b * lam
            phi = x - e_ * (x - math.atan(x))
            arg = c * math.atan(phi)
            dphi = b * (1.0 - e_ + e_ / (1.0 + x * x))
            return d * math.sin(arg), d * math.cos(arg) * c / (1.0 + phi * phi) * dphi

    def model(lam: float, v: float) -> tuple[float, float]:
        sign = 1.0 if lam >= 0.0 else -1.0
        a = min(abs(lam), 1.0)
        mu, slope = base(a)
        m = factor(v)
        return sign * mu * m, (slope * m if abs(lam) < 1.0 else 0.0)

    return model


def relaxation_time_s(length_m: float, speed_mps: float) -> float:
    """σ / v, bounded below so that the lag stays finite at standstill."""
    return length_m / max(speed_mps, 0.5) if length_m > 0 else 0.0


__all__ = ["BURCKHARDT_SURFACES", "TyreCurve", "magic_formula_plausible", "slip_for_force", "tmeasy_base",
           "tmeasy_like", "scalar_model", "scalar_speed_factor", "relaxation_time_s"]
