"""The estimator's parameter vector x and what it maps to.

x holds ln θ per wheel, then σ0, v_s and σ2 each divided by its prior; the bounds, priors and
the soft ties between the wheels' ln θ are set on x, and each fit's x is turned into the tyre
model's parameters here (as `LugreParams`, or as the floats the compiled fit takes, both cached
per x). `FitParameters` is a part of `LugreTrustRegionEstimator` (its options and x are the
estimator's).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from .samples import N_WHEELS
from .tyre_model import LugreParams

# The parameters pooled over the wheels, in their order in x after the wheels' ln θ.
SHARED = ("sigma0", "v_s", "sigma2")


class FitParameters:
    """The fit's parameter space (`_init_parameter_space`) and the mapping from x to the tyre
    model's parameters (`_thetas`, `_params`, `_floats_of_x`, `_compiled_params`)."""

    def _init_parameter_space(self, o: Any) -> None:
        """Scales, bounds, priors and ties of x, from the estimator's options `o`."""
        # x: ln θ per wheel, then σ0, v_s, σ2 divided by their nominal values.
        self._scale = np.array([1.0] * N_WHEELS + [o.prior_sigma0, o.prior_v_s, max(o.prior_sigma2, 1e-3)])
        self._lb = np.array([math.log(o.theta_min)] * N_WHEELS + [o.sigma0_min, o.v_s_min, o.sigma2_min]) / self._scale
        self._ub = np.array([math.log(o.theta_max)] * N_WHEELS + [o.sigma0_max, o.v_s_max, o.sigma2_max]) / self._scale
        self._lb_list, self._ub_list = self._lb.tolist(), self._ub.tolist()
        self._theta_bounds = list(zip(self._lb_list[:N_WHEELS], self._ub_list[:N_WHEELS]))
        self._prior_std = np.array([o.prior_std_log_theta] * N_WHEELS + [o.prior_std_sigma0, o.prior_std_v_s,
                                                                         o.prior_std_sigma2]) / self._scale
        self._base = LugreParams(mu_c=o.mu_c, mu_s=o.mu_s, alpha=o.alpha, patch_length=o.patch_length)
        self._J_prior = np.diag(1.0 / self._prior_std)
        # Soft ties between wheels' ln θ: front–rear on each side, left–right on each axle.
        self._tie_a = np.array([0, 1, 0, 2])
        self._tie_b = np.array([2, 3, 1, 3])
        self._tie_rel = np.array([o.front_rear_coupling, o.front_rear_coupling,
                                  o.left_right_coupling, o.left_right_coupling])
        if self._scale[0] != 1.0:
            raise AssertionError("ln θ is fitted unscaled")
        # The priors and ties as rows appended to the data (see `_normal`): (x − prior)/std and
        # (ln θ_a − ln θ_b)/rel, both linear in x.
        self._inv_prior_std = 1.0 / self._prior_std
        self._prior_rows = np.diag(self._inv_prior_std)
        self._tie_rel_d = np.zeros((len(self._tie_a), N_WHEELS))   # rows (e_a − e_b)/rel
        for k, (a, b, rel) in enumerate(zip(self._tie_a, self._tie_b, self._tie_rel)):
            self._tie_rel_d[k, a], self._tie_rel_d[k, b] = 1.0 / rel, -1.0 / rel
        self._tie_rows_t = self._tie_rel_d.T.copy()

    @staticmethod
    def _thetas(x: np.ndarray) -> np.ndarray:
        """Each wheel's θ from the fitted ln θ."""
        return np.exp(x[:N_WHEELS])

    def _floats_of_x(self) -> tuple[list[float], list[float], tuple[float, ...]]:
        """The fitted point as floats: (x, each wheel's θ, `_compiled_params(x)`), kept until
        `_x` is replaced (each fit makes a new array; nothing changes one in place)."""
        x = self._x
        cached = self._x_floats
        if cached is None or cached[0] is not x:
            xs = x.tolist()
            exp = math.exp   # (np.exp of four numbers costs more than the four calls)
            thetas = [exp(xs[0]), exp(xs[1]), exp(xs[2]), exp(xs[3])]
            cached = self._x_floats = (x, xs, thetas, self._params_entry_of(tuple(xs[N_WHEELS:]))[0])
        return cached[1], cached[2], cached[3]

    def _params(self, x: np.ndarray) -> LugreParams:
        entry = self._params_entry(x)
        if entry[1] is None:
            sigma0, v_s, sigma2 = entry[0][3], entry[0][5], entry[0][6]
            b = self._base
            entry[1] = LugreParams(theta=1.0, sigma0=sigma0, sigma2=sigma2, mu_c=b.mu_c, mu_s=b.mu_s, v_s=v_s,
                                   alpha=b.alpha, patch_length=b.patch_length)
        return entry[1]

    def _compiled_params(self, x: np.ndarray) -> tuple[float, ...]:
        """`compiled_params(self._params(x))` (σ0, v_s, σ2 at 3, 5, 6), without building the
        LugreParams (a frozen dataclass costs more than the compiled calls it feeds)."""
        return self._params_entry(x)[0]

    def _params_entry(self, x: np.ndarray) -> list:
        """[compiled parameters, LugreParams or None until asked for] of the shared parameters in x."""
        return self._params_entry_of(tuple(x[N_WHEELS:].tolist()))

    def _params_entry_of(self, key: tuple[float, ...]) -> list:
        """`_params_entry` of the shared parameters as floats."""
        cached = self._params_cache
        if cached is not None and cached[0] == key:
            return cached[1]
        sigma0, v_s, sigma2 = (v * s for v, s in zip(key, self._shared_scale))
        b = self._base
        entry = [(b.mu_c, b.mu_s - b.mu_c, b.alpha, sigma0, sigma0 * b.patch_length, v_s, sigma2), None]
        self._params_cache = (key, entry)
        return entry
