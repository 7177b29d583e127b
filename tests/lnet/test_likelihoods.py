"""Every log-density against scipy.stats, including large kappa and near-singular covariances."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import special, stats

from mor.lnet.likelihoods import gaussian_nll, log_i0, mahalanobis_squared, scale_tril, von_mises_nll


def _random_tril(rng: np.random.Generator, scale_low: float, scale_high: float) -> np.ndarray:
    a, b = rng.uniform(scale_low, scale_high, size=2)
    c = rng.normal(0.0, max(a, b))
    return np.array([[a, 0.0], [c, b]])


@pytest.mark.parametrize("scales", [(0.05, 3.0), (1e-3, 1e-2), (1e-3, 5.0)])
def test_gaussian_nll_matches_scipy(scales: tuple[float, float]) -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        tril = _random_tril(rng, *scales)
        mean = rng.normal(0, 3, size=2)
        x = mean + tril @ rng.normal(size=2) * rng.uniform(0.1, 4.0)
        expected = -stats.multivariate_normal(mean, tril @ tril.T, allow_singular=True).logpdf(x)
        got = gaussian_nll(*(torch.tensor(v, dtype=torch.float64) for v in (x, mean, tril)))
        assert float(got) == pytest.approx(expected, rel=1e-6, abs=1e-6)


def test_near_singular_covariance_stays_finite_and_exact() -> None:
    # Correlation 0.999999: the covariance is almost rank one.
    tril = np.array([[1.0, 0.0], [0.999999, np.sqrt(1 - 0.999999**2)]])
    x, mean = np.array([0.3, 0.3001]), np.zeros(2)
    expected = -stats.multivariate_normal(mean, tril @ tril.T).logpdf(x)
    got = float(gaussian_nll(*(torch.tensor(v, dtype=torch.float64) for v in (x, mean, tril))))
    assert np.isfinite(got) and got == pytest.approx(expected, rel=1e-5)


@given(theta=st.floats(-10, 10), mu=st.floats(-10, 10), kappa=st.floats(1e-3, 1e4))
@settings(max_examples=200, deadline=None)
def test_von_mises_nll_matches_scipy(theta: float, mu: float, kappa: float) -> None:
    expected = -stats.vonmises.logpdf(theta, kappa, loc=mu)
    got = float(von_mises_nll(*(torch.tensor(v, dtype=torch.float64) for v in (theta, mu, kappa))))
    assert got == pytest.approx(expected, rel=1e-6, abs=1e-6)


def test_log_i0_is_stable_for_large_kappa_in_float32() -> None:
    kappa = torch.tensor([1e-3, 1.0, 50.0, 100.0, 1e3, 1e5], dtype=torch.float32)
    got = log_i0(kappa).double().numpy()
    expected = np.log(special.i0e(kappa.double().numpy())) + kappa.double().numpy()
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6)
    assert not torch.isfinite(torch.log(torch.special.i0(kappa[-1])))  # the naive formula overflows


def test_scale_tril_is_a_valid_cholesky_factor_with_finite_gradients() -> None:
    raw = (torch.randn(100, 3, dtype=torch.float64) * 3).requires_grad_()
    tril = scale_tril(raw)
    assert torch.all(torch.diagonal(tril, dim1=-2, dim2=-1) > 0)
    assert torch.all(tril[..., 0, 1] == 0)
    covariance = tril @ tril.transpose(-1, -2)
    assert torch.all(torch.linalg.eigvalsh(covariance) > 0)
    x = torch.randn(100, 2, dtype=torch.float64)
    gaussian_nll(x, torch.zeros_like(x), tril).sum().backward()
    assert torch.all(torch.isfinite(raw.grad))


def test_mahalanobis_matches_the_inverse_covariance() -> None:
    rng = np.random.default_rng(1)
    tril = _random_tril(rng, 0.1, 2.0)
    d = rng.normal(size=2)
    expected = d @ np.linalg.inv(tril @ tril.T) @ d
    got = mahalanobis_squared(torch.tensor(d), torch.zeros(2, dtype=torch.float64), torch.tensor(tril))
    assert float(got) == pytest.approx(expected, rel=1e-9)
