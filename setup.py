"""Build of the compiled modules; everything else is in pyproject.toml.

All are optional: `frictiond._fitcore` (the estimator's per-update numerics), `_frontcore` (the
front end's derivative filter and interpolation, and the relaxation compensator's step),
`_codeccore` (input decoding, output packing and E2E protection) and `_logcore` (reading
candump lines). Without a C compiler the install
still succeeds and the same computations run in numpy and plain Python, several times slower.
"""
from setuptools import Extension, setup

setup(ext_modules=[
    Extension("frictiond._fitcore", ["frictiond/_fitcore.c"], depends=["frictiond/_ccommon.h"], optional=True),
    Extension("frictiond._frontcore", ["frictiond/_frontcore.c"], depends=["frictiond/_ccommon.h"], optional=True),
    # (no fused multiply-add: decoded values must be the Python path's to the last bit)
    Extension("frictiond._codeccore", ["frictiond/_codeccore.c"], extra_compile_args=["-ffp-contract=off"],
              optional=True),
    Extension("frictiond._logcore", ["frictiond/_logcore.c"], optional=True),
])
