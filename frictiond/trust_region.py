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
from typing import Callable, NamedTuple

import numpy as np

ResidualFunction = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

try:
    # numpy's LAPACK gufunc behind `np.linalg.eigh`, without the wrapper's checks and errstate
    # context: half the cost on the solver's 7×7 matrices, called once per iteration. Its
    # inputs here are finite by construction (checked below); a numpy without it gets the wrapper.
    from numpy.linalg import _umath_linalg

    def _eigh(H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _umath_linalg.eigh_lo(H, signature="d->dd")

    _eigh(np.eye(2))
except Exception:  # pragma: no cover - depends on the numpy build
    _eigh = np.linalg.eigh  # type: ignore[assignment]


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


def _scaling(x, upper, lower, lb, ub) -> tuple[np.ndarray, np.ndarray]:
    """Coleman–Li v(x) and its derivative (diagonal); `upper`/`lower` mark the coordinates whose
    gradient points at a finite upper/lower bound."""
    v = np.where(lower, x - lb, np.where(upper, ub - x, 1.0))
    dv = lower.astype(float) - upper
    return v, dv


def _subproblem(eig: tuple[np.ndarray, np.ndarray, np.ndarray], radius: float) -> np.ndarray:
    """argmin ½ sᵀHs + gᵀs over ‖s‖ ≤ radius, from H = Q diag(w) Qᵀ and a = Qᵀg (H may be indefinite)."""
    w, Q, a = eig
    wl, al = w.tolist(), a.tolist()
    w0, w_last = wl[0], wl[-1]
    if w0 > 1e-12 * max(1.0, abs(w_last)):
        s = [ai / wi for ai, wi in zip(al, wl)]
        if math.fsum(si * si for si in s) <= radius * radius:
            return -(Q @ np.array(s))
    # Boundary solution: find λ ≥ max(0, −w_min) with ‖(H + λI)⁻¹ g‖ = radius (Newton on the
    # secular equation 1/radius − 1/‖s(λ)‖ = 0, which is nearly linear in λ). On n-vectors of
    # a handful of entries: plain floats.
    lam_low = max(0.0, -w0) + 1e-14 * max(1.0, abs(w_last))
    norm_a = math.sqrt(sum(ai * ai for ai in al))
    lam = max(lam_low, norm_a / radius - w0)
    sqrt = math.sqrt
    try:
        for _ in range(50):
            ss = 0.0
            s3 = 0.0
            for ai, wi in zip(al, wl):
                inv = 1.0 / (wi + lam)
                si = ai * inv
                ss += si * si
                s3 += si * si * inv
            ns = sqrt(ss)
            if ns == 0.0:
                break
            phi = 1.0 / radius - 1.0 / ns
            if abs(phi) * radius < 1e-6:
                break
            dns = -s3 / ns
            step = phi / (dns / (ns * ns))
            lam = max(lam - step, lam_low)
    except (ArithmeticError, ValueError):
        pass
    return -(Q @ (a / (w + lam)))


_BOXES: dict[bytes, tuple] = {}


def _box(lb, ub) -> tuple:
    """The bounds and what the solver derives from them, as arrays and floats (cached: a
    recursive caller passes the same bounds every time)."""
    lb = np.asarray(lb, dtype=float)
    ub = np.asarray(ub, dtype=float)
    key = lb.tobytes() + b"|" + ub.tobytes()
    box = _BOXES.get(key)
    if box is None:
        lb, ub = lb.copy(), ub.copy()   # the caller may change its arrays later
        fin_lb = np.isfinite(lb)
        fin_ub = np.isfinite(ub)
        span = np.where(np.isfinite(ub - lb), ub - lb, 1.0)
        inner_lb, inner_ub = lb + 1e-10 * span, ub - 1e-10 * span
        box = (lb, ub, fin_lb, fin_ub, inner_lb, inner_ub, lb.tolist(), ub.tolist(), fin_lb.tolist(),
               fin_ub.tolist(), inner_lb.tolist(), inner_ub.tolist())
        if len(_BOXES) >= 64:
            _BOXES.clear()
        _BOXES[key] = box
    return box


NormalFunction = Callable[[np.ndarray], tuple[float, np.ndarray, np.ndarray, object]]


@dataclass(slots=True)
class NormalResult:
    x: np.ndarray
    cost: float                 # ½‖r‖² at x
    gradient: np.ndarray        # Jᵀr at x
    normal: np.ndarray          # JᵀJ at x
    extra: object               # what `fun` returned with the evaluation at x
    radius: float
    iterations: int
    converged: bool
    evaluations: int


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

    def normal(r: np.ndarray, J: np.ndarray):
        return 0.5 * float(r @ r), J.T @ r, J.T @ J, (r, J)

    def fun_normal(x: np.ndarray):
        return normal(*fun(x))

    res = solve_normal(fun_normal, x0, lb, ub, radius=radius, max_iterations=max_iterations, ftol=ftol,
                       xtol=xtol, gtol=gtol, initial=None if initial is None else normal(*initial),
                       max_rejections=max_rejections)
    evaluations = res.evaluations - (1 if initial is not None else 0)
    r, J = res.extra
    return TrustRegionResult(res.x, res.cost, r, J, res.radius, res.iterations, res.converged, evaluations)


def _scaled_gradient(xl: list[float], gl: list[float], lbl: list[float], ubl: list[float], fin_lbl: list[bool],
                     fin_ubl: list[bool]) -> tuple[list[float], list[float], list[float], float, float, bool]:
    """`_scaling` on floats, with what `solve_normal` needs of it: the scale d = √v, the scaled
    gradient d·g, the diagonal term g·dv/dx, max |g·v| (the gtol test), max |d·g| and whether a
    NaN was met."""
    n = len(xl)
    sqrt = math.sqrt
    d, g_h, g_dv = [0.0] * n, [0.0] * n, [0.0] * n
    gv_max = gh_max = 0.0
    nan = False
    for i in range(n):
        gi, xi = gl[i], xl[i]
        if gi > 0 and fin_lbl[i]:
            vi = xi - lbl[i]
            g_dv[i] = gi
        elif gi < 0 and fin_ubl[i]:
            vi = ubl[i] - xi
            g_dv[i] = -gi
        else:
            vi = 1.0
        gv = abs(gi * vi)
        nan = nan or gv != gv
        gv_max = gv if gv > gv_max else gv_max
        di = sqrt(vi) if vi > 0 else 0.0
        d[i] = di
        ghi = di * gi
        g_h[i] = ghi
        ghi = abs(ghi)
        gh_max = ghi if ghi > gh_max else gh_max
    return d, g_h, g_dv, gv_max, gh_max, nan


def _step_inside(s_h: list[float], d: list[float], lower_room: list[float],
                 upper_room: list[float]) -> tuple[list[float], list[float]]:
    """The step s = d·ŝ kept strictly inside the box, and ŝ to match: a component that would
    cross its bound goes a fraction θ of the way there (`lower_room`, `upper_room`), the others
    keep their full length (a projected step; scaling the whole step would stall the free
    coordinates at a bound)."""
    n = len(s_h)
    s = [d[i] * s_h[i] for i in range(n)]
    for i in range(n):
        if s[i] > upper_room[i] or s[i] < lower_room[i]:
            s = [min(max(s[k], lower_room[k]), upper_room[k]) for k in range(n)]
            return s, [s[k] / d[k] for k in range(n)]
    return s, s_h


def _interior_start(x0: np.ndarray, lbl: list[float], ubl: list[float], inner_lbl: list[float],
                    inner_ubl: list[float]) -> np.ndarray:
    """x0 clipped to the box, then into its interior: trf-style, a bound-touching start has no
    room to scale."""
    return np.array([min(max(min(max(v, lo), hi), ilo), ihi)
                     for v, lo, hi, ilo, ihi in zip(np.asarray(x0, dtype=float).tolist(), lbl, ubl, inner_lbl,
                                                    inner_ubl)])


def _initial_radius(x: np.ndarray, g: np.ndarray, lb: np.ndarray, ub: np.ndarray, fin_lb: np.ndarray,
                    fin_ub: np.ndarray) -> float:
    """The trust radius for a cold start: ‖x/d‖ in the scaled variables (1 at the origin)."""
    v, _ = _scaling(x, (g < 0) & fin_ub, (g > 0) & fin_lb, lb, ub)
    return math.sqrt(float(np.sum(x * x / v))) or 1.0


def _scaled_model(N: np.ndarray, d: list[float], g_h: list[float], g_dv: list[float],
                  diagonal: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, tuple] | None:
    """The scaled subproblem's matrix H = D N D + diag(g·dv/dx) and its eigen-decomposition
    (w, Q, Qᵀĝ) for `_subproblem`; None if H is not finite."""
    d_arr = np.array(d)
    H = N * np.multiply.outer(d_arr, d_arr)
    H[diagonal] += g_dv
    if not np.isfinite(H).all():
        return None
    w, Q = _eigh(H)
    return H, (w, Q, np.array(g_h) @ Q)


def _updated_radius(radius: float, actual: float, predicted: float, step_norm: float) -> float:
    """The trust radius after a step, from the ratio of actual to predicted reduction."""
    ratio = actual / predicted if predicted > 0 else -1.0
    if ratio < 0.25:
        return 0.25 * step_norm if step_norm > 0 else 0.25 * radius
    if ratio > 0.75 and step_norm >= 0.95 * radius:
        return radius * 2.0
    return radius


class _Trial(NamedTuple):
    """An accepted step: the new point, its (unscaled) step, the cost reduction and `fun` there."""
    x: np.ndarray
    step: list[float]
    actual: float
    evaluation: tuple[float, np.ndarray, np.ndarray, object]


def _decreasing_step(fun: NormalFunction, xl: list[float], cost: float, H: np.ndarray, eig: tuple,
                     g_h: list[float], d: list[float], gh_max: float, box: tuple, radius: float,
                     max_rejections: int, predicted_ftol: float) -> tuple[_Trial | None, float, int]:
    """Shrink the radius until a step from xl decreases the cost: (the accepted step, or None when
    the point is to be kept as converged; the updated radius; the evaluations spent)."""
    _, _, _, _, _, _, lbl, ubl, _, _, inner_lbl, inner_ubl = box
    n = len(xl)
    sqrt = math.sqrt
    theta = max(0.995, 1.0 - gh_max)
    upper_room = [theta * (ubl[i] - xl[i]) for i in range(n)]
    lower_room = [theta * (lbl[i] - xl[i]) for i in range(n)]
    evaluations = 0
    for _attempt in range(max_rejections):
        s, s_h = _step_inside(_subproblem(eig, radius).tolist(), d, lower_room, upper_room)
        s_arr = np.array(s_h)
        predicted = -(sum(g_h[i] * s_h[i] for i in range(n)) + 0.5 * float(s_arr @ H @ s_arr))
        if predicted_ftol > 0 and predicted < predicted_ftol * cost:
            return None, radius, evaluations
        # Iterates stay as far inside as the start is put: the result, passed back in as the
        # next warm start, is then used exactly as returned.
        x_new = np.array([min(max(xl[i] + s[i], inner_lbl[i]), inner_ubl[i]) for i in range(n)])
        evaluation = fun(x_new)
        evaluations += 1
        cost_new = evaluation[0]
        actual = cost - cost_new
        radius = _updated_radius(radius, actual, predicted, sqrt(sum(v * v for v in s_h)))
        if actual > 0 and math.isfinite(cost_new):
            return _Trial(x_new, s, actual, evaluation), radius, evaluations
        if radius < 1e-12 * (1.0 + sqrt(sum(v * v for v in xl))):
            return None, radius, evaluations
    return None, radius, evaluations


def solve_normal(
    fun: NormalFunction,
    x0: np.ndarray,
    lb: np.ndarray,
    ub: np.ndarray,
    *,
    radius: float | None = None,
    max_iterations: int = 50,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
    gtol: float = 1e-8,
    initial: tuple[float, np.ndarray, np.ndarray, object] | None = None,
    max_rejections: int = 60,
    predicted_ftol: float = 0.0,
) -> NormalResult:
    """`solve` on the normal equations: `fun(x)` returns (½‖r‖², Jᵀr, JᵀJ, extra).

    The same iterations as `solve` (everything it does with r and J goes through these three),
    for a caller that can form JᵀJ and Jᵀr more cheaply than the full Jacobian; `extra` is
    handed back with the accepted point (e.g. the residuals).

    `predicted_ftol` > 0 also stops before evaluating a step whose predicted reduction is below
    `predicted_ftol`·cost (the quadratic model says the point is as good as converged): for a
    recursive caller, whose next update continues anyway, it saves an evaluation per update.
    """
    box = _box(lb, ub)
    lb, ub, fin_lb, fin_ub, _, _, lbl, ubl, fin_lbl, fin_ubl, inner_lbl, inner_ubl = box
    x = _interior_start(x0, lbl, ubl, inner_lbl, inner_ubl)
    cost, g, N, extra = initial if initial is not None else fun(x)
    evaluations = 1
    if radius is None or not math.isfinite(radius) or radius <= 0:
        radius = _initial_radius(x, g, lb, ub, fin_lb, fin_ub)
    converged = False
    iterations = 0
    # The n-vectors (a handful of entries) are handled as floats: fused loops instead of a
    # dozen numpy calls on tiny arrays per iteration. Same operations as `_scaling`.
    n = len(x)
    sqrt = math.sqrt
    diagonal = (np.arange(n), np.arange(n))
    while iterations < max_iterations:
        xl, gl = x.tolist(), g.tolist()
        d, g_h, g_dv, gv_max, gh_max, nan = _scaled_gradient(xl, gl, lbl, ubl, fin_lbl, fin_ubl)
        if not nan and gv_max < gtol:
            converged = True
            break
        model = _scaled_model(N, d, g_h, g_dv, diagonal)
        if model is None:
            break   # (a non-finite Jacobian: nothing to step on; the caller keeps x)
        iterations += 1
        trial, radius, spent = _decreasing_step(fun, xl, cost, *model, g_h, d, gh_max, box, radius,
                                                max_rejections, predicted_ftol)
        evaluations += spent
        if trial is None:
            return NormalResult(x, cost, g, N, extra, radius, iterations, True, evaluations)
        x_norm = sqrt(sum(v * v for v in xl))
        x, (cost_new, g, N, extra) = trial.x, trial.evaluation
        small_cost = trial.actual < ftol * cost
        small_step = sqrt(sum(v * v for v in trial.step)) < xtol * (xtol + x_norm)
        cost = cost_new
        if small_cost or small_step:
            converged = True
            break
    return NormalResult(x, cost, g, N, extra, radius, iterations, converged, evaluations)
