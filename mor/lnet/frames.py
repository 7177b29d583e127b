"""The frame conventions of ``mor.sim.geometry`` on torch tensors (the same formulas; tests check they agree)."""

from __future__ import annotations

import torch


def world_to_ego(points: torch.Tensor, agent_xy: torch.Tensor, theta: torch.Tensor) -> torch.Tensor:
    """World points (..., K, 2) in the ego frame (x forward, y left) of agents at (..., 2), heading (...)."""
    delta = points - agent_xy.unsqueeze(-2)
    c, s = torch.cos(theta).unsqueeze(-1), torch.sin(theta).unsqueeze(-1)
    return torch.stack([c * delta[..., 0] + s * delta[..., 1], -s * delta[..., 0] + c * delta[..., 1]], -1)


def ego_to_world(points: torch.Tensor, agent_xy: torch.Tensor, theta: torch.Tensor) -> torch.Tensor:
    """Ego points (..., K, 2) of agents at (..., 2) with heading (...) in the world frame."""
    c, s = torch.cos(theta).unsqueeze(-1), torch.sin(theta).unsqueeze(-1)
    x = agent_xy[..., 0:1] + c * points[..., 0] - s * points[..., 1]
    y = agent_xy[..., 1:2] + s * points[..., 0] + c * points[..., 1]
    return torch.stack([x, y], -1)


def rotate_tril(tril: torch.Tensor, theta: torch.Tensor) -> torch.Tensor:
    """Cholesky factors (..., K, 2, 2) of ego-frame covariances, expressed in the world frame (R L)."""
    c, s = torch.cos(theta), torch.sin(theta)
    rotation = torch.stack([torch.stack([c, -s], -1), torch.stack([s, c], -1)], -2).unsqueeze(-3)
    return rotation @ tril
