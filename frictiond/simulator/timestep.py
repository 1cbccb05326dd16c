"""The simulator's integration step (1 kHz), shared by the vehicle's dynamics and its brakes."""

DT_S = 0.001
