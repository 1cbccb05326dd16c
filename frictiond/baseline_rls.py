"""Baseline: recursive least squares on the linearised Burckhardt model (Tanelli et al. 2009).

    μ(λ) = c1 (1 − e^(−c2 λ)) − c3 λ

For a fixed c2 the model is linear in (c1, c3), so each wheel runs a small bank of 2-parameter
RLS filters with exponential forgetting, one per c2 on a grid spanning ice to dry asphalt; the
filter with the smallest recent prediction error is used (the multiple-model form of the
linearisation). Estimates are projected onto c1, c3 ≥ 0 (the constrained variant of de Castro
et al. 2012). Same outputs and the same honesty rules as the LuGre estimator, so the two can be
compared on identical input.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from .samples import N_WHEELS, FrictionEstimate, PhysicalSample, Status
from .vehicle import VehicleParams


@dataclass(frozen=True, slots=True)
class BurckhardtRLSOptions:
    """Tuning of the baseline; config keys under estimator.burckhardt_rls."""

    forgetting_factor: float = 0.985        # per sample (≈ 0.65 s memory at 100 Hz)
    c2_grid: tuple[float, ...] = (15.0, 25.0, 35.0, 55.0, 90.0, 150.0, 300.0)
    initial_covariance: float = 10.0
    error_time_constant: float = 0.3        # s; smoothing of each filter's prediction error
    min_slip: float = 0.003
    measurement_std: float = 0.04
    excitation_slip_ratio: float = 0.75
    excitation_min_slip: float = 0.03       # as the LuGre estimator: no road peaks below this
    valid_confidence: float = 0.5
    confidence_tolerance: float = 0.06
    hold_s: float = 2.0
    prior_c1: float = 1.0
    prior_c3: float = 0.3

    def validate(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and (not math.isfinite(value) or value < 0):
                raise ValueError(f"{f.name}: must be a finite number ≥ 0, got {value!r}")
        if not 0.5 < self.forgetting_factor <= 1.0:
            raise ValueError("forgetting_factor: must be in (0.5, 1]")
        if not self.c2_grid or any(c <= 0 for c in self.c2_grid):
            raise ValueError("c2_grid: must be a non-empty list of positive numbers")


def burckhardt_peak(c1: float, c2: float, c3: float) -> tuple[float, float]:
    """(μ_max, λ*) of the Burckhardt curve; λ* = 1 when it rises monotonically."""
    if c1 <= 0:
        return 0.0, 0.0
    if c3 <= 1e-9 or c1 * c2 <= c3:
        lam = 1.0 if c3 <= 1e-9 else 1e-3
    else:
        lam = min(1.0, math.log(c1 * c2 / c3) / c2)
    return c1 * (1.0 - math.exp(-c2 * lam)) - c3 * lam, lam


class _RLS2:
    """Two-parameter RLS with forgetting: μ ≈ a·φ1 + b·φ2."""

    __slots__ = ("a", "b", "p11", "p12", "p22", "error", "n")

    def __init__(self, a: float, b: float, p0: float) -> None:
        self.a, self.b = a, b
        self.p11, self.p12, self.p22 = p0, 0.0, p0
        self.error = 0.05
        self.n = 0

    def update(self, f1: float, f2: float, y: float, lam: float, err_alpha: float) -> None:
        e = y - (self.a * f1 + self.b * f2)
        self.error += err_alpha * (e * e - self.error)
        pf1 = self.p11 * f1 + self.p12 * f2
        pf2 = self.p12 * f1 + self.p22 * f2
        denom = lam + f1 * pf1 + f2 * pf2
        k1, k2 = pf1 / denom, pf2 / denom
        self.a += k1 * e
        self.b += k2 * e
        # Constrained variant: project onto c1 ≥ 0, c3 ≥ 0 (b = c3, φ2 = −λ).
        self.a = max(self.a, 0.0)
        self.b = max(self.b, 0.0)
        self.p11 = (self.p11 - k1 * pf1) / lam
        self.p12 = (self.p12 - k1 * pf2) / lam
        self.p22 = (self.p22 - k2 * pf2) / lam
        # Keep the covariance bounded when excitation is poor (wind-up under forgetting).
        limit = 1e4
        if self.p11 > limit or self.p22 > limit:
            scale = limit / max(self.p11, self.p22)
            self.p11 *= scale
            self.p12 *= scale
            self.p22 *= scale
        self.n += 1


class BurckhardtRLSEstimator:
    kind = "burckhardt-rls"

    def __init__(self, options: BurckhardtRLSOptions | None = None, vehicle: VehicleParams | None = None) -> None:
        self.options = options or BurckhardtRLSOptions()
        self.options.validate()
        self.vehicle = vehicle or VehicleParams()
        self.reset()

    def reset(self) -> None:
        o = self.options
        self._banks = [[_RLS2(o.prior_c1, o.prior_c3, o.initial_covariance) for _ in o.c2_grid]
                       for _ in range(N_WHEELS)]
        self._recent_slip = [0.0] * N_WHEELS
        self._last_valid: FrictionEstimate | None = None
        self._last_excited_s = -math.inf
        self._last_time: float | None = None

    def state(self) -> dict[str, Any]:
        best = [self._best(i) for i in range(N_WHEELS)]
        return {"kind": self.kind, "parameters": [[b.a, c2, b.b] for b, c2 in best]}

    def load_state(self, state: dict[str, Any]) -> None:
        if not isinstance(state, dict) or state.get("kind") != self.kind:
            raise ValueError("state is not from the burckhardt-rls estimator")
        params = state.get("parameters")
        if not isinstance(params, list) or len(params) != N_WHEELS:
            raise ValueError("state lacks per-wheel parameters")
        self.reset()
        for i, row in enumerate(params):
            if not (isinstance(row, list) and len(row) == 3 and all(isinstance(v, (int, float)) and math.isfinite(v) for v in row)):
                raise ValueError("bad parameter row in state")
            for f in self._banks[i]:
                f.a, f.b = max(0.0, float(row[0])), max(0.0, float(row[2]))

    def _best(self, i: int) -> tuple[_RLS2, float]:
        bank = self._banks[i]
        k = min(range(len(bank)), key=lambda j: bank[j].error)
        return bank[k], self.options.c2_grid[k]

    def update(self, sample: PhysicalSample) -> FrictionEstimate:
        o = self.options
        t = sample.time_s
        dt = 0.01 if self._last_time is None else min(max(t - self._last_time, 1e-4), 0.1)
        self._last_time = t
        err_alpha = 1.0 - math.exp(-dt / o.error_time_constant)
        decay = math.exp(-dt / 0.3)
        added = False
        for i in range(N_WHEELS):
            slip = sample.slip[i]
            self._recent_slip[i] *= decay
            if not (sample.usable[i] and slip >= o.min_slip and math.isfinite(sample.mu_used[i])):
                continue
            added = True
            self._recent_slip[i] = max(self._recent_slip[i], slip)
            for f, c2 in zip(self._banks[i], o.c2_grid):
                f.update(1.0 - math.exp(-c2 * slip), -slip, sample.mu_used[i], o.forgetting_factor, err_alpha)
        if not added:
            return self._hold(t)
        wheel_mu, wheel_lam, variances, excited = [], [], [], 0.0
        for i in range(N_WHEELS):
            f, c2 = self._best(i)
            m, lam = burckhardt_peak(f.a, c2, f.b)
            wheel_mu.append(m)
            wheel_lam.append(lam)
            # Delta method on (c1, c3): ∂μmax/∂c1 = 1 − e^(−c2λ*), ∂μmax/∂c3 = −λ*.
            g1, g2 = 1.0 - math.exp(-c2 * lam), -lam
            var = (g1 * g1 * f.p11 + 2 * g1 * g2 * f.p12 + g2 * g2 * f.p22) * max(f.error, o.measurement_std**2)
            variances.append(var * (1.0 - o.forgetting_factor) * 2.0)
            if lam > 0 and self._recent_slip[i] >= max(o.excitation_slip_ratio * lam, o.excitation_min_slip):
                excited = max(excited, min(1.0, self._recent_slip[i] / lam))
        mu_max = sum(wheel_mu) / N_WHEELS
        std = math.sqrt(max(sum(variances), 0.0)) / N_WHEELS
        confidence = math.exp(-0.5 * (std / max(mu_max, 0.05) / o.confidence_tolerance) ** 2) * (1.0 if excited else 0.0)
        slip_star = sum(wheel_lam) / N_WHEELS
        if excited and confidence >= o.valid_confidence:
            status = Status.VALID
            self._last_excited_s = t
        elif excited:
            status = Status.CONVERGING
        else:
            return self._hold(t, (mu_max, slip_star, tuple(wheel_mu)))
        est = FrictionEstimate(t, status, mu_max, slip_star, 1.0, confidence, tuple(wheel_mu), std)
        if status == Status.VALID:
            self._last_valid = est
        return est

    def _hold(self, t: float, fitted: tuple | None = None) -> FrictionEstimate:
        last = self._last_valid
        if last is not None and t - self._last_excited_s <= self.options.hold_s:
            return FrictionEstimate(t, Status.VALID, last.mu_max, last.slip_at_mu_max, 1.0, last.confidence,
                                    last.wheel_mu_max, last.mu_max_std)
        if last is not None:
            return FrictionEstimate(t, Status.NOT_EXCITED, last.mu_max, last.slip_at_mu_max, 1.0, 0.0,
                                    last.wheel_mu_max)
        if fitted is None:
            f, c2 = self._best(0)
            m, lam = burckhardt_peak(f.a, c2, f.b)
            fitted = (m, lam, (m,) * N_WHEELS)
        return FrictionEstimate(t, Status.NOT_EXCITED, fitted[0], fitted[1], 1.0, 0.0, fitted[2])

    def mu_curve(self, slip, speed_mps: float, wheel: int | None = None):
        import numpy as np

        slip = np.asarray(slip, dtype=float)
        curves = []
        for i in range(N_WHEELS) if wheel is None else [wheel]:
            f, c2 = self._best(i)
            curves.append(f.a * (1 - np.exp(-c2 * slip)) - f.b * slip)
        return np.mean(curves, axis=0)
