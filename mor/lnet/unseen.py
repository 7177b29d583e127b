"""``TrackingSettings.negative_information``: what not seeing an object says about where it is (our addition).

The filter's Kalman update learns from measurements only: a belief that puts an object right in front of the agent
stays there while the camera looks at the spot and sees nothing. Here a frame in which the PoseNet does not see
slot k (probability ``missed_k = 1 - visibility_k``) is evidence against the part of k's belief that lies in the
camera's view within ``UNSEEN_REACH`` metres (``mor.sim.rules.CAMERA_FOV``): a point x there would have been seen
with probability ``UNSEEN_DETECTION``, so the frame's likelihood is
``L(x) = 1 - UNSEEN_DETECTION missed_k in_view_within_reach(x)`` (occlusion ignored: a hidden object costs its belief
a little width; the agent's pose is taken at its mean). It follows the filter's soft Kalman update of the same
frame, which weights the measurement by ``visibility_k``.

A belief partly in view moves away from the view. A confident belief that lies wholly in view is not moved by ``L``
alone (every point is scaled alike), so the belief is read as two hypotheses: it is right, or it is wrong by about
``UNSEEN_SPREAD`` metres (the same mean, the covariance widened by ``UNSEEN_SPREAD^2``), the latter with prior
probability ``UNSEEN_DOUBT``. The frame moves probability to "wrong" by Bayes' rule, and the share it moved,
``omega = (P(wrong | frame) - UNSEEN_DOUBT) / (1 - UNSEEN_DOUBT)`` (a heuristic weight, not the posterior itself:
it is 0 where the frame says nothing), mixes the two hypotheses, each times ``L``; the mixture's mean and covariance
are the new belief. So a contradicted confident belief widens about where it was, and the next frames, which see
the view empty again, push its mass out of it. Without evidence (nothing missed, or no belief in view) omega is 0
and the belief is unchanged.

Moments under ``L`` are taken by a fixed 2-D Gauss-Hermite rule (``UNSEEN_NODES`` per axis), so the update is
deterministic. A tracking-time rule (off in training), recorded by ``mor calibrate-lnet`` like the others.

Shapes: B episodes, K slots, P quadrature points. Metres and radians.
"""

from __future__ import annotations

import numpy as np
import torch

from mor.lnet.small_matrices import cholesky_2x2, eye_like, outer, symmetric, wrap
from mor.sim.rules import CAMERA_FOV, PICK_RANGE

#: probability that the PoseNet sees an object that lies in view within ``UNSEEN_REACH``
UNSEEN_DETECTION: float = 0.9
#: metres: how far in front of the agent not seeing an object says anything (PICK's reach)
UNSEEN_REACH: float = PICK_RANGE
#: prior probability that a belief is wrong
UNSEEN_DOUBT: float = 0.1
#: metres: how far off a wrong belief is, about
UNSEEN_SPREAD: float = 1.0
#: Gauss-Hermite nodes per axis (P = UNSEEN_NODES^2 points)
UNSEEN_NODES: int = 16


def _quadrature() -> tuple[torch.Tensor, torch.Tensor]:
    """Standard-normal points (P, 2) and weights (P,) summing to 1: the product Gauss-Hermite rule."""
    nodes, weights = np.polynomial.hermite_e.hermegauss(UNSEEN_NODES)
    x, y = np.meshgrid(nodes, nodes, indexing="ij")
    w = np.outer(weights, weights).ravel()
    return torch.tensor(np.stack([x.ravel(), y.ravel()], -1)), torch.tensor(w / w.sum())


_UNIT, _WEIGHTS = _quadrature()  # made once, float64 (torch.compile traces no NumPy conversion per step)
_HALF_FOV = float(CAMERA_FOV) / 2.0  # a Python float, for the same reason


def in_view_within_reach(points: torch.Tensor, agent: torch.Tensor, heading: torch.Tensor) -> torch.Tensor:
    """Whether world points (B, ..., 2) lie in the camera's view (``rules.CAMERA_FOV``, as ``mor.lnet.search.in_view``
    in torch) within ``UNSEEN_REACH`` metres of agents at ``agent`` (B, 2) facing ``heading`` (B,): (B, ...) bool."""
    extra = (1,) * (points.dim() - 2)
    delta = points - agent.reshape(agent.shape[0], *extra, 2)
    theta = heading.reshape(-1, *extra)
    bearing = wrap(torch.atan2(delta[..., 1], delta[..., 0]) - theta)
    return (torch.linalg.vector_norm(delta, dim=-1) <= UNSEEN_REACH) & (bearing.abs() <= _HALF_FOV)


def _weighted_moments(mean: torch.Tensor, cov: torch.Tensor, agent: torch.Tensor, heading: torch.Tensor,
                      missed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """N(mean (B, K, 2), cov (B, K, 2, 2)) times ``L`` -> (its mass (B, K) in (0, 1], mean, covariance)."""
    unit, weights = (t.to(device=mean.device, dtype=mean.dtype) for t in (_UNIT, _WEIGHTS))
    points = mean[..., None, :] + (cholesky_2x2(cov)[..., None, :, :] @ unit[..., None])[..., 0]  # (B, K, P, 2)
    inside = in_view_within_reach(points, agent, heading).to(mean.dtype)                  # (B, K, P)
    likelihood = 1.0 - UNSEEN_DETECTION * missed[..., None] * inside
    w = weights * likelihood                                                               # (B, K, P)
    mass = w.sum(-1)
    moved_mean = (w[..., None] * points).sum(-2) / mass[..., None]
    spread = points - moved_mean[..., None, :]
    moved_cov = (w[..., None, None] * outer(spread)).sum(-3) / mass[..., None, None]
    return mass, moved_mean, moved_cov


def not_seen_update(mean: torch.Tensor, cov: torch.Tensor, agent: torch.Tensor, heading: torch.Tensor,
                    missed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The objects' beliefs N(mean (B, K, 2), cov (B, K, 2, 2)) after a frame in which each went unseen with
    probability ``missed`` (B, K) in [0, 1] (0 for a held object), the agent at ``agent`` (B, 2) facing ``heading``
    (B,) (module docstring). Returns (mean, cov), equal to the inputs where the frame says nothing."""
    right_mass, right_mean, right_cov = _weighted_moments(mean, cov, agent, heading, missed)
    widened = cov + UNSEEN_SPREAD ** 2 * eye_like(cov)
    wrong_mass, wrong_mean, wrong_cov = _weighted_moments(mean, widened, agent, heading, missed)
    wrong = UNSEEN_DOUBT * wrong_mass / ((1.0 - UNSEEN_DOUBT) * right_mass + UNSEEN_DOUBT * wrong_mass)
    omega = ((wrong - UNSEEN_DOUBT) / (1.0 - UNSEEN_DOUBT)).clamp(0.0, 1.0)[..., None]
    new_mean = (1.0 - omega) * right_mean + omega * wrong_mean

    new_cov = ((1.0 - omega[..., None]) * (right_cov + outer(right_mean - new_mean))
               + omega[..., None] * (wrong_cov + outer(wrong_mean - new_mean)))
    evidence = (right_mass < 1.0 - 1e-6)  # some of the belief lay in view and the frame missed it
    return (torch.where(evidence[..., None], new_mean, mean),
            torch.where(evidence[..., None, None], symmetric(new_cov), cov))
