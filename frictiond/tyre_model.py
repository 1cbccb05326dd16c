"""Static (steady-state, distributed) LuGre tyre model: μ(λ, v; p), its Jacobian and its peak.

With braking-positive slip λ, vehicle speed v, sliding speed u = λ v (model.md):

    g(u)    = μ_c + (μ_s − μ_c) exp(−(u / v_s)^α)
    Z(λ, v) = θ σ0 L λ / (g(u) (1 − λ))
    μ(λ, v) = (g(u) / θ) · F(Z) + σ2 λ v,      F(Z) = 1 − (1 − e^(−Z)) / Z

Traction (λ < 0) is the odd extension. All functions are vectorised over samples; the parameter
vector is a `LugreParams`. Pure numpy, nothing of CAN.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

try:
    # The peak search and the partials at a handful of points, compiled with the estimator's
    # fit (setup.py); the float code below is the fallback and the reference (tests compare).
    from . import _fitcore as _compiled
except ImportError:  # pragma: no cover - depends on the install
    _compiled = None

# Slip is kept away from 1 (locked wheel: Z → ∞) so every formula stays finite.
MAX_MODEL_SLIP = 0.98
# Below this Z the closed form of F loses digits to cancellation; use the series instead.
_SMALL_Z = 1e-4

PARAMETER_NAMES = ("theta", "sigma0", "sigma2", "mu_c", "mu_s", "v_s", "alpha", "patch_length")


@dataclass(frozen=True, slots=True)
class LugreParams:
    """Static LuGre parameters; defaults are Canudas-de-Wit et al. 2003 (α = ½, L = 0.2 m)."""

    theta: float = 1.0          # road condition: 1 dry, larger is more slippery (peak ~ 1/θ)
    sigma0: float = 181.54      # bristle stiffness [1/m]
    sigma2: float = 0.0018      # viscous friction [s/m]
    mu_c: float = 0.8           # Coulomb level
    mu_s: float = 1.55          # static level
    v_s: float = 6.57           # Stribeck speed [m/s]
    alpha: float = 0.5          # Stribeck exponent
    patch_length: float = 0.2   # contact patch length L [m]

    def with_values(self, **values: float) -> "LugreParams":
        return replace(self, **values)

    def as_dict(self) -> dict[str, float]:
        return {f.name: float(getattr(self, f.name)) for f in fields(self)}


def _F_and_dF(Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """F(Z) = 1 − (1 − e^−Z)/Z and F'(Z), accurate for small Z."""
    small = Z < _SMALL_Z
    Zs = np.where(small, 1.0, Z)
    em = np.exp(-Zs)
    one_minus = -np.expm1(-Zs)
    F = 1.0 - one_minus / Zs
    dF = (one_minus - Zs * em) / (Zs * Zs)
    if small.any():
        F = np.where(small, Z / 2.0 - Z * Z / 6.0, F)
        dF = np.where(small, 0.5 - Z / 3.0, dF)
    return F, dF


def _stribeck(u: np.ndarray, p: LugreParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """g(u), e = exp(−(u/v_s)^α) and (u/v_s)^α."""
    ratio = (np.maximum(u, 0.0) / p.v_s) ** p.alpha
    e = np.exp(-ratio)
    return p.mu_c + (p.mu_s - p.mu_c) * e, e, ratio


def mu(slip, speed_mps, p: LugreParams) -> np.ndarray:
    """Utilised friction in steady state for braking-positive slip (odd in slip)."""
    slip = np.asarray(slip, dtype=float)
    sign = np.sign(slip)
    lam = np.minimum(np.abs(slip), MAX_MODEL_SLIP)
    v = np.asarray(speed_mps, dtype=float)
    g, _, _ = _stribeck(lam * v, p)
    Z = p.theta * p.sigma0 * p.patch_length * lam / (g * (1.0 - lam))
    F, _ = _F_and_dF(Z)
    return sign * ((g / p.theta) * F + p.sigma2 * lam * v)


def mu_and_jacobian(slip, speed_mps, p: LugreParams, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """μ at the samples and ∂μ/∂p for the named parameters (columns in the order of `names`)."""
    slip = np.asarray(slip, dtype=float)
    sign = np.sign(slip)
    lam = np.minimum(np.abs(slip), MAX_MODEL_SLIP)
    v = np.asarray(speed_mps, dtype=float)
    u = lam * v
    g, e, ratio = _stribeck(u, p)
    theta = p.theta
    k = p.sigma0 * p.patch_length
    Z = theta * k * lam / (g * (1.0 - lam))
    F, dF = _F_and_dF(Z)
    value = sign * ((g / theta) * F + p.sigma2 * lam * v)
    dmu_dg = (F - Z * dF) / theta
    columns = []
    for name in names:
        if name == "theta":
            col = (g / (theta * theta)) * (Z * dF - F)
        elif name == "sigma0":
            col = (g / theta) * dF * Z / p.sigma0
        elif name == "patch_length":
            col = (g / theta) * dF * Z / p.patch_length
        elif name == "sigma2":
            col = lam * v
        elif name == "mu_c":
            col = dmu_dg * (1.0 - e)
        elif name == "mu_s":
            col = dmu_dg * e
        elif name == "v_s":
            col = dmu_dg * (p.mu_s - p.mu_c) * e * p.alpha * ratio / p.v_s
        elif name == "alpha":
            with np.errstate(divide="ignore", invalid="ignore"):
                log_ratio = np.where(u > 0, np.log(np.maximum(u, 1e-300) / p.v_s), 0.0)
            col = dmu_dg * (p.mu_s - p.mu_c) * e * (-ratio * log_ratio)
        else:
            raise ValueError(f"unknown LuGre parameter {name!r}")
        columns.append(sign * col)
    jac = np.stack(columns, axis=-1) if columns else np.zeros(value.shape + (0,))
    return value, jac


def mu_and_jacobian_theta(slip, speed_mps, theta, p: LugreParams, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """As `mu_and_jacobian`, with θ given per sample (pooled fits with one θ per wheel)."""
    slip = np.asarray(slip, dtype=float)
    theta = np.asarray(theta, dtype=float)
    sign = np.sign(slip)
    lam = np.minimum(np.abs(slip), MAX_MODEL_SLIP)
    v = np.asarray(speed_mps, dtype=float)
    u = lam * v
    g, e, ratio = _stribeck(u, p)
    k = p.sigma0 * p.patch_length
    Z = theta * k * lam / (g * (1.0 - lam))
    F, dF = _F_and_dF(Z)
    g_over_theta = g / theta
    value = sign * (g_over_theta * F + p.sigma2 * lam * v)
    dmu_dg = (F - Z * dF) / theta
    columns = []
    for name in names:
        if name == "theta":
            col = (g_over_theta / theta) * (Z * dF - F)
        elif name == "sigma0":
            col = g_over_theta * dF * Z / p.sigma0
        elif name == "sigma2":
            col = lam * v
        elif name == "v_s":
            col = dmu_dg * (p.mu_s - p.mu_c) * e * p.alpha * ratio / p.v_s
        elif name == "mu_s":
            col = dmu_dg * e
        elif name == "mu_c":
            col = dmu_dg * (1.0 - e)
        else:
            raise ValueError(f"parameter {name!r} is not supported in per-sample θ fits")
        columns.append(sign * col)
    return value, np.stack(columns, axis=-1)


def braking_mu_and_partials(lam: np.ndarray, v: np.ndarray, theta: np.ndarray, p: LugreParams,
                            out: np.ndarray) -> np.ndarray:
    """Fast path of the estimator: μ and ∂μ/∂(θ, σ0, v_s, σ2) for positive (braking) slip.

    Writes the four partials into the columns of `out` (shape (m, 4)) and returns μ. Same
    formulas as `mu_and_jacobian_theta`, with the work shared between columns (this runs several
    times per bus cycle).
    """
    lam = np.minimum(lam, MAX_MODEL_SLIP)
    lam_v = lam * v
    ratio = (lam_v * (1.0 / p.v_s)) ** p.alpha
    e = np.exp(-ratio)
    dmu_s = p.mu_s - p.mu_c
    g = p.mu_c + dmu_s * e
    inv_theta = 1.0 / theta
    Z = theta * (p.sigma0 * p.patch_length) * lam / (g * (1.0 - lam))
    Zs = np.maximum(Z, _SMALL_Z)
    one_minus = -np.expm1(-Zs)
    inv_Z = 1.0 / Zs
    F = 1.0 - one_minus * inv_Z
    dF = (one_minus - Zs * np.exp(-Zs)) * inv_Z * inv_Z
    small = Z < _SMALL_Z
    if small.any():
        F = np.where(small, Z / 2.0 - Z * Z / 6.0, F)
        dF = np.where(small, 0.5 - Z / 3.0, dF)
    g_over_theta = g * inv_theta
    ZdF = Z * dF
    out[:, 0] = g_over_theta * inv_theta * (ZdF - F)
    out[:, 1] = g_over_theta * ZdF * (1.0 / p.sigma0)
    out[:, 2] = (F - ZdF) * inv_theta * dmu_s * e * (p.alpha / p.v_s) * ratio
    out[:, 3] = lam_v
    return g_over_theta * F + p.sigma2 * lam_v


def compiled_params(p: LugreParams) -> tuple[float, ...]:
    """The parameters as the compiled tyre-model functions take them (`_fitcore.c`)."""
    return (p.mu_c, p.mu_s - p.mu_c, p.alpha, p.sigma0, p.sigma0 * p.patch_length, p.v_s, p.sigma2)


def braking_mu_and_partials_few(lam, v: float, theta, p: LugreParams) -> tuple[np.ndarray, np.ndarray]:
    """`braking_mu_and_partials` at one speed for a handful of (λ, θ) pairs, in floats.

    Returns μ (k,) and the partials (k, 4); for the few points of a peak this is much cheaper
    than the array path.
    """
    lams = np.asarray(lam, dtype=float).ravel().tolist()
    thetas = np.asarray(theta, dtype=float).ravel().tolist()
    if _compiled is not None and len(lams) == len(thetas) <= 16:
        mus, flat = _compiled.mu_partials_few(lams, float(v), thetas, compiled_params(p))
        return np.array(mus), np.array(flat).reshape(-1, 4)
    exp, expm1 = math.exp, math.expm1
    mu_c, dmu, alpha, sigma0, v_s, sigma2 = p.mu_c, p.mu_s - p.mu_c, p.alpha, p.sigma0, p.v_s, p.sigma2
    k = sigma0 * p.patch_length
    inv_v_s, inv_sigma0, c_v_s = 1.0 / v_s, 1.0 / sigma0, alpha / v_s
    mus, rows = [], []
    for lam_i, theta_i in zip(lams, thetas):
        lam_i = min(lam_i, MAX_MODEL_SLIP)
        lam_v = lam_i * v
        ratio = (lam_v * inv_v_s) ** alpha if lam_v >= 0 else math.nan
        e = exp(-ratio)
        g = mu_c + dmu * e
        inv_theta = 1.0 / theta_i
        Z = theta_i * k * lam_i / (g * (1.0 - lam_i))
        if Z < _SMALL_Z:
            F = Z / 2.0 - Z * Z / 6.0
            dF = 0.5 - Z / 3.0
        else:
            one_minus = -expm1(-Z)
            inv_Z = 1.0 / Z
            F = 1.0 - one_minus * inv_Z
            dF = (one_minus - Z * exp(-Z)) * inv_Z * inv_Z
        g_over_theta = g * inv_theta
        ZdF = Z * dF
        rows.append((g_over_theta * inv_theta * (ZdF - F), g_over_theta * ZdF * inv_sigma0,
                     (F - ZdF) * inv_theta * dmu * e * c_v_s * ratio, lam_v))
        mus.append(g_over_theta * F + sigma2 * lam_v)
    return np.array(mus), np.array(rows).reshape(-1, 4)


# Peak search: a fixed slip grid, then a fine grid around the best point and a parabola
# through the three best fine points. Vectorised over several θ (one per wheel).
_PEAK_GRID = np.geomspace(2e-3, MAX_MODEL_SLIP, 48)
_FINE = np.linspace(-1.0, 1.0, 21)


def peaks(speed_mps: float, p: LugreParams, thetas, near=None) -> tuple[np.ndarray, np.ndarray]:
    """(μ_max, λ*) at one vehicle speed for each θ in `thetas` (other parameters from `p`).

    `near` (previous λ* per θ) skips the coarse search when the peak is still bracketed by ±8 %
    around it — the usual case for a recursive caller whose fit moves a little per update.
    """
    v = float(speed_mps)
    if near is not None:
        found = _peaks_near(v, p, thetas, near)
        if found is not None:
            return found
    thetas = np.atleast_1d(np.asarray(thetas, dtype=float))
    if _compiled is not None and thetas.ndim == 1 and len(thetas) <= 16:
        mus, lams = _compiled.peaks_grid(v, thetas.tolist(), _PEAK_GRID, _FINE, compiled_params(p))
        return np.array(mus), np.array(lams)
    thetas = thetas[:, None]
    grid = _PEAK_GRID[None, :]
    values = _mu_grid(grid, v, thetas, p)
    # The tyre's peak is the first local maximum: with a large viscous term σ2·λ·v the curve
    # can dip after it and climb again towards lock, which is not a grip the road offers.
    falling = np.diff(values, axis=1) < 0
    i = np.where(falling.any(axis=1), np.argmax(falling, axis=1), len(_PEAK_GRID) - 1)
    lo = _PEAK_GRID[np.maximum(i - 1, 0)]
    hi = _PEAK_GRID[np.minimum(i + 1, len(_PEAK_GRID) - 1)]
    centre = _PEAK_GRID[i]
    half = np.maximum(centre - lo, hi - centre)[:, None]
    fine = np.minimum(np.maximum(centre[:, None] + half * _FINE[None, :], 1e-4), MAX_MODEL_SLIP)
    fv = _mu_grid(fine, v, thetas, p)
    return _refine(fine, fv, np.argmax(fv, axis=1), v, thetas, p)


def _peaks_near(v: float, p: LugreParams, thetas, near) -> tuple[np.ndarray, np.ndarray] | None:
    """The bracketed refinement of `peaks` around `near`, in scalars (a handful of θ: cheaper
    than arrays); None when some peak is not bracketed (then the caller searches the grid)."""
    exp, expm1 = math.exp, math.expm1
    mu_c, dmu, alpha, theta_k = p.mu_c, p.mu_s - p.mu_c, p.alpha, p.sigma0 * p.patch_length
    v_ratio, s2v = v / p.v_s, p.sigma2 * v
    low, high = 2e-3, 0.9 * MAX_MODEL_SLIP

    def mu_at(lam: float, theta: float) -> float:
        g = mu_c + dmu * exp(-((lam * v_ratio) ** alpha))
        Z = (theta * theta_k) * lam / (g * (1.0 - lam))
        if Z < _SMALL_Z:
            Z = _SMALL_Z
        return (g / theta) * (1.0 + expm1(-Z) / Z) + s2v * lam

    if not (v_ratio > 0 and math.isfinite(v_ratio)):
        return None
    mus, lams = [], []
    theta_list = np.asarray(thetas, dtype=float).ravel().tolist()
    near_list = np.asarray(near, dtype=float).ravel().tolist()
    if len(theta_list) != len(near_list):
        return None
    if _compiled is not None and len(theta_list) <= 16:
        found = _compiled.peaks_near(v, theta_list, near_list, compiled_params(p))
        return None if found is None else (np.array(found[0]), np.array(found[1]))
    pairs = list(zip(theta_list, near_list))
    for theta, lam in pairs:
        # Parabolic steps through three points around the previous peak; each must find the
        # middle point highest (the peak bracketed). A recursive fit moves its peak a little per
        # update: when the first step lands within a quarter of its bracket, the parabola's
        # error (third order in the bracket) is far below what μ_max can resolve on that flat top
        # and the second, finer step is skipped.
        lam = min(max(lam, low), high)
        for h_rel in (0.08, 0.02):
            h = h_rel * lam
            try:
                y0, y1, y2 = mu_at(lam - h, theta), mu_at(lam, theta), mu_at(lam + h, theta)
            except (ArithmeticError, ValueError):
                return None
            denom = y0 - 2 * y1 + y2
            if not (denom < 0 and y1 >= y0 and y1 >= y2):
                return None
            shift = 0.5 * (y0 - y2) / denom
            lam = lam + shift * h
            if abs(shift) <= 0.25:
                break
        try:
            mus.append(mu_at(lam, theta))
        except (ArithmeticError, ValueError):
            return None
        lams.append(lam)
    return np.array(mus), np.array(lams)


def _refine(fine, fv, j, v, thetas, p) -> tuple[np.ndarray, np.ndarray]:
    """Parabola through the best fine-grid point and its neighbours."""
    j = np.minimum(np.maximum(j, 1), fine.shape[1] - 2)
    rows = np.arange(len(j))
    y0, y1, y2 = fv[rows, j - 1], fv[rows, j], fv[rows, j + 1]
    x1 = fine[rows, j]
    h = fine[rows, j + 1] - x1
    denom = y0 - 2 * y1 + y2
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.where(denom < 0, 0.5 * (y0 - y2) / denom, 0.0)
    shift = np.minimum(np.maximum(shift, -1.0), 1.0)
    lam_star = np.minimum(np.maximum(x1 + shift * h, 1e-4), MAX_MODEL_SLIP)
    # Evaluate at the refined slip rather than trusting the parabola's height (at the edge of
    # the slip range the curve is not a parabola).
    mu_star = _mu_grid(lam_star[:, None], v, thetas, p)[:, 0]
    return np.maximum(mu_star, y1), lam_star


def _mu_grid(lam: np.ndarray, v: float, thetas: np.ndarray, p: LugreParams) -> np.ndarray:
    """μ on a slip grid (lean: used only by the peak search, where Z is never tiny)."""
    g = p.mu_c + (p.mu_s - p.mu_c) * np.exp(-((lam * (v / p.v_s)) ** p.alpha))
    Z = np.maximum((thetas * (p.sigma0 * p.patch_length)) * lam / (g * (1.0 - lam)), _SMALL_Z)
    return (g / thetas) * (1.0 + np.expm1(-Z) / Z) + (p.sigma2 * v) * lam


def supported_slip(support: np.ndarray, peak_extrapolation: float, extrapolation_max_slip: float) -> np.ndarray:
    """The furthest slip a fitted curve's peak may be read at, from the highest slips its data
    reached (`support`, per wheel): `peak_extrapolation` times them, and beyond them no further
    than `extrapolation_max_slip`. Past that the curve's rise is the model's shape, not the
    tyre's (the wheels' peak report, compiled in `_fitcore.peak_report` too, and the car's total
    force both hold their peaks to it)."""
    return np.minimum(support * peak_extrapolation, np.maximum(support, extrapolation_max_slip))


def peak(speed_mps: float, p: LugreParams) -> tuple[float, float]:
    """(μ_max, λ*) at one vehicle speed: the first maximum of μ(λ, v) over braking slip."""
    m, lam = peaks(speed_mps, p, [p.theta])
    return float(m[0]), float(lam[0])


def peak_gradient(speed_mps: float, p: LugreParams, names: tuple[str, ...]) -> tuple[float, float, np.ndarray]:
    """μ_max, λ* and ∂μ_max/∂p (envelope theorem: ∂μ/∂λ = 0 at the peak)."""
    mu_max, lam = peak(speed_mps, p)
    _, jac = mu_and_jacobian(np.array([lam]), np.array([speed_mps]), p, names)
    return mu_max, lam, jac[0]
