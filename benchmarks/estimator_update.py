"""Estimator update cost against scipy's least_squares(method="trf") refitting the same window.

For every update of the LuGre estimator during simulated ABS stops:
  - the estimator's own update (bounded: at most `max_iterations` trust-region iterations);
  - from the same warm start (the parameters before the update), on the same window, weights
    and bounds, to the same tolerances: frictiond.trust_region.solve run to convergence, and
    scipy.optimize.least_squares(method="trf", jac=analytic) — with |Δμ_max| between the two.

    python benchmarks/estimator_update.py [--limit N]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import braking_samples, percentile, summary_us  # noqa: E402

from frictiond import trust_region  # noqa: E402
from frictiond.estimator import LugreTrustRegionEstimator  # noqa: E402
from frictiond.tyre_model import peaks  # noqa: E402

TOL = dict(ftol=1e-8, xtol=1e-8, gtol=1e-8)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--limit", type=int, default=400, help="refit comparisons (default 400)")
    args = parser.parse_args(argv)
    config, samples = braking_samples()
    est = LugreTrustRegionEstimator(config.estimator.lugre_tr, config.vehicle)
    update_times, ours_full, scipy_full, mu_diff, upd_diff, fits = [], [], [], [], [], 0
    compared_updates = []  # the estimator's own update on exactly the fits that were refitted
    for sample in samples:
        x_before = est._x.copy()
        fits_before = est._fits
        t0 = time.perf_counter()
        est.update(sample)
        update_times.append(time.perf_counter() - t0)
        if est._fits == fits_before or fits >= args.limit:
            continue
        fits += 1
        compared_updates.append(update_times[-1])
        slip, speeds, mu, times, wheel = est._window.view()
        weights = est._weights(sample.time_s, times)
        sw = np.sqrt(weights) / est.options.measurement_std
        rows = np.arange(len(slip))

        def fun(x):
            return est._residuals(x, slip, speeds, mu, sw, wheel, rows)

        t0 = time.perf_counter()
        mine = trust_region.solve(fun, x_before, est._lb, est._ub, max_iterations=200, **TOL)
        ours_full.append(time.perf_counter() - t0)
        start = np.clip(x_before, est._lb + 1e-10, est._ub - 1e-10)
        t0 = time.perf_counter()
        ref = least_squares(lambda x: fun(x)[0], start, jac=lambda x: fun(x)[1], bounds=(est._lb, est._ub),
                            method="trf", **TOL)
        scipy_full.append(time.perf_counter() - t0)
        v = max(sample.speed_mps, 1.0)
        mu_a = peaks(v, est._params(mine.x), est._thetas(mine.x))[0]
        mu_b = peaks(v, est._params(ref.x), est._thetas(ref.x))[0]
        mu_diff.append(float(np.max(np.abs(mu_a - mu_b))))
        mu_u = peaks(v, est._params(est._x), est._thetas(est._x))[0]   # the bounded update's own fit
        upd_diff.append(float(np.max(np.abs(mu_u - mu_b))))
    braking_updates = [t for t in update_times if t > 20e-6]
    print(f"samples {len(samples)}, fits compared {fits}")
    print(f"estimator update (all)          {summary_us(update_times)}")
    print(f"estimator update (fitting)      {summary_us(braking_updates)}")
    print(f"trust_region.solve to tolerance {summary_us(ours_full)}")
    print(f"least_squares(trf) refit        {summary_us(scipy_full)}")
    ratio_update = statistics.median(scipy_full) / statistics.median(braking_updates)
    ratio_solver = statistics.median(scipy_full) / statistics.median(ours_full)
    ratio_same = statistics.median(scipy_full) / statistics.median(compared_updates)
    print(f"ratio least_squares / estimator update (median): {ratio_update:6.1f}x   "
          f"p99: {percentile(scipy_full, 99) / percentile(braking_updates, 99):6.1f}x")
    print(f"estimator update on the refitted updates {summary_us(compared_updates)}")
    print(f"ratio least_squares / estimator update, same updates (median): {ratio_same:6.1f}x   "
          f"p99: {percentile(scipy_full, 99) / percentile(compared_updates, 99):6.1f}x")
    print(f"ratio least_squares / trust_region.solve, same tolerance (median): {ratio_solver:6.1f}x")
    print(f"|Δμ_max| solve vs least_squares: median {statistics.median(mu_diff):.2e}  max {max(mu_diff):.2e}")
    print(f"|Δμ_max| estimator update (≤ max_iterations) vs least_squares: median {statistics.median(upd_diff):.2e}  "
          f"p99 {percentile(upd_diff, 99):.2e}  max {max(upd_diff):.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
