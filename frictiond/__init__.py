"""frictiond: online tyre/road friction estimation."""
__version__ = "0.1.0"
