"""Braking simulator (truth side, no CAN): tyre truth models, vehicle + hydraulics + ABS, sensors.

    from frictiond.simulator import simulate, MessageSchedule, SCENARIOS
    result = simulate("wet", VehicleParams(), [MessageSchedule("WHEELS", 0.01, ("wheel_speed_fl", ...))])
    result.events          # SensorEvent(time_s, message, values) in time order
    result.truth.at(2.0)   # truth row nearest t = 2 s (mu_max, slips, forces, ...)
"""
from .run import simulate
from .scenarios import SCENARIOS, Scenario
from .sensors import SIGNALS, MessageSchedule, SensorEvent
from .truth import SimulationResult, Truth
from .tyres import SURFACES, TRUTH_MODELS, make_tyre

__all__ = [
    "simulate",
    "MessageSchedule",
    "SensorEvent",
    "SimulationResult",
    "Truth",
    "Scenario",
    "SCENARIOS",
    "TRUTH_MODELS",
    "SURFACES",
    "SIGNALS",
    "make_tyre",
]
