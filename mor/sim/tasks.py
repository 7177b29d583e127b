"""The three tasks of paper section 3.2 with their rewards (Eq. 1, Eq. 2) and termination rules."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from mor.sim import metrics
from mor.sim.config import RewardParams
from mor.sim.env import MOREnv, StepOutcome
from mor.sim.geometry import vector_norm
from mor.sim.rules import Action, Events, WorldState

#: (reward, terminated, success): one step's verdict, or N steps' as (N,) arrays
Verdicts = tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]


def progress_reward(before: ArrayLike, after: ArrayLike, goal: ArrayLike, success: ArrayLike,
                    obstructed: ArrayLike, rewards: RewardParams) -> NDArray[np.float64]:
    """Eq. 1: -(D_{t+1} - D_t) + s * [success] - c * [obstructed], D the agent-to-goal distance (metres), s and c
    ``rewards.success`` and ``rewards.collision`` (the paper's 10 and 1); agent positions ``before`` and ``after``
    the step and the goal (..., 2) metres, flags (...,) -> (...,)."""
    progress = vector_norm(np.subtract(before, goal)) - vector_norm(np.subtract(after, goal))
    return progress + rewards.success * np.asarray(success) - rewards.collision * np.asarray(obstructed)


def pick_verdicts(before: ArrayLike, after: ArrayLike, goal_position: ArrayLike, goal: ArrayLike, action: ArrayLike,
                  picked: ArrayLike, obstructed: ArrayLike, rewards: RewardParams) -> Verdicts:
    """Pick's verdict on N steps (or one): agent positions (..., 2) metres before and after, the goal object's
    position (..., 2) metres and index, the action, what PICK took (-1: nothing) and whether a MOVE was obstructed
    (...,); paid by ``progress_reward`` with ``rewards``."""
    success = np.equal(picked, goal)
    ended = np.equal(action, Action.PICK) | np.asarray(obstructed)
    return progress_reward(before, after, goal_position, success, obstructed, rewards), ended, success


def drop_verdicts(before: ArrayLike, after: ArrayLike, goal_position: ArrayLike, goal: ArrayLike, action: ArrayLike,
                  dropped: ArrayLike, landed: ArrayLike, obstructed: ArrayLike, rewards: RewardParams) -> Verdicts:
    """Drop's verdict on N steps (or one): as ``pick_verdicts`` with the target position, what DROP released
    (-1: nothing) and where the goal object lies on the floor after the step (..., 2) metres."""
    success = np.equal(dropped, goal) & metrics.is_fixed(landed, goal_position)
    ended = np.equal(action, Action.DROP) | np.asarray(obstructed)
    return progress_reward(before, after, goal_position, success, obstructed, rewards), ended, success


def _goal_position_space(half_extent: float, shape: tuple[int, ...]) -> spaces.Box:
    return spaces.Box(-half_extent, half_extent, shape, np.float32)


class PickEnv(MOREnv):
    """Pick(s_i^0): pick object ``goal_object``. Ends on any PICK, an obstruction, or after 150 steps.

    Reward (Eq. 1): -(D_{t+1} - D_t) + 10 * [picked the goal] - [obstructed], D = agent-to-goal-object distance;
    the weights are ``SimConfig.rewards`` (these are its defaults). DROP is removed (masked).
    """

    default_horizon = 150
    removed_action = Action.DROP

    def _goal_spaces(self, n: int, half_extent: float) -> dict[str, spaces.Space]:
        return {"goal_object": spaces.Discrete(n)}

    def _begin_task(self) -> None:
        self.goal_object = int(self.np_random.integers(self.config.n_objects))

    def _goal_observation(self) -> dict[str, np.ndarray | int]:
        return {"goal_object": self.goal_object}

    def _outcome(self, before: WorldState, events: Events) -> StepOutcome:
        reward, ended, success = pick_verdicts(
            before.agent_pose[:2], self.state.agent_pose[:2], before.floor_positions[self.goal_object],
            self.goal_object, events.action, events.picked, events.obstructed, self.config.rewards)
        return StepOutcome(float(reward), bool(ended), bool(success))


class DropEnv(MOREnv):
    """Drop(s_i^*): the agent starts where object ``held`` lay, holding it, and must drop it within 1 m of
    ``goal_position``. Ends on any DROP, an obstruction, or after 150 steps.

    Reward: as Eq. 1 with D = agent-to-target distance. PICK is removed (masked).
    """

    default_horizon = 150
    removed_action = Action.PICK

    def _goal_spaces(self, n: int, half_extent: float) -> dict[str, spaces.Space]:
        return {"goal_position": _goal_position_space(half_extent, (2,))}

    def _begin_task(self) -> None:
        self.goal_object = int(self.np_random.integers(self.config.n_objects))
        self.state.held = self.goal_object
        self.state.agent_pose[:2] = self.state.floor_positions[self.goal_object]

    @property
    def goal_position(self) -> np.ndarray:
        return self.layout.target_positions[self.goal_object]

    def _goal_observation(self) -> dict[str, np.ndarray | int]:
        return {"goal_position": self.goal_position.astype(np.float32)}

    def _landmarks(self) -> list[tuple[np.ndarray, int]]:
        return [(self.goal_position, int(self.layout.object_classes[self.goal_object]))]

    def _outcome(self, before: WorldState, events: Events) -> StepOutcome:
        reward, ended, success = drop_verdicts(
            before.agent_pose[:2], self.state.agent_pose[:2], self.goal_position, self.goal_object, events.action,
            events.dropped, self.state.floor_positions[self.goal_object], events.obstructed, self.config.rewards)
        return StepOutcome(float(reward), bool(ended), bool(success))


class RearrangeEnv(MOREnv):
    """The full task: move every object to within 1 m of its target. Ends when all are placed (nothing held),
    on an obstruction, or after 1000 steps.

    Reward (Eq. 2): -0.01 + 10 * (change in the number of objects lying at their targets) - [obstructed], the
    weights ``SimConfig.rewards`` (these are its defaults).
    Counting the change (rather than a one-off indicator) pays each placement once and takes it back if the
    object is picked up again, so the reward cannot be farmed (docs/assumptions.md).
    """

    default_horizon = 1000

    def _goal_spaces(self, n: int, half_extent: float) -> dict[str, spaces.Space]:
        return {"target_positions": _goal_position_space(half_extent, (n, 2))}

    def _goal_observation(self) -> dict[str, np.ndarray | int]:
        return {"target_positions": self.layout.target_positions.astype(np.float32)}

    def _landmarks(self) -> list[tuple[np.ndarray, int]]:
        return [(t, int(c)) for t, c in zip(self.layout.target_positions, self.layout.object_classes, strict=True)]

    def _begin_task(self) -> None:
        self._placed_count = self._placed()

    def _placed(self) -> int:
        """How many objects lie (not held) within the success radius of their targets."""
        fixed = metrics.is_fixed(self.state.floor_positions, self.layout.target_positions)
        return int(np.sum(fixed & self.state.on_floor()))

    def _outcome(self, before: WorldState, events: Events) -> StepOutcome:
        placed = self._placed()
        change, self._placed_count = placed - self._placed_count, placed
        success = placed == self.config.n_objects
        rewards = self.config.rewards
        reward = -rewards.step + rewards.success * change - rewards.collision * events.obstructed
        return StepOutcome(float(reward), success or events.obstructed, success)

    def _metrics(self, outcome: StepOutcome) -> dict[str, float]:
        positions, targets = self.state.object_positions(), self.layout.target_positions
        return {
            "success": metrics.rearrange_success(positions, targets),
            "fixed_strict": metrics.fixed_strict(positions, targets),
            "energy_remaining": metrics.energy_remaining(positions, targets, self.layout.initial_positions),
        }
