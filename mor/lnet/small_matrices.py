"""Batched 2x2 matrix helpers of the belief filter (``mor.lnet.filter``, ``mor.lnet.unseen``), written out: batched
LAPACK on 2x2 matrices is slow on CPU. Shapes: (..., 2, 2) matrices, (..., 2) vectors."""

from __future__ import annotations

import torch

#: the floor under variances and determinants
EPS: float = 1e-6


def eye_like(like: torch.Tensor) -> torch.Tensor:
    """The 2x2 identity in ``like``'s dtype and device."""
    return torch.eye(2, dtype=like.dtype, device=like.device)


def cholesky_2x2(cov: torch.Tensor) -> torch.Tensor:
    """Lower Cholesky factors of covariances (..., 2, 2)."""
    a = torch.sqrt(cov[..., 0, 0].clamp(min=EPS))
    c = cov[..., 1, 0] / a
    b = torch.sqrt((cov[..., 1, 1] - c * c).clamp(min=EPS))
    zero = torch.zeros_like(a)
    return torch.stack([torch.stack([a, zero], -1), torch.stack([c, b], -1)], -2)


def outer(v: torch.Tensor) -> torch.Tensor:
    """v v^T of vectors (..., 2) -> (..., 2, 2)."""
    return v.unsqueeze(-1) * v.unsqueeze(-2)


def symmetric(cov: torch.Tensor) -> torch.Tensor:
    """The symmetric part of (..., 2, 2), with ``EPS`` on the diagonal."""
    return 0.5 * (cov + cov.transpose(-1, -2)) + EPS * eye_like(cov)


def wrap(angle: torch.Tensor) -> torch.Tensor:
    """Angles wrapped to (-pi, pi]."""
    return torch.atan2(torch.sin(angle), torch.cos(angle))
