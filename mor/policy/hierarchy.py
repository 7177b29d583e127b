"""The hierarchy of paper section 4.2: frozen pick and drop skills chained by a decision policy (a semi-MDP).

One decision = "rearrange object i next": the pick skill runs with goal i until it takes PICK (or its 150-step
horizon runs out), then, if the agent holds an object, the drop skill runs towards that object's target until
it takes DROP. When the agent already holds an object at a decision (a blocked drop), only the drop skill runs.
The decision's reward is the sum of the full task's rewards (Eq. 2) over its primitive steps; the episode
ends as the full task does (all placed, an obstruction, or 1,000 primitive steps). docs/assumptions.md,
"Policies", says why.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces

from mor.policy.belief import PoseBelief
from mor.policy.features import Encode, observation_vector, pose_inputs
from mor.policy.names import Task
from mor.policy.observations import Tracker, observation_space
from mor.sim.metrics import is_fixed
from mor.sim.rules import N_ACTIONS, Action
from mor.sim.tasks import DropEnv, PickEnv, RearrangeEnv

SKILL_HORIZON = 150  # primitive steps, the Pick and Drop tasks' horizon


def skill_mask(task: Task) -> np.ndarray:
    """(5,) bool: the actions a skill may take; the same action the Pick/Drop env removes is masked."""
    removed = {"pick": PickEnv.removed_action, "drop": DropEnv.removed_action}[task]
    mask = np.ones(N_ACTIONS, dtype=bool)
    mask[removed] = False
    return mask


POLICY_FILE = "policy.pth"  # a trained policy for inference: ``mor.policy.policy_file`` (weights + architecture)


class Skill:
    """A frozen policy from sb3-contrib's MaskablePPO (a trained ``MaskablePPO`` or its
    ``MaskableActorCriticPolicy``): ``act(vector (D,), mask (A,), rng) -> action``.

    deterministic: the most likely allowed action; otherwise an action drawn from the policy's distribution with
    the caller's generator (one per episode, seeded by the episode: the draws do not depend on batching).
    """

    def __init__(self, model: Any, deterministic: bool = True) -> None:
        self.policy = getattr(model, "policy", model)
        self.deterministic = deterministic

    @classmethod
    def load(cls, path: Path, deterministic: bool = True) -> Skill:
        """The policy saved at ``path`` (a ``policy.pth``), loaded without unpickling (``mor.policy.policy_file``)."""
        from mor.policy.policy_file import load_policy_file  # noqa: PLC0415 - SB3 only where a policy is loaded

        return cls(load_policy_file(path), deterministic)

    def act(self, vector: np.ndarray, mask: np.ndarray, rng: np.random.Generator | None = None) -> int:
        """vector (D,), mask (A,) -> one action."""
        return int(self.act_batch(vector[None], mask[None], None if rng is None else [rng])[0])

    def act_batch(self, vectors: np.ndarray, masks: np.ndarray, rngs: list[np.random.Generator] | None = None
                  ) -> np.ndarray:
        """vectors (k, D) (or a dict of (k, ...) arrays), masks (k, A) bool -> actions (k,): one forward pass."""
        observations, _ = self.policy.obs_to_tensor(vectors)
        with torch.no_grad():
            distribution = self.policy.get_distribution(observations, action_masks=masks)
        probabilities = distribution.distribution.probs.cpu().numpy().astype(np.float64)
        if self.deterministic or rngs is None:
            return probabilities.argmax(-1)
        return np.array([rng.choice(len(p), p=p / p.sum()) for p, rng in zip(probabilities, rngs, strict=True)])


def decision_mask(object_means: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(..., n) bool: the objects a decision may choose, those not believed (by their means) to lie at their
    targets already (the success rule of ``mor.sim.metrics``); every object when all are believed placed."""
    mask = ~is_fixed(object_means, targets)
    return np.where(mask.any(-1, keepdims=True), mask, True)


def nearest_unfixed(belief: PoseBelief, targets: np.ndarray) -> int:
    """The rule-based decision: of the objects ``decision_mask`` allows, the nearest to the agent (means)."""
    objects = belief.object_mean[0]
    distances = np.linalg.norm(objects - belief.agent_mean[0], axis=-1)
    return int(np.argmin(np.where(decision_mask(objects, targets), distances, np.inf)))


@dataclass
class SkillChain:
    """One environment's place in the hierarchy: which skill runs (``task``; None: a decision is due), on which
    object (``index``: pick's goal object, or drop's held object whose target it drives to), for how many steps."""

    task: Task | None = None
    index: int = -1
    steps: int = 0

    def decide(self, choice: int, held: int, n_objects: int) -> None:
        """Start decision ``choice``: pick that object, or, when one is already held, drop it."""
        self.task, self.index, self.steps = ("drop", held, 0) if held < n_objects else ("pick", choice, 0)

    def goal(self, targets: np.ndarray) -> np.ndarray:
        """The running skill's goal as its observation layout wants it: pick () index, drop (2,) position."""
        return np.asarray(self.index) if self.task == "pick" else targets[self.index]

    def advance(self, action: int, held: int, n_objects: int) -> bool:
        """After the skill took ``action`` (and the env stepped): move on; True when the decision is over."""
        self.steps += 1
        if self.task == "pick" and (action == Action.PICK or self.steps >= SKILL_HORIZON):
            if held < n_objects:
                self.task, self.index, self.steps = "drop", held, 0
                return False
            self.task = None
        elif self.task == "drop" and (action == Action.DROP or self.steps >= SKILL_HORIZON):
            self.task = None
        return self.task is None


class HierarchicalRearrange(gym.Env):
    """The decision policy's environment: ``MOR/Rearrange-v0`` seen one decision at a time.

    observation_space: Box (D,) the ``decision`` layout of ``mor.policy.features``; action_space: Discrete(n),
    the object to rearrange next. ``info`` carries the full task's ``metrics`` at the end and
    ``primitive_steps``, the environment steps this decision took. ``encode``: what the skills read (default: the
    pose policies' ``pose_inputs``; a baseline's ``mor.policy.baselines.baseline_inputs``).
    """

    metadata = {"render_modes": []}

    def __init__(self, env: gym.Env, tracker: Tracker, pick: Skill, drop: Skill, uncertainty: bool = True,
                 encode: Encode | None = None) -> None:
        if not isinstance(env.unwrapped, RearrangeEnv):
            raise TypeError(f"HierarchicalRearrange needs MOR/Rearrange-v0, got {type(env.unwrapped).__name__}")
        self.env, self.tracker, self.skills = env, tracker, {"pick": pick, "drop": drop}
        self.uncertainty = uncertainty
        self.encode = encode or pose_inputs(uncertainty)
        self.n_objects = env.unwrapped.config.n_objects
        self.observation_space = observation_space("decision", self.n_objects, uncertainty)
        self.action_space = spaces.Discrete(self.n_objects)
        self.chain = SkillChain()
        self.skill_rng = np.random.default_rng()
        self._observation: dict[str, Any] = {}
        self._info: dict[str, Any] = {}
        self.belief: PoseBelief | None = None
        self.on_step: Callable[[HierarchicalRearrange], None] | None = None  # e.g. a video recorder

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        if seed is not None:
            self.skill_rng = np.random.default_rng(seed)  # the skills' draws, as in mor.eval.lockstep
        self._observation, self._info = self.env.reset(seed=seed, options=options)
        self.belief = self.tracker.start(self._observation, self._info)
        self.chain = SkillChain()
        self._notify()
        return self._decision_vector(), self._info

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if isinstance(action, bool | np.bool_) or not self.action_space.contains(action):
            raise ValueError(f"decision {action!r} is not an object index in [0, {self.n_objects})")
        self.chain.decide(int(action), self.held, self.n_objects)
        total, steps = 0.0, 0
        while True:
            task = self.chain.task
            inputs = self.encode(task, [self._observation], [self._info], self.belief,
                                 self.chain.goal(self.targets)[None], self.env.unwrapped.arena)
            primitive = int(self.skills[task].act_batch(inputs, skill_mask(task)[None], [self.skill_rng])[0])
            self._observation, reward, terminated, truncated, self._info = self.env.step(primitive)
            self.belief = self.tracker.update(self._observation, self._info, primitive)
            self._notify()
            total, steps = total + float(reward), steps + 1
            if terminated or truncated or self.chain.advance(primitive, self.held, self.n_objects):
                info = {**self._info, "primitive_steps": steps}
                return self._decision_vector(), total, terminated, truncated, info

    def action_masks(self) -> np.ndarray:
        """(n,) bool: ``decision_mask`` of the current belief (objects believed placed are not chosen again)."""
        return decision_mask(self.belief.object_mean[0], self.targets)

    def close(self) -> None:
        self.env.close()

    @property
    def observation(self) -> dict[str, Any]:
        """The full task's latest raw observation (``image`` when the env renders frames)."""
        return self._observation

    @property
    def targets(self) -> np.ndarray:
        """(n, 2) every object's target position, metres (the full task's goal)."""
        return np.asarray(self._observation["target_positions"])

    @property
    def held(self) -> int:
        """The held object's index, n when none (the env's convention)."""
        return int(self._observation["held"])

    def _decision_vector(self) -> np.ndarray:
        """The decision's observation (D,) (the skills read ``encode``'s)."""
        return observation_vector(self.belief, np.array([self.held]), "decision", self.targets[None], self.uncertainty,
                                  self.env.unwrapped.arena)[0]

    def _notify(self) -> None:
        if self.on_step is not None:
            self.on_step(self)
