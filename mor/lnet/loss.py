"""The training loss: the sum of the negative log-likelihoods of paper Eq. 5, for the PoseNet and the LSTM."""

from __future__ import annotations

import torch

from mor.lnet.frames import world_to_ego
from mor.lnet.likelihoods import gaussian_nll, von_mises_nll
from mor.lnet.model import PoseEstimate


def nll_terms(estimate: PoseEstimate, agent_pose: torch.Tensor, object_positions: torch.Tensor,
              object_mask: torch.Tensor) -> dict[str, torch.Tensor]:
    """Mean NLL of the agent position, the heading and the present objects' positions, plus the means' errors.

    agent_pose (..., 3) world [x, y, theta]; object_positions (..., K, 2) world; object_mask (..., K) or (B, K)
    broadcastable. Ego-frame estimates are scored against the labels moved into the true ego frame.

    The error terms (squared metres, 1 - cos of the heading error) keep the means learning while the stated
    uncertainty is still wide: the NLL's gradient on a von Mises mean is kappa * sin(error), which vanishes when
    kappa collapses to ~0 early in training, and then kappa cannot grow either (docs/assumptions.md).
    """
    targets = object_positions
    if estimate.frame == "ego":
        targets = world_to_ego(object_positions, agent_pose[..., :2], agent_pose[..., 2])
    per_object = gaussian_nll(targets, estimate.object_mean, estimate.object_tril)
    mask = object_mask.to(per_object.dtype).expand_as(per_object)
    object_error = (targets - estimate.object_mean).pow(2).sum(-1)
    return {
        "agent": gaussian_nll(agent_pose[..., :2], estimate.agent_mean, estimate.agent_tril).mean(),
        "heading": von_mises_nll(agent_pose[..., 2], estimate.heading, estimate.kappa).mean(),
        "objects": (per_object * mask).sum() / mask.sum().clamp(min=1.0),
        "agent_error": (agent_pose[..., :2] - estimate.agent_mean).pow(2).sum(-1).mean(),
        "heading_error": (1.0 - torch.cos(agent_pose[..., 2] - estimate.heading)).mean(),
        "objects_error": (object_error * mask).sum() / mask.sum().clamp(min=1.0),
    }


def lnet_loss(single: PoseEstimate, tracked: PoseEstimate, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, dict]:
    """Total loss (PoseNet terms + LSTM terms) and its parts as floats, for logging."""
    mask = batch["object_mask"].unsqueeze(1)
    parts = {}
    total = torch.zeros((), device=batch["agent_pose"].device)
    for name, estimate in (("posenet", single), ("lstm", tracked)):
        for term, value in nll_terms(estimate, batch["agent_pose"], batch["object_positions"], mask).items():
            parts[f"{name}_{term}"] = float(value.detach())
            total = total + value
    return total, parts


def previous_actions(actions: torch.Tensor) -> torch.Tensor:
    """(B, T) actions taken after each frame -> the action taken before each frame (-1 at the first)."""
    return torch.cat([torch.full_like(actions[:, :1], -1), actions[:, :-1]], 1)
