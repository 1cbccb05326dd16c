"""The estimator's fit over its window.

Each update runs a bounded trust-region step (or a few) from the last solution on the window's
weighted residuals μ_meas − μ(λ, v; p), the priors and the soft ties between the wheels' θ, with
the analytic Jacobian: in one compiled call (`_fitcore.fit_window`) when installed, else as the
normal equations (`_normal`) driven by `trust_region.solve_normal`. What its newest residuals say
of a change of road is `road_change.RoadChangeTest`'s. `WindowFit` is a part of
`LugreTrustRegionEstimator` (its window, parameters and options are the estimator's).
"""
from __future__ import annotations

import math

import numpy as np

from . import trust_region
from .road_change import RoadChangeTest
from .samples import N_WHEELS, FrictionEstimate
from .tyre_model import _SMALL_Z, braking_mu_and_partials

_WHEEL_COLUMN = np.arange(N_WHEELS)[:, None]


class WindowFit(RoadChangeTest):
    """The update's fit (`_fit`: compiled, or `_normal` + `trust_region.solve_normal`); after
    each, the change of road its newest residuals show (`RoadChangeTest`)."""

    def _residuals(self, x: np.ndarray, slip, speed, mu_meas, sw, wheel, rows_index=None) -> tuple[np.ndarray, np.ndarray]:
        """Weighted data residuals, then the priors, then the soft ties between wheels' θ.

        `sw` are the data rows' weights √w/σ (fixed within one update).
        """
        p = self._params(x)
        scale = self._scale
        theta = self._thetas(x)[wheel]
        m = len(slip)
        n = len(x)
        n_ties = len(self._tie_a)
        if self._work is None or self._work.shape[0] < m:
            self._work = np.empty((max(m, 64) * 2, 4))
        partials = self._work[:m]
        model = braking_mu_and_partials(slip, speed, theta, p, partials)
        r = np.empty(m + n + n_ties)
        J = np.zeros((m + n + n_ties, n))
        r[:m] = sw * (model - mu_meas)
        J[rows_index if rows_index is not None else np.arange(m), wheel] = partials[:, 0] * theta * sw  # ∂/∂ln θ
        J[:m, N_WHEELS:] = partials[:, 1:] * sw[:, None] * scale[N_WHEELS:]
        r[m:m + n] = (x - self._prior) / self._prior_std
        J[m:m + n] = self._J_prior
        r[m + n:] = self._tie_rel_d @ x[:N_WHEELS]
        J[m + n:, :N_WHEELS] = self._tie_rel_d
        return r, J

    def _rows(self, x: np.ndarray, lo: int, hi: int, out: np.ndarray) -> None:
        """Unweighted Jacobian rows and model − measurement of window samples [lo, hi) at x.

        `out` (8, hi − lo): rows 0–3 ∂μ/∂ln θ_wheel (one-hot), 4–6 ∂μ/∂(σ0, v_s, σ2) in the scaled
        variables, 7 μ_model − μ_meas. The formulas of `braking_mu_and_partials`, on the
        window's precomputed per-sample columns.
        """
        w = self._window
        b = self._base
        sc4, sc5, sc6 = self._shared_scale
        sigma0, v_s, sigma2 = float(x[4]) * sc4, float(x[5]) * sc5, float(x[6]) * sc6
        thetas = self._thetas(x)
        wheel = w.wheel[lo:hi]
        onehot = wheel == _WHEEL_COLUMN    # (N_WHEELS, hi − lo): the ln θ column of each sample
        alpha = self._alpha
        dmu = b.mu_s - b.mu_c
        ratio = w.pow_lam_v[lo:hi] * v_s**-alpha
        e = np.exp(-ratio)
        g = e * dmu
        g += b.mu_c
        inv_t = (1.0 / thetas)[wheel]
        Z = (thetas * sigma0)[wheel]
        Z *= w.stiff[lo:hi]
        Z /= g
        if hi > lo and Z.min() < _SMALL_Z:
            partials = np.empty((hi - lo, 4))
            model = braking_mu_and_partials(w.slip[lo:hi], w.speed[lo:hi], thetas[wheel], self._params(x), partials)
            partials[:, 0] *= thetas[wheel]     # ∂/∂ln θ
            np.multiply(onehot, partials[:, 0], out=out[:N_WHEELS])
            out[4] = partials[:, 1] * sc4
            out[5] = partials[:, 2] * sc5
            out[6] = partials[:, 3] * sc6
            np.subtract(model, w.mu[lo:hi], out=out[7])
            return
        om = np.expm1(-Z)
        om *= -1.0                      # 1 − e^(−Z)
        iz = 1.0 / Z
        F = 1.0 - om * iz
        ZdF = om * (1.0 + Z)
        ZdF -= Z
        ZdF *= iz                       # Z·F'(Z)
        FmZ = F - ZdF
        gt = g * inv_t
        a0 = gt * FmZ                   # −∂μ/∂ln θ = (g/θ)(F − Z·F')
        np.multiply(onehot, a0, out=out[:N_WHEELS])
        out[:N_WHEELS] *= -1.0
        np.multiply(gt, ZdF, out=out[4])
        out[4] *= sc4 / sigma0
        np.multiply(FmZ, inv_t, out=out[5])
        out[5] *= e
        out[5] *= ratio
        out[5] *= dmu * alpha / v_s * sc5
        lv = w.lam_v[lo:hi]
        np.multiply(lv, sc6, out=out[6])
        np.multiply(gt, F, out=out[7])
        out[7] += sigma2 * lv
        out[7] -= w.mu[lo:hi]

    def _rows_few(self, x: np.ndarray, lo: int, hi: int) -> None:
        """`_rows` for the few samples an update adds, into the window's row cache, in floats."""
        w = self._window
        b = self._base
        sc4, sc5, sc6 = self._shared_scale
        xs = x.tolist()
        thetas = [math.exp(u) for u in xs[:N_WHEELS]]
        sigma0, v_s, sigma2 = xs[4] * sc4, xs[5] * sc5, xs[6] * sc6
        alpha = self._alpha
        dmu, mu_c = b.mu_s - b.mu_c, b.mu_c
        v_pow = v_s**-alpha
        k4 = sc4 / sigma0
        k5 = dmu * alpha / v_s * sc5
        exp, expm1 = math.exp, math.expm1
        cols = []
        for j in range(lo, hi):
            wi = int(w.wheel[j])
            th = thetas[wi]
            ratio = float(w.pow_lam_v[j]) * v_pow
            e = exp(-ratio)
            g = e * dmu + mu_c
            inv_t = 1.0 / th
            Z = (th * sigma0) * float(w.stiff[j]) / g
            if not Z >= _SMALL_Z:
                self._rows(x, lo, hi, w.rows[:, lo:hi])
                return
            om = -expm1(-Z)
            iz = 1.0 / Z
            F = 1.0 - om * iz
            ZdF = (om * (1.0 + Z) - Z) * iz
            FmZ = F - ZdF
            gt = g * inv_t
            lv = float(w.lam_v[j])
            col = [0.0] * N_WHEELS + [gt * ZdF * k4, FmZ * inv_t * e * ratio * k5, lv * sc6,
                                      gt * F + sigma2 * lv - float(w.mu[j])]
            col[wi] = -(gt * FmZ)
            cols.append(col)
        if cols:
            w.rows[:, lo:hi] = np.array(cols).T

    def _normal(self, x: np.ndarray, sw: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, tuple]:
        """½‖r‖², Jᵀr and JᵀJ of `_residuals` (data rows weighted by `sw`, priors, ties) at x."""
        w = self._window
        lo, hi = w.start, w.end
        cache_x = self._cache_x
        if cache_x is not None and w.cached_end > lo and (x == cache_x).all():
            # The rows of the samples already in the window were computed at this x by the
            # last update (its accepted point): only the new samples' rows are missing.
            if w.cached_end < hi:
                self._rows_few(x, w.cached_end, hi)
                w.cached_end = hi
            rows = w.rows[:, lo:hi]
            fresh = None
        else:
            fresh = rows = np.empty((w.rows.shape[0], hi - lo))
            self._rows(x, lo, hi, rows)
        # One product gives JᵀJ, Jᵀr and rᵀr: the weighted data rows, then the prior rows
        # (x − prior)/std and the tie rows (ln θ_a − ln θ_b)/rel appended as further columns.
        m = hi - lo
        n = len(x)
        B = np.empty((n + 1, m + n + N_WHEELS))
        np.multiply(rows, sw, out=B[:, :m])
        B[:n, m:m + n] = self._prior_rows
        np.multiply(x - self._prior, self._inv_prior_std, out=B[n, m:m + n])
        B[:N_WHEELS, m + n:] = self._tie_rows_t
        B[N_WHEELS:n, m + n:] = 0.0
        np.dot(self._tie_rel_d, x[:N_WHEELS], out=B[n, m + n:])
        M = np.dot(B, B.T)
        N = M[:n, :n]
        grad = M[:n, n]
        cost = float(M[n, n])
        return 0.5 * cost, grad, N, (fresh, B[n, :m], x)

    def _fit(self, now_s: float, speed: float) -> FrictionEstimate:
        o = self.options
        if self.core is not None:
            return self._fit_compiled(now_s, speed)
        slip, speeds, mu_meas, times, wheel = self._window.view()
        weights = self._weights(now_s, times)
        w_sum = float(weights.sum())
        sw = np.sqrt(weights) * (1.0 / o.measurement_std)
        normal, r_data = self._solve_numpy(sw)
        self._numpy_residuals = r_data / sw
        self._fits += 1
        self._last_fit_s = now_s
        self._innovation_score = self._innovation(now_s, times, r_data, weights)
        estimate = self._report(now_s, speed, float(r_data @ r_data), normal, weights, w_sum, len(slip))
        self._detect_jump(now_s, speed, self._innovation_score)
        return estimate

    def _fit_compiled(self, now_s: float, speed: float) -> FrictionEstimate:
        """`_fit` in one compiled call on the window's own columns (`_fitcore.fit_window`: the
        weights, the trust-region iterations and the newest residuals' bias), without slicing
        them here: numpy's per-call machinery was most of an update's cost on a cold cache."""
        o = self.options
        w = self._window
        lo, hi = w.start, w.end
        x = self._x.copy()
        # The rows of the samples already in the window were computed at this x by the last
        # update (its result): only the new samples' rows are computed for the first evaluation.
        cached = w.core_cached_end - lo if self._core_rows_x is not None and w.core_cached_end > lo else 0
        normal = self._normal_buffer
        w_sum, radius, residual_ss, first, mean, rms, same_sign, n_front, *front_bias = self.core.fit_window(
            w.core_columns, lo, hi, now_s, o.forgetting_time_constant, o.measurement_std, now_s - o.jump_window_s,
            x, self._lb, self._ub, self._prior, self._inv_prior_std, self._tie_rel_d, self._gradient_buffer, normal,
            self._core_constants, math.nan if self._radius is None else self._radius, o.max_iterations, o.ftol,
            o.xtol, 1e-8, o.predicted_ftol, 4, self._core_rows_x if cached else x, cached)
        w.core_cached_end = hi
        self._core_rows_x = x
        self._cache_x = None   # (the numpy path's row cache is not kept up here)
        self._x = x
        self._radius = max(radius, 1e-3)
        self._fits += 1
        self._last_fit_s = now_s
        m = hi - lo
        n_recent = m - first
        counts = self._innovation_counts(m, n_recent)
        self._innovation_score = self._innovation_score_of(n_recent, mean, rms, same_sign) if counts else 0.0
        self._front_innovation_score = self._front_score(n_front, *front_bias) if counts else 0.0
        estimate = self._report(now_s, speed, residual_ss, normal, None, w_sum, m)
        self._detect_jump(now_s, speed, self._innovation_score)
        return estimate

    def _solve_numpy(self, sw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`_solve_compiled` on the numpy path: `_normal` driven by `trust_region.solve_normal`."""
        o = self.options

        def fun(x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, tuple]:
            return self._normal(x, sw)

        result = trust_region.solve_normal(fun, self._x, self._lb, self._ub, radius=self._radius,
                                           max_iterations=o.max_iterations, ftol=o.ftol, xtol=o.xtol, gtol=1e-8,
                                           max_rejections=4, predicted_ftol=o.predicted_ftol)
        fresh, r_data, x_at = result.extra
        window = self._window
        if fresh is not None:
            window.rows[:, window.start:window.end] = fresh
        window.cached_end = window.end
        self._cache_x = x_at
        self._x = result.x
        self._radius = max(result.radius, 1e-3)
        return result.normal, r_data
