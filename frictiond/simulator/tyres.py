"""Truth tyre models of the simulator: Burckhardt, Magic Formula and a dynamic lumped LuGre.

Deliberately independent of `frictiond.tyre_model` (the estimator's static distributed LuGre): the
simulator's truth must not share the estimator's structure or parameter values.

Every model is built for one surface (scalar parameters) or for the four wheels at once (parameters
stacked into arrays of shape (4,), see `stack`), and exposes, with braking-positive slip
`λ = (v − Rω)/max(v, Rω)` and `v` the wheel's ground speed [m/s]:

- `mu(slip, speed_mps)`          steady-state friction coefficient (odd in slip: traction is negative);
- `dmu_dslip(slip, speed_mps)`   its slope (used by the semi-implicit wheel integrator);
- `mu_max(speed_mps)`            the true peak over λ ∈ (0, 1] at that speed;
- `slip_at_mu_max(speed_mps)`    the slip of that peak (1.0 when μ(λ) rises monotonically, e.g. the
                                 Burckhardt ice set with c3 = 0).

Burckhardt with speed dependence (Burckhardt 1993; Kiencke & Nielsen):
    μ(λ, v) = (c1 (1 − e^(−c2 λ)) − c3 λ) e^(−c4 v)
Magic Formula (Pacejka), with a mild speed dependence of the peak factor:
    μ(λ, v) = D e^(−dv v) sin(C atan(Bλ − E(Bλ − atan Bλ)))
Dynamic lumped LuGre (Canudas-de-Wit et al. 2003, "average lumped" form with the patch-boundary term
κ|Rω|z), sliding speed s = v − Rω (positive braking):
    dz/dt = s − (θ σ0 |s| / g(s) + κ |Rω|) z,     μ = σ0 z + σ1 dz/dt + σ2 s,
    g(s) = μ_c + (μ_s − μ_c) exp(−|s / v_s|^α)
Its steady state (dz/dt = 0) is μ_ss(λ, v) = σ0 λ / (θ σ0 λ / g(λv) + κ (1 − λ)) + σ2 λ v, whose peak
and peak slip depend on speed; `mu_max` / `slip_at_mu_max` are tabulated on a speed grid.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Sequence

import numpy as np

SURFACES: tuple[str, ...] = ("dry", "wet", "snow", "ice", "cobblestone_wet")

_SLIP_GRID = np.concatenate([np.linspace(1e-4, 0.3, 3000), np.linspace(0.3, 1.0, 701)[1:]])


def _as(x) -> np.ndarray:
    return np.asarray(x, dtype=float)


# --------------------------------------------------------------------------- Burckhardt
@dataclass(frozen=True)
class BurckhardtParams:
    c1: float
    c2: float
    c3: float
    c4: float  # speed dependence [s/m]


BURCKHARDT_SURFACES: dict[str, BurckhardtParams] = {
    "dry": BurckhardtParams(1.2801, 23.99, 0.52, 0.020),
    "wet": BurckhardtParams(0.857, 33.822, 0.347, 0.025),
    "snow": BurckhardtParams(0.1946, 94.129, 0.0646, 0.020),
    "ice": BurckhardtParams(0.05, 306.39, 0.01, 0.020),  # c3 > 0: a peak below lock (published c3 = 0 has none)
    "cobblestone_wet": BurckhardtParams(0.4004, 33.708, 0.1204, 0.025),
}


class Burckhardt:
    family = "burckhardt"
    dynamic = False

    def __init__(self, c1, c2, c3, c4, surface: str | Sequence[str] = ""):
        self.c1, self.c2, self.c3, self.c4 = _as(c1), _as(c2), _as(c3), _as(c4)
        self.surface = surface
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.where(self.c3 > 0, np.log(self.c1 * self.c2 / np.where(self.c3 > 0, self.c3, 1.0)) / self.c2, 1.0)
        self._slip_star = np.clip(lam, 1e-4, 1.0)

    @classmethod
    def for_surface(cls, surface: str) -> "Burckhardt":
        p = BURCKHARDT_SURFACES[surface]
        return cls(p.c1, p.c2, p.c3, p.c4, surface)

    def mu(self, slip, speed_mps):
        s = np.abs(slip)
        return np.sign(slip) * (self.c1 * (1.0 - np.exp(-self.c2 * s)) - self.c3 * s) * np.exp(-self.c4 * _as(speed_mps))

    def dmu_dslip(self, slip, speed_mps):
        s = np.abs(slip)
        return (self.c1 * self.c2 * np.exp(-self.c2 * s) - self.c3) * np.exp(-self.c4 * _as(speed_mps))

    def slip_at_mu_max(self, speed_mps):
        return np.broadcast_to(self._slip_star, np.broadcast(self._slip_star, _as(speed_mps)).shape).copy()

    def mu_max(self, speed_mps):
        return self.mu(self._slip_star, speed_mps)


# --------------------------------------------------------------------------- Magic Formula
@dataclass(frozen=True)
class MagicFormulaParams:
    B: float
    C: float
    D: float
    E: float
    dv: float = 0.004  # mild speed dependence of D [s/m]: D(v) = D e^(−dv v)


MAGIC_FORMULA_SURFACES: dict[str, MagicFormulaParams] = {
    "dry": MagicFormulaParams(10.0, 1.9, 1.0, 0.97),
    "wet": MagicFormulaParams(12.0, 2.3, 0.82, 1.0),
    "snow": MagicFormulaParams(5.0, 2.0, 0.3, 1.0),
    "ice": MagicFormulaParams(4.0, 2.0, 0.1, 1.0),
    "cobblestone_wet": MagicFormulaParams(9.0, 2.0, 0.42, 1.0),
}


class MagicFormula:
    family = "magic-formula"
    dynamic = False

    def __init__(self, B, C, D, E, dv=0.004, surface: str | Sequence[str] = ""):
        self.B, self.C, self.D, self.E, self.dv = _as(B), _as(C), _as(D), _as(E), _as(dv)
        self.surface = surface
        # the peak slip does not depend on speed (only D does): locate it once on a grid
        g = _SLIP_GRID.reshape((-1,) + (1,) * self.B.ndim)
        curve = self._shape(g)
        i = np.argmax(curve, axis=0)
        self._slip_star = _SLIP_GRID[i]
        self._peak_shape = np.take_along_axis(curve, np.expand_dims(i, 0), 0)[0] if self.B.ndim else curve[i]

    @classmethod
    def for_surface(cls, surface: str) -> "MagicFormula":
        p = MAGIC_FORMULA_SURFACES[surface]
        return cls(p.B, p.C, p.D, p.E, p.dv, surface)

    def _shape(self, s):
        x = self.B * s
        return np.sin(self.C * np.arctan(x - self.E * (x - np.arctan(x))))

    def mu(self, slip, speed_mps):
        return np.sign(slip) * self.D * np.exp(-self.dv * _as(speed_mps)) * self._shape(np.abs(slip))

    def dmu_dslip(self, slip, speed_mps):
        x = self.B * np.abs(slip)
        phi = x - self.E * (x - np.arctan(x))
        dphi = 1.0 - self.E + self.E / (1.0 + x * x)
        return (self.D * np.exp(-self.dv * _as(speed_mps)) * self.C * np.cos(self.C * np.arctan(phi))
                / (1.0 + phi * phi) * dphi * self.B)

    def slip_at_mu_max(self, speed_mps):
        return np.broadcast_to(self._slip_star, np.broadcast(self._slip_star, _as(speed_mps)).shape).copy()

    def mu_max(self, speed_mps):
        return self.D * np.exp(-self.dv * _as(speed_mps)) * self._peak_shape


# --------------------------------------------------------------------------- dynamic LuGre
@dataclass(frozen=True)
class LugreParams:
    sigma0: float = 300.0     # bristle stiffness [1/m]
    sigma1: float = 0.4       # bristle damping [s/m]
    sigma2: float = 0.0005    # viscous term [s/m]
    mu_c: float = 0.72        # Coulomb level
    mu_s: float = 1.30        # static (Stribeck) level
    v_s: float = 3.5          # Stribeck speed [m/s]
    alpha: float = 0.8        # Stribeck exponent (the estimator's literature uses 1/2)
    kappa: float = 11.0       # lumped patch-boundary coefficient [1/m] (slip stiffness ≈ σ0/κ)
    theta: float = 1.0        # road condition (peak ~ 1/θ)


LUGRE_SURFACES: dict[str, LugreParams] = {
    "dry": LugreParams(theta=1.0),
    "wet": LugreParams(theta=1.45, v_s=2.5),
    "snow": LugreParams(theta=4.3, kappa=16.0, v_s=3.0, sigma2=0.0002),
    "ice": LugreParams(theta=11.0, kappa=25.0, v_s=3.0, sigma2=0.0001),
    "cobblestone_wet": LugreParams(theta=2.7, v_s=2.5),
}

_V_GRID = np.linspace(0.0, 70.0, 141)


class LugreDynamic:
    family = "lugre"
    dynamic = True

    def __init__(self, sigma0, sigma1, sigma2, mu_c, mu_s, v_s, alpha, kappa, theta, surface: str | Sequence[str] = "",
                 _tables=None):
        self.sigma0, self.sigma1, self.sigma2 = _as(sigma0), _as(sigma1), _as(sigma2)
        self.mu_c, self.mu_s, self.v_s, self.alpha = _as(mu_c), _as(mu_s), _as(v_s), _as(alpha)
        self.kappa, self.theta = _as(kappa), _as(theta)
        self.surface = surface
        if _tables is None:
            lam = _SLIP_GRID[:, None]
            curve = self._mu_ss(lam, _V_GRID[None, :])  # (n_slip, n_v), scalar params only
            i = np.argmax(curve, axis=0)
            _tables = (curve[i, np.arange(len(_V_GRID))], _SLIP_GRID[i])
        self._peak_table, self._slip_table = _tables

    @classmethod
    def for_surface(cls, surface: str) -> "LugreDynamic":
        p = LUGRE_SURFACES[surface]
        return cls(**{f.name: getattr(p, f.name) for f in fields(LugreParams)}, surface=surface)

    def g(self, sliding_mps):
        return self.mu_c + (self.mu_s - self.mu_c) * np.exp(-np.abs(sliding_mps / self.v_s) ** self.alpha)

    def _mu_ss(self, lam, v):
        s = np.abs(lam)
        return np.sign(lam) * (self.sigma0 * s / (self.theta * self.sigma0 * s / self.g(s * v) + self.kappa * (1.0 - s))
                               + self.sigma2 * s * v)

    def mu(self, slip, speed_mps):
        """Steady-state μ (dz/dt = 0); the simulation integrates the bristle state instead."""
        return self._mu_ss(_as(slip), _as(speed_mps))

    def dmu_dslip(self, slip, speed_mps, h=1e-5):
        slip = _as(slip)
        return (self.mu(slip + h, speed_mps) - self.mu(slip - h, speed_mps)) / (2 * h)

    def _interp(self, table, speed_mps):
        v = _as(speed_mps)
        if isinstance(table, list):  # stacked: one table per wheel
            vb = np.broadcast_to(v, (len(table),))
            return np.array([np.interp(vb[k], _V_GRID, t) for k, t in enumerate(table)])
        return np.interp(v, _V_GRID, table)

    def mu_max(self, speed_mps):
        return self._interp(self._peak_table, speed_mps)

    def slip_at_mu_max(self, speed_mps):
        return self._interp(self._slip_table, speed_mps)

    def steady_state_z(self, slip, speed_mps):
        """Bristle deflection in steady state (for initialising the dynamic state)."""
        s = _as(slip) * _as(speed_mps)
        rw = (1.0 - _as(slip)) * _as(speed_mps)
        return s / (self.theta * self.sigma0 * np.abs(s) / self.g(s) + self.kappa * np.abs(rw) + 1e-9)


FAMILIES = {"burckhardt": Burckhardt, "magic-formula": MagicFormula, "lugre": LugreDynamic}
# Names accepted for `truth_model` (the CLI offers these).
TRUTH_MODELS: dict[str, type] = dict(FAMILIES)


def make_tyre(family: str, surface: str):
    """One surface's truth model of a family ("burckhardt", "magic-formula", "lugre")."""
    if family not in FAMILIES:
        raise ValueError(f"unknown truth tyre model {family!r}; choose from {', '.join(sorted(FAMILIES))}")
    if surface not in SURFACES:
        raise ValueError(f"unknown surface {surface!r}; choose from {', '.join(SURFACES)}")
    return FAMILIES[family].for_surface(surface)


def stack(models: Sequence) -> object:
    """Four per-wheel models of one family → one model with parameter arrays of shape (4,)."""
    cls = type(models[0])
    if any(type(m) is not cls for m in models):
        raise ValueError("all wheels must use the same tyre model family")
    surfaces = tuple(m.surface for m in models)
    if cls is Burckhardt:
        return Burckhardt(*[np.array([getattr(m, a) for m in models]) for a in ("c1", "c2", "c3", "c4")], surfaces)
    if cls is MagicFormula:
        return MagicFormula(*[np.array([getattr(m, a) for m in models]) for a in ("B", "C", "D", "E", "dv")], surfaces)
    names = [f.name for f in fields(LugreParams)]
    tables = ([m._peak_table for m in models], [m._slip_table for m in models])
    return LugreDynamic(*[np.array([getattr(m, a) for m in models]) for a in names], surface=surfaces, _tables=tables)
