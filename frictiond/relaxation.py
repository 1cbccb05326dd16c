"""The tyre's relaxation: its force lags the slip, and the static curve is read from the lagged force.

A tyre's longitudinal force builds up over a relaxation length σ of rolling (0.1–0.6 m on car
tyres), a lag of τ = σ/v: τ·Ḟ + F = F_ss(λ). Under an ABS the slip sweeps through the peak in a
few tens of ms, which is τ at 10 m/s: the measured force then runs below the static curve while
the slip rises and above it while it falls, and the top of each cycle never reaches the peak. A
static model fitted to those samples puts the peak 20–30 % low, with the confidence of a fit
whose samples agree (the loops repeat every cycle).

The first-order lag is inverted per sample: μ_ss = μ + (σ/v)·μ̇, with μ̇ the central difference
of the wheel's neighbouring samples (so each sample is passed on one sample late). σ is the
tyre's, learnt from the loops themselves: within narrow bands of slip the static μ is a straight
line in λ, and what is left of μ varies with −μ̇/v by σ; a least-squares σ over the bands, with
forgetting. The noise of the differenced μ shrinks that estimate towards 0 (σ under-corrected,
never over): with a tyre that does not relax it stays near 0 and the samples pass almost
unchanged. The bands pool the four wheels: on split μ a band holds two roads' μ, and a tyre
without lag can read 0.1–0.2 m (measured on the campaign's split stops; left so, see
benchmarks/README).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .samples import PhysicalSample

try:
    from . import _frontcore as compiled_front
except ImportError:  # pragma: no cover - the build without a C compiler
    compiled_front = None

# Slip bands of the σ regression: narrow enough that the static curve is nearly straight in each
# (a peak on ice at 2 % slip, on dry asphalt at 10–20 %), log-spaced.
SLIP_BANDS = np.concatenate(([0.0], np.geomspace(0.005, 1.0, 30)))
# Below this speed τ = σ/v is taken at this speed, and nothing is learnt: the slips there are not
# measured well enough to show a peak at all (`LugreTROptions.peak_evidence_min_speed`), and
# dividing by a walking pace would turn the differenced μ's noise into corrections.
MIN_SPEED_MPS = 5.0
MAX_SIGMA_M = 1.0              # beyond any car tyre's relaxation length
MAX_LAG_S = 0.12               # τ used at most (σ = 0.6 m at 5 m/s)
MAX_NEIGHBOUR_SPAN_S = 0.06    # neighbours further apart than this (lost frames): no μ̇
MIN_BAND_SAMPLES = 6           # a band's samples before it counts in the σ regression
MEMORY_S = 3.0                 # forgetting time constant of the regression's sums
# Band samples (with forgetting) before σ is used: the first ABS cycles' σ, from a few dozen
# noisy differences, bent every sample (a dry stop's convergence went from 0.1 s to 0.9 s).
MIN_EVIDENCE_SAMPLES = 200
SIGMA_EVERY = 5                # σ recomputed every this many samples (it moves over seconds)


class RelaxationCompensator:
    """Passes each `PhysicalSample` on one sample late, its μ (and force) corrected for the tyre's
    relaxation lag with the σ learnt so far (`sigma_m`)."""

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled
        self.core = compiled_front    # `_corrected`'s wheels compiled (same numbers); None: Python
        self._sums = np.zeros((len(SLIP_BANDS) + 1, 9))
        self._last_learnt_s: float | None = None
        self._since_sigma = 0
        self.sigma_m = 0.0
        self._before: PhysicalSample | None = None
        self._held: PhysicalSample | None = None

    def flush(self) -> PhysicalSample | None:
        """The sample held back, uncorrected (no neighbour after it: a gap), and start again;
        σ is kept (it is the tyre's)."""
        held = self._held
        self._before = self._held = None
        return held

    def push(self, sample: PhysicalSample) -> PhysicalSample | None:
        """Take the newest sample; return the one before it, corrected (None at the first)."""
        if not self.enabled:
            return sample
        before, held = self._before, self._held
        self._before, self._held = held, sample
        if held is None:
            return None
        if before is None or not 0.0 < sample.time_s - before.time_s <= MAX_NEIGHBOUR_SPAN_S:
            return held     # (a gap on either side: no derivative, the sample passes as it is)
        return self._corrected(before, held, sample)

    def _corrected(self, before: PhysicalSample, sample: PhysicalSample, after: PhysicalSample) -> PhysicalSample:
        dt = after.time_s - before.time_s
        speed = max(sample.speed_mps, MIN_SPEED_MPS)
        learn = sample.speed_mps > MIN_SPEED_MPS
        lag = min(self.sigma_m / speed, MAX_LAG_S)
        if self.core is not None:
            last = self._last_learnt_s
            last, mus, forces = self.core.relaxation_step(
                self._sums, SLIP_BANDS, MEMORY_S, sample.time_s, math.nan if last is None else last, learn,
                lag, dt, speed, sample.slip, before.mu_used, sample.mu_used, after.mu_used, before.usable,
                sample.usable, after.usable, sample.normal_force_n, sample.tyre_force_n)
            self._last_learnt_s = None if math.isnan(last) else last
            self._count_for_sigma(learn)
            if mus is None:
                return sample
            return replace(sample, mu_used=mus, tyre_force_n=forces)
        mus = list(sample.mu_used)
        forces = list(sample.tyre_force_n)
        changed = False
        for i in range(4):
            if not (before.usable[i] and sample.usable[i] and after.usable[i]):
                continue
            rate = (after.mu_used[i] - before.mu_used[i]) / dt
            if not math.isfinite(rate):
                continue
            # (a NaN in the regression's sums would stay there, through every forgetting)
            if learn and math.isfinite(sample.mu_used[i]) and math.isfinite(sample.slip[i]):
                self._learn(sample.time_s, sample.slip[i], sample.mu_used[i], rate / speed)
            if lag > 0.0:
                mus[i] = sample.mu_used[i] + lag * rate
                forces[i] = mus[i] * sample.normal_force_n[i]
                changed = True
        self._count_for_sigma(learn)
        if not changed:
            return sample
        return replace(sample, mu_used=tuple(mus), tyre_force_n=tuple(forces))  # type: ignore[arg-type]

    def _count_for_sigma(self, learn: bool) -> None:
        if learn:
            self._since_sigma += 1
            if self._since_sigma >= SIGMA_EVERY:
                self._since_sigma = 0
                self.sigma_m = self._fitted_sigma()

    def _learn(self, time_s: float, slip: float, mu: float, rate_per_speed: float) -> None:
        if self._last_learnt_s is not None and time_s > self._last_learnt_s:
            self._sums *= math.exp(-(time_s - self._last_learnt_s) / MEMORY_S)
        self._last_learnt_s = time_s
        z = rate_per_speed
        band = int(SLIP_BANDS.searchsorted(slip))
        self._sums[band] += (1.0, slip, slip * slip, z, z * z, z * slip, mu, mu * slip, mu * z)

    def _fitted_sigma(self) -> float:
        """σ from the bands' sums: per band, μ and z = μ̇/v with their straight lines in λ taken
        out; the least-squares σ = −Σ cov(z, μ) / Σ var(z) over the bands with enough samples
        (0 until there are `MIN_EVIDENCE_SAMPLES` of them)."""
        if self.core is not None:
            return self.core.relaxation_sigma(self._sums, MIN_BAND_SAMPLES, MIN_EVIDENCE_SAMPLES, MAX_SIGMA_M)
        s = self._sums[self._sums[:, 0] >= MIN_BAND_SAMPLES]
        if not len(s):
            return 0.0
        n, sl, sll, sz, szz, szl, sm, sml, smz = s.T
        var_l = sll - sl * sl / n
        cov_zl = szl - sz * sl / n
        cov_ml = sml - sm * sl / n
        inv = np.divide(1.0, var_l, out=np.zeros_like(var_l), where=var_l > 1e-12)
        var_z = szz - sz * sz / n - cov_zl * cov_zl * inv
        cov_zm = smz - sz * sm / n - cov_zl * cov_ml * inv
        den = float(var_z.sum())
        if not den > 0.0 or float(n.sum()) < MIN_EVIDENCE_SAMPLES:
            return 0.0
        sigma = -float(cov_zm.sum()) / den
        return min(max(sigma, 0.0), MAX_SIGMA_M) if math.isfinite(sigma) else 0.0
