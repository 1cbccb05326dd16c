"""The estimator's state: what `reset` sets up, what a new braking event and a step of the clock
forget, and what is saved for a restart (`state`, `load_state`).

`EstimatorState` is a part of `LugreTrustRegionEstimator` (its options, parameter space, window
capacity and `kind` are the estimator's, set in its `__init__`). `reset` has each concern set up
its own state: the fit, the change-of-road test, what the update follows per sample, what was
reported, the evidence drawn from the samples, the axles' balance and the fits of the body's force
(`BodySumReport`, `BodyCurveReport`). A new event and a clock step keep the fitted parameters and
forget what the old samples showed.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from .estimator_window import _SmoothedMaximum, _Window
from .fit_parameters import SHARED
from .samples import N_WHEELS, FrictionEstimate
from .speed_error import SpeedErrorBound, SpeedErrorOptions


class EstimatorState:
    """The estimator's state set up (`reset`), forgotten per event (`_new_event`) or clock step
    (`_restart_after_clock_step`), saved (`state`) and loaded (`load_state`)."""

    def reset(self) -> None:
        """Start again from the prior (the loaded state's, else the nominal one): an empty window,
        no evidence, nothing reported, the axles' balance at zero."""
        o = self.options
        self._init_fit(o)
        self._init_road_change()
        self._init_inputs(o)
        self._init_reports()
        self._init_evidence()
        self._init_axle_balance()
        self._init_body_sum()
        self._init_body_curve()

    def _init_fit(self, o: Any) -> None:
        """The fit at the prior, with no trust radius, cached rows, covariance or fits yet."""
        nominal = np.array([math.log(o.prior_theta)] * N_WHEELS + [o.prior_sigma0, o.prior_v_s, o.prior_sigma2]) / self._scale
        self._prior = self._saved_prior.copy() if self._saved_prior is not None else nominal
        self._x = self._prior.copy()
        self._radius: float | None = None
        self._cache_x: np.ndarray | None = None
        self._core_rows_x: np.ndarray | None = None
        self._fits = 0
        self._last_fit_s = -math.inf
        self._residual_scale = 1.0
        self._numpy_residuals: np.ndarray | None = None
        self._cov_unit: np.ndarray | None = None

    def _init_road_change(self) -> None:
        """No change of road seen (`RoadChangeTest`)."""
        self._jumps = 0
        self._jump_times: deque[float] = deque()
        self._innovation_score = 0.0
        self._front_innovation_score = 0.0
        self._last_jump_s = -math.inf
        self._rear_straddles_until_s = -math.inf   # (`_detect_jump`: the rear axle crossing a change of road)

    def _init_inputs(self, o: Any) -> None:
        """An empty window, and nothing yet of what the update follows per sample."""
        self._window = _Window(self._window_capacity, alpha=o.alpha, patch_length=o.patch_length)
        self._last_sample_s = -math.inf
        self._input_share = 0.0   # the newest sample's share of corrupted input (input_quality)
        self._brake_gain_doubt = 0.0   # the newest sample's `brake_gain_doubt` (`_confidence`)
        self._lateral_mu = 0.0         # the tyres' lateral μ, averaged (`_follow_lateral`)
        self._lateral_time_s = -math.inf
        self._load_share = [1.0 / N_WHEELS] * N_WHEELS
        self._abs_seen_s = [-math.inf] * N_WHEELS
        self._speed_error = SpeedErrorBound(SpeedErrorOptions(
            o.speed_error_mps, o.speed_drift_mps2, o.speed_anchor_slip, o.excitation_window_s))
        self._body_mu = _SmoothedMaximum(o.body_floor_smoothing_s)

    def _init_reports(self) -> None:
        """Nothing reported yet: no estimate, no VALID, no stop's fit."""
        self._last_valid: FrictionEstimate | None = None
        self._valid_since_s = math.inf   # when the standing run of VALID began (`_excitation_hold`)
        self._last_excited_s = -math.inf
        self._last_estimate: FrictionEstimate | None = None
        self._withdrawn_moving_s = -math.inf   # the last non-VALID update at a speed with evidence (`_hold`)
        self._stop_fit: FrictionEstimate | None = None   # this stop's last fit (`_starved`)
        self._last_braking_s = -math.inf
        self._not_valid = ""          # why the last update's estimate is not VALID (`not_valid`)
        self._lateral_doubt = 0.0      # the share of μ_max the lateral μ's tolerance could take off

    def _init_evidence(self) -> None:
        """No evidence drawn from the samples: excitation, peaks shown, runaways, slip support,
        the floors from the data, the μ_max history behind the drift term."""
        self._event_first_fit = self._spread_loss_fit = 0   # `_fits` at the event's start, at the last spread loss
        self._peak_spread_loss = 0.0
        self._event_start_s = -math.inf
        self._mu_history: deque[tuple[float, float]] = deque()
        self._excitation_cache: float | None = None
        self._excitation_why: list = ["", "", "", ""]
        self._data_above_fit = 0.0
        self._last_peak_slips: list[float] | None = None
        self._slip_support: list[float] | None = None
        self._capped: np.ndarray | None = None
        self._slip_floor = [0.0] * N_WHEELS
        self._measured_peaks = [0.0] * N_WHEELS
        self._band_ratio = 0.0
        self._excited_since_s = math.inf
        self._peak_seen_speed = 0.0
        self._forget_shown_peaks()
        self._forget_runaways()

    def _init_axle_balance(self) -> None:
        """The axles' brake gains taken as balanced (`AxleBalance`)."""
        self._axle_balance = 0.0
        self._axle_scales_cache: tuple[float, tuple[float, float]] = (math.nan, (1.0, 1.0))
        self._last_update_s: float | None = None   # (`_balance_axles`: the time of its last step)

    def _new_event(self) -> None:
        """The first samples after the window ran empty: a new braking event begins.

        The fitted parameters stay (a warm start and prior: the road is usually the same), but
        all evidence derived from the previous event's samples is forgotten: the cached
        excitation, covariance and slip support, the μ_max history behind the drift term and the
        start of the excitation ramp. Otherwise the first fits of the new event, before its data
        reach the peak, would be reported VALID on the old event's evidence (with the old road's
        μ_max, on what may be a new surface). A VALID still held from the last event (`hold_s`)
        is left to expire as usual, but it is no longer renewed by stale excitation.
        """
        self._excitation_cache = None
        self._excitation_why: list = ["", "", "", ""]
        self._data_above_fit = 0.0
        self._event_first_fit = self._spread_loss_fit = self._fits
        self._peak_spread_loss = 0.0
        self._event_start_s = self._last_sample_s
        self._cov_unit = None
        self._slip_support = None
        self._capped = None
        self._mu_history.clear()
        self._body_mu.clear()
        self._excited_since_s = math.inf
        self._peak_seen_speed = 0.0
        self._forget_runaways()
        self._forget_shown_peaks()
        self._innovation_score = 0.0
        self._front_innovation_score = 0.0
        self._radius = None
        self._last_update_s = None
        self._jump_times.clear()

    def state(self) -> dict[str, Any]:
        """JSON-serialisable: fitted parameters and the last valid estimate (a prior for a restart)."""
        params = self._thetas(self._x).tolist() + (self._x[N_WHEELS:] * self._scale[N_WHEELS:]).tolist()
        last = self._last_valid
        return {
            "kind": self.kind,
            "parameters": dict(zip([f"theta_{w}" for w in ("fl", "fr", "rl", "rr")] + list(SHARED), params)),
            "last_valid": None if last is None else {
                "mu_max": last.mu_max, "slip_at_mu_max": last.slip_at_mu_max, "theta": last.theta,
                "wheel_mu_max": list(last.wheel_mu_max), "time_s": last.time_s,
            },
        }

    def load_state(self, state: dict[str, Any]) -> None:
        """Use saved parameters as the prior and starting point; `ValueError` on bad content."""
        if not isinstance(state, dict) or state.get("kind") != self.kind:
            raise ValueError("state is not from the lugre-tr estimator")
        params = state.get("parameters")
        names = [f"theta_{w}" for w in ("fl", "fr", "rl", "rr")] + list(SHARED)
        if not isinstance(params, dict) or any(n not in params for n in names):
            raise ValueError("state lacks fitted parameters")
        values = []
        for n in names:
            v = params[n]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"state parameter {n} is not a finite number")
            if n.startswith("theta_") and v <= 0:
                raise ValueError(f"state parameter {n} must be > 0")
            values.append(math.log(v) if n.startswith("theta_") else float(v))
        x = np.clip(np.array(values) / self._scale, self._lb, self._ub)
        self._saved_prior = x
        self.reset()

    @property
    def parameters(self) -> dict[str, float]:
        """The fitted parameters by name, as `state` saves them."""
        return self.state()["parameters"]

    def _restart_after_clock_step(self, t: float) -> None:
        """The clock went backwards (log splice, clock step): the window's samples would get
        weights from the future. Start the window again; the fitted parameters stay."""
        self._window.clear()
        self._mu_history.clear()
        self._clear_body_sum()
        self._clear_body_curve()
        self._last_update_s = None
        self._stop_fit = None
        self._last_braking_s = -math.inf
        # The times kept as anchors (last excitation, last jump) are from the old clock: left
        # there, `now − last excitation` would stay negative, and a VALID would be held for as
        # long as the clock went back (hours of free rolling) instead of `hold_s`. Carry them
        # over the step, as if one bus period had passed.
        step = t - self._last_sample_s - 0.01
        if math.isfinite(self._last_excited_s):
            self._last_excited_s += step
        if math.isfinite(self._last_jump_s):
            self._last_jump_s += step
        if math.isfinite(self._rear_straddles_until_s):
            self._rear_straddles_until_s += step
        self._speed_error.shift(step)
        self._excited_since_s = math.inf
