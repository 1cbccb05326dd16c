"""Build of the one compiled module; everything else is in pyproject.toml.

`frictiond._fitcore` (the estimator's per-update fit in C) is optional: without a C compiler the
install still succeeds and the estimator runs the same fit in numpy, several times slower.
"""
from setuptools import Extension, setup

setup(ext_modules=[Extension("frictiond._fitcore", ["frictiond/_fitcore.c"], optional=True)])
