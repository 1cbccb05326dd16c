"""The canonical input signals: what the front end reads, by the names a signal map gives them.

Names only, no numerics: the codec, the configuration and the front end share them, so that
reading a DBC or a config needs nothing of the physics.
"""
from __future__ import annotations

WHEEL_SPEED_NAMES = ("wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl", "wheel_speed_rr")
PRESSURE_NAMES = ("brake_pressure_fl", "brake_pressure_fr", "brake_pressure_rl", "brake_pressure_rr")
DRIVE_TORQUE_NAMES = ("drive_torque_fl", "drive_torque_fr", "drive_torque_rl", "drive_torque_rr")
# The driver's demand, on a car that sends no wheel pressures; an ABS's own flags, for the car and
# per wheel (`abs_activity`).
MASTER_PRESSURE_NAME = "brake_pressure_master"
ABS_FLAG_NAMES = ("abs_active", "abs_active_fl", "abs_active_fr", "abs_active_rl", "abs_active_rr")
REQUIRED_INPUTS = WHEEL_SPEED_NAMES + ("accel_long", "accel_lat") + PRESSURE_NAMES
OPTIONAL_INPUTS = ("yaw_rate", "vehicle_speed_ref") + DRIVE_TORQUE_NAMES + (MASTER_PRESSURE_NAME,) + ABS_FLAG_NAMES
