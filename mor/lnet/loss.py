"""The training loss: the negative log-likelihoods of paper Eq. 5 for the PoseNet and the tracker, plus the means'
errors, and with ``visibility`` the PoseNet's visibility BCE and its ego object terms only where the object is in
view."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from mor.lnet.frames import world_to_ego
from mor.lnet.likelihoods import gaussian_nll, von_mises_nll
from mor.lnet.model import PoseEstimate


def _masked_mean(values: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    mask = mask.to(values.dtype).expand_as(values)
    return (values * mask).sum() / mask.sum().clamp(min=1.0)


def nll_terms(estimate: PoseEstimate, agent_pose: torch.Tensor, object_positions: torch.Tensor,
              object_mask: torch.Tensor, beta: float = 0.0) -> dict[str, torch.Tensor]:
    """Mean NLL of the agent position, the heading and the masked objects' positions, plus the means' errors.

    agent_pose (..., 3) world [x, y, theta]; object_positions (..., K, 2) world; object_mask (..., K) or (B, 1, K)
    broadcastable. Ego-frame estimates are scored against the labels moved into the true ego frame.
    beta > 0: the objects' NLL is the beta-NLL (Seitzer et al., ICLR 2022): each term weighted by the
    stop-gradient generalized variance det(Sigma)^(beta/2), so that well-fitted means are not traded for wide
    variances.

    The error terms (squared metres, 1 - cos of the heading error) keep the means learning while the stated
    uncertainty is still wide: the NLL's gradient on a von Mises mean is kappa * sin(error), which vanishes when
    kappa collapses to ~0 early in training, and then kappa cannot grow either (docs/assumptions.md).
    """
    targets = object_positions
    if estimate.frame == "ego":
        targets = world_to_ego(object_positions, agent_pose[..., :2], agent_pose[..., 2])
    per_object = gaussian_nll(targets, estimate.object_mean, estimate.object_tril)
    if beta > 0:
        diagonal = torch.diagonal(estimate.object_tril, dim1=-2, dim2=-1)
        per_object = per_object * (diagonal[..., 0] * diagonal[..., 1]).detach() ** beta
    object_error = (targets - estimate.object_mean).pow(2).sum(-1)
    return {
        "agent": gaussian_nll(agent_pose[..., :2], estimate.agent_mean, estimate.agent_tril).mean(),
        "heading": von_mises_nll(agent_pose[..., 2], estimate.heading, estimate.kappa).mean(),
        "objects": _masked_mean(per_object, object_mask),
        "agent_error": (agent_pose[..., :2] - estimate.agent_mean).pow(2).sum(-1).mean(),
        "heading_error": (1.0 - torch.cos(agent_pose[..., 2] - estimate.heading)).mean(),
        "objects_error": _masked_mean(object_error, object_mask),
    }


def _summed(terms: dict[str, torch.Tensor], prefix: str, parts: dict[str, float]) -> torch.Tensor:
    """The sum of ``terms``, each also logged into ``parts`` as ``prefix_name`` (a float)."""
    total = torch.zeros(())
    for term, value in terms.items():
        parts[f"{prefix}_{term}"] = float(value.detach())
        total = total + value
    return total


def posenet_loss(single: PoseEstimate, batch: dict[str, torch.Tensor], beta: float = 0.0
                 ) -> tuple[torch.Tensor, dict[str, float]]:
    """The PoseNet's per-frame loss and its parts (floats). With a visibility head (``single.visibility_logit``),
    the visibility BCE over present objects, and the ego object terms only on frames where the object is visible
    (``batch["visible"]``); without one, on every present object."""
    present = batch["object_mask"].unsqueeze(1)
    mask, terms = present, {}
    if single.visibility_logit is not None:
        mask = batch["visible"] & present
        terms["visibility"] = _masked_mean(F.binary_cross_entropy_with_logits(
            single.visibility_logit, mask.to(single.visibility_logit.dtype), reduction="none"), present)
    terms = {**nll_terms(single, batch["agent_pose"], batch["object_positions"], mask, beta), **terms}
    parts: dict[str, float] = {}
    return _summed(terms, "posenet", parts), parts


def lnet_loss(single: PoseEstimate, tracked: PoseEstimate, batch: dict[str, torch.Tensor],
              beta: float = 0.0) -> tuple[torch.Tensor, dict]:
    """Total loss (``posenet_loss`` + the tracker's terms) and its parts as floats, for logging. The tracker is
    scored on every present object on every frame (its belief must be honest when unseen too)."""
    total, parts = posenet_loss(single, batch, beta)
    present = batch["object_mask"].unsqueeze(1)
    tracker = nll_terms(tracked, batch["agent_pose"], batch["object_positions"], present)
    return total + _summed(tracker, "tracker", parts), parts


def previous_actions(actions: torch.Tensor) -> torch.Tensor:
    """(B, T) actions taken after each frame -> the action taken before each frame (-1 at the first)."""
    return torch.cat([torch.full_like(actions[:, :1], -1), actions[:, :-1]], 1)
