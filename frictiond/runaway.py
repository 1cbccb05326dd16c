"""A wheel running away into slip: a stop's first evidence of the peak where no ABS is seen.

Over its peak a tyre gives no more force as the brake torque rises, and the wheel runs on
towards lock-up until the torque falls. `RunawayEvidence` is a part of the estimator (through
`peak_evidence.PeakEvidence`): it follows each wheel's candidate runaway sample by sample and
confirms it when the slip runs on.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from .samples import N_WHEELS
from .vehicle import GRAVITY_MPS2


@dataclass(slots=True)
class _Runaway:
    """A wheel's latest runaway into slip, until confirmed or `runaway_confirm_s` old."""
    since_s: float = -math.inf
    reached: float = 0.0              # the slip it had reached when seen
    confirmed: bool = False


class RunawayEvidence:
    """Each wheel's latest runaway (`_runaway`, a list of `_Runaway`, forgotten per stop),
    followed per sample and confirmed when its slip runs on."""

    def _forget_runaways(self) -> None:
        """No wheel has run away yet (a new stop)."""
        self._runaway = [_Runaway() for _ in range(N_WHEELS)]

    def _running_away(self, wheel: int, runaway_rate: float, lam_hi: float, mu_hi: float, speed: float) -> bool:
        """Whether the wheel ran away into slip, confirmed (`_runaway_confirmed`): a stop's first
        evidence of the peak where no ABS is seen working the wheel.

        Over its peak a tyre gives no more force as the brake torque rises: the wheel runs away
        into slip (ABS exists to catch this). Steady braking, however bent its μ–slip data look
        (a LuGre-like tyre bends well before the peak; the driver's release bends them more),
        moves the slip slowly. Growth over ~50 ms (`_runaway_lag` samples): beyond the slip
        noise, within an ABS cycle; and the force no longer following it: Δμ/μ ≤ elasticity·Δλ/λ.
        The pedal applied briskly moves the slip as fast in the linear region (0.3 /s at 65 % of
        the grip on wet), but there μ rises in proportion. Near-zero-slip peaks (polished ice)
        run away at a rate relative to their slip. And in sliding speed, not only in slip: at
        walking pace the speed estimate's noise, divided by a small speed, makes slip "grow" at
        rates a runaway shows at speed. Past its peak a wheel decelerates faster than the car by
        (T_brake − R·F_peak)·R/J; with F_z·R²/J ≈ 25 g per unit of μ on cars, 1.5 μ·g is a brake
        torque 6 % past the peak.
        """
        o = self.options
        needed = max(min(o.excitation_slip_rate, o.excitation_relative_slip_rate * lam_hi),
                     o.excitation_runaway_decel * GRAVITY_MPS2 * max(mu_hi, 0.0) / max(speed, 1.0))
        return self._runaway_confirmed(wheel, runaway_rate >= needed, lam_hi)

    def _runaway_confirmed(self, wheel: int, running_away: bool, lam_hi: float) -> bool:
        """Whether the wheel's runaway is a real one (`_follow_runaways`). A slip that grows
        fast for a moment and then stays is the linear region's transient: a tyre with
        relaxation lags the slip as the pedal goes down, and its force seems not to follow."""
        o = self.options
        state = self._runaway[wheel]
        if self._last_sample_s - state.since_s <= o.runaway_confirm_s:
            return state.confirmed
        if running_away:
            self._runaway[wheel] = _Runaway(self._last_sample_s, lam_hi)
        return False

    def _follow_runaways(self, now_s: float, slips: Sequence[float]) -> None:
        """Per sample, each wheel with an unconfirmed runaway. Past its peak, with the brake
        torque above what the road can take, the slip runs on towards lock-up until the torque
        falls: running on to twice the slip reached (and by `runaway_confirm_slip`) confirms
        it. Nothing else does: a slip that falls back while the force holds is what a relaxing
        tyre shows after the pedal's application (its force catching up with a slip that
        overshot), as much as a wheel released from past its peak; an ABS release is evidence
        of its own (`abs_activity`)."""
        o = self.options
        for i in range(N_WHEELS):
            state = self._runaway[i]
            if state.confirmed or now_s - state.since_s > o.runaway_confirm_s:
                continue
            slip = slips[i]
            if slip >= max(2.0 * state.reached, state.reached + o.runaway_confirm_slip):
                state.confirmed = True
