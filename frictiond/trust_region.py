"""A bounded trust-region least-squares solver for small problems, in plain numpy.

Minimises ½‖r(x)‖² subject to lb ≤ x ≤ ub with the interior (reflective-scaling) trust region of
Coleman & Li (1996), the method behind `scipy.optimize.least_squares(method="trf")`:

- the variables are scaled by d_i = √|v_i|, where v_i is the distance to the bound the gradient
  points at (1 for an unbounded direction), so the trust region shrinks along a coordinate as it
  approaches its bound;
- the scaled subproblem  min ½ sᵀ(ĴᵀĴ + C)s + ĝᵀs,  ‖s‖ ≤ Δ  (C = diag(g·∂v)) is solved exactly
  by an eigen-decomposition of the n×n matrix and a Newton iteration on the secular equation
  (Moré & Sorensen 1983) — n is a handful of parameters, so this is cheaper than any iterative
  method;
- a step that would leave the box is cut back to a fraction θ of the way to the bound (strictly
  feasible iterates);
- Δ is updated from the ratio of actual to predicted reduction (Conn, Gould & Toint 2000, ch. 6).

It is written to be called repeatedly: `solve` takes and returns the trust radius, so a recursive
estimator can warm-start both the point and the radius, and `max_iterations` bounds the work
per call.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

ResidualFunction = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(slots=True)
class TrustRegionResult:
    x: np.ndarray
    cost: float                 # ½‖r‖² at x
    residuals: np.ndarray
    jacobian: np.ndarray
    radius: float               # trust radius to start the next call with
    iterations: int
    converged: bool             # a tolerance was met (not merely the iteration bound)
    evaluations: int


def _scaling(x: np.ndarray, g: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coleman–Li v(x) and its derivative (diagonal)."""
    v = np.ones_like(x)
    dv = np.zeros_like(x)
    upper = (g < 0) & np.isfinite(ub)
    v[upper] = ub[upper] - x[upper]
    dv[upper] = -1.0
    lower = (g > 0) & np.isfinite(lb)
    v[lower] = x[lower] - lb[lower]
    dv[lower] = 1.0
    return v, dv


def _subproblem(eig: tuple[np.ndarray, np.ndarray, np.ndarray], radius: float) -> np.ndarray:
    """argmin ½ sᵀHs + gᵀs over ‖s‖ ≤ radius, from H = Q diag(w) Qᵀ and a = Qᵀg (H may be indefinite)."""
    w, Q, a = eig
    if w[0] > 1e-12 * max(1.0, abs(w[-1])):
        s = -(a / w)
        if float(s @ s) <= radius * radius:
            return Q @ s
    # Boundary solution: find λ ≥ max(0, −w_min) with ‖(H + λI)⁻¹ g‖ = radius (Newton on the
    # secular equation 1/radius − 1/‖s(λ)‖ = 0, which is nearly linear in λ).
    lam_low = max(0.0, -w[0]) + 1e-14 * max(1.0, abs(w[-1]))
    norm_a = math.sqrt(float(a @ a))
    lam = max(lam_low, norm_a / radius - w[0])
    for _ in range(50):
        denom = w + lam
        s = a / denom
        ns = math.sqrt(float(s @ s))
        if ns == 0.0:
            break
        phi = 1.0 / radius - 1.0 / ns
        if abs(phi) * radius < 1e-6:
            break
        dns = -float(np.sum(a * a / denom**3)) / ns
        step = phi / (dns / (ns * ns))
        lam = max(lam - step, lam_low)
    return -(Q @ (a / (w + lam)))


def solve(
    fun: ResidualFunction,
    x0: np.ndarray,
    lb: np.ndarray,
    ub: np.ndarray,
    *,
    radius: float | None = None,
    max_iterations: int = 50,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
    gtol: float = 1e-8,
    initial: tuple[np.ndarray, np.ndarray] | None = None,
    max_rejections: int = 60,
) -> TrustRegionResult:
    """Bounded nonlinear least squares; `fun(x)` returns the residuals and their Jacobian.

    Tolerances have `least_squares`' meaning: stop when the relative cost reduction of a step is
    below `ftol`, the step is below `xtol·(xtol + ‖x‖)`, or the scaled gradient's max norm is below
    `gtol`. `max_rejections` bounds the radius reductions per iteration (a recursive caller
    would rather continue on the next update than spend an unbounded time now).
    """
    lb = np.asarray(lb, dtype=float)
    ub = np.asarray(ub, dtype=float)
    # Strictly interior start: trf-style, a bound-touching start has no room to scale.
    x = np.clip(np.asarray(x0, dtype=float), lb, ub)
    span = np.where(np.isfinite(ub - lb), ub - lb, 1.0)
    x = np.clip(x, lb + 1e-10 * span, ub - 1e-10 * span)
    r, J = initial if initial is not None else fun(x)
    evaluations = 0 if initial is not None else 1
    cost = 0.5 * float(r @ r)
    g = J.T @ r
    if radius is None or not math.isfinite(radius) or radius <= 0:
        v, _ = _scaling(x, g, lb, ub)
        radius = math.sqrt(float(np.sum(x * x / v))) or 1.0
    converged = False
    iterations = 0
    while iterations < max_iterations:
        v, dv = _scaling(x, g, lb, ub)
        if float(np.max(np.abs(g * v))) < gtol:
            converged = True
            break
        d = np.sqrt(v)
        g_h = d * g
        J_h = J * d
        H = J_h.T @ J_h + np.diag(g * dv)
        w, Q = np.linalg.eigh(H)
        eig = (w, Q, Q.T @ g_h)
        iterations += 1
        # Inner loop: shrink the radius until a step decreases the cost.
        for _attempt in range(max_rejections):
            s_h = _subproblem(eig, radius)
            s = d * s_h
            # Stay strictly inside the box: a component that would cross its bound goes a
            # fraction θ of the way there, the others keep their full length (a projected
            # step; scaling the whole step would stall the free coordinates at a bound).
            theta = max(0.995, 1.0 - float(np.max(np.abs(g_h))))
            upper_room = theta * (ub - x)
            lower_room = theta * (lb - x)
            if np.any(s > upper_room) or np.any(s < lower_room):
                s = np.minimum(np.maximum(s, lower_room), upper_room)
                s_h = s / d
            predicted = -(float(g_h @ s_h) + 0.5 * float(s_h @ H @ s_h))
            x_new = x + s
            r_new, J_new = fun(x_new)
            evaluations += 1
            cost_new = 0.5 * float(r_new @ r_new)
            actual = cost - cost_new
            step_norm = math.sqrt(float(s_h @ s_h))
            ratio = actual / predicted if predicted > 0 else -1.0
            if ratio < 0.25:
                radius = 0.25 * step_norm if step_norm > 0 else 0.25 * radius
            elif ratio > 0.75 and step_norm >= 0.95 * radius:
                radius *= 2.0
            if actual > 0 and math.isfinite(cost_new):
                break
            if radius < 1e-12 * (1.0 + math.sqrt(float(x @ x))):
                return TrustRegionResult(x, cost, r, J, radius, iterations, True, evaluations)
        else:
            return TrustRegionResult(x, cost, r, J, radius, iterations, True, evaluations)
        x_norm = math.sqrt(float(x @ x))
        x, r, J = x_new, r_new, J_new
        g = J.T @ r
        small_cost = actual < ftol * cost
        small_step = math.sqrt(float(s @ s)) < xtol * (xtol + x_norm)
        cost = cost_new
        if small_cost or small_step:
            converged = True
            break
    return TrustRegionResult(x, cost, r, J, radius, iterations, converged, evaluations)
