"""`simulate()`: one scenario → sensor events (for any message layout) and the truth."""
from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from ..vehicle import VehicleParams
from .scenarios import SCENARIOS, Scenario
from .sensors import MessageSchedule, SensorModel, check_schedules, generate_events
from .truth import SimulationResult, build_truth
from .tyres import FAMILIES
from .vehicle_sim import run_dynamics


def simulate(
    scenario: str | Scenario,
    vehicle: VehicleParams | None,
    schedules: Sequence[MessageSchedule],
    *,
    seed: int = 0,
    truth_model: str | None = None,
    reference_speed: bool | None = None,
    grade: float | None = None,
) -> SimulationResult:
    """Simulate one braking manoeuvre.

    `scenario` names an entry of `SCENARIOS` (or is a `Scenario`); `truth_model` overrides its
    tyre family ("burckhardt", "magic-formula", "lugre"); `reference_speed` None follows the
    scenario (default: no ground-speed sensor), False drops every message that carries only
    `vehicle_speed_ref` (and that signal from mixed messages); `grade` (rise over run, uphill
    positive) puts the scenario on a hill. Deterministic for a given seed;
    the physics does not depend on the schedules (separate random streams).
    """
    if isinstance(scenario, Scenario):
        scn = scenario
    else:
        try:
            scn = SCENARIOS[scenario]
        except KeyError:
            raise ValueError(f"unknown scenario {scenario!r}; choose from {', '.join(sorted(SCENARIOS))}") from None
    if grade is not None:
        scn = dataclasses.replace(scn, grade=float(grade))
    family = truth_model or scn.truth_model
    if family not in FAMILIES:
        raise ValueError(f"unknown truth tyre model {family!r}; choose from {', '.join(sorted(FAMILIES))}")
    veh = vehicle if vehicle is not None else VehicleParams()
    schedules = [s if isinstance(s, MessageSchedule) else MessageSchedule(*s) for s in schedules]
    check_schedules(schedules)
    ref = scn.reference_speed if reference_speed is None else bool(reference_speed)

    seq_dyn, seq_sensor, seq_bus = np.random.SeedSequence(seed).spawn(3)
    # The car as it is (loaded), against the configured one the estimator is given.
    true_vehicle = dataclasses.replace(veh, mass=veh.mass * scn.load_factor)
    trace = run_dynamics(scn, true_vehicle, family, np.random.default_rng(seq_dyn))
    sensors = SensorModel(trace, np.random.default_rng(seq_sensor), scn.noise_scale)
    events = generate_events(
        schedules, sensors, np.random.default_rng(seq_bus), float(trace.t[-1]),
        drop_rate=scn.drop_rate, reference_speed=ref,
    )
    return SimulationResult(
        events=events,
        truth=build_truth(trace, family),
        scenario=scn,
        truth_model=family,
        reference_speed=ref,
        seed=seed,
        brake_gains=tuple(float(x) for x in trace.brake_gains),
    )
