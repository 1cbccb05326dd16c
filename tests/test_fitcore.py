"""The compiled per-update fit (`frictiond._fitcore`) against the numpy path it replaces."""
from __future__ import annotations

import math

import numpy as np
import pytest

from frictiond import estimator as estimator_module
from frictiond import tyre_model as tm
from frictiond.estimator import LugreTrustRegionEstimator
from frictiond.samples import Status

from .conftest import assert_each_refused

from .test_estimator import braking, lugre_curve

core = estimator_module.compiled_fit


def test_the_compiled_fit_is_built():
    # scripts/test.sh installs a C compiler and Python's headers, so the test venv must have it;
    # a silent fallback to numpy would make every benchmark figure wrong.
    assert core is not None, "frictiond._fitcore did not build: see the pip install output (gcc, python3-dev)"


def random_peak_case(rng, sigma2_max: float = 0.01, v_min: float = 1.0):
    """LuGre parameters, four wheels' θ from dry to polished ice, and a speed."""
    p = tm.LugreParams(sigma0=float(rng.uniform(60, 600)), v_s=float(rng.uniform(1.0, 15.0)),
                       sigma2=float(rng.uniform(0.0, sigma2_max)))
    return p, np.exp(rng.uniform(np.log(0.8), np.log(60.0), 4)), float(rng.uniform(v_min, 40.0))


def _window_problem(theta=2.0, seed=4, duration=0.6):
    p = tm.LugreParams(theta=theta, sigma0=230.0, v_s=5.0, sigma2=0.002)
    curve = lugre_curve(p)
    est = LugreTrustRegionEstimator()
    est.core = None
    for s in braking(lambda t, i: curve, seed=seed, duration=duration):
        est.update(s)
    times = est._window.view()[3]
    sw = np.sqrt(est._weights(float(times[-1]), times)) / est.options.measurement_std
    return est, sw


def _with_samples_at_the_end(est, slips, mus, speed=20.0):
    """Append samples (wheels in turn) at the window's last instant; the rows' weights √w/σ after it."""
    w = est._window
    t_last = float(w.time[w.end - 1])
    for k, (slip, mu) in enumerate(zip(slips, mus)):
        w.append(slip, speed, mu, t_last, k % 4)
    est._cache_x = None   # (the numpy path would reuse its rows from before the additions)
    return np.sqrt(est._weights(t_last, w.view()[3])) / est.options.measurement_std


def _compiled_normal(est, x, sw):
    """One evaluation of the compiled normal equations (zero iterations)."""
    w = est._window
    lo, hi = w.start, w.end
    x = x.copy()
    gradient, normal = np.empty(7), np.empty((7, 7))
    r_data, r_work = np.empty(hi - lo), np.empty(hi - lo)
    cost, *_ = core.solve(w.pow_lam_v[lo:hi], w.stiff[lo:hi], w.lam_v[lo:hi], w.mu[lo:hi], w.wheel[lo:hi], sw, x,
                          np.full(7, -np.inf), np.full(7, np.inf), est._prior, est._inv_prior_std, est._tie_rel_d,
                          gradient, normal, r_data, r_work, est._core_constants, 1.0, 0, 1e-8, 1e-8, 1e-8, 0.0, 4)
    return cost, gradient, normal, r_data


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
@pytest.mark.parametrize("offset", [[0.0] * 7, [0.1, -0.2, 0.3, 0.05, 0.1, -0.1, 0.2], [-3.0, -3.0, 2.0, 2.0, 1.5, 2.0, 0.5]])
def test_compiled_normal_equations_match_numpy(offset):
    est, _ = _window_problem()
    x = est._x + np.array(offset)
    # The compiled rows take 1 − e^−Z by expm1 up to Z = 0.5 and by exp beyond: braking data
    # lie beyond, so a few samples at small slip (rolling, light braking) join the window and
    # the comparison holds both.
    sw = _with_samples_at_the_end(est, [2e-4 * (k + 1) for k in range(12)], [0.01 * (k + 1) for k in range(12)])
    w = est._window
    p = est._params(x)
    g = tm._stribeck(w.lam_v[w.start:w.end], p)[0]
    Z = np.exp(x[:4])[w.wheel[w.start:w.end]] * p.sigma0 * w.stiff[w.start:w.end] / g
    assert tm._SMALL_Z < Z.min() < 0.5 < Z.max() and 0.05 < Z[Z < 0.5].max()
    cost, grad, normal, extra = est._normal(x, sw)
    c_cost, c_grad, c_normal, c_r = _compiled_normal(est, x, sw)
    assert c_cost == pytest.approx(cost, rel=1e-12)
    np.testing.assert_allclose(c_grad, grad, rtol=1e-10, atol=1e-10 * np.abs(grad).max())
    np.testing.assert_allclose(c_normal, normal, rtol=1e-10, atol=1e-12 * np.abs(normal).max())
    braking = Z > 0.5
    np.testing.assert_allclose(c_r[braking], extra[1][braking], rtol=1e-12, atol=1e-14)
    # (at small Z, F = 1 − (1 − e^−Z)/Z cancels a digit or two, on both paths alike)
    np.testing.assert_allclose(c_r[~braking], extra[1][~braking], rtol=1e-12, atol=1e-13)


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
def test_compiled_normal_equations_use_the_series_near_zero_slip():
    # Samples at tiny slip put Z below tyre_model._SMALL_Z, where the closed form of F loses digits.
    est, _ = _window_problem()
    sw = _with_samples_at_the_end(est, [1e-7 * (k + 1) for k in range(8)], [0.001] * 8)
    w = est._window
    x = est._x.copy()
    assert float((np.exp(x[:4]).max() * x[4] * est._shared_scale[0]) * w.stiff[w.end - 1] / 0.8) < tm._SMALL_Z
    cost, grad, normal, extra = est._normal(x, sw)
    c_cost, c_grad, c_normal, c_r = _compiled_normal(est, x, sw)
    np.testing.assert_allclose(c_r, extra[1], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(c_grad, grad, rtol=1e-10, atol=1e-10 * np.abs(grad).max())


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
@pytest.mark.parametrize("radius", [50.0, 0.3, 1e-3])   # the Newton step inside; on the boundary
@pytest.mark.parametrize("offset", [[0.0] * 7, [0.1, -0.2, 0.3, 0.05, 0.1, -0.1, 0.2], [-1.0, 0.5, 1.0, 0.2, 0.4, 0.6, -0.3]])
def test_one_compiled_step_is_the_numpy_step(radius, offset):
    # The compiled solve takes the Newton step without an eigen-decomposition when it lies
    # inside the radius; numpy's path always solves the subproblem from eigh. Same step.
    from frictiond import trust_region

    est, sw = _window_problem(theta=2.5, seed=3, duration=0.8)
    start = est._x + np.array(offset)
    reference = trust_region.solve_normal(lambda x: est._normal(x, sw), start, est._lb, est._ub, radius=radius,
                                          max_iterations=1, ftol=0.0, xtol=0.0, gtol=0.0, max_rejections=1)
    w = est._window
    lo, hi = w.start, w.end
    x = start.copy()
    _, c_radius, iterations, _, evaluations = core.solve(
        w.pow_lam_v[lo:hi], w.stiff[lo:hi], w.lam_v[lo:hi], w.mu[lo:hi], w.wheel[lo:hi], sw, x, est._lb, est._ub,
        est._prior, est._inv_prior_std, est._tie_rel_d, np.empty(7), np.empty((7, 7)), np.empty(hi - lo),
        np.empty(hi - lo), est._core_constants, radius, 1, 0.0, 0.0, 0.0, 0.0, 1)
    assert (iterations, evaluations) == (reference.iterations, reference.evaluations) == (1, 2)
    step, ref_step = x - start, reference.x - start
    assert np.linalg.norm(ref_step) > 1e-6
    np.testing.assert_allclose(step, ref_step, rtol=1e-7, atol=1e-9 * np.abs(ref_step).max())
    assert c_radius == pytest.approx(reference.radius, rel=1e-7)


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
@pytest.mark.parametrize("theta", [1.0, 3.5, 30.0])
def test_compiled_solve_to_tolerance_finds_the_numpy_solution(theta):
    from frictiond import trust_region

    est, sw = _window_problem(theta=theta, seed=2, duration=1.0)
    start = est._prior.copy()
    reference = trust_region.solve_normal(lambda x: est._normal(x, sw), start, est._lb, est._ub, max_iterations=200,
                                          ftol=1e-12, xtol=1e-12, gtol=1e-12)
    w = est._window
    lo, hi = w.start, w.end
    x = start.copy()
    gradient, normal = np.empty(7), np.empty((7, 7))
    r_data, r_work = np.empty(hi - lo), np.empty(hi - lo)
    cost, radius, iterations, converged, evaluations = core.solve(
        w.pow_lam_v[lo:hi], w.stiff[lo:hi], w.lam_v[lo:hi], w.mu[lo:hi], w.wheel[lo:hi], sw, x, est._lb, est._ub,
        est._prior, est._inv_prior_std, est._tie_rel_d, gradient, normal, r_data, r_work, est._core_constants,
        math.nan, 200, 1e-12, 1e-12, 1e-12, 0.0, 60)
    assert converged and iterations >= 2 and evaluations >= iterations
    assert cost == pytest.approx(reference.cost, rel=1e-9)
    np.testing.assert_allclose(x, reference.x, atol=1e-5)
    # What the estimator reports from x: the wheels' peaks.
    p_ref, p_c = est._params(reference.x), est._params(x)
    mu_ref, _ = tm.peaks(10.0, p_ref, est._thetas(reference.x))
    mu_c, _ = tm.peaks(10.0, p_c, est._thetas(x))
    np.testing.assert_allclose(mu_c, mu_ref, atol=1e-7)
    # ... and the arrays handed back belong to that x.
    c_cost, c_grad, c_normal, c_r = _compiled_normal(est, x, sw)
    np.testing.assert_allclose(normal, c_normal, rtol=1e-12)
    np.testing.assert_allclose(r_data, c_r, rtol=1e-12, atol=1e-15)


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
@pytest.mark.parametrize("theta, seed, noise", [(1.0, 1, 0.02), (2.5, 3, 0.02), (25.0, 5, 0.005)])
def test_the_estimator_says_the_same_on_both_paths(theta, seed, noise, monkeypatch):
    # Everything compiled against an install without a compiler (fit, peaks, partials in Python).
    # (On ice, μ ≈ 0.05, the noise of dry asphalt would leave nothing VALID to compare.)
    p = tm.LugreParams(theta=theta, sigma0=230.0, v_s=5.0, sigma2=0.002)
    curve = lugre_curve(p)
    samples = list(braking(lambda t, i: curve, seed=seed, noise=noise))
    compiled = LugreTrustRegionEstimator()
    compiled_estimates, compiled_front = [], []
    for s in samples:
        compiled_estimates.append(compiled.update(s))
        compiled_front.append(compiled._front_innovation_score)
    monkeypatch.setattr(tm, "_compiled", None)
    numpy_path = LugreTrustRegionEstimator()
    numpy_path.core = None
    for s, a, front in zip(samples, compiled_estimates, compiled_front):
        b = numpy_path.update(s)
        # (the front wheels' residual bias: fit_window's in C, `_innovation`'s in numpy)
        assert front == pytest.approx(numpy_path._front_innovation_score, rel=1e-6, abs=1e-6)
        assert a.status == b.status
        assert a.mu_max == pytest.approx(b.mu_max, abs=1e-5)
        assert a.confidence == pytest.approx(b.confidence, abs=1e-4)
        assert (a.detail or {}).get("data_above_fit") == pytest.approx((b.detail or {}).get("data_above_fit"), abs=1e-4)
    assert compiled._fits > 100 and compiled._fits == numpy_path._fits
    assert sum(f > 0.0 for f in compiled_front) > 50
    assert sum(e.status == Status.VALID for e in compiled_estimates) > 0.3 * len(samples)


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
def test_both_paths_measure_the_same_data_above_the_fit(monkeypatch):
    # A sharp Magic Formula peak the static model rounds off: the excess is large, and the two
    # paths read it from different residual stores (the compiled fit's scratch, the numpy solve's).
    # (Their peak searches locate the peak slip to different precision, and the bands of slip are
    # relative to it: a few samples change band, a few % of the excess, and 5.0 % on one fit of
    # this scenario on an AMD EPYC with numpy 2.3 and 2.4 alike.)
    from .test_peak_floors import overshooting_abs
    from frictiond.estimator import LugreTROptions
    compiled = [e for _, e, _ in overshooting_abs(LugreTROptions())]
    monkeypatch.setattr(estimator_module, "compiled_fit", None)
    monkeypatch.setattr(tm, "_compiled", None)
    numpy_path = [e for _, e, _ in overshooting_abs(LugreTROptions())]
    above = [(a.detail or {}).get("data_above_fit", 0.0) for a in compiled]
    assert max(above) > 0.05
    for a, b in zip(compiled, numpy_path):
        assert (a.detail or {}).get("data_above_fit", 0.0) == pytest.approx((b.detail or {}).get("data_above_fit", 0.0),
                                                                             rel=0.08, abs=1e-4)


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
def test_compiled_fit_rejects_bad_arrays_with_a_message():
    est, sw = _window_problem()
    w = est._window
    lo, hi = w.start, w.end
    args = [w.pow_lam_v[lo:hi], w.stiff[lo:hi], w.lam_v[lo:hi], w.mu[lo:hi], w.wheel[lo:hi], sw, est._x.copy(),
            est._lb, est._ub, est._prior, est._inv_prior_std, est._tie_rel_d, np.empty(7), np.empty((7, 7)),
            np.empty(hi - lo), np.empty(hi - lo), est._core_constants, 1.0, 2, 1e-4, 1e-4, 1e-8, 1e-3, 4]
    bad = list(args)
    bad[5] = sw.astype(np.float32)
    with pytest.raises(TypeError, match="sw"):
        core.solve(*bad)
    bad = list(args)
    bad[1] = w.stiff[lo:hi - 1]
    with pytest.raises(ValueError, match="stiff"):
        core.solve(*bad)
    bad = list(args)
    bad[4] = w.wheel[lo:hi].copy()
    bad[4][3] = 7
    with pytest.raises(ValueError, match="wheel"):
        core.solve(*bad)
    bad = list(args)
    bad[6] = est._x.copy()
    bad[6].flags.writeable = False
    with pytest.raises((TypeError, BufferError, ValueError)):
        core.solve(*bad)
    assert core.solve(*args)[2] >= 0   # the good arguments still work


def test_the_numpy_path_is_still_valid_on_its_own(monkeypatch):
    # The fallback for installs without a compiler: it alone must still estimate well.
    monkeypatch.setattr(tm, "_compiled", None)
    p = tm.LugreParams(theta=1.6, sigma0=230.0, v_s=5.0, sigma2=0.002)
    curve = lugre_curve(p)
    est = LugreTrustRegionEstimator()
    est.core = None
    statuses = [est.update(s).status for s in braking(lambda t, i: curve, seed=1)]
    assert statuses.count(Status.VALID) > 0.6 * len(statuses)
    assert est._cache_x is not None   # (the numpy path's row cache was used)


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
def test_compiled_peaks_and_partials_match_the_float_code(monkeypatch):
    rng = np.random.default_rng(11)
    cases = []
    for _ in range(200):
        p, thetas, v = random_peak_case(rng)
        lam = rng.uniform(1e-5, 0.99, 4)
        cases.append((p, thetas, v, lam))
    compiled = []
    for p, thetas, v, lam in cases:
        exact = tm.peaks(v, p, thetas)                       # grid search (no `near`)
        near = exact[1] * rng.uniform(0.97, 1.03, 4)
        compiled.append((tm._peaks_near(v, p, thetas, near), tm.braking_mu_and_partials_few(lam, v, thetas, p), near))
    monkeypatch.setattr(tm, "_compiled", None)
    bracketed = 0
    for (p, thetas, v, lam), (c_peaks, c_few, near) in zip(cases, compiled):
        f_peaks = tm._peaks_near(v, p, thetas, near)
        assert (c_peaks is None) == (f_peaks is None)
        if f_peaks is not None:
            bracketed += 1
            np.testing.assert_allclose(c_peaks[0], f_peaks[0], rtol=1e-13)
            np.testing.assert_allclose(c_peaks[1], f_peaks[1], rtol=1e-12)
        f_few = tm.braking_mu_and_partials_few(lam, v, thetas, p)
        np.testing.assert_allclose(c_few[0], f_few[0], rtol=1e-13)
        np.testing.assert_allclose(c_few[1], f_few[1], rtol=1e-12, atol=1e-300)
        assert c_few[1].shape == (4, 4)
    assert bracketed > 50   # (the others: some wheel's peak not bracketed, refused on both paths)
    # Not bracketed: a `near` far from the peak is refused on both paths (the grid then searches).
    p, thetas, v, _ = cases[0]
    far = tm.peaks(v, p, thetas)[1] * 4.0
    monkeypatch.setattr(tm, "_compiled", core)
    assert tm._peaks_near(v, p, thetas, far) is None


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
def test_compiled_peaks_refuse_bad_arguments():
    with pytest.raises(ValueError, match="at most"):
        core.peaks_near(10.0, [1.0] * 17, [0.1] * 17, (0.8, 0.75, 0.5, 180.0, 36.0, 6.0, 0.002))
    with pytest.raises(TypeError):
        core.mu_partials_few([0.1, "x"], 10.0, [1.0, 1.0], (0.8, 0.75, 0.5, 180.0, 36.0, 6.0, 0.002))
    with pytest.raises(ValueError, match="length"):
        core.mu_partials_few([0.1, 0.2], 10.0, [1.0], (0.8, 0.75, 0.5, 180.0, 36.0, 6.0, 0.002))
    assert core.peaks_near(10.0, [1.0], [0.1, 0.2], (0.8, 0.75, 0.5, 180.0, 36.0, 6.0, 0.002)) is None
    assert core.peaks_near(0.0, [1.0], [0.1], (0.8, 0.75, 0.5, 180.0, 36.0, 6.0, 0.002)) is None


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
@pytest.mark.parametrize("m, lag", [(0, 5), (3, 5), (7, 2), (40, 5), (400, 5), (401, 13)])
def test_compiled_wheel_stats_match_numpy(m, lag):
    from frictiond.peak_evidence import _wheel_stats_numpy

    rng = np.random.default_rng(m + lag)
    slip = rng.uniform(0.001, 0.3, m)
    slip[: m // 3] = np.round(slip[: m // 3], 2)          # ties, as a held wheel gives
    mu = np.clip(3.0 * slip + rng.normal(0, 0.05, m), 0.01, None)
    wheel = rng.choice([0, 1, 3], m).astype(np.intp)      # wheel 2 has no samples at all
    times = np.cumsum(rng.uniform(0.0, 0.01, m))          # (repeated times: the 1 ms floor)
    compiled = core.wheel_stats(slip, mu, wheel, times, lag, 0.3)
    reference = _wheel_stats_numpy(slip, mu, wheel, times, lag, 0.3)
    assert len(compiled) == 4
    for c, r in zip(compiled, reference):
        assert c[0] == r[0]
        np.testing.assert_allclose(c[1:7], r[1:7], rtol=1e-12, equal_nan=True)
        np.testing.assert_allclose(c[7:], r[7:], rtol=1e-10)
    assert compiled[2][0] == 0 and math.isnan(compiled[2][1])
    with pytest.raises(ValueError, match="lag"):
        core.wheel_stats(slip, mu, wheel, times, 0, 0.3)


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
def test_compiled_peak_report_matches_numpy():
    from frictiond.estimate_report import _peak_report_numpy

    rng = np.random.default_rng(5)
    capped_seen = {False: 0, True: 0}
    for k in range(300):
        p, thetas, v = random_peak_case(rng)
        wheel_mu, wheel_lam = tm.peaks(v, p, thetas)
        support = rng.uniform(0.005, 0.3, 4)
        support[rng.random(4) < 0.2] = np.inf          # wheels without recent samples
        if k % 10 == 0:
            support[:] = np.inf
        floor = rng.uniform(0.0, 0.05, 4)
        a = rng.normal(size=(7, 7))
        cov_unit = a @ a.T * 1e-4
        if k % 25 == 0:
            cov_unit[:] = np.inf                            # a singular normal matrix
        share = list(rng.dirichlet(np.ones(4)))
        args = (wheel_mu.tolist(), wheel_lam.tolist(), support.tolist(), floor.tolist(), 2.0, 0.15, thetas.tolist(), v)
        tail = ((1.0, 0.5, 3e-3), cov_unit, float(rng.uniform(1, 3)), share)
        c = core.peak_report(*args, tm.compiled_params(p), *tail)
        r = _peak_report_numpy(*args, p, *tail)
        np.testing.assert_allclose(c[0], r[0], rtol=1e-13)
        np.testing.assert_allclose(c[1], r[1], rtol=1e-13)
        assert c[2] == r[2]
        assert c[3] == pytest.approx(r[3], rel=1e-13) and c[4] == pytest.approx(r[4], rel=1e-13)
        np.testing.assert_allclose([c[5], *c[6]], [r[5], *r[6]], rtol=1e-9, equal_nan=True)
        for flag in c[2]:
            capped_seen[flag] += 1
    assert capped_seen[True] > 50 and capped_seen[False] > 50
    # Its arguments are converted by hand (METH_FASTCALL): each wrong one is refused, none crashes.
    good = [*args, tm.compiled_params(p), *tail]
    assert_each_refused(core.peak_report, good,
                        ((4, "2.0"), (7, None), (8, tm.compiled_params(p)[:6]), (8, "params"), (9, (1.0, 0.5)),
                         (10, [0.0] * 7), (11, []), (0, [0.1] * 3)), (TypeError, ValueError))
    assert core.peak_report(*good) == c


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
def test_compiled_weights_bias_and_covariance_match_numpy():
    rng = np.random.default_rng(9)
    times = np.sort(rng.uniform(0.0, 0.8, 300))
    weights, sw = np.empty(300), np.empty(300)
    total = core.weights(times, 0.75, 0.4, 0.02, weights, sw)   # (the newest samples lie after `now`: weight 1)
    assert total == pytest.approx(weights.sum(), rel=1e-13)
    np.testing.assert_allclose(weights, np.exp(np.minimum(times - 0.75, 0.0) / 0.4), rtol=1e-15)
    np.testing.assert_allclose(sw, np.sqrt(weights) / 0.02, rtol=1e-15)
    r = rng.normal(0.3, 1.0, 300)
    mean, rms, same_sign = core.residual_bias(r, weights, 250, 0.02)
    resid = r[250:] * 0.02 / np.sqrt(weights[250:])
    assert mean == pytest.approx(resid.mean(), rel=1e-12)
    assert rms == pytest.approx(resid.std(), rel=1e-12)
    assert same_sign == pytest.approx(abs(np.sign(resid).mean()), rel=1e-12)
    with pytest.raises(ValueError, match="first"):
        core.residual_bias(r, weights, 300, 0.02)
    a = rng.normal(size=(7, 9))
    normal = a @ a.T
    for free in ([True] * 7, [True, False, True, True, False, True, True], [False] * 7):
        out = np.full((7, 7), 5.0)
        assert core.inverse_free(normal, free, out) is True
        expected = np.zeros((7, 7))
        f = np.array(free)
        if f.any():
            expected[np.ix_(f, f)] = np.linalg.inv(normal[np.ix_(f, f)])
        np.testing.assert_allclose(out, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max(initial=1.0))
    out = np.full((7, 7), 5.0)
    rank_deficient = np.zeros((7, 7))
    rank_deficient[:2, :2] = 1.0   # exactly singular: the same row twice
    assert core.inverse_free(rank_deficient, [True, True] + [False] * 5, out) is False
    assert (out == 5.0).all()    # untouched: the caller marks the covariance infinite


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
def test_compiled_grid_peak_search_matches_numpy(monkeypatch):
    rng = np.random.default_rng(3)
    cases = []
    for _ in range(300):
        cases.append(random_peak_case(rng, sigma2_max=0.05, v_min=0.5))   # (large σ2: curves that climb again)
    compiled = [tm.peaks(v, p, th) for p, th, v in cases]
    monkeypatch.setattr(tm, "_compiled", None)
    for (p, th, v), (c_mu, c_lam) in zip(cases, compiled):
        mu, lam = tm.peaks(v, p, th)
        np.testing.assert_allclose(c_mu, mu, rtol=1e-12)
        np.testing.assert_allclose(c_lam, lam, rtol=1e-12)
    with pytest.raises(ValueError, match="grid"):
        core.peaks_grid(10.0, [1.0], np.array([0.1, 0.2]), tm._FINE, (0.8, 0.75, 0.5, 180.0, 36.0, 6.0, 0.002))


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
def test_the_row_cache_gives_the_uncached_result_and_is_ignored_at_another_point():
    est, sw = _window_problem()
    w = est._window
    lo, hi = w.start, w.end
    m = hi - lo

    def solve(x0, cache):
        x = x0.copy()
        normal, r_data = np.empty((7, 7)), np.empty(m)
        out = core.solve(w.pow_lam_v[lo:hi], w.stiff[lo:hi], w.lam_v[lo:hi], w.mu[lo:hi], w.wheel[lo:hi], sw, x,
                         est._lb, est._ub, est._prior, est._inv_prior_std, est._tie_rel_d, np.empty(7), normal,
                         r_data, np.empty(m), est._core_constants, 0.5, 2, 1e-4, 1e-4, 1e-8, 1e-3, 4, *cache)
        return x, normal, r_data, out

    x0 = est._x + 0.05
    plain = solve(x0, ())
    rows = np.empty((m, 5))
    first = solve(x0, ((rows, x0, 0),))           # fills the cache at its result
    np.testing.assert_array_equal(first[0], plain[0])
    again = solve(first[0], ((rows, first[0], m),))   # every row cached at that point
    fresh = solve(first[0], ())
    np.testing.assert_array_equal(again[0], fresh[0])
    np.testing.assert_array_equal(again[1], fresh[1])
    np.testing.assert_array_equal(again[2], fresh[2])
    rows[:] = 1e3                                   # wrong rows, recorded at another point: not used
    other = solve(first[0], ((rows, first[0] + 1e-3, m),))
    np.testing.assert_array_equal(other[0], fresh[0])
    with pytest.raises(ValueError, match="cached_n"):
        solve(x0, ((rows, x0, m + 1),))


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
def test_append_instant_fills_the_window_as_append_does():
    from frictiond.estimator import _Window

    rng = np.random.default_rng(41)
    compiled, floats = _Window(capacity=64, alpha=0.6, patch_length=0.18), _Window(capacity=64, alpha=0.6,
                                                                                  patch_length=0.18)
    for step in range(200):   # (past the capacity several times: the compaction path too)
        wheels = sorted(rng.choice(4, size=int(rng.integers(1, 5)), replace=False).tolist())
        slips = [float(rng.choice([rng.uniform(0.0, 0.3), 0.0, 0.99, 1.5])) for _ in wheels]
        mus = [float(rng.uniform(-0.2, 1.2)) for _ in wheels]
        speed, t = float(rng.uniform(0.0, 40.0)), 0.01 * step
        compiled.append_instant(slips, speed, mus, t, wheels, core)
        floats.append_instant(slips, speed, mus, t, wheels, None)
        if step % 9 == 0:
            compiled.drop_before(t - 0.15)
            floats.drop_before(t - 0.15)
        assert (compiled.start, compiled.end, compiled.last_time_by_axle) == (floats.start, floats.end,
                                                                             floats.last_time_by_axle)
        for name in ("slip", "speed", "mu", "time", "wheel", "lam_v", "pow_lam_v", "stiff"):
            np.testing.assert_array_equal(getattr(compiled, name)[compiled.start:compiled.end],
                                          getattr(floats, name)[floats.start:floats.end], err_msg=name)
    columns = (compiled.slip, compiled.speed, compiled.mu, compiled.time, compiled.wheel, compiled.lam_v,
               compiled.pow_lam_v, compiled.stiff)
    with pytest.raises(IndexError):
        core.append_samples(columns, 63, [0.1, 0.1], 10.0, [0.5, 0.5], 1.0, [0, 1], 0.5, 0.2, 0.98)
    # Its arguments are converted by hand (METH_FASTCALL): each wrong one is refused.
    good = [columns, 0, [0.1], 10.0, [0.5], 1.0, [0], 0.5, 0.2, 0.98]
    assert_each_refused(core.append_samples, good,
                        ((0, list(columns)), (0, columns[:7]), (1, 0.0), (3, "10"), (5, None), (9, [0.98])))


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
@pytest.mark.parametrize("trim", [0, 37])
def test_fit_window_is_weights_solve_and_bias_on_the_window(trim):
    """`fit_window` on the window's own columns [lo, hi) gives what its steps give on slices."""
    est, _ = _window_problem(duration=1.0)
    w = est._window
    w.start += trim            # (not from column 0: the offsets must be applied to every column)
    lo, hi = w.start, w.end
    m = hi - lo
    times = w.time[lo:hi]
    now, tau, sigma = float(times[-1]) + 0.003, 0.4, 0.02
    jump_t = float(times[m - 60])
    weights, sw = np.empty(m), np.empty(m)
    w_sum = core.weights(times, now, tau, sigma, weights, sw)
    x0 = est._x + 0.05
    x_steps = x0.copy()
    normal, gradient, r_data = np.empty((7, 7)), np.empty(7), np.empty(m)
    rows = np.empty((m, 5))
    steps = core.solve(w.pow_lam_v[lo:hi], w.stiff[lo:hi], w.lam_v[lo:hi], w.mu[lo:hi], w.wheel[lo:hi], sw, x_steps,
                       est._lb, est._ub, est._prior, est._inv_prior_std, est._tie_rel_d, gradient, normal, r_data,
                       np.empty(m), est._core_constants, 0.5, 8, 1e-6, 1e-6, 1e-8, 1e-3, 4, (rows, x0, 0))
    first = int(times.searchsorted(jump_t, side="left"))
    bias = core.residual_bias(r_data, weights, first, sigma)

    x = x0.copy()
    c_normal, c_gradient = np.empty((7, 7)), np.empty(7)
    got = core.fit_window(w.core_columns, lo, hi, now, tau, sigma, jump_t, x, est._lb, est._ub, est._prior,
                          est._inv_prior_std, est._tie_rel_d, c_gradient, c_normal, est._core_constants, 0.5, 8,
                          1e-6, 1e-6, 1e-8, 1e-3, 4, x0, 0)
    assert got[0] == w_sum and got[1] == steps[1]
    np.testing.assert_array_equal(x, x_steps)
    np.testing.assert_array_equal(c_normal, normal)
    np.testing.assert_array_equal(w.scratch[0, lo:hi], r_data)
    np.testing.assert_array_equal(w.scratch[2, lo:hi], weights)
    np.testing.assert_array_equal(w.scratch[3, lo:hi], sw)
    np.testing.assert_array_equal(w.core_rows[lo:hi], rows)
    assert got[2] == pytest.approx(float(r_data @ r_data), rel=1e-13)
    assert got[3] == first and got[4:7] == bias
    # ... and the front wheels' (index 0, 1) alone, as residual_bias gives it on their samples.
    front = w.wheel[lo:hi][first:] < 2
    assert 0 < got[7] == front.sum() < m - first
    assert got[8:] == core.residual_bias(r_data[first:][front], weights[first:][front], 0, sigma)
    # No sample at or after jump_t: no bias, none made up.
    assert core.fit_window(w.core_columns, lo, hi, now, tau, sigma, now + 1.0, x0.copy(), est._lb, est._ub, est._prior,
                           est._inv_prior_std, est._tie_rel_d, c_gradient, c_normal, est._core_constants, 0.5, 0,
                           1e-6, 1e-6, 1e-8, 1e-3, 4, x0, 0)[3:] == (m, 0.0, 0.0, 0.0, 0, 0.0, 0.0, 0.0)
    for bad_lo, bad_hi, bad_cached in ((hi, hi, 0), (lo, w.capacity + 1, 0), (lo, hi, m + 1), (-1, hi, 0)):
        with pytest.raises(ValueError, match="outside"):
            core.fit_window(w.core_columns, bad_lo, bad_hi, now, tau, sigma, jump_t, x0.copy(), est._lb, est._ub,
                            est._prior, est._inv_prior_std, est._tie_rel_d, c_gradient, c_normal,
                            est._core_constants, 0.5, 8, 1e-6, 1e-6, 1e-8, 1e-3, 4, x0, bad_cached)
    assert core.search_left(w.time, lo, hi, jump_t) == lo + first
    assert core.search_left(w.time, lo, hi, math.nan) == hi == lo + int(times.searchsorted(math.nan))
    # The excitation's statistics on the same columns, from the weights fit_window left there.
    for threshold in (math.exp(-0.1 / tau), 0.5, 2.0):
        k = lo + int(weights.searchsorted(threshold, side="right"))
        np.testing.assert_array_equal(
            np.array(core.recent_wheel_stats(w.slip, w.core_columns, lo, hi, threshold, 5, 0.5)),
            np.array(core.wheel_stats(w.slip[k:hi], w.mu[k:hi], w.wheel[k:hi], w.time[k:hi], 5, 0.5)))
    with pytest.raises(ValueError, match="outside"):
        core.recent_wheel_stats(w.slip, w.core_columns, lo, w.capacity + 1, 0.5, 5, 0.5)
    # Its arguments are converted by hand (METH_FASTCALL): each wrong one is refused, none crashes.
    good = [w.core_columns, lo, hi, now, tau, sigma, jump_t, x0.copy(), est._lb, est._ub, est._prior,
            est._inv_prior_std, est._tie_rel_d, c_gradient, c_normal, est._core_constants, 0.5, 8, 1e-6, 1e-6, 1e-8,
            1e-3, 4, x0, 0]
    assert_each_refused(core.fit_window, good,
                        ((0, list(w.core_columns)), (1, 1.5), (2, "9"), (3, "now"), (15, est._core_constants[:5]),
                         (15, list(est._core_constants)), (16, None), (17, 2.0), (17, 1 << 40), (22, "4"),
                         (24, 0.0), (7, [0.0] * 7), (23, x0.astype(np.float32))), (TypeError, ValueError, OverflowError))
    assert core.fit_window(*good)[3] == first   # (the good arguments still work)


@pytest.mark.skipif(core is None, reason="no compiled fit (test_the_compiled_fit_is_built fails instead)")
def test_drift_reference_is_the_confidence_loop():
    from collections import deque

    def loop(history, since, span):   # LugreTrustRegionEstimator._confidence's own loop
        values, until = [], math.inf
        for t, m in history:
            if t < since:
                continue
            if not values:
                until = t + span
            elif t > until:
                break
            values.append(m)
        values.sort()
        return values[len(values) // 2]

    rng = np.random.default_rng(31)
    for _ in range(300):
        n = int(rng.integers(1, 150))   # (the median is sorted in place up to 64 values, by qsort beyond)
        times = np.cumsum(rng.uniform(0.0, 0.005 if n > 64 else 0.02, n))   # (steps of 0: repeated times)
        mus = rng.choice([0.2, 0.5, 0.8], n) + rng.normal(0, 0.01, n)
        history = deque(zip(times.tolist(), mus.tolist()))
        since = float(rng.uniform(-0.1, times[-1]))
        span = float(rng.uniform(0.0, 0.3))
        assert core.drift_reference(history, since, span) == loop(history, since, span)
    assert core.drift_reference(deque([(0.0, 0.5), (0.01, math.nan), (0.02, 0.4)]), 0.0, 1.0) is None
    with pytest.raises(ValueError, match="since"):
        core.drift_reference(deque([(0.0, 0.5)]), 1.0, 1.0)
    with pytest.raises(TypeError, match="pairs"):
        core.drift_reference([(0.0, 0.5, 1.0)], 0.0, 1.0)


def _random_window(rng, cap: int, n_max: int, decimals: int, wheels: int = 4):
    """Window columns (slip, μ, wheel) of capacity `cap` with n < `n_max` random samples from
    `lo` on (NaN and −1 around them), slips rounded to `decimals` so that ties occur: (lo, n, ...)."""
    n = int(rng.integers(0, n_max))
    lo = int(rng.integers(0, cap - n))
    slip = np.full(cap, np.nan)
    mu = np.full(cap, np.nan)
    wheel = np.full(cap, -1, dtype=np.intp)
    slip[lo:lo + n] = np.round(rng.random(n) * 0.3, decimals)
    mu[lo:lo + n] = rng.random(n)
    wheel[lo:lo + n] = rng.integers(0, wheels, n)
    return lo, n, slip, mu, wheel


def test_data_peaks_compiled_equals_numpy():
    # Random windows, slips rounded so that ties occur (numpy's stable order must be kept), some
    # wheels with too few samples, margins and group sizes as configured and beyond.
    from frictiond.estimate_confidence import _data_peaks_numpy

    rng = np.random.default_rng(11)
    for trial in range(300):
        lo, n, slip, mu, wheel = _random_window(rng, 512, 300, 2, 4 if trial % 3 else 2)
        k = int(rng.integers(2, 9))
        min_n = int(rng.integers(0, 40))
        margin = float(rng.choice([0.0, 0.05, 0.2]))
        got = core.data_peaks(slip, mu, wheel, lo, lo + n, k, min_n, margin)
        want = _data_peaks_numpy(slip[lo:lo + n], mu[lo:lo + n], wheel[lo:lo + n], k, min_n, margin)
        assert got == pytest.approx(want, abs=1e-12), (trial, got, want)


def test_band_ratio_compiled_equals_numpy():
    # Random windows, peaks per wheel that put the slips in every band and outside them, peaks at
    # the 1e-3 floor, some bands short of samples.
    from frictiond.estimate_confidence import _BAND_FLOOR_EDGES, _band_ratio_numpy

    rng = np.random.default_rng(13)
    found = 0
    for trial in range(500):
        lo, n, slip, mu, wheel = _random_window(rng, 512, 300, 3)
        if n and trial % 11 == 0:     # (a NaN μ: its band's mean is NaN, and numpy's max takes it)
            mu[lo + int(rng.integers(0, n))] = np.nan
        peak_mu = (rng.random(4) * 1.2).tolist()
        peak_slip = (rng.random(4) * (0.3 if trial % 5 else 0.0005)).tolist()
        min_n = int(rng.integers(1, 30))
        got = core.band_ratio(slip, mu, wheel, lo, lo + n, peak_mu, peak_slip, _BAND_FLOOR_EDGES, min_n)
        want = _band_ratio_numpy(slip[lo:lo + n], mu[lo:lo + n], wheel[lo:lo + n], peak_mu, peak_slip, min_n)
        assert got == want or (math.isnan(got) and math.isnan(want)), (trial, got, want)
        found += got > 0
    assert found > 200   # (most windows have a full band: the comparison is not of zeros)


def test_excess_over_fit_compiled_equals_numpy():
    # Random windows and residuals, some weights zero (no residual: counted as 0), peaks at the
    # 1e-3 floor, a NaN slip among them, bands short of samples: `_excess_over_fit`'s compiled sums
    # against its numpy form, fed what the compiled fit leaves in the window's scratch.
    from frictiond.estimate_confidence import _MISFIT_EDGES, excess_over_fit_numpy

    rng = np.random.default_rng(17)
    found = 0
    for trial in range(500):
        lo, n, slip, _, wheel = _random_window(rng, 512, 300, 3)
        if n and trial % 7 == 0:
            slip[lo + int(rng.integers(0, n))] = np.nan
        scratch = np.full((4, 512), np.nan)
        scratch[3, lo:lo + n] = np.where(rng.random(n) < 0.1, 0.0, rng.random(n) * 20.0)
        scratch[0, lo:lo + n] = rng.normal(-0.03, 0.05, n) * scratch[3, lo:lo + n]   # (data above the model)
        wheel_mu = (0.05 + rng.random(4)).tolist()
        fitted_mu = [m - float(rng.random()) * 0.05 for m in wheel_mu]
        wheel_lam = (rng.random(4) * (0.2 if trial % 5 else 0.0005)).tolist()
        min_n = int(rng.integers(1, 30))
        got = core.excess_over_fit(scratch, slip, wheel, lo, lo + n, wheel_mu, fitted_mu, wheel_lam, _MISFIT_EDGES, min_n)
        sw = scratch[3, lo:lo + n]
        model_minus_data = np.divide(scratch[0, lo:lo + n], sw, out=np.zeros(n), where=sw > 0)
        want = excess_over_fit_numpy(model_minus_data, slip[lo:lo + n], wheel[lo:lo + n], wheel_mu, fitted_mu,
                                     wheel_lam, min_n) if n else 0.0
        assert got == want, (trial, got, want)
        found += got > 0
    assert found > 150   # (most windows have data above the fit somewhere: not a comparison of zeros)
    with pytest.raises(ValueError, match="capacity"):
        core.excess_over_fit(np.zeros((3, 512)), slip, wheel, 0, 10, wheel_mu, fitted_mu, wheel_lam, _MISFIT_EDGES, 5)
    with pytest.raises(ValueError, match="outside the window"):
        core.excess_over_fit(scratch, slip, wheel, 10, 600, wheel_mu, fitted_mu, wheel_lam, _MISFIT_EDGES, 5)


def _random_spread(rng, slip: np.ndarray) -> np.ndarray:
    """A window's `spread` rows for `slip`: each sample's window-end slips around its own (some
    samples without any, weights 0), and the ends' weights."""
    cap = len(slip)
    spread = np.zeros((4, cap))
    has = rng.random(cap) < 0.8
    spread[0] = np.where(has, slip - rng.random(cap) * 0.05, 0.0)
    spread[1] = np.where(has, slip + rng.random(cap) * 0.05, 0.0)
    spread[2] = np.where(has, rng.uniform(0.1, 0.4, cap), 0.0)
    spread[3] = np.where(has, rng.uniform(0.1, 0.4, cap), 0.0)
    return spread


def test_top_elasticity_compiled_equals_numpy():
    # Random windows: some wheels with too few samples, slips with ties (a quantile on a tie),
    # since before, inside and after the window.
    from frictiond.wheel_verdicts import _top_elasticity_numpy

    rng = np.random.default_rng(12)
    defined = 0
    for trial in range(2000):
        start, n, slip, mu, wheel = _random_window(rng, 256, 160, 2 if trial % 2 else 6)
        times = np.full(256, np.nan)
        times[start:start + n] = np.sort(rng.random(n))
        args = (slip, mu, wheel, times, _random_spread(rng, slip), start, start + n, float(rng.uniform(-0.2, 1.1)),
                int(rng.integers(0, 4)), int(rng.integers(1, 16)), int(rng.integers(1, 8)))
        got, want = core.top_elasticity(*args), _top_elasticity_numpy(*args)
        assert (got is None) == (want is None), (trial, got, want)
        if want is not None:
            defined += 1
            assert got == pytest.approx(want, rel=1e-9, abs=1e-12), (trial, got, want)
    assert defined > 300   # (the comparison ran on real values, not only on the Nones)


def test_top_elasticity_standard_error_is_the_slopes():
    # μ = a + b·λ + noise over one wheel's top slips: the elasticity is b·λ̄/μ̄ and its standard
    # error the regression's, which shrinks as the slips spread and grows with the noise.
    from frictiond.wheel_verdicts import _top_elasticity_numpy

    rng = np.random.default_rng(3)
    errors = {}
    for spread, noise in ((0.02, 0.01), (0.002, 0.01), (0.02, 0.0)):
        n = 200
        slip = 0.1 + spread * rng.random(n)
        mu = 0.5 + 1.0 * (slip - 0.1) + noise * rng.standard_normal(n)
        args = (slip, mu, np.zeros(n, dtype=np.intp), np.linspace(0.0, 1.0, n), np.zeros((4, n)), 0, n, -1.0, 0, 8, 4)
        (el, se, smear), (el_c, se_c, smear_c) = _top_elasticity_numpy(*args), core.top_elasticity(*args)
        upper = (slip >= np.quantile(slip, 0.5)) & (slip <= np.quantile(slip, 0.95))
        fit, cov = np.polyfit(slip[upper], mu[upper], 1, cov="unscaled")
        scale = slip[upper].mean() / mu[upper].mean()
        resid = mu[upper] - np.polyval(fit, slip[upper])
        assert el == pytest.approx(fit[0] * scale, rel=1e-9)
        assert se == pytest.approx(np.sqrt(resid @ resid / (upper.sum() - 2) * cov[0, 0]) * scale, rel=1e-6, abs=1e-12)
        assert (el_c, se_c) == pytest.approx((el, se), rel=1e-9, abs=1e-12)
        assert smear == smear_c == 0.0    # (no sweep known: no smear)
        errors[spread, noise] = se
    assert errors[0.002, 0.01] > 5 * errors[0.02, 0.01] > 0
    assert errors[0.02, 0.0] < 1e-9


@pytest.mark.parametrize("sweep", [0.001, 0.004, 0.02])
def test_top_elasticity_smear_is_the_filter_sweep_over_the_top_slips_spread(sweep):
    # Every sample's μ averaged over slips ± `sweep` around its own, with weights ¼ at each end:
    # the rms sweep is sweep·√½, against the top slips' own standard deviation.
    from frictiond.wheel_verdicts import _top_elasticity_numpy

    rng = np.random.default_rng(5)
    n = 120
    slip = 0.08 + 0.02 * rng.random(n)
    mu = 0.6 + 0.5 * (slip - 0.08)
    spread = np.vstack((slip - sweep, slip + sweep, np.full(n, 0.25), np.full(n, 0.25)))
    args = (slip, mu, np.zeros(n, dtype=np.intp), np.linspace(0.0, 1.0, n), spread, 0, n, -1.0, 0, 8, 4)
    upper = (slip >= np.quantile(slip, 0.5)) & (slip <= np.quantile(slip, 0.95))
    want = sweep * math.sqrt(0.5) / slip[upper].std()
    assert _top_elasticity_numpy(*args)[2] == pytest.approx(want, rel=1e-9)
    assert core.top_elasticity(*args)[2] == pytest.approx(want, rel=1e-9)


def test_spread_loss_compiled_equals_numpy():
    # Windows of random slips and μ with and without a spread (some wheels' ends far apart, over
    # the peak; some none), at random parameters: the compiled mean over the top of each wheel's
    # data is numpy's.
    from frictiond.estimator import _spread_loss_numpy, _Window

    rng = np.random.default_rng(5)
    for trial in range(200):
        p, thetas, v = random_peak_case(rng, v_min=3.0)
        window = _Window(256)
        n = int(rng.integers(0 if trial % 7 == 0 else 1, 200))
        for k in range(n):
            slip = float(rng.uniform(0.002, 0.7))
            window.append(slip, v, float(rng.uniform(0.05, 1.0)), 0.01 * k, int(rng.integers(0, 4)))
            if rng.random() < 0.8:
                window.set_spread(1, [(max(0.0, slip - float(rng.uniform(0, 0.2))), slip + float(rng.uniform(0, 0.2)))],
                                  (0.25, 0.25) if rng.random() < 0.5 else (0.1625, 0.1625))
        lo = int(rng.integers(0, n + 1))
        params = tm.compiled_params(p)
        got = core.spread_loss(window.slip, window.speed, window.mu, window.wheel, window.spread, lo, window.end,
                               thetas.tolist(), params)
        want = _spread_loss_numpy(window, lo, thetas.tolist(), p)
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12), (trial, got, want)
        assert got >= 0.0
    with pytest.raises(ValueError):
        core.spread_loss(window.slip, window.speed, window.mu, window.wheel, window.spread, 0, 10**6, thetas.tolist(),
                         params)
