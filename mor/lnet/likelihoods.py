"""Negative log-likelihoods of paper Eq. 3-5, and the parameterizations that keep them valid.

Positions: bivariate Gaussians N(mean, L L^T) with L a lower-triangular Cholesky factor with a positive diagonal.
Heading: von Mises(mu, kappa) with kappa > 0; log I0 is computed stably as log(i0e(kappa)) + kappa.
(The paper's Eq. 3 writes the normalizer as sqrt(2 pi |Sigma|); the bivariate density's is 2 pi sqrt(|Sigma|),
which is what we use.)
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from scipy.stats import vonmises

#: Smallest standard deviation / concentration the parameterizations can produce (metres / 1).
MIN_SCALE: float = 1e-3
MIN_KAPPA: float = 1e-3
_LOG_2PI = math.log(2.0 * math.pi)


def positive(raw: torch.Tensor, floor: float) -> torch.Tensor:
    """softplus(raw) + floor: an unconstrained number to a positive one."""
    return F.softplus(raw) + floor


def scale_tril(raw: torch.Tensor) -> torch.Tensor:
    """(..., 3) unconstrained -> (..., 2, 2) lower-triangular Cholesky factor [[a, 0], [c, b]], a, b > 0."""
    a = positive(raw[..., 0], MIN_SCALE)
    b = positive(raw[..., 1], MIN_SCALE)
    zero = torch.zeros_like(a)
    return torch.stack([torch.stack([a, zero], -1), torch.stack([raw[..., 2], b], -1)], -2)


def mahalanobis_squared(x: torch.Tensor, mean: torch.Tensor, tril: torch.Tensor) -> torch.Tensor:
    """(x - mean)^T Sigma^-1 (x - mean) with Sigma = tril tril^T; x, mean (..., 2), tril (..., 2, 2) -> (...)."""
    delta = x - mean
    # Forward substitution with the 2x2 factor [[a, 0], [c, b]], written out: batched LAPACK calls on 2x2
    # matrices are an order of magnitude slower on the CPU, forward and backward.
    first = delta[..., 0] / tril[..., 0, 0]
    second = (delta[..., 1] - tril[..., 1, 0] * first) / tril[..., 1, 1]
    return first.pow(2) + second.pow(2)


def gaussian_nll(x: torch.Tensor, mean: torch.Tensor, tril: torch.Tensor) -> torch.Tensor:
    """-log N(x; mean, tril tril^T) for 2-D x (..., 2) -> (...)."""
    log_det = 2.0 * torch.log(torch.diagonal(tril, dim1=-2, dim2=-1)).sum(-1)
    return 0.5 * mahalanobis_squared(x, mean, tril) + 0.5 * log_det + _LOG_2PI


def log_i0(kappa: torch.Tensor) -> torch.Tensor:
    """log I0(kappa), stable for large kappa (I0 itself overflows float32 past ~88)."""
    return torch.log(torch.special.i0e(kappa)) + kappa


def von_mises_nll(theta: torch.Tensor, mu: torch.Tensor, kappa: torch.Tensor) -> torch.Tensor:
    """-log VonMises(theta; mu, kappa) (radians) -> same shape."""
    return -kappa * torch.cos(theta - mu) + _LOG_2PI + log_i0(kappa)


def heading_halfwidth(kappa: float | np.ndarray, mass: float) -> float | np.ndarray:
    """Half-width (radians) of the central interval of a von Mises(mu, kappa) holding ``mass`` of the probability.

    For large kappa it approaches z / sqrt(kappa) with z the normal quantile (about 2 for mass 0.954); as kappa -> 0
    the distribution becomes uniform and it approaches mass * pi (kappa at or below 1e-12 gives exactly that).
    kappa: a number or an array (then an array of the same shape is returned); NaN gives NaN.
    """
    if not 0.0 < mass < 1.0:
        raise ValueError(f"mass: must be in (0, 1) (got {mass})")
    values = np.asarray(kappa, np.float64)
    if np.any(values < 0):
        raise ValueError("kappa: a von Mises concentration must be >= 0")
    tiny = values <= 1e-12
    _, upper = vonmises.interval(mass, np.where(tiny, 1.0, values))
    width = np.where(tiny, mass * np.pi, upper)
    return float(width) if width.ndim == 0 else width
