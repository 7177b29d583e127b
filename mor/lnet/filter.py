"""``tracker: filter``: a differentiable Gaussian belief over the world, updated frame by frame (our addition).

The agent: a motion model learned from the previous action (per action, a forward distance and turn with learned
noise, nothing taken from the simulator's noise), corrected by the PoseNet's global fix (a Kalman update).
Each object: a Gaussian that starts at a learned prior over the arena, stays put on the floor, equals the agent's
position while held (the held index is observed), lands ``rules.DROP_DISTANCE`` ahead of the agent when released
(the agent's position and heading uncertainty carried into it), and is corrected by the PoseNet's ego measurement
moved into the world frame with the estimated agent pose, weighted by the predicted visibility and a soft
Mahalanobis gate. Everything is a torch expression, so the whole belief is trained with the NLL end to end
(as backprop Kalman filters: Haarnoja et al. 2016; Kloss et al. 2021).

``TrackingSettings.data_association`` (a tracking-time rule, off in training; ``lnet.data_association``, recorded in
``calibration.json``): the PoseNet confuses objects of one colour (its false "visible" frames are mostly a
same-coloured object in view), so a slot's measurement that coincides with another slot's is shared between them by
how well each belief explains it, and every weighted update keeps the spread of its two outcomes in the covariance
(the probabilistic data association filter's covariance, Bar-Shalom et al. 2009), so a doubtful update widens the
belief instead of shrinking it onto a possibly wrong place.

``TrackingSettings.noise_own`` and ``noise_shared`` (tracking-time settings fitted on validation by
``mor calibrate-lnet``, recorded in ``calibration.json``): multipliers of the PoseNet's object measurement
covariance for objects of a colour of their own and for objects that share their colour with another
(``mor.sim.catalog.shares_colour``). The PoseNet's object head sees one slot's class at a time, so it cannot know
that a same-coloured object is in the episode; nearly all the badly wrong beliefs are of such objects, while the
measurements of the others deserve more trust than the one learned scale gives (docs/assumptions.md).

``TrackingSettings.negative_information`` (a tracking-time rule, off in training and by default;
``lnet.negative_information``, recorded in ``calibration.json``): a frame that does not see an object is evidence
against the part of its belief in the camera's view (``mor.lnet.unseen``).

Shapes: B episodes, K object slots. Positions in metres, headings in radians; the heading's belief is a Gaussian
(mean, variance) on the circle, reported as a von Mises with kappa = 1 / variance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn

from mor.lnet.likelihoods import MIN_KAPPA
from mor.lnet.small_matrices import EPS, eye_like, outer, symmetric, wrap
from mor.lnet.unseen import not_seen_update
from mor.sim.rules import DROP_DISTANCE, N_ACTIONS

_GATE_SHARPNESS = 2.0
_MAX_LOG_RATIO = 60.0  # exp(60) ~ 1e26: a claim this much better takes the measurement whole
_LOG_PRIOR_STD = math.log(6.0 / math.sqrt(12.0))  # a uniform 6 m side: std 1.73 m (learned from there)

#: The state: agent mean (B, 2), agent cov (B, 2, 2), heading (B,), heading variance (B,), object means (B, K, 2),
#: object covs (B, K, 2, 2), the held index of the previous frame (B,) (-1 none).
FilterState = tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]


@dataclass(frozen=True)
class TrackingSettings:
    """How the filter tracks, chosen by whoever runs it (module docstring), not weights: ``data_association`` the
    rule; ``noise_own`` and ``noise_shared`` the multipliers (> 0) of the object measurement covariance for objects
    of a colour of their own and for objects sharing their colour; ``gate`` the squared Mahalanobis distance of an
    innovation beyond which a measurement is gated out (default: chi-square, 2 dof, 99%; ``lnet.gate``);
    ``negative_information`` whether a frame that does not see an object moves its belief out of the camera's view
    (``mor.lnet.unseen``; ``lnet.negative_information``). ``calibration.json`` records the settings its scales
    were fitted with (``mor.lnet.calibration_file``);
    ``LNet.use_tracking`` applies them. The LSTM tracker has none: only the defaults."""

    data_association: bool = False
    noise_own: float = 1.0
    noise_shared: float = 1.0
    gate: float = 9.21
    negative_information: bool = False


def _inverse(matrix: torch.Tensor) -> torch.Tensor:
    """Inverse of symmetric positive 2x2 matrices (..., 2, 2), written out."""
    a, b, c, d = matrix[..., 0, 0], matrix[..., 0, 1], matrix[..., 1, 0], matrix[..., 1, 1]
    det = (a * d - b * c).clamp(min=EPS * EPS)
    return torch.stack([torch.stack([d, -b], -1), torch.stack([-c, a], -1)], -2) / det[..., None, None]


def _squared_mahalanobis(difference: torch.Tensor, inverse: torch.Tensor) -> torch.Tensor:
    """d^T inverse d of differences (..., 2) under inverse covariances (..., 2, 2) -> (...)."""
    return (difference.unsqueeze(-2) @ inverse @ difference.unsqueeze(-1))[..., 0, 0]


def _kalman(mean: torch.Tensor, cov: torch.Tensor, z: torch.Tensor, noise: torch.Tensor,
            weight: torch.Tensor | None = None, gate: float | None = None, spread: bool = False
            ) -> tuple[torch.Tensor, torch.Tensor]:
    """A Kalman update of N(mean, cov) by a direct measurement z ~ N(x, noise). The gain is scaled by ``weight``
    (in [0, 1]; None: 1) and, given a ``gate``, by a soft gate that drops innovations beyond it (Mahalanobis^2
    under cov + noise). ``spread``: the covariance of the mixture "updated with probability w, else not" (adds
    w (1 - w) (K v)(K v)^T, v the innovation). Returns (mean, cov); (1 - w K) cov stays positive semi-definite for
    w in [0, 1]."""
    innovation = z - mean
    s_inv = _inverse(cov + noise)
    gain = cov @ s_inv
    if gate is not None:
        d2 = _squared_mahalanobis(innovation, s_inv)
        kept = torch.sigmoid(_GATE_SHARPNESS * (gate - d2))
        weight = kept if weight is None else kept * weight
    full_step = (gain @ innovation.unsqueeze(-1))[..., 0]
    if weight is None:
        return mean + full_step, symmetric(cov - gain @ cov)
    cov = cov - weight[..., None, None] * gain @ cov
    if spread:
        cov = cov + (weight * (1.0 - weight))[..., None, None] * outer(full_step)
    return mean + weight[..., None] * full_step, symmetric(cov)


def _log_density(x: torch.Tensor, mean: torch.Tensor, cov: torch.Tensor) -> torch.Tensor:
    """log N(x; mean, cov) of 2-D points (..., 2) under covariances (..., 2, 2)."""
    d2 = _squared_mahalanobis(x - mean, _inverse(cov))
    det = (cov[..., 0, 0] * cov[..., 1, 1] - cov[..., 0, 1] * cov[..., 1, 0]).clamp(min=EPS * EPS)
    return -0.5 * d2 - 0.5 * torch.log(det) - math.log(2.0 * math.pi)


def associate(weight: torch.Tensor, measured: torch.Tensor, noise: torch.Tensor, objects: torch.Tensor,
              object_cov: torch.Tensor) -> torch.Tensor:
    """The weight of each slot's measurement once shared with the other slots that claim the same thing.

    weight (B, K) each measurement's probability of being of its own object (the predicted visibility); measured
    (B, K, 2) and noise (B, K, 2, 2) the measurements in the world frame; objects (B, K, 2) and object_cov
    (B, K, 2, 2) the beliefs. Slot j claims slot k's measurement z_k as much as j's own measurement coincides with
    it, c_kj = weight_j exp(-d^2 / 2) (d^2: Mahalanobis^2 of z_k - z_j under both noises); the measurement is then
    k's in proportion to how well k's belief explains it against the claimants':
    weight_k L_kk / (L_kk + sum_j c_kj L_kj), L_kj = N(z_k; mean_j, cov_j + noise_k). Returns (B, K) in [0, 1].
    """
    z, r = measured.unsqueeze(2), noise.unsqueeze(2)                                       # (B, K, 1, ...)
    explained = _log_density(z, objects.unsqueeze(1), object_cov.unsqueeze(1) + r)        # (B, K, K): z_k | j
    coincide = torch.exp(-0.5 * _squared_mahalanobis(z - measured.unsqueeze(1), _inverse(r + noise.unsqueeze(1))))
    others = 1.0 - torch.eye(weight.shape[-1], dtype=weight.dtype, device=weight.device)
    claims = weight.unsqueeze(1) * coincide * others                                       # (B, K, K): c_kj
    own = torch.diagonal(explained, dim1=1, dim2=2).unsqueeze(-1)
    # L_kj / L_kk, capped so that a belief that cannot explain z_k at all never overflows to inf (0 x inf = NaN)
    ratio = torch.exp((explained - own).clamp(max=_MAX_LOG_RATIO))
    return weight / (1.0 + (claims * ratio).sum(-1))


class BeliefFilter(nn.Module):
    """The learned parameters of the filter and one step of it (see the module docstring)."""

    def __init__(self, n_slots: int, tracking: TrackingSettings = TrackingSettings()) -> None:
        super().__init__()
        self.n_slots = n_slots
        self.tracking = tracking  # tracking-time settings, not weights (module docstring)
        actions = N_ACTIONS + 1  # the last row: no previous action (an episode's first frame)
        self.forward_distance = nn.Parameter(torch.zeros(actions))
        self.turn = nn.Parameter(torch.zeros(actions))
        self.log_forward_std = nn.Parameter(torch.full((actions,), math.log(0.05)))
        self.log_turn_std = nn.Parameter(torch.full((actions,), math.log(0.05)))
        self.agent_prior_mean = nn.Parameter(torch.zeros(2))
        self.log_agent_prior_std = nn.Parameter(torch.tensor(_LOG_PRIOR_STD))
        self.object_prior_mean = nn.Parameter(torch.zeros(2))
        self.log_object_prior_std = nn.Parameter(torch.tensor(_LOG_PRIOR_STD))
        self.log_agent_std = nn.Parameter(torch.tensor(math.log(0.01)))   # the agent, any direction, per step
        self.log_floor_std = nn.Parameter(torch.tensor(math.log(0.01)))   # objects on the floor, per step
        self.log_drop_std = nn.Parameter(torch.tensor(math.log(0.05)))    # where a dropped object lands
        self.log_fix_scale = nn.Parameter(torch.zeros(3))                 # PoseNet agent, heading, objects

    def initial_state(self, n: int, device: torch.device | str = "cpu") -> FilterState:
        """The prior belief of ``n`` episodes (agent and objects anywhere in the arena, heading unknown)."""
        eye = torch.eye(2, device=device)
        agent_var = torch.exp(2 * self.log_agent_prior_std)
        object_var = torch.exp(2 * self.log_object_prior_std)
        return (self.agent_prior_mean.expand(n, 2), (agent_var * eye).expand(n, 2, 2),
                torch.zeros(n, device=device), torch.full((n,), math.pi ** 2 / 3.0, device=device),
                self.object_prior_mean.expand(n, self.n_slots, 2),
                (object_var * eye).expand(n, self.n_slots, 2, 2), torch.full((n,), -1, dtype=torch.long, device=device))

    def step(self, state: FilterState, agent_fix: tuple[torch.Tensor, ...], ego_objects: tuple[torch.Tensor, ...],
             visibility: torch.Tensor | None, held: torch.Tensor, previous_action: torch.Tensor,
             shared: torch.Tensor | None = None) -> FilterState:
        """One frame. agent_fix: the PoseNet's (mean (B, 2), tril (B, 2, 2), heading (B,), kappa (B,));
        ego_objects: (mean (B, K, 2), tril (B, K, 2, 2)) in the ego frame; visibility (B, K) probabilities or
        None (then every measurement is weighted by the gate alone); held (B,) index or -1; previous_action (B,)
        the action before this frame, -1 none; shared (B, K) bool, the object shares its colour with another
        (which measurement-noise multiplier of ``tracking`` it gets; None: all of their own colour)."""
        agent, agent_cov, heading, heading_var, objects, object_cov, previous_held = state
        eye = eye_like(agent)
        # 1. Motion: the previous action's learned displacement and turn, and their learned noise.
        action = torch.where(previous_action >= 0, previous_action, torch.full_like(previous_action, N_ACTIONS))
        distance, turn = self.forward_distance[action], self.turn[action]
        direction = torch.stack([torch.cos(heading), torch.sin(heading)], -1)
        normal = torch.stack([-torch.sin(heading), torch.cos(heading)], -1)
        agent = agent + distance[:, None] * direction
        agent_cov = (agent_cov + (distance ** 2 * heading_var)[:, None, None] * outer(normal)
                     + torch.exp(2 * self.log_forward_std[action])[:, None, None] * outer(direction)
                     + torch.exp(2 * self.log_agent_std) * eye)
        heading = wrap(heading + turn)
        heading_var = heading_var + torch.exp(2 * self.log_turn_std[action])
        # 2. The PoseNet's global fix.
        fix_mean, fix_tril, fix_heading, fix_kappa = agent_fix
        scale = torch.exp(2 * self.log_fix_scale)
        agent, agent_cov = _kalman(agent, agent_cov, fix_mean, scale[0] * fix_tril @ fix_tril.transpose(-1, -2))
        fix_var = scale[1] / fix_kappa.clamp(min=MIN_KAPPA)
        gain = heading_var / (heading_var + fix_var)
        heading = wrap(heading + gain * wrap(fix_heading - heading))
        heading_var = (1.0 - gain) * heading_var
        # 3. Objects on the floor drift a little; the held one is where the agent is; a released one lands ahead.
        slots = torch.arange(self.n_slots, device=held.device)
        is_held = held[:, None] == slots
        dropped = (previous_held[:, None] == slots) & ~is_held
        object_cov = object_cov + torch.exp(2 * self.log_floor_std) * eye
        direction = torch.stack([torch.cos(heading), torch.sin(heading)], -1)
        normal = torch.stack([-torch.sin(heading), torch.cos(heading)], -1)
        landing = agent + DROP_DISTANCE * direction
        landing_cov = (agent_cov + (DROP_DISTANCE ** 2 * heading_var)[:, None, None] * outer(normal)
                       + torch.exp(2 * self.log_drop_std) * eye)
        objects = torch.where(is_held[..., None], agent[:, None], torch.where(dropped[..., None], landing[:, None],
                                                                               objects))
        object_cov = torch.where(is_held[..., None, None], agent_cov[:, None],
                                 torch.where(dropped[..., None, None], landing_cov[:, None], object_cov))
        # 4. The PoseNet's ego measurements, moved into the world frame with the estimated agent pose.
        ego_mean, ego_tril = ego_objects
        c, s = torch.cos(heading)[:, None, None], torch.sin(heading)[:, None, None]
        rotation = torch.cat([torch.cat([c, -s], -1), torch.cat([s, c], -1)], -2).unsqueeze(1)  # (B, 1, 2, 2)
        measured = agent[:, None] + (rotation @ ego_mean.unsqueeze(-1))[..., 0]
        jacobian = torch.stack([-s[..., 0] * ego_mean[..., 0] - c[..., 0] * ego_mean[..., 1],
                                c[..., 0] * ego_mean[..., 0] - s[..., 0] * ego_mean[..., 1]], -1)  # d measured / d heading
        ego_cov = ego_tril @ ego_tril.transpose(-1, -2)
        own, common = self.tracking.noise_own, self.tracking.noise_shared
        if (own, common) != (1.0, 1.0):
            multiplier = torch.full_like(ego_cov[..., 0, 0], own)
            if shared is not None:
                multiplier = torch.where(shared, common, multiplier)
            ego_cov = ego_cov * multiplier[..., None, None]
        noise = (scale[2] * rotation @ ego_cov @ rotation.transpose(-1, -2) + agent_cov[:, None]
                 + heading_var[:, None, None, None] * outer(jacobian))
        weight = (~is_held).to(objects.dtype) if visibility is None else visibility * ~is_held
        if self.tracking.data_association:
            weight = associate(weight, measured, noise, objects, object_cov)
        objects, object_cov = _kalman(objects, object_cov, measured, noise, weight, gate=self.tracking.gate,
                                      spread=self.tracking.data_association)
        # 5. What the frame did not see (``mor.lnet.unseen``).
        if self.tracking.negative_information and visibility is not None:
            objects, object_cov = not_seen_update(objects, object_cov, agent, heading, (1.0 - visibility) * ~is_held)
        return agent, agent_cov, heading, heading_var, objects, object_cov, held
