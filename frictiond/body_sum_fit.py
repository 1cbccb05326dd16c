"""μ_max from the car's total tyre force, for a car whose wheels' brake torques are unknown.

A car that sends one master-cylinder pressure for all wheels: once its ABS releases a wheel, no
wheel's brake torque is known, and so no wheel's μ. The accelerometer still measures the sum,
Σ N_i μ(λ_i, v) / Σ N_i, with the four slips and loads known. The static LuGre curve, its shape
held at the priors, with one θ per side of the car (the wheels of a side roll on one road),
fitted to that sum over the last `window_s`, gives a μ_max: the sides' peaks weighted by load.

A sum constrains the curves only over the slips the wheels swept. It shows the peak where a
wheel on each side spent `span_share` of the window below 0.8 and past 1.2 times its side's
fitted peak slip: their μ passed over the peak, and the sum's top is the curves'. A slip
controller holding its wheels short of the peak, or a gentle stop, sweeps no such span. Rows with
a wheel far past the peak are left out, and a window made mostly of them (a threshold ABS) is
fitted with a curve of no shape instead, which follows a tyre past its peak (`body_sum_curve`).
The sum can trade one side's θ against the other's (on the campaign's split-μ stops the two fits
swapped roads within a second), so it is evidence of one road only:
the sides' peaks must agree within `max_side_ratio`, and so must the window's older and newer
halves fitted apart (a change of road). Residuals above `max_rms_share` of μ_max mean the curves
do not describe the wheels; residuals that grow with how deep the wheels are in slip
(`BodySumResult.rise_share`) mean the tyre's force still rises where the fitted curve tops out, so
its peak is beyond the fit's (the report counts that in its confidence); in a turn the tyres'
lateral force takes grip the sum does not see: beyond `max_lateral_mu`, and `max_lateral_share`
of the peak where the report adds the lateral μ back (the friction circle), no peak is shown.
Pure numerics: nothing of CAN or of the front end.
"""
from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from .body_sum_curve import DRIFTING, NOT_IN_BOTH_HALVES, CurveSumFit, curve_sum, fit_curve_sum
from .samples import LEFT_WHEELS, N_WHEELS, RIGHT_WHEELS
from .tyre_model import MAX_MODEL_SLIP, LugreParams, mu_and_jacobian_theta, peak, supported_slip

# Each wheel's side (0 left, 1 right): the index of its θ.
_SIDE_INDEX = np.array([0 if i in LEFT_WHEELS else 1 for i in range(N_WHEELS)])

# Slips (as multiples of the fitted peak slip) a wheel must have spent time below and past.
SPAN_BELOW = 0.8
SPAN_PAST = 1.2
# The verdict of a fit whose curve does not describe the four wheels: the road may be changing.
MISFIT = "one curve does not fit the four wheels"
# The verdict of the newest rows straying from the last fit: the window starts again.
ROAD_CHANGE = "the road changing"
# The verdict of a window whose free curve showed the peak at the last fit and no longer does: its
# window spans several ABS cycles, so what changed is the rows (a road, the stop's end), not a phase.
CURVE_LOST = "the free curve no longer shows the peak"
# The verdict of a window whose wheels mostly stay near the peak, where only deep ones are read.
NOT_DEEP = "wheels not deep past the peak"
# The verdict of sides whose fitted peaks differ: the sum cannot tell split μ (below).
SIDES_DIFFER = "the two sides' fitted peaks differ"
# Gauss–Newton on ln θ: the steps a fit may take, and the step size that ends it.
MAX_STEPS = 12
STEP_TOLERANCE = 1e-3
MAX_LOG_STEP = 0.7


@dataclass(frozen=True)
class BodySumOptions:
    window_s: float = 1.0            # the rows fitted: the newest this long (a few ABS cycles)
    min_rows: int = 20               # ... at least this many, over at least half the window
    min_speed_mps: float = 5.0       # below this a slip is the speed estimate's error (as the wheels' evidence)
    fit_every_s: float = 0.05        # one fit per this long (the sum moves with the ABS cycles)
    measurement_std: float = 0.04    # a row's noise (accelerometer and slips), against the prior's weight
    max_slip_ratio: float = 2.0      # rows fitted: every wheel within this many times the fitted peak slip ...
    min_near_share: float = 0.5      # ... at least this share of the window's rows
    span_share: float = 0.1          # a wheel spans the peak: this share of the rows each side of it
    max_side_ratio: float = 1.15     # one road: the sides' fitted peaks, and the window's halves', within this ratio
    max_rms_share: float = 0.06      # one curve fits: the residuals' rms within this share of μ_max ...
    misfit_block_s: float = 0.05     # ... the rms of their means over this long (the accelerometer's noise averaged)
    innovation_window_s: float = 0.1  # a change of road: the newest this long of rows ...
    max_innovation_share: float = 0.1  # ... off the last fit by this share of its μ_max on average
    max_lateral_mu: float = 0.05     # going straight: the window's lateral μ at most this ...
    max_lateral_share: float = 0.0   # ... or this share of the fitted peak (a turn the report reads by the friction circle)
    peak_extrapolation: float = 1.6  # a wheel's peak is not read beyond this multiple of its slips fitted ...
    extrapolation_max_slip: float = 0.3  # ... nor beyond this slip where they did not go (the wheels' rule)
    deep_curve: bool = True          # a window mostly of wheels deep past the peak: the free curve's (`body_sum_curve`)
    deep_only: bool = False          # only such windows fitted (beside the wheels' fit: `body_curve_report`)


@dataclass(frozen=True)
class BodySumResult:
    """One fit: μ_max and λ* at the speed given, each wheel's fitted peak slip, θ, the
    residuals' rms over μ_max, how far the residuals rise from the rows of shallow slips to the
    deep ones (over μ_max: `_rise`), which wheels spanned the fitted peak, the window's largest
    lateral μ, the rows fitted, and why it does not show the peak ("" when it does); from the free
    curve (`body_sum_curve`), its peak's standard error over μ_max (0 from the static curve) and
    the highest mean of the body's μ over `misfit_block_s` among its rows (0 from the static curve)."""
    mu_max: float
    slip_star: float
    wheel_slip_star: tuple[float, ...]
    theta: float
    rms_share: float
    rise_share: float
    spans: tuple[bool, ...]
    lateral_mu: float
    rows: int
    verdict: str
    curve_se_share: float = 0.0
    window_utilisation: float = 0.0


class BodySumFit:
    """The rows of the car's total force and slips, and the fit of the sides' θ to them."""

    def __init__(self, shape: LugreParams, prior_theta: float, prior_std_log_theta: float,
                 theta_bounds: tuple[float, float], side_coupling_std: float,
                 options: BodySumOptions | None = None) -> None:
        self.options = options or BodySumOptions()
        self._shape = shape
        self._prior_log_theta = math.log(prior_theta)
        self._prior_std = prior_std_log_theta
        self._side_coupling_std = side_coupling_std
        self._log_bounds = (math.log(theta_bounds[0]), math.log(theta_bounds[1]))
        self._rows: deque[tuple[float, float, tuple[float, ...], tuple[float, ...], float, float]] = deque()
        self._log_thetas = np.full(2, self._prior_log_theta)
        self._last_fit_s = -math.inf
        self._last: BodySumResult | None = None
        self._last_curve: CurveSumFit | None = None   # the free curve behind `_last`, if it is one

    def clear(self) -> None:
        """Forget the rows and the last fit (a new stop, a new road)."""
        self._rows.clear()
        self._log_thetas = np.full(2, self._prior_log_theta)
        self._last_fit_s = -math.inf
        self._last = None
        self._last_curve = None

    def push(self, time_s: float, speed_mps: float, slips: tuple[float, ...], loads: tuple[float, ...],
             body_mu: float, lateral_mu: float) -> None:
        """One row: the wheels' slips and normal loads, the body's μ. Rows that cannot be fitted
        (a speed a slip says nothing at, a NaN, no load) are left out."""
        total = sum(loads)
        if not (speed_mps >= self.options.min_speed_mps and math.isfinite(body_mu) and total > 0.0
                and all(math.isfinite(s) for s in slips) and min(loads) >= 0.0):
            return
        shares = tuple(f / total for f in loads)
        clipped = tuple(min(max(s, 0.0), MAX_MODEL_SLIP) for s in slips)
        lateral = lateral_mu if math.isfinite(lateral_mu) else math.inf
        self._rows.append((time_s, speed_mps, clipped, shares, body_mu, lateral))

    def result(self, now_s: float, speed_mps: float) -> BodySumResult | None:
        """The fit over the newest `window_s` of rows, refitted every `fit_every_s`; None without
        enough rows."""
        o = self.options
        rows = self._rows
        while rows and rows[0][0] < now_s - o.window_s:
            rows.popleft()
        if len(rows) < o.min_rows or rows[-1][0] - rows[0][0] < 0.5 * o.window_s:
            return None
        if self._road_changed():
            # (the rows before the change describe the old road: the window starts again)
            while rows and rows[0][0] < rows[-1][0] - o.innovation_window_s:
                rows.popleft()
            changed = dataclasses.replace(self._last, verdict=ROAD_CHANGE)
            self._last = None
            return changed
        if self._last is not None and now_s - self._last_fit_s < o.fit_every_s:
            return self._last
        self._last_fit_s = now_s
        curve_shown = self._last_curve is not None
        self._last_curve = None
        fit = self._fit(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                        np.array([r[2] for r in rows]), np.array([r[3] for r in rows]),
                        np.array([r[4] for r in rows]), max(r[5] for r in rows), max(speed_mps, o.min_speed_mps))
        if curve_shown and fit.verdict and fit.verdict != MISFIT:
            fit = dataclasses.replace(fit, verdict=CURVE_LOST)
        self._last = fit
        return fit

    def _road_changed(self) -> bool:
        """Whether the newest `innovation_window_s` of rows stray from the last fit by more than
        `max_innovation_share` of its μ_max on average: a change of road, seen at once rather
        than when the window's halves disagree. Their noise averages over an ABS cycle's rows;
        the fit's own misfit is within `max_rms_share`.

        Read only against a fit that shows the peak, and on the rows whose wheels all stay within
        `max_slip_ratio` of their fitted peak slip, as the fit's: there the curve describes the
        tyre. A wheel far past its peak gives its tyre's sliding level, up to 55 % under the peak
        where the curve at the priors' shape falls 12 %; and a fit that does not show the peak
        has its curve where the prior's shape puts it, not the tyre's. The newest 0.1 s is one
        phase of an ABS cycle: with the wheels running towards lock, either read as a new road at
        every cycle, and the window, started again each time, never filled (campaign stop 475,
        a car sending its master cylinder's pressure alone). A change under a fit that shows no
        peak still shows: the window's halves then differ (`MISFIT`) until the old road's rows
        have left it."""
        o = self.options
        last = self._last
        if last is None or last.verdict:   # (none yet, a change just started the window again,
            return False                   # or a curve that does not describe the rows)
        newest = []
        for row in reversed(self._rows):
            if row[0] < self._rows[-1][0] - o.innovation_window_s:
                break
            newest.append(row)
        if self._last_curve is not None:
            # (the free curve describes deep slips too: every newest row is read)
            model = curve_sum(self._last_curve.values, np.array([r[2] for r in newest]),
                              np.array([r[3] for r in newest]))
            residual = float(np.mean(np.array([r[4] for r in newest]) - model))
            return len(newest) >= 4 and abs(residual) > o.max_innovation_share * last.mu_max
        deepest = o.max_slip_ratio * np.array(last.wheel_slip_star)
        described = [row for row in newest if (np.array(row[2]) <= deepest).all()]
        # (a few described rows among deep ones are the cycle's turning points: re-applying
        # tyres whose force lags their slip, not a road)
        if len(described) < max(4, len(newest) / 2):
            return False
        newest = described
        model, _ = self._sum_and_slope(np.array([r[2] for r in newest]), np.array([[r[1]] for r in newest]),
                                       np.array([r[3] for r in newest]), self._log_thetas)
        residual = float(np.mean(np.array([r[4] for r in newest]) - model))
        return abs(residual) > o.max_innovation_share * last.mu_max

    def _fit(self, times: np.ndarray, speed: np.ndarray, slips: np.ndarray, shares: np.ndarray, body: np.ndarray,
             lateral_mu: float, speed_now: float) -> BodySumResult:
        """θ per side fitted to every row, then again to the rows whose wheels all stay within
        `max_slip_ratio` of their side's fitted peak slip; the peaks and the evidence from those.

        A wheel far past its peak gives its tyre's sliding level: from 5 % (a Burckhardt dry
        tyre) to 55 % (a Magic Formula tyre with C = 2.5) below the peak. The curve, its shape at
        the priors, falls about 12 % there: rows with such a wheel would pull the fitted peak
        towards the sliding level. Near the peak every tyre's curve is round, as the model's."""
        o = self.options
        if o.deep_only:
            return self._deep_only_fit(times, slips, shares, body, lateral_mu)
        x = self._solve(self._log_thetas, speed, slips, shares, body)
        _, wheel_slip = self._peaks(x, speed_now)
        near = (slips <= o.max_slip_ratio * wheel_slip).all(axis=1)
        enough = int(near.sum()) >= max(o.min_rows, o.min_near_share * len(body))
        if not enough and o.deep_curve:
            return self._deep_fit(x, times, slips, shares, body, lateral_mu)
        if enough:
            times, speed, slips, shares, body = times[near], speed[near], slips[near], shares[near], body[near]
            x = self._solve(x, speed, slips, shares, body)
        self._log_thetas = x
        model, _ = self._sum_and_slope(slips, speed[:, None], shares, x)
        wheel_mu, wheel_slip = self._peaks(x, speed_now)
        share = shares.mean(axis=0)
        mu_max = float(share @ self._held_within_data(x, wheel_mu, wheel_slip, slips.max(axis=0), speed_now))
        period = float(np.median(np.diff(times))) if len(times) > 1 else o.misfit_block_s
        rms_share = _block_rms(model - body, o.misfit_block_s / max(period, 1e-6)) / max(mu_max, 1e-6)
        rise_share = _rise(body - model, (shares * slips / wheel_slip).sum(axis=1)) / max(mu_max, 1e-6)
        below = (slips <= SPAN_BELOW * wheel_slip).mean(axis=0)
        past = (slips >= SPAN_PAST * wheel_slip).mean(axis=0)
        spans = (below >= o.span_share) & (past >= o.span_share)
        verdict = ""
        if not enough:
            verdict = "wheels deep past the peak"
        elif not (spans[LEFT_WHEELS,].any() and spans[RIGHT_WHEELS,].any()):
            verdict = "wheels' slips not across the fitted peak on both sides"
        elif max(wheel_mu) > o.max_side_ratio * max(min(wheel_mu), 1e-9):
            verdict = SIDES_DIFFER
        elif rms_share > o.max_rms_share or self._halves_differ(x, times, speed, slips, shares, body, speed_now):
            verdict = MISFIT
        elif self._turning(lateral_mu, mu_max):
            verdict = "turning"
        return BodySumResult(mu_max, float(share @ wheel_slip), tuple(wheel_slip.tolist()), float(np.exp(x).mean()),
                             rms_share, rise_share,
                             tuple(spans.tolist()), lateral_mu, len(body), verdict)

    def _deep_only_fit(self, times: np.ndarray, slips: np.ndarray, shares: np.ndarray, body: np.ndarray,
                       lateral_mu: float) -> BodySumResult:
        """The free curve's fit where most rows hold a wheel past twice the slip of the curve's own
        top (as `_fit` asks of the static curve's, without its Gauss–Newton solve); else `NOT_DEEP`."""
        o = self.options
        curve = fit_curve_sum(slips, shares, body)
        near = (slips <= o.max_slip_ratio * curve.slip_star).all(axis=1)
        if int(near.sum()) >= max(o.min_rows, o.min_near_share * len(body)):
            return BodySumResult(math.nan, math.nan, (math.nan,) * N_WHEELS, math.nan, 0.0, 0.0, (False,) * N_WHEELS,
                                 lateral_mu, len(body), NOT_DEEP)
        return self._deep_fit(self._log_thetas, times, slips, shares, body, lateral_mu, curve)

    def _deep_fit(self, x: np.ndarray, times: np.ndarray, slips: np.ndarray, shares: np.ndarray, body: np.ndarray,
                  lateral_mu: float, curve: CurveSumFit | None = None) -> BodySumResult:
        """The free curve's fit (`curve`, if already fitted to these rows) where most rows hold a
        wheel far past the peak (`body_sum_curve`); its verdict in words after "wheels deep past
        the peak"."""
        o = self.options
        curve = curve or fit_curve_sum(slips, shares, body)
        star = curve.slip_star
        rows_per_block = o.misfit_block_s / max(float(np.median(np.diff(times))), 1e-6)
        rms_share = _block_rms(curve_sum(curve.values, slips, shares) - body, rows_per_block) / max(curve.mu_max, 1e-6)
        below = (slips <= SPAN_BELOW * star).mean(axis=0)
        past = (slips >= SPAN_PAST * star).mean(axis=0)
        spans = (below >= o.span_share) & (past >= o.span_share)
        if curve.verdict in (DRIFTING, NOT_IN_BOTH_HALVES):
            verdict = MISFIT
        elif curve.verdict:
            verdict = f"wheels deep past the peak; {curve.verdict}"
        elif self._turning(lateral_mu, curve.mu_max):
            verdict = "turning"
        else:
            verdict = ""
            self._last_curve = curve
        self._log_thetas = x
        k = max(1, int(round(rows_per_block)))   # (as `_block_rms` counts a block)
        utilisation = float(np.convolve(body, np.full(k, 1.0 / k), "valid").max())
        return BodySumResult(curve.mu_max, star, (star,) * N_WHEELS, float(np.exp(x).mean()), rms_share, 0.0,
                             tuple(spans.tolist()), lateral_mu, len(body), verdict, curve.se_share, utilisation)

    def _turning(self, lateral_mu: float, mu_max: float) -> bool:
        """Whether the window's lateral μ is beyond both `max_lateral_mu` and `max_lateral_share`
        of the fitted peak. Each tyre carries its load's share of the car's lateral force, so on one
        road every tyre has the same share of its grip left for the longitudinal force the sum
        measures: the curve is the road's scaled down, and the friction circle gives the road's
        peak back. How far a tyre's lateral grip differs from its longitudinal one (an ellipse)
        is unknown; its error grows with the lateral share, 4 % at half with a lateral grip 13 %
        short."""
        o = self.options
        return lateral_mu > max(o.max_lateral_mu, o.max_lateral_share * mu_max)

    def _held_within_data(self, x: np.ndarray, wheel_mu: np.ndarray, wheel_slip: np.ndarray, support: np.ndarray,
                          speed: float) -> np.ndarray:
        """Each wheel's peak μ, read no further than its fitted slips reach (the wheels' fit's
        rule, `tyre_model.supported_slip`): beyond `peak_extrapolation` times its highest slip (`support`)
        (and `extrapolation_max_slip` where it did not go) the curve's rise is the prior's shape,
        not the tyre's. Where a slip controller or a gentle stop kept the wheels short of the
        fitted peak, that peak read 15 % above the road on average on the development campaign's
        cars that send their master cylinder's pressure alone (dev 0–999), 2 % held so."""
        o = self.options
        cap = supported_slip(support, o.peak_extrapolation, o.extrapolation_max_slip)
        beyond = wheel_slip > cap
        if not beyond.any():
            return wheel_mu
        thetas = np.exp(x)[_SIDE_INDEX]
        mu_cap, _ = mu_and_jacobian_theta(cap[None, :], np.array([[speed]]), thetas, self._shape, ("theta",))
        return np.where(beyond, np.minimum(mu_cap[0], wheel_mu), wheel_mu)

    def _halves_differ(self, x: np.ndarray, times: np.ndarray, speed: np.ndarray, slips: np.ndarray,
                       shares: np.ndarray, body: np.ndarray, speed_now: float) -> bool:
        """Whether the window's older and newer halves, fitted apart, give peaks further apart
        than `max_side_ratio`: the road changed within it. Two θ can fit a sum that mixes two
        roads in time about as well as one road, so the residuals alone do not show it."""
        newer = times >= 0.5 * (times[0] + times[-1])
        peaks = []
        for half in (~newer, newer):
            if int(half.sum()) < self.options.min_rows // 2:
                return False
            fitted = self._solve(x, speed[half], slips[half], shares[half], body[half])
            peaks.append(float(shares[half].mean(axis=0) @ self._peaks(fitted, speed_now)[0]))
        return max(peaks) > self.options.max_side_ratio * max(min(peaks), 1e-9)

    def _peaks(self, x: np.ndarray, speed: float) -> tuple[np.ndarray, np.ndarray]:
        """Each wheel's peak (μ, λ) at `speed`: its side's θ."""
        sides = np.array([peak(speed, dataclasses.replace(self._shape, theta=math.exp(float(value)))) for value in x])
        return sides[_SIDE_INDEX, 0], sides[_SIDE_INDEX, 1]

    def _solve(self, x: np.ndarray, speed: np.ndarray, slips: np.ndarray, shares: np.ndarray,
               body: np.ndarray) -> np.ndarray:
        """Gauss–Newton on the sides' ln θ from `x`: the prior a weak pull on each, the sides held
        together as the wheels' fit holds them (`side_coupling_std`), the bounds a clamp."""
        prior_weight = self.options.measurement_std / self._prior_std
        coupling_weight = self.options.measurement_std / self._side_coupling_std
        # (the prior's and the coupling's part of the normal matrix: the same at every step)
        prior_normal = prior_weight ** 2 * np.eye(2)
        coupling_normal = coupling_weight ** 2 * np.array([[1.0, -1.0], [-1.0, 1.0]])
        apart = np.array([1.0, -1.0])
        v = speed[:, None]
        x = np.array(x, dtype=float)
        for _ in range(MAX_STEPS):
            model, jac = self._sum_and_slope(slips, v, shares, x)
            residual = model - body
            prior = prior_weight * (x - self._prior_log_theta)
            coupling = coupling_weight * (x[0] - x[1])
            normal = jac.T @ jac + prior_normal + coupling_normal
            gradient = jac.T @ residual + prior_weight * prior + coupling_weight * coupling * apart
            step = np.clip(-np.linalg.solve(normal, gradient), -MAX_LOG_STEP, MAX_LOG_STEP)
            x_new = np.clip(x + step, *self._log_bounds)
            done = float(np.abs(x_new - x).max()) < STEP_TOLERANCE
            x = x_new
            if done:
                break
        return x

    def _sum_and_slope(self, slips: np.ndarray, v: np.ndarray, shares: np.ndarray,
                       log_thetas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The load-weighted sum of the four wheels' μ per row, and its derivatives in the sides'
        ln θ (one column per side)."""
        thetas = np.exp(np.asarray(log_thetas, dtype=float))[_SIDE_INDEX]
        mu, d_theta = mu_and_jacobian_theta(slips, v, thetas, self._shape, ("theta",))
        weighted = shares * d_theta[..., 0] * thetas
        jac = np.stack((weighted[:, LEFT_WHEELS,].sum(axis=1), weighted[:, RIGHT_WHEELS,].sum(axis=1)), axis=1)
        return (shares * mu).sum(axis=1), jac


def _rise(residuals: np.ndarray, depth: np.ndarray) -> float:
    """How much higher the residuals sit on the rows whose wheels are deepest in slip than on the
    shallowest: their straight line over `depth` (each row's load-weighted slip over the fitted
    peak slips), from its 10th to its 90th percentile.

    A sum cannot show one wheel's curve, but it shows the shape's error: where the tyre's force
    still climbs past the fitted peak slip (a cobblestone curve peaks at slip 0.4, the fit's
    shape near 0.3 at walking pace), the fit of a sum runs above the shallow wheels and below the
    deep ones, and its peak is the curve's top within the data, under the road's (campaign stop
    292, 23 % low with residuals rising 0.10 of μ_max across the rows)."""
    spread = depth - depth.mean()
    norm = float(spread @ spread)
    if len(depth) < 3 or norm <= 0.0:
        return 0.0
    low, high = np.quantile(depth, (0.1, 0.9))
    return float(spread @ residuals) / norm * float(high - low)


def _block_rms(residuals: np.ndarray, rows_per_block: float) -> float:
    """The rms of the residuals' means over consecutive blocks of about `rows_per_block` rows.

    A misfit of the curve (two roads under one θ, a change of road) lasts an ABS cycle or more;
    the accelerometer's noise, ±0.1–0.2 m/s² per sample, does not: on ice it alone is a tenth of
    μ. The block means keep the first and average the second."""
    k = max(1, int(round(rows_per_block)))
    n = len(residuals) - len(residuals) % k
    if n < k:
        return float(np.sqrt(np.mean(residuals ** 2)))
    means = residuals[len(residuals) - n:].reshape(-1, k).mean(axis=1)
    return float(np.sqrt(np.mean(means ** 2)))
