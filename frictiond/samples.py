"""Plain data passed between the layers: physical samples in, friction estimates out.

Nothing here knows about CAN or about a tyre model; both sides import it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

WHEELS: tuple[str, str, str, str] = ("FL", "FR", "RL", "RR")
N_WHEELS = len(WHEELS)
FRONT_WHEELS = (0, 1)
REAR_WHEELS = (2, 3)
LEFT_WHEELS = (0, 2)
RIGHT_WHEELS = (1, 3)

Quad = tuple[float, float, float, float]


class Status(IntEnum):
    """`EstimatorStatus` values of FRICTION_ESTIMATE (can-contract.md)."""

    INIT = 0
    NOT_EXCITED = 1
    CONVERGING = 2
    VALID = 3
    INPUT_STALE = 4
    FAULT = 5


@dataclass(slots=True)
class PhysicalSample:
    """One time-aligned sample of the vehicle, produced by the front end per wheel-speed frame.

    All quantities are SI. `time_s` is the instant the values describe (the front end
    delays all signals equally so that the wheel-acceleration filter is centred).
    """

    time_s: float
    speed_mps: float
    slip: Quad
    mu_used: Quad                 # utilised friction F_x / F_N per wheel
    normal_force_n: Quad
    tyre_force_n: Quad            # F_x per wheel, positive when retarding
    usable: tuple[bool, bool, bool, bool]   # passed the front end's gates
    braking: bool = False         # brake applied (pressure above push-out) on any wheel
    speed_from_reference: bool = False
    abs_active: tuple[bool, bool, bool, bool] = (False, False, False, False)   # an ABS works the wheel
    body_mu: float = float("nan")  # the car's total tyre force / weight, from its accelerometer
    # The same from the accelerometer alone, its best estimate rather than a bound (the learnt
    # offset and the configured drag taken off), and the half-width the offset's and the drag's
    # doubt leave it (over g): the one measure of the tyres' force where no wheel's brake torque
    # is known (`wheel_torques_unknown`: one master-cylinder pressure, an ABS releasing wheels).
    body_force_mu: float = float("nan")
    body_force_doubt: float = 0.0
    wheel_torques_unknown: bool = False
    # The car's lateral acceleration over g, less what the accelerometer's offset may read: the
    # lateral force per unit load its tyres carry, which a turn takes from their grip.
    lateral_mu: float = 0.0
    # How far the brake gain (and so every wheel's μ) may still be off, as a share: what the gain
    # limits and the body equation leave open while the accelerometer's offset is unlearnt; else 0.
    brake_gain_doubt: float = 0.0
    # ... and the accelerometer's offset (σ, m/s²) while free rolling has not yet taught it; else 0.
    # A speed estimate coasting on the accelerometer drifts by that much per second.
    accel_offset_doubt_mps2: float = 0.0
    # Share of input frames of about the last second rejected or repaired as implausible
    # (`plausibility.InputGate.suspect_share`): corruption that may have got through.
    input_suspect_share: float = 0.0
    # μ is measured through the wheel-acceleration filter, a weighted mean over its window: it is
    # the mean of the tyre's μ over the slips the wheel passed through then, not μ at `slip`.
    # Per wheel the slips at the window's two ends, and the weights (`slip_spread_weights`, the
    # centre taking the rest) that give the filter's mean and spread in time; None when unknown.
    slip_spread: tuple[tuple[float, float], ...] | None = None
    slip_spread_weights: tuple[float, float] = (0.0, 0.0)


@dataclass(slots=True)
class FrictionEstimate:
    """What the estimator reports after one update."""

    time_s: float
    status: Status
    mu_max: float                 # road peak friction at the current speed
    slip_at_mu_max: float
    theta: float                  # LuGre road-condition parameter (1.0 for non-LuGre estimators' nominal)
    confidence: float             # 0..1; only meaningful with VALID
    wheel_mu_max: Quad = (0.0, 0.0, 0.0, 0.0)
    mu_max_std: float = float("inf")
    detail: dict[str, float] = field(default_factory=dict)


@dataclass(slots=True)
class FrontEndResult:
    """Outcome of one trigger frame in the front end (`frontend.FrontEnd.push`)."""

    sample: PhysicalSample | None       # None while the filter warms up or after a fault
    stale_messages: tuple[str, ...] = ()
    fault: str | None = None
    # Wheels whose speed sensor reads (near) zero while the car rolls on: excluded from the
    # sample; the estimate goes on with the others, but must not be called VALID.
    dead_wheels: tuple[int, ...] = ()
