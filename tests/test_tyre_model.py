"""Static LuGre: analytic Jacobian against finite differences, peak against a dense search."""
from __future__ import annotations

import numpy as np
import pytest

from frictiond import tyre_model as tm

P0 = tm.LugreParams()


@pytest.mark.parametrize("name", tm.PARAMETER_NAMES)
def test_jacobian_matches_central_differences(name):
    rng = np.random.default_rng(3)
    slip = np.concatenate([rng.uniform(1e-4, 0.9, 200), -rng.uniform(1e-4, 0.5, 20), [1e-7, 0.5]])
    speed = rng.uniform(1.0, 40.0, len(slip))
    p = P0.with_values(theta=1.7, sigma2=0.004)
    _, jac = tm.mu_and_jacobian(slip, speed, p, (name,))
    base = getattr(p, name)
    h = 1e-6 * max(1.0, abs(base))
    numeric = (tm.mu(slip, speed, p.with_values(**{name: base + h})) - tm.mu(slip, speed, p.with_values(**{name: base - h}))) / (2 * h)
    scale = max(1e-9, float(np.max(np.abs(numeric))))
    assert np.max(np.abs(jac[:, 0] - numeric)) / scale < 1e-6


def test_per_sample_theta_jacobian_matches_scalar_form():
    rng = np.random.default_rng(4)
    slip = rng.uniform(0.001, 0.6, 50)
    speed = rng.uniform(2, 30, 50)
    names = ("theta", "sigma0", "sigma2", "v_s", "mu_s", "mu_c")
    for theta in (0.8, 2.5):
        p = P0.with_values(theta=theta)
        v1, j1 = tm.mu_and_jacobian(slip, speed, p, names)
        v2, j2 = tm.mu_and_jacobian_theta(slip, speed, np.full(50, theta), p, names)
        np.testing.assert_allclose(v1, v2, rtol=1e-12)
        np.testing.assert_allclose(j1, j2, rtol=1e-10, atol=1e-14)


def test_small_slip_is_linear_with_theta_independent_stiffness():
    lam = np.array([1e-7, 1e-6])
    for theta in (1.0, 3.0, 10.0):
        m = tm.mu(lam, np.array([20.0, 20.0]), P0.with_values(theta=theta, sigma2=0.0))
        np.testing.assert_allclose(m / lam, P0.sigma0 * P0.patch_length / 2, rtol=2e-3)


def test_odd_in_slip():
    lam = np.linspace(0.001, 0.5, 20)
    np.testing.assert_allclose(tm.mu(-lam, 15.0, P0), -tm.mu(lam, 15.0, P0))


@pytest.mark.parametrize("theta", [0.8, 1.0, 1.6, 3.0, 8.0, 20.0])
@pytest.mark.parametrize("speed", [3.0, 15.0, 35.0])
def test_peak_matches_dense_search(theta, speed):
    p = P0.with_values(theta=theta)
    lam = np.linspace(1e-4, tm.MAX_MODEL_SLIP, 400_001)
    values = tm.mu(lam, speed, p)
    # The tyre's peak is the first local maximum (the viscous term may climb again near lock).
    falling = np.nonzero(np.diff(values) < 0)[0]
    k = falling[0] if len(falling) else len(values) - 1
    mu_max, lam_star = tm.peak(speed, p)
    assert mu_max == pytest.approx(values[k], rel=1e-7)
    assert lam_star == pytest.approx(lam[k], abs=2e-4)


def test_peak_falls_with_theta_and_moves_with_speed():
    peaks = [tm.peak(20.0, P0.with_values(theta=t))[0] for t in (1.0, 1.25, 1.67, 2.5)]
    assert all(a > b for a, b in zip(peaks, peaks[1:]))
    # The speed dependence static LuGre adds over Burckhardt/MF (paper Fig. 2).
    assert tm.peak(5.0, P0)[0] > tm.peak(30.0, P0)[0]


def test_peak_gradient_is_envelope_derivative():
    names = ("theta", "sigma0", "v_s", "sigma2")
    p = P0.with_values(theta=1.4)
    _, _, grad = tm.peak_gradient(18.0, p, names)
    for k, name in enumerate(names):
        h = 1e-5 * getattr(p, name)
        hi = tm.peak(18.0, p.with_values(**{name: getattr(p, name) + h}))[0]
        lo = tm.peak(18.0, p.with_values(**{name: getattr(p, name) - h}))[0]
        assert grad[k] == pytest.approx((hi - lo) / (2 * h), rel=1e-3, abs=1e-9)


@pytest.mark.parametrize("theta", [1.0, 3.0, 25.0])
@pytest.mark.parametrize("offset", [0.97, 1.0, 1.03])
def test_peak_refined_near_a_previous_one_matches_the_full_search(theta, offset):
    # The recursive estimator's path: a bracketed parabolic refinement around the last λ*.
    p = tm.LugreParams(sigma0=300.0, v_s=5.0, sigma2=0.001)
    thetas = np.array([theta, 1.3 * theta])
    mu_full, lam_full = tm.peaks(15.0, p, thetas)
    assert tm._peaks_near(15.0, p, thetas, lam_full * offset) is not None   # no fallback to the grid
    mu_near, lam_near = tm.peaks(15.0, p, thetas, near=lam_full * offset)
    np.testing.assert_allclose(lam_near, lam_full, rtol=0.01)
    np.testing.assert_allclose(mu_near, mu_full, rtol=1e-5)
