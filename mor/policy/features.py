"""The one observation layout of every policy variant: a flat float32 vector built from a ``PoseBelief``.

Layout, in order (n objects; "ego" = the agent's frame of the belief's mean pose, x forward, y left; a
"polar" triple is [distance m, cos bearing, sin bearing] of a point seen from the agent; an "uncertainty"
triple is [σ_forward m, σ_left m, correlation] of a covariance rotated into the ego frame):

- agent: x, y, cos θ, sin θ                                              4
- each object: x, y, polar                                               5 n
- held: one-hot over the n objects and "nothing"                         n + 1
- clearance: free distance along R rays (default -60..60 deg), m          R  (``mor.policy.clearance``)
- goal, by task:
    pick      one-hot goal object (n), polar of the goal object (3)
    drop      goal position x, y (2), polar of the goal position (3)
    decision  each object: target x, y, object-to-target distance, polar of the target   6 n
- uncertainty (left out where ``layout.uncertainty`` is False): the agent's triple and heading σ (4), each object's
  triple (3 n), and for pick the goal object's triple (3)
- the stated belief (only where ``layout.search``): each object's found flag and lost probability (2 n), for pick
  the goal object's (2), and the search belief's mass around the agent (``mor.policy.search_view``; S sectors x
  rings, default 8 x 2)
- the L-Net's detection (only pick, where ``layout.reads_visibility``): each object's probability of being in view
  on this frame (n) and the goal object's (1)

The rays and the sectors are ``policy.observation`` in ``params.yaml`` (``ObservationParams``); the layout of a
variant is ``ObservationLayout.of(variant, profile.policy.observation)``.

The egocentric polar features are computed from the same global belief (they tell the policy nothing new),
but without them PPO does not learn Pick (docs/assumptions.md, "Policies").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mor.policy.belief import PoseBelief
from mor.policy.clearance import clearance
from mor.policy.names import Task
from mor.policy.params import ObservationParams
from mor.policy.search_view import sector_count, sector_masses, sector_names
from mor.policy.variants import Variant
from mor.sim.arena import Arena


#: the ``ObservationParams`` fields that only a layout with the stated belief (``search``) reads
SEARCH_FIELDS: tuple[str, ...] = ("search_sectors", "search_ring_edges_m")
#: the ``ObservationParams`` fields that only a layout with the PICK gate (``gate``) reads; they mask an action and
#: change no feature, so a policy may warm-start from one trained without them
GATE_FIELDS: tuple[str, ...] = ("pick_gate_probability",)
#: the ``ObservationParams`` fields that only an L-Net variant's Pick layout (``visibility``) reads; they add
#: features under names of their own, so a policy may warm-start from one trained without them (zero weights)
VISIBILITY_FIELDS: tuple[str, ...] = ("pick_visibility",)


@dataclass(frozen=True)
class ObservationLayout:
    """What a pose policy's vector holds: the uncertainty entries or not, the stated belief's parts or not, and
    the derived features' settings (``features``: the free-space rays, the search sectors); ``gate``: its Pick skill
    reads the PICK gate (``mor.policy.pick_gate``; only the L-Net's beliefs with uncertainty); ``visibility``: its
    Pick skill reads the L-Net's detection where ``features.pick_visibility`` asks (only the L-Net's beliefs)."""

    uncertainty: bool = True
    search: bool = False
    features: ObservationParams = field(default_factory=ObservationParams)
    gate: bool = False
    visibility: bool = False

    @classmethod
    def of(cls, variant: Variant, features: ObservationParams) -> ObservationLayout:
        """``variant``'s layout with the profile's ``policy.observation`` settings."""
        return cls(variant.uncertainty, variant.search, features, variant.uses_lnet and variant.uncertainty,
                   variant.uses_lnet)

    def read_fields(self, task: Task) -> tuple[str, ...]:
        """The ``ObservationParams`` fields this layout's ``task`` policy reads (the gate's and the detection's only
        for pick)."""
        gated, detects = self.gate and task == "pick", self.visibility and task == "pick"
        return tuple(name for name in ObservationParams.model_fields
                     if (self.search or name not in SEARCH_FIELDS) and (gated or name not in GATE_FIELDS)
                     and (detects or name not in VISIBILITY_FIELDS))

    def reads_visibility(self, task: Task) -> bool:
        """Whether this layout's ``task`` vector holds the L-Net's detection (``features.pick_visibility``)."""
        return self.visibility and task == "pick" and self.features.pick_visibility

    def pick_gate_probability(self, task: Task) -> float:
        """The PICK gate's probability for this layout's ``task`` skill (0: no gate)."""
        return self.features.pick_gate_probability if self.gate and task == "pick" else 0.0

    def recorded_features(self, task: Task) -> ObservationParams:
        """``features`` as a ``task`` policy's signature records them: the fields it does not read at their
        defaults, so that a setting a policy never reads refuses none of its loads."""
        defaults = ObservationParams()
        unread = (name for name in ObservationParams.model_fields if name not in self.read_fields(task))
        return self.features.model_copy(update={name: getattr(defaults, name) for name in unread})


def feature_names(task: Task, n_objects: int, layout: ObservationLayout) -> list[str]:
    """The name of each entry of ``observation_vector``'s output, in order."""
    polar = ("distance", "cos_bearing", "sin_bearing")
    names = ["agent_x", "agent_y", "agent_cos", "agent_sin"]
    for i in range(n_objects):
        names += [f"object{i}_x", f"object{i}_y", *(f"object{i}_{p}" for p in polar)]
    names += [f"held_{i}" for i in range(n_objects)] + ["held_none"]
    names += [f"clearance_{round(ray):+d}deg" for ray in layout.features.clearance_rays_deg]
    if task == "pick":
        names += [f"goal_is_{i}" for i in range(n_objects)] + [f"goal_{p}" for p in polar]
    elif task == "drop":
        names += ["goal_x", "goal_y", *(f"goal_{p}" for p in polar)]
    else:
        for i in range(n_objects):
            names += [f"target{i}_x", f"target{i}_y", f"object{i}_to_target", *(f"target{i}_{p}" for p in polar)]
    if layout.uncertainty:
        triple = ("sigma_forward", "sigma_left", "correlation")
        names += [f"agent_{t}" for t in triple] + ["heading_sigma"]
        for i in range(n_objects):
            names += [f"object{i}_{t}" for t in triple]
        if task == "pick":
            names += [f"goal_{t}" for t in triple]
    if layout.search:
        names += [f"object{i}_{part}" for i in range(n_objects) for part in ("found", "lost")]
        names += ["goal_found", "goal_lost"] if task == "pick" else []
        names += sector_names(layout.features.search_sectors, layout.features.search_ring_edges_m)
    if layout.reads_visibility(task):
        names += [f"object{i}_visible" for i in range(n_objects)] + ["goal_visible"]
    return names


def observation_size(task: Task, n_objects: int, layout: ObservationLayout) -> int:
    return len(feature_names(task, n_objects, layout))


def _polar(belief: PoseBelief, points: NDArray) -> NDArray:
    """points (N, ..., 2) world -> (N, ..., 3) [distance, cos bearing, sin bearing] from each agent."""
    extra = points.ndim - 2
    agent = belief.agent_mean.reshape(belief.n_envs, *(1,) * extra, 2)
    theta = belief.heading.reshape(belief.n_envs, *(1,) * extra)
    delta = points - agent
    distance = np.linalg.norm(delta, axis=-1)
    bearing = np.arctan2(delta[..., 1], delta[..., 0]) - theta
    return np.stack([distance, np.cos(bearing), np.sin(bearing)], -1)


def _ego_uncertainty(covariance: NDArray, heading: NDArray) -> NDArray:
    """covariance (N, ..., 2, 2) world, heading (N,) -> (N, ..., 3) [σ_forward, σ_left, correlation] in ego."""
    if not covariance.any():  # the ground truth: no rotation needed (a third of a step's cost on the true poses)
        return np.zeros((*covariance.shape[:-2], 3), np.float32)
    c, s = np.cos(heading), np.sin(heading)
    rotation = np.stack([np.stack([c, s], -1), np.stack([-s, c], -1)], -2)  # world -> ego, (N, 2, 2)
    rotation = rotation.reshape(rotation.shape[0], *(1,) * (covariance.ndim - 3), 2, 2)
    ego = rotation @ covariance @ np.swapaxes(rotation, -1, -2)
    sigma = np.sqrt(np.maximum(np.stack([ego[..., 0, 0], ego[..., 1, 1]], -1), 0.0))
    correlation = ego[..., 0, 1] / np.maximum(sigma[..., 0] * sigma[..., 1], 1e-9)
    return np.concatenate([sigma, correlation[..., None]], -1)


def observation_vector(
    belief: PoseBelief, held: NDArray, task: Task, goal: NDArray, layout: ObservationLayout, arena: Arena,
) -> NDArray[np.float32]:
    """The flat observation (N, D) of ``feature_names(task, n, layout)`` in ``arena`` (its walls are known). A
    belief without stated parts (the truth's) states every object found, none lost, nothing searched.

    held (N,) index of the held object, n when none (the env's convention). goal by task: pick (N,) object
    index; drop (N, 2) target position, m; decision (N, n, 2) every object's target position, m.
    """
    n_envs, n = belief.n_envs, belief.n_objects
    rows = np.arange(n_envs)
    index = np.asarray(goal, int).reshape(n_envs) if task == "pick" else None  # the goal object's, (N,)
    parts = [belief.agent_mean, np.cos(belief.heading)[:, None], np.sin(belief.heading)[:, None],
             np.concatenate([belief.object_mean, _polar(belief, belief.object_mean)], -1).reshape(n_envs, -1),
             np.eye(n + 1, dtype=np.float32)[np.asarray(held, int)],
             clearance(belief, held, arena, layout.features.clearance_rays_deg, layout.features.clearance_max_m)]
    if task == "pick":
        parts += [np.eye(n, dtype=np.float32)[index], _polar(belief, belief.object_mean[rows, index])]
    elif task == "drop":
        position = np.asarray(goal, np.float32).reshape(n_envs, 2)
        parts += [position, _polar(belief, position)]
    else:
        targets = np.asarray(goal, np.float32).reshape(n_envs, n, 2)
        to_target = np.linalg.norm(belief.object_mean - targets, axis=-1)[..., None]
        parts.append(np.concatenate([targets, to_target, _polar(belief, targets)], -1).reshape(n_envs, -1))
    if layout.uncertainty:
        heading_sigma = np.sqrt(np.maximum(belief.heading_var, 0.0))[:, None]
        objects = _ego_uncertainty(belief.object_cov, belief.heading)
        parts += [_ego_uncertainty(belief.agent_cov, belief.heading), heading_sigma, objects.reshape(n_envs, -1)]
        if task == "pick":
            parts.append(objects[rows, index])
    if layout.search:
        parts += _stated(belief, task, goal, layout.features)
    if layout.reads_visibility(task):
        if belief.object_visible is None:
            raise ValueError("policy.observation.pick_visibility: this belief has no detection; the L-Net needs its "
                             "visibility head (lnet.model.visibility: true), or set pick_visibility: false")
        parts += [belief.object_visible, belief.object_visible[rows, index]]
    return np.concatenate([np.asarray(p, np.float32).reshape(n_envs, -1) for p in parts], -1)


def _stated(belief: PoseBelief, task: Task, goal: NDArray, features: ObservationParams) -> list[NDArray]:
    """The stated belief's features: (found, lost) per object, the goal's for pick, and the search sectors."""
    n_envs, n = belief.n_envs, belief.n_objects
    found = np.ones((n_envs, n), np.float32) if belief.object_found is None else belief.object_found
    lost = np.zeros((n_envs, n), np.float32) if belief.object_lost is None else belief.object_lost
    pairs = np.stack([found, lost], -1)                                                  # (N, n, 2)
    sectors = (np.zeros((n_envs, sector_count(features.search_sectors, features.search_ring_edges_m)), np.float32)
               if belief.search is None else sector_masses(belief.search, belief.agent_mean, belief.heading,
                                                           features.search_sectors, features.search_ring_edges_m))
    goal_pair = [pairs[np.arange(n_envs), np.asarray(goal, int).reshape(n_envs)]] if task == "pick" else []
    return [pairs.reshape(n_envs, -1), *goal_pair, sectors]


#: (skill task, the k envs' MOR observations, their infos, their beliefs, goals (k, ...), arena) -> the skill's
#: batched input: the pose policies' vectors (k, D) (``pose_inputs``) or a baseline's dict of (k, ...) arrays
#: (``mor.policy.baselines.baseline_inputs``)
Encode = Callable[[Task, list[dict[str, Any]], list[dict[str, Any]], PoseBelief, np.ndarray, Arena],
                  np.ndarray | dict[str, np.ndarray]]


def pose_inputs(layout: ObservationLayout) -> Encode:
    """The pose policies' encoding: ``observation_vector`` of the beliefs in ``layout``."""
    def encode(task: Task, observations: list[dict[str, Any]], infos: list[dict[str, Any]], belief: PoseBelief,
               goals: np.ndarray, arena: Arena) -> np.ndarray:
        held = np.array([o["held"] for o in observations])
        return observation_vector(belief, held, task, goals, layout, arena)

    return encode
