"""Recursive trust-region fit of the static LuGre model (paper §3): the friction estimator.

Design (the choices model.md leaves open, and why):

- Identified: one road parameter θ per wheel (split-μ must show per wheel), fitted as ln θ,
  and, pooled over the wheels, the bristle stiffness σ0 (slip stiffness σ0·L/2), the Stribeck
  speed v_s (how the peak moves with sliding speed) and the viscous σ2 (the shape beyond the
  peak). Fitting static LuGre to Burckhardt and Magic Formula curves on every surface, these
  four reproduce the peak within ~1 %; without σ2 and v_s the error reaches 20–100 % on low-μ
  surfaces. μ_c, μ_s, α and L are held at their published values: with θ free they are not
  separately identifiable (θ and the g-scale multiply), and with σ0 free L is redundant.
- Priors: every free parameter is regularised toward a prior (nominal values, or the state
  saved from the last run), so unexcited directions stay put instead of wandering. θ scales
  μ as 1/θ and spans 1 (dry asphalt) to ~30 (ice): its prior is on ln θ, a relative
  uncertainty; an absolute one strong enough to hold θ on dry roads kept it far from ice (fits
  stalled at twice ice's μ_max). The ln θ of the front and rear wheel on one side are tied by a
  soft constraint (they roll on the same track); left and right only weakly (split-μ).
- Window: samples older than `window_s` are dropped, the rest weighted by exp(−age/τ). A change
  detector watches the newest residuals: when they agree on a sign well beyond the noise (a μ
  jump), older samples are dropped at once, so the fit re-converges in a fraction of a second.
- Each update adds the wheels' new samples and runs at most `max_iterations` trust-region
  iterations warm-started from the last solution and trust radius (`trust_region.solve`).
- Honesty: the peak is only identifiable once the slip has been near it. An excitation measure
  (how close the window's slips came to λ*, and how much of μ_max was used; the data's own μ–slip
  curve bending over; and, for a stop's first evidence, a wheel running away into slip as tyres
  do past their peak) gates the status,
  and the confidence comes from the Gauss–Newton covariance σ²(JᵀWJ)⁻¹ pushed onto μ_max by the
  delta method, with σ² from the residuals (model mismatch counts as noise).

The excitation evidence is `peak_evidence.PeakEvidence`, the confidence and the vetoes on VALID
`estimate_confidence.EstimateConfidence`, the report of a fit (peaks, spread, status, hold)
`estimate_report.EstimateReport`, the fit itself `window_fit.WindowFit` and the change of road
read from its residuals `road_change.RoadChangeTest`, the parameter vector and its mapping to
the tyre model's parameters `fit_parameters.FitParameters`, the brake-gain balance between the
axles `axle_balance.AxleBalance`, the state that a reset sets up, a new braking event or a clock
step forgets and a restart loads `estimator_state.EstimatorState`: parts of the estimator class,
each in its own module. The window of samples the fit reads is `estimator_window._Window`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

try:
    # The per-update fit compiled (setup.py builds it when a C compiler is there); without it,
    # the same fit runs on the numpy path (`window_fit`: `_normal` + `trust_region.solve_normal`).
    from . import _fitcore as compiled_fit
except ImportError:  # pragma: no cover - depends on the install
    compiled_fit = None
from . import not_valid
from .samples import N_WHEELS, FrictionEstimate, PhysicalSample, Status
from .tyre_model import mu_and_jacobian_theta
from .vehicle import VehicleParams
from .axle_balance import AxleBalance
from .body_curve_report import BodyCurveReport
from .body_sum_report import BodySumReport
from .estimate_confidence import EstimateConfidence
from .estimate_report import EstimateReport
from .estimator_state import EstimatorState
from .estimator_window import _spread_loss_numpy, _Window  # noqa: F401 (_Window re-exported for the tests)
from .fit_parameters import SHARED, FitParameters  # noqa: F401 (SHARED re-exported)
from .peak_evidence import PeakEvidence
from .stop_fit import StopFit
from .window_fit import WindowFit


@dataclass(frozen=True, slots=True)
class LugreTROptions:
    """Tuning of the LuGre trust-region estimator; field names are config keys under estimator.lugre_tr."""

    window_s: float = 0.8                 # samples older than this leave the window
    forgetting_time_constant: float = 0.4  # s; weight exp(−age/τ)
    max_iterations: int = 2               # trust-region iterations per update (bounded work)
    ftol: float = 1e-4                    # per-update stopping tolerances (the next update continues)
    xtol: float = 1e-4
    predicted_ftol: float = 1e-3          # ... or when the next step promises less than this share of the cost
    measurement_std: float = 0.04         # assumed std of a utilised-μ sample (sets the prior's weight)
    # Priors (nominal values; Canudas-de-Wit et al. 2003 except θ) and their standard deviations.
    prior_theta: float = 1.2
    prior_sigma0: float = 181.54
    prior_v_s: float = 6.57
    prior_sigma2: float = 0.0018
    prior_std_log_theta: float = 4.0      # prior std of ln θ (θ is fitted as ln θ)
    prior_std_sigma0: float = 60.0
    prior_std_v_s: float = 3.0
    prior_std_sigma2: float = 0.003
    front_rear_coupling: float = 0.08     # std of ln θ_front − ln θ_rear on one side (relative)
    left_right_coupling: float = 0.6      # std of ln θ_left − ln θ_right (split-μ allowed)
    # Bounds of the free parameters.
    theta_min: float = 0.35               # μ_max up to ~4
    theta_max: float = 300.0              # μ_max down to ~0.005 (polished ice at speed is ~0.02)
    sigma0_min: float = 20.0
    sigma0_max: float = 2000.0
    v_s_min: float = 0.3
    v_s_max: float = 60.0
    sigma2_min: float = 0.0
    sigma2_max: float = 0.015
    # Held parameters.
    mu_c: float = 0.8
    mu_s: float = 1.55
    alpha: float = 0.5
    patch_length: float = 0.2
    # Gating and status.
    min_slip: float = 0.003               # samples below this carry no information on the peak
    min_samples: int = 25
    excitation_slip_ratio: float = 0.75   # slip must have reached this fraction of λ*
    excitation_mu_ratio: float = 0.85     # ... or the utilised μ this fraction of μ_max
    excitation_min_slip: float = 0.015    # no road peaks below this slip; smaller excursions prove nothing
    excitation_min_sliding_mps: float = 0.06  # ... nor slips whose sliding speed λ·v is a few wheel-speed quanta
    peak_evidence_speed_ratio: float = 0.6    # a peak seen at speed v is evidence down to this × v
    # m/s: below this no wheel shows a peak not seen before. A slip is a speed difference over
    # the speed: the speed estimate's error (~0.05 m/s) makes it 1 % of slip here, and more below,
    # where the ABS also lets go of the wheels (its cut-out) and they lock through the peak
    # between two samples. First evidence found below 5 m/s was 19 % false on dev seeds.
    peak_evidence_min_speed: float = 5.0
    excitation_slip_rate: float = 0.3     # 1/s: a stop's first evidence of the peak needs a wheel running away
    excitation_relative_slip_rate: float = 5.0   # ... or its slip growing at this many times itself per second
    excitation_runaway_elasticity: float = 0.3   # ... while μ grows by at most this share of the slip's relative growth
    excitation_runaway_decel: float = 1.5        # ... and the wheel decelerating faster than the car by this × μ·g
    runaway_confirm_s: float = 0.5        # ... and within this long after, its slip running on (the wheel locking)
    runaway_confirm_slip: float = 0.05    # ... by this much and to twice the slip it had reached
    max_peak_secant: float = 25.0         # μ/λ at a peak stays below this on every road
    min_slip_spread: float = 0.3          # a wheel's recent slips (10–90 % quantiles) span this share of the highest
    abs_min_slip_spread: float = 0.15     # ... or this share with an ABS working the wheel (its cycles hold the rest)
    # ... beyond twice what the speed estimate's error makes of a held slip (`speed_error`):
    speed_error_mps: float = 0.02         # its error where two wheels, a reference or free rolling anchor it
    speed_drift_mps2: float = 0.02        # ... growing this fast while it coasts on the accelerometer (its offset's error)
    speed_anchor_slip: float = 0.01       # anchored: the second-least-slipping wheel within this slip of it
    wheel_evidence_hold_s: float = 1.0    # a wheel has shown its peak if a verdict said so within this long
    unshown_wheel_tolerance: float = 0.1  # VALID: μ_max moves less than this share if the wheels that have not
    #   shown their peak took the others' (split μ: their extrapolated peaks are not evidence)
    flat_elasticity: float = 0.35         # a wheel at its peak: μ's slope over the top of its slips ≤ this × μ/λ
    rising_elasticity: float = 0.54       # ... and the wheels' pooled slope one standard error up short of this (80 % of a peak)
    flat_window_s: float = 0.5            # ... over the wheel's samples of the newest this long (a few ABS cycles)
    flat_min_samples: int = 8             # ... at least this many of them, half in the top half of the slips
    # ... whose slips spread at least half as wide (σ) as the derivative filter swept a sample's
    # slip (rms): μ is a mean over that sweep, and errors in the regressor shrink a slope towards
    # zero. Against the truth's slope over the same samples (dev 0–599, 40,566 evaluations), a
    # curve still rising (true elasticity > 0.5) read flat 8 % of the time with a smear below 1,
    # 12 % at 1–1.5, 25 % at 1.5–2 and 31–37 % beyond 2.
    max_top_smear: float = 2.0
    contradiction_elasticity: float = 0.7     # μ still rising at this share of μ/λ ...
    contradiction_slip_ratio: float = 1.2     # ... at slips this far past the fitted peak: the fit is not this tyre
    excitation_every: int = 3             # updates between excitation evaluations
    excitation_window_s: float = 0.3      # the newest samples that must show the peak
    excitation_fit_ratio: float = 0.92    # ... or reach this fraction of the fitted μ_max
    peak_extrapolation: float = 1.6       # μ_max is not read beyond this multiple of the slips seen
    extrapolation_max_slip: float = 0.3   # ... nor beyond this slip where the slips seen did not go
    min_utilisation: float = 0.8          # measured μ (90 % quantile) must reach this share of μ_max
    # The confidence is P(|error| ≤ band) under a normal error of the fit's σ; the same σ puts
    # 1 − erf(2·erfinv(c)) on an error past twice the band (20 %: a false VALID): 18 % at c = 0.5,
    # 7 % at 0.628, 4 % at 0.685. A VALID must make that error unlikely, not only a 10 % one likely:
    # entered at σ ≤ 0.099 and kept to σ ≤ 0.112 (wider, the held-out seeds' false VALID failed).
    valid_confidence: float = 0.685       # VALID is entered here ...
    keep_valid_confidence: float = 0.628  # ... and kept down to this (no one-cycle flicker)
    confidence_band: float = 0.10         # the confidence is the probability of μ_max within this share of the road's
    evidence_interval_s: float = 0.35     # the data tell about the peak once per this long (an ABS cycle), not
    #   once per sample: μ_max's spread grows by √(this / the sample period)
    # The relative floor of the uncertainty (the road is not LuGre): what is left of the error where
    # the fit's own terms vanish. Outputs past the evidence gates whose other terms were below 0.04
    # were off by 0.018–0.036 rms on the campaign's dev seeds; the floor keeps a margin over that
    # for tyres the campaign does not draw.
    model_mismatch: float = 0.045
    misfit_bin_samples: int = 10          # the data above the fitted curve count in slip bands of at least this many
    misfit_peak_ratio: float = 1.0        # ... and miss the peak by this many times their mean excess over a band
    drift_window_s: float = 0.15
    settle_s: float = 0.08                # confidence ramps up over the first excited instants
    hold_s: float = 2.0                   # VALID is kept this long after braking ends
    # ... and this long while braking without excitation: one ABS cycle (`evidence_interval_s`), as the
    # data show the peak once per cycle; a shorter hold withdraws a VALID between two cycles that
    # each show it.
    excitation_hold_s: float = 0.35
    jump_threshold: float = 2.5           # change detector: newest mean residual in noise std units
    jump_window_s: float = 0.08
    jump_refractory_s: float = 0.2        # after a detected jump, let the new road fill the window
    #   (short enough to see the rear axle cross the same change a wheelbase later)
    misfit_changes: int = 3               # this many detected changes of road within ...
    misfit_window_s: float = 4.0          # ... this long: the model misfits the tyre, nothing VALID
    peak_group_samples: int = 6           # μ_max is never below a wheel's mean μ over this many neighbouring slips
    measured_peak_margin: float = 0.05    # ... less this share (the axles' brake-gain split), ...
    measured_peak_settle_s: float = 0.5   # ... from this long into a stop (the brake gain corrected)
    band_floor: bool = True               # ... nor below the wheels' mean μ over a band of slips around their peaks
    body_floor_window_s: float = 0.3      # μ_max is never below the car's utilisation of the last this long ...
    body_floor_smoothing_s: float = 0.05  # ... averaged over this (the accelerometer's noise)
    body_floor_margin: float = 0.03       # ... less this (offset, pitch) ...
    body_floor_relative_margin: float = 0.03   # ... and this share of it
    stop_floor_tolerance: float = 0.12    # VALID needs μ_max within this share of the stop's highest body utilisation
    # In a turn each tyre also carries the car's lateral μ (`PhysicalSample.lateral_mu`, averaged
    # over `forgetting_time_constant`), and the longitudinal peak the data show is what is left of
    # the road's grip: μ_max = √(μ_x² + μ_y²) (the friction circle). The lateral μ is known to
    # within this (an accelerometer's offset, 0.3 m/s²); what that could take off μ_max counts
    # in the confidence. (`lateral_grip` off: the longitudinal peak as it is.)
    lateral_grip: bool = True
    lateral_mu_tolerance: float = 0.03
    # The body sum (`body_sum_fit`) in a turn, by the same circle, up to this lateral share of its peak.
    body_sum_lateral_share: float = 0.5
    axle_balance_time_constant: float = 2.0   # s; 0 disables the front/rear brake-gain balance
    axle_balance_limit: float = 0.3
    # μ is measured as a mean over the slips a wheel swept within the derivative filter's window
    # (`PhysicalSample.slip_spread`). Where the fitted curve bends within such a sweep the mean
    # falls short of it, and the samples do not resolve the curve there to better than that: the
    # share lost at the top of the wheels' data counts this many times in the confidence's σ,
    # evaluated every `spread_loss_every` fits. 0 disables. The loss is measured on the fitted
    # static LuGre curve, and a mean's shortfall at the top grows with the curvature there. Read
    # as |μ''|·λ*²/μ*, the static LuGre peak has 0.13–0.17. A Burckhardt dry-asphalt tyre has 0.31,
    # a Magic Formula tyre 0.42 at C = 1.5, 1.0 at C = 2 and 1.4 at C = 2.5. So a real tyre loses
    # at least twice what the fitted curve says.
    spread_loss_weight: float = 2.0
    spread_loss_every: int = 4
    # Where no wheel's brake torque is known (one master-cylinder pressure, an ABS releasing
    # wheels), μ_max from a fit of the car's total tyre force (`body_sum_fit`), with this σ
    # floor: past its evidence gates 94-99 % of such outputs were within 10 % on the campaign's
    # dev seeds, but the forced split-μ set's were not (see benchmarks/README.md, session 73).
    body_sum: bool = True
    body_sum_mismatch: float = 0.08
    # The free curve's peak (`body_sum_curve`, wheels deep past the peak): its standard error from
    # the residuals counts this many times in σ. On the development campaign's master-cylinder-only
    # cars the error against the truth was within 2.4 standard errors two times in three (dev 0–999,
    # 20000–20999, 40000–40999): the max of the knots picks the one noise lifted, and the rows of
    # an ABS cycle correlate over more than the blocks the noise is read over.
    body_sum_curve_error_ratio: float = 2.4
    body_sum_curve: bool = True   # the free curve where the body sum's wheels run deep (off: "wheels deep past the peak")
    # Where the wheels' torques are known and their fit is not VALID, the free curve of the car's
    # total force beside it, VALID where it shows the peak with VALID's confidence (`body_curve_report`).
    body_curve_beside_wheels: bool = True
    body_curve_agreement: float = 0.15   # ... and where the wheels' fit, CONVERGING, is within this share of it

    def validate(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                if not math.isfinite(value) or value < 0:
                    raise ValueError(f"{f.name}: must be a finite number ≥ 0, got {value!r}")
        if self.window_s <= 0 or self.forgetting_time_constant <= 0 or self.measurement_std <= 0:
            raise ValueError("window_s, forgetting_time_constant and measurement_std must be > 0")
        if self.max_iterations < 1:
            raise ValueError("max_iterations: must be ≥ 1")
        for name in ("theta", "sigma0", "v_s", "sigma2"):
            low, high = getattr(self, f"{name}_min"), getattr(self, f"{name}_max")
            prior = getattr(self, f"prior_{name}")
            if not low <= prior <= high or low >= high:
                raise ValueError(f"prior_{name}: {prior} must lie within [{name}_min, {name}_max] = [{low}, {high}]")
            std_name = "prior_std_log_theta" if name == "theta" else f"prior_std_{name}"
            if getattr(self, std_name) <= 0:
                raise ValueError(f"{std_name}: must be > 0")
        if self.confidence_band <= 0:
            raise ValueError("confidence_band: must be > 0")
        if self.keep_valid_confidence > self.valid_confidence:
            raise ValueError("keep_valid_confidence: must not exceed valid_confidence")
        if self.rising_elasticity < self.flat_elasticity:
            raise ValueError("rising_elasticity: must not be below flat_elasticity")
        if not self.max_top_smear > 0:
            raise ValueError("max_top_smear: must be > 0")
        if self.theta_min <= 0:
            raise ValueError("theta_min: must be > 0")


class LugreTrustRegionEstimator(WindowFit, PeakEvidence, EstimateConfidence, EstimateReport, FitParameters,
                                AxleBalance, BodySumReport, BodyCurveReport, StopFit, EstimatorState):
    """Recursive, bounded trust-region NLLS fit of static LuGre; one `update` per bus cycle."""

    kind = "lugre-tr"

    def __init__(self, options: LugreTROptions | None = None, vehicle: VehicleParams | None = None,
                 sample_period_s: float = 0.01) -> None:
        self.options = options or LugreTROptions()
        self.options.validate()
        self.vehicle = vehicle or VehicleParams()
        o = self.options
        if not (math.isfinite(sample_period_s) and sample_period_s > 0):
            raise ValueError(f"sample_period_s: must be a finite number > 0, got {sample_period_s!r}")
        # The evidence counted in samples is set for the samples' cycle time (the wheel-speed
        # message's): a wheel's recent slips need ~0.1 s of samples, a slip's run-away is read
        # over ~50 ms. Counts fixed for 10 ms asked a 20 ms car for twice the time.
        self._min_wheel_samples = max(5, round(0.1 / sample_period_s))
        self._runaway_lag = max(2, round(0.05 / sample_period_s))
        self._variance_inflation = max(1.0, o.evidence_interval_s / sample_period_s)   # (`_confidence`)
        # The forgetting weight of a sample `excitation_window_s` old: newer ones are "recent".
        self._recent_threshold = math.exp(-o.excitation_window_s / o.forgetting_time_constant)
        # Room for a whole window at twice the expected rate, four wheels a sample (a window
        # that outgrows it loses its oldest quarter); bounded so that a window_s of hours does not
        # preallocate gigabytes.
        self._window_capacity = int(min(max(4096.0, 8 * o.window_s / sample_period_s + 64), 1 << 17))
        self._init_parameter_space(o)
        self._saved_prior: np.ndarray | None = None
        self._work: np.ndarray | None = None
        self._alpha = float(o.alpha)
        self._shared_scale = tuple(float(v) for v in self._scale[N_WHEELS:])
        self._prior_peak: tuple[tuple, tuple] | None = None   # (speed, prior) → peak of the prior
        self._params_cache: tuple[tuple, list] | None = None
        self._x_floats: tuple | None = None   # (x, x as floats, θ per wheel, compiled parameters)
        self._core_constants = (float(o.mu_c), float(o.mu_s - o.mu_c), self._alpha) + self._shared_scale
        self._gradient_buffer, self._normal_buffer = np.empty(len(self._scale)), np.empty((len(self._scale),) * 2)
        # The compiled fit when installed; `None` runs the numpy path (tests, benchmarks compare).
        self.core = compiled_fit
        self.reset()

    # ----------------------------------------------------------------------------- update
    def update(self, sample: PhysicalSample) -> FrictionEstimate:
        o = self.options
        t = sample.time_s
        window = self._window
        self._not_valid = not_valid.FEW_SAMPLES   # (until a fit or a restated one says otherwise)
        if not math.isfinite(t) or not math.isfinite(sample.speed_mps):
            return self._hold(self._last_sample_s if math.isfinite(self._last_sample_s) else 0.0, 0.0)
        if t < self._last_sample_s - 1e-3:
            self._restart_after_clock_step(t)
        self._last_sample_s = t
        self._input_share = sample.input_suspect_share   # (corrupted input costs confidence: input_quality)
        self._brake_gain_doubt = sample.brake_gain_doubt
        self._follow_lateral(t, sample.lateral_mu)
        window.drop_before(t - o.window_s, self.core)
        fresh = len(window) == 0
        v = sample.speed_mps
        added = self._take_in(sample)
        if added and fresh:
            self._new_event()
        if added and o.spread_loss_weight > 0 and self._fits > self._spread_loss_fit:
            if (self._fits - self._event_first_fit) % max(o.spread_loss_every, 1) == 0:
                self._spread_loss_fit = self._fits
                self._peak_spread_loss = self._spread_loss()
        self._follow_braking(t, sample.braking)
        if added and t - self._last_fit_s > o.excitation_window_s:
            # The first samples after a pause in the data (the brake released and applied again
            # while older samples stay in the window): the excitation was read from samples that
            # are no longer the newest. Not carried into this fit.
            self._excitation_cache = None
        estimate = self._estimate_now(sample, added)
        self._last_estimate = estimate
        if estimate.status != Status.VALID and v >= o.peak_evidence_min_speed:
            self._withdrawn_moving_s = t   # (`_hold`: what was withdrawn while moving stays withdrawn)
        return estimate

    def _estimate_now(self, sample: PhysicalSample, added: int) -> FrictionEstimate:
        """This update's estimate: a fit of the window, or the body sum's; else the last
        CONVERGING fit restated while the window still holds this stop's data; else this stop's
        last fit where the window has run short of samples (`_starved`), or the hold."""
        o = self.options
        t, v = sample.time_s, sample.speed_mps
        samples = len(self._window)
        last = self._last_estimate
        if added and samples >= o.min_samples:
            return self._kept_as_stop_fit(self._beside_body_curve(self._fit(t, v), sample), t)
        if not added and sample.wheel_torques_unknown and (body := self._body_sum_estimate(t, v)) is not None:
            return self._kept_as_stop_fit(body, t)
        if (samples >= o.min_samples and last is not None and last.status == Status.CONVERGING
                and last.time_s != self._last_jump_s):
            # No usable sample this cycle (wheels deep in slip, a lost frame) while the window
            # still holds this stop's data: the untrusted fit stands. Falling back to the prior
            # here made MuMax flicker between the fit and the nominal dry-road peak. (Not the fit
            # that saw the road change: it describes the old road. The brakes still hold a wheel
            # in slip: not the pedal letting go, every slip fallen below what the fit takes.)
            slipping = sample.braking and any(slip >= o.min_slip for slip in sample.slip)
            return self._beside_body_curve(self._restate(last, t, slipping), sample)
        return self._beside_body_curve(self._starved(t, v), sample)

    @property
    def not_valid_reason(self) -> str:
        """Why the last update's estimate is not VALID, in words (`not_valid`); "" when it is."""
        last = self._last_estimate
        if last is None or last.status == Status.VALID:
            return ""
        if self._not_valid == not_valid.NOT_EXCITED:
            return not_valid.not_excited_reason(self._excitation_why)
        return self._not_valid

    def _follow_lateral(self, t: float, lateral_mu: float) -> None:
        """The tyres' lateral μ, averaged over the window's forgetting time (the accelerometer's
        noise; in a turn at constant radius it falls with the speed, slowly)."""
        if not lateral_mu >= 0.0 or not math.isfinite(lateral_mu):   # (NaN, a broken input: straight on)
            lateral_mu = 0.0
        age = t - self._lateral_time_s
        keep = math.exp(-age / self.options.forgetting_time_constant) if age >= 0.0 else 0.0
        self._lateral_mu = keep * self._lateral_mu + (1.0 - keep) * lateral_mu
        self._lateral_time_s = t

    def _take_in(self, sample: PhysicalSample) -> int:
        """The sample's usable wheels into the window (each wheel's μ corrected for the axles'
        brake-gain split), and what the evidence follows per sample: the loads' shares, the
        wheels' runaways, the body's utilisation, the wheels an ABS works. Returns how many
        wheels entered the window."""
        t, v = sample.time_s, sample.speed_mps
        loads = sample.normal_force_n
        total_load = sum(loads)
        if total_load > 0 and min(loads) >= 0:   # (a NaN load makes the sum NaN: fails the first)
            self._load_share = [f / total_load for f in loads]
        scales = None
        slips, mus, wheels = [], [], []
        spread = sample.slip_spread
        min_slip, isfinite, usable = self.options.min_slip, math.isfinite, sample.usable
        wheel_slips, wheel_mus = sample.slip, sample.mu_used
        self._follow_runaways(t, wheel_slips)
        self._speed_error.follow(sample)
        abs_active = sample.abs_active
        body_mu = sample.body_mu
        if body_mu == body_mu:   # (not NaN: braking, with a fresh accelerometer)
            self._body_mu.push(t, body_mu)
        self._take_in_body_sum(sample)
        self._take_in_body_curve(sample)
        if abs_active[0] or abs_active[1] or abs_active[2] or abs_active[3]:
            for i in range(N_WHEELS):
                if abs_active[i]:
                    self._abs_seen_s[i] = t
        for i in range(N_WHEELS):   # (indexing the four wheels: no zip/enumerate tuples per update)
            slip, mu_used = wheel_slips[i], wheel_mus[i]
            if usable[i] and slip >= min_slip and isfinite(mu_used):
                if scales is None:
                    scales = self._axle_scales()
                slips.append(slip)
                mus.append(mu_used * scales[i >= 2])
                wheels.append(i)
        if not slips:
            return 0
        self._window.append_instant(slips, v, mus, t, wheels, self.core)
        if spread is not None:
            self._window.set_spread(len(slips), [spread[i] for i in wheels], sample.slip_spread_weights)
        return len(slips)

    def _spread_loss(self) -> float:
        """The share of the fitted curve that the front end's mean over each sample's slips
        (`PhysicalSample.slip_spread`) loses, averaged over the samples that show the grip: the
        top of each wheel's data (μ within 10 % of its highest) among those the fit leans on
        (younger than `forgetting_time_constant`).

        A wheel under ABS crosses its peak in one or two samples; μ read through the derivative
        filter is the tyre's mean over that sweep, below the curve wherever it bends within it
        (on a sharp Magic Formula peak at 50 Hz the samples read 10–25 % below it). The samples
        that set the peak's height cannot show it to better than that. Measured on the fitted
        curve, which is rounder than such a tyre, it is an underestimate there."""
        w = self._window
        _, thetas, params = self._floats_of_x()
        since = self._last_sample_s - self.options.forgetting_time_constant
        if self.core is not None:
            lo = self.core.search_left(w.time, w.start, w.end, since)
            return self.core.spread_loss(w.slip, w.speed, w.mu, w.wheel, w.spread, lo, w.end, thetas, params)
        lo = w.start + int(w.time[w.start:w.end].searchsorted(since, side="left"))
        return _spread_loss_numpy(w, lo, thetas, self._params(self._x))

    def _weights(self, now_s: float, times: np.ndarray) -> np.ndarray:
        return np.exp(np.minimum(times - now_s, 0.0) / self.options.forgetting_time_constant)

    def _due(self, step: int) -> bool:
        """Whether this fit refreshes one of the slow-moving quantities (0 slip range, 1 excitation,
        2 covariance): each every `excitation_every` fits, on different fits so that together they
        do not make every third update the slowest (the p99 of the update and of the daemon's
        latency); every fit when `excitation_every` ≤ 1."""
        every = self.options.excitation_every
        return every <= 1 or self._fits % every == step % every

    # ------------------------------------------------------------------------------ tools
    def mu_curve(self, slip: np.ndarray, speed_mps: float, wheel: int | None = None) -> np.ndarray:
        """The fitted μ(λ) at a speed (for plots): one wheel's θ, or the wheels' mean."""
        p = self._params(self._x)
        thetas = self._thetas(self._x)
        theta = float(np.mean(thetas)) if wheel is None else float(thetas[wheel])
        slip = np.asarray(slip, dtype=float)
        value, _ = mu_and_jacobian_theta(slip, np.full_like(slip, speed_mps), np.full_like(slip, theta), p, ("theta",))
        return value
