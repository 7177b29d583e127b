"""N episodes of Pick or Drop stepped together as arrays: the batched form of N ``PickEnv`` / ``DropEnv``.

Each slot keeps its own numpy Generator and draws from it what its env would, in the env's order: a seeded
reset makes the generator as Gymnasium does (``seeding.np_random``), a reset draws the layout
(``batch_layout.sample_layouts``) and then the goal object, and every MOVE or turn one standard normal. So slot i
with seed s plays, for the same actions, exactly the episodes of ``gym.make(...).reset(seed=s)`` followed by
unseeded resets: the same states, rewards, terminations and truncations. Rewards and verdicts are
``mor.sim.tasks``' own functions, the rules ``mor.sim.rules``'. No rendering: this is the ground-truth path.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding
from numpy.typing import NDArray

from mor.errors import ConfigError
from mor.sim.arena import Arena
from mor.sim.batch_layout import sample_layouts
from mor.sim.batch_world import NO_ACTION, NOISY_ACTIONS, WorldBatch, apply_actions
from mor.sim.config import SimConfig
from mor.sim.geometry import Array
from mor.sim.rules import N_ACTIONS, Action, MotionNoise
from mor.sim.tasks import DropEnv, PickEnv, drop_verdicts, pick_verdicts

BatchTask = Literal["pick", "drop"]
_ENVS: dict[str, type[PickEnv | DropEnv]] = {"pick": PickEnv, "drop": DropEnv}


@dataclass(frozen=True)
class StepBatch:
    """N steps' results, each (N,): reward float64, terminated, truncated, success (the episode's ``metrics``
    success on its last step)."""

    reward: NDArray[np.float64]
    terminated: NDArray[np.bool_]
    truncated: NDArray[np.bool_]
    success: NDArray[np.bool_]


class TaskBatch:
    """``n_envs`` episodes of ``task`` ("pick" or "drop") in the world ``sim`` (rendering fields unused), paid by
    ``sim.rewards``.

    State (after ``reset``): ``world`` (``WorldBatch``), ``goal`` (N,) the goal object, ``targets`` (N, n, 2) m,
    ``steps`` (N,) steps taken in the current episode. Slots whose episode has ended must be reset before they
    step again (``step`` does not reset them: their last state is the terminal observation's).
    """

    def __init__(self, task: BatchTask, n_envs: int, sim: SimConfig, horizon: int | None = None) -> None:
        if task not in _ENVS:
            raise ConfigError(f"task: {task!r} has no batched environment; choose pick or drop")
        if isinstance(n_envs, bool) or not isinstance(n_envs, int | np.integer) or n_envs < 1:
            raise ConfigError(f"n_envs: must be an int of at least 1 (got {n_envs!r})")
        if horizon is not None and int(horizon) < 1:
            raise ConfigError(f"horizon: must be at least 1 step (got {horizon!r})")
        self.task: BatchTask = task
        env_class = _ENVS[task]
        self.removed_action = env_class.removed_action
        self.horizon = int(horizon) if horizon is not None else env_class.default_horizon
        self.sim = sim
        self.n_envs, self.n_objects = int(n_envs), sim.n_objects
        self.arena = Arena.build(sim.arena, sim.arena_size)
        self.noise = MotionNoise()
        self.rngs: list[np.random.Generator | None] = [None] * self.n_envs
        n = self.n_objects
        self.world = WorldBatch(np.zeros((self.n_envs, 3)), np.zeros((self.n_envs, n, 2)),
                                np.full(self.n_envs, -1, dtype=np.int64))
        self.goal = np.zeros(self.n_envs, dtype=np.int64)
        self.targets = np.zeros((self.n_envs, n, 2))
        self.steps = np.zeros(self.n_envs, dtype=np.int64)
        masks = np.ones(N_ACTIONS, dtype=bool)
        masks[self.removed_action] = False
        self._masks = masks
        self._started = False  # every slot has been reset once

    def action_masks(self) -> NDArray[np.bool_]:
        """(N, 5) bool: False for the action this task removes (the same for every slot)."""
        return np.broadcast_to(self._masks, (self.n_envs, N_ACTIONS)).copy()

    def goal_positions(self) -> Array:
        """(N, 2) metres: Pick's goal object where it lies, Drop's target position."""
        rows = np.arange(self.n_envs)
        source = self.world.floor_positions if self.task == "pick" else self.targets
        return source[rows, self.goal]

    def reset(self, rows: NDArray[np.int64], seeds: Sequence[int | None] | None = None) -> None:
        """New episodes in slots ``rows`` (M,); ``seeds`` (M,): a seed makes the slot's generator anew, None
        continues it (a slot never seeded gets fresh entropy, as Gymnasium does)."""
        rows = np.asarray(rows, dtype=np.int64)
        if len(rows) == 0:
            return
        seeds = [None] * len(rows) if seeds is None else list(seeds)
        for row, seed in zip(rows, seeds, strict=True):
            if seed is not None or self.rngs[row] is None:
                self.rngs[row] = seeding.np_random(seed)[0]
        rngs = [self.rngs[row] for row in rows]
        layouts = sample_layouts(rngs, self.arena, self.n_objects, self.sim.texture_pool)
        goal = np.array([rng.integers(self.n_objects) for rng in rngs], dtype=np.int64)  # _begin_task
        pose, floor = layouts.agent_pose, layouts.initial_positions
        held = np.full(len(rows), -1, dtype=np.int64)
        if self.task == "drop":  # DropEnv._begin_task: start where the goal object lies, holding it
            held = goal
            pose[:, :2] = floor[np.arange(len(rows)), goal]
        self.world.agent_pose[rows], self.world.floor_positions[rows], self.world.held[rows] = pose, floor, held
        self.goal[rows], self.targets[rows], self.steps[rows] = goal, layouts.target_positions, 0

    def check_actions(self, actions: object) -> NDArray[np.int64]:
        """``actions`` as an (N,) int64 array; ValueError in one line unless it is N integers (not bools) in [0, 5)."""
        array = np.asarray(actions)
        if array.shape != (self.n_envs,) or not np.issubdtype(array.dtype, np.integer) or (
                array.size and (array.min() < 0 or array.max() >= N_ACTIONS)):
            names = ", ".join(f"{a.value}={a.name}" for a in Action)
            raise ValueError(f"actions: expected {self.n_envs} integer actions in [0, {N_ACTIONS}) of shape "
                             f"({self.n_envs},) ({names}); got dtype {array.dtype}, shape {array.shape}")
        return array.astype(np.int64, copy=False)

    def step(self, actions: NDArray[np.int64]) -> StepBatch:
        """One step of every slot: actions (N,) int in [0, 5) (a removed action is a no-op step, as in the env)."""
        actions = self.check_actions(actions)
        if not self._started:
            if any(rng is None for rng in self.rngs):
                raise ResetNeeded("call reset() on every slot before step()")
            self._started = True
        rows = np.arange(self.n_envs)
        noisy = np.flatnonzero(np.any(actions[:, None] == NOISY_ACTIONS, axis=1))
        standard = np.zeros(self.n_envs)
        standard[noisy] = [self.rngs[row].standard_normal() for row in noisy.tolist()]
        before = self.world.agent_pose[:, :2].copy()
        goal_position = self.goal_positions()  # before the step (Pick: where the goal object lay)
        applied = np.where(actions == self.removed_action, NO_ACTION, actions)
        events = apply_actions(self.world, applied, self.arena, self.noise, standard)
        after = self.world.agent_pose[:, :2]
        if self.task == "pick":
            reward, terminated, success = pick_verdicts(before, after, goal_position, self.goal, actions,
                                                        events.picked, events.obstructed, self.sim.rewards)
        else:
            landed = self.world.floor_positions[rows, self.goal]
            reward, terminated, success = drop_verdicts(before, after, goal_position, self.goal, actions,
                                                        events.dropped, landed, events.obstructed, self.sim.rewards)
        self.steps += 1
        truncated = ~terminated & (self.steps >= self.horizon)
        return StepBatch(reward, terminated, truncated, success)

