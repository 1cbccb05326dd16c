"""Truth tyre models of the campaign, independent of the estimator's (no LuGre here, on purpose).

A tyre curve is separable: μ(λ, v) = base(λ) · m(v), with `base` a Burckhardt or Magic Formula
curve in slip and `m(v)` a linear speed factor of either sign. Separable
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
    """One tyre on one surface: `kind` is "burckhardt" or "magic-formula"; `params` its
    coefficients, (c1, c2, c3) or (B, C, D, E); `speed_slope` k of m(v) = 1 + k (v − 15)/15;
    `label` names the surface it was drawn around (for the tables)."""

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


__all__ = ["BURCKHARDT_SURFACES", "TyreCurve", "magic_formula_plausible", "slip_for_force",
           "scalar_model", "scalar_speed_factor", "relaxation_time_s"]
