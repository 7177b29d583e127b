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
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from mor.policy.belief import PoseBelief
from mor.policy.features import Task, observation_vector
from mor.policy.observations import Tracker, observation_space
from mor.sim.rules import N_ACTIONS, Action
from mor.sim.tasks import DropEnv, PickEnv, RearrangeEnv

SKILL_HORIZON = 150  # primitive steps, the Pick and Drop tasks' horizon


def skill_mask(task: Task) -> np.ndarray:
    """(5,) bool: the actions a skill may take; the same action the Pick/Drop env removes is masked."""
    removed = {"pick": PickEnv.removed_action, "drop": DropEnv.removed_action}[task]
    mask = np.ones(N_ACTIONS, dtype=bool)
    mask[removed] = False
    return mask


class Skill:
    """A frozen sub-policy: ``act(vector (D,), mask (5,)) -> action`` from a saved sb3-contrib MaskablePPO."""

    def __init__(self, model: Any, deterministic: bool = True) -> None:
        self.model = model
        self.deterministic = deterministic

    @classmethod
    def load(cls, path: Path, deterministic: bool = True) -> Skill:
        from sb3_contrib import MaskablePPO  # noqa: PLC0415 - torch/SB3 load only where a model is used

        return cls(MaskablePPO.load(path, device="cpu"), deterministic)

    def act(self, vector: np.ndarray, mask: np.ndarray) -> int:
        action, _ = self.model.predict(vector, action_masks=mask, deterministic=self.deterministic)
        return int(action)


DecisionRule = Callable[[PoseBelief, np.ndarray], int]


def nearest_unfixed(belief: PoseBelief, targets: np.ndarray) -> int:
    """The rule-based decision: the nearest object (by the belief's means) not yet believed at its target."""
    from mor.sim.metrics import is_fixed  # noqa: PLC0415

    objects = belief.object_mean[0]
    candidates = np.flatnonzero(~is_fixed(objects, targets))
    if candidates.size == 0:
        candidates = np.arange(objects.shape[0])
    distances = np.linalg.norm(objects[candidates] - belief.agent_mean[0], axis=-1)
    return int(candidates[int(np.argmin(distances))])


class HierarchicalRearrange(gym.Env):
    """The decision policy's environment: ``MOR/Rearrange-v0`` seen one decision at a time.

    observation_space: Box (D,) the ``decision`` layout of ``mor.policy.features``; action_space: Discrete(n),
    the object to rearrange next. ``info`` carries the full task's ``metrics`` at the end and
    ``primitive_steps``, the environment steps this decision took.
    """

    metadata = {"render_modes": []}

    def __init__(self, env: gym.Env, tracker: Tracker, pick: Skill, drop: Skill, uncertainty: bool = True) -> None:
        if not isinstance(env.unwrapped, RearrangeEnv):
            raise TypeError(f"HierarchicalRearrange needs MOR/Rearrange-v0, got {type(env.unwrapped).__name__}")
        self.env, self.tracker, self.pick, self.drop = env, tracker, pick, drop
        self.uncertainty = uncertainty
        self.n_objects = env.unwrapped.config.n_objects
        self.observation_space = observation_space("decision", self.n_objects, uncertainty)
        self.action_space = spaces.Discrete(self.n_objects)
        self._observation: dict[str, Any] = {}
        self.belief: PoseBelief | None = None
        self.on_step: Callable[[HierarchicalRearrange], None] | None = None  # e.g. a video recorder

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self._observation, info = self.env.reset(seed=seed, options=options)
        self.belief = self.tracker.start(self._observation, info)
        self._notify()
        return self._vector(), info

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action) or isinstance(action, bool | np.bool_):
            raise ValueError(f"decision {action!r} is not an object index in [0, {self.n_objects})")
        total, steps, ended, info = 0.0, 0, False, {}
        if self._held() == self.n_objects:
            total, steps, ended, info = self._run_skill("pick", int(action))
        if not ended and self._held() < self.n_objects:
            reward, more, ended, info = self._run_skill("drop", self._held())
            total, steps = total + reward, steps + more
        terminated, truncated = info.get("terminated", False), info.get("truncated", False)
        return self._vector(), total, terminated, truncated, {**info, "primitive_steps": steps}

    def action_masks(self) -> np.ndarray:
        return np.ones(self.n_objects, dtype=bool)

    def close(self) -> None:
        self.env.close()

    @property
    def targets(self) -> np.ndarray:
        """(n, 2) every object's target position, metres (the full task's goal)."""
        return np.asarray(self._observation["target_positions"])

    # ---- helpers ---------------------------------------------------------------------------------------------
    def _held(self) -> int:
        return int(self._observation["held"])

    def _vector(self) -> np.ndarray:
        held = np.array([self._held()])
        return observation_vector(self.belief, held, "decision", self.targets[None], self.uncertainty)[0]

    def _run_skill(self, task: Task, index: int) -> tuple[float, int, bool, dict[str, Any]]:
        """Run a skill on object ``index`` (pick: that object; drop: towards its target) until it acts or ends."""
        skill, mask = (self.pick, skill_mask("pick")) if task == "pick" else (self.drop, skill_mask("drop"))
        final_action = Action.PICK if task == "pick" else Action.DROP
        total, info = 0.0, {}
        for step in range(1, SKILL_HORIZON + 1):
            goal = index if task == "pick" else self.targets[index]
            vector = observation_vector(self.belief, np.array([self._held()]), task, np.asarray(goal)[None],
                                        self.uncertainty)[0]
            action = skill.act(vector, mask)
            self._observation, reward, terminated, truncated, info = self.env.step(action)
            self.belief = self.tracker.update(self._observation, info, action)
            self._notify()
            total += float(reward)
            if terminated or truncated:
                return total, step, True, {**info, "terminated": terminated, "truncated": truncated}
            if action == final_action:
                break
        return total, step, False, info

    def _notify(self) -> None:
        if self.on_step is not None:
            self.on_step(self)
