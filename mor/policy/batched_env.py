"""The ground-truth training path as one SB3 ``VecEnv`` of N Pick or Drop episodes stepped as arrays.

``BatchedPoseVecEnv(task, sim, n_envs, layout)`` gives what ``DummyVecEnv`` of N ``PoseObservation(env,
GroundTruthTracker(), layout)`` gives for the same seeds (``seed()``: slot i gets seed + i) and actions: the same
observation vectors (``mor.policy.features``, one batched call for all N), rewards, dones and action masks, step by
step; the world is ``mor.sim.batch_tasks.TaskBatch``. sb3-contrib's MaskablePPO uses it unchanged: its
``env_method("action_masks")`` answers with one (N, 5) array.

``info`` is kept to what training reads: ``{}`` while an episode runs; on its last step ``metrics`` (``success``),
``terminal_observation`` (D,), ``TimeLimit.truncated`` and ``episode`` (``r`` return, ``l`` length, ``t`` seconds
since the env was made, as SB3's Monitor writes it). ``reset_infos`` are empty.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnvIndices,
    VecEnvStepReturn,
)

from mor.errors import ConfigError
from mor.policy.belief import PoseBelief
from mor.policy.features import ObservationLayout, observation_vector
from mor.policy.names import Task
from mor.policy.observations import observation_space
from mor.sim.batch_tasks import TaskBatch
from mor.sim.config import SimConfig
from mor.sim.rules import N_ACTIONS

#: the tasks that have a batched environment (the decision's semi-MDP runs frozen skills: not batched here)
BATCHED_TASKS: tuple[Task, ...] = ("pick", "drop")
#: the VecEnv methods that ``env_method`` answers (batched, one array for all the indices)
BATCHED_METHODS: tuple[str, ...] = ("action_masks",)


class BatchedPoseVecEnv(VecEnv):
    """``n_envs`` Pick or Drop episodes of ``sim``'s world observed through the ground truth in ``layout`` (the
    truth's variant's, with or without its zero uncertainty entries); see the module docstring.

    observation (N, D) float32, ``feature_names(task, n, layout)``; reward (N,) float32; done (N,) bool.
    """

    def __init__(self, task: Task, sim: SimConfig, n_envs: int, layout: ObservationLayout,
                 horizon: int | None = None) -> None:
        if task not in BATCHED_TASKS:
            raise ConfigError(f"task: {task!r} has no batched environment; choose pick or drop "
                              f"(vec_env: batched is for the ground truth's Pick and Drop)")
        self.batch = TaskBatch(task, n_envs, sim, horizon)
        self.task, self.layout = task, layout
        self.render_mode = None  # read by VecEnv.__init__ through get_attr
        super().__init__(self.batch.n_envs, observation_space(task, sim.n_objects, layout),
                         spaces.Discrete(N_ACTIONS))
        self._returns = np.zeros(self.num_envs)
        self._actions: NDArray[np.int64] | None = None
        self._made = time.monotonic()

    # ---- the VecEnv API --------------------------------------------------------------------------------------
    def reset(self) -> NDArray[np.float32]:
        """Every slot starts a new episode, with the seeds of ``seed()`` if given (then forgotten)."""
        if any(self._options):
            raise ConfigError("reset options: BatchedPoseVecEnv accepts none (the layout comes from the seed and "
                              "the env's parameters)")
        rows = np.arange(self.num_envs)
        self.batch.reset(rows, self._seeds)
        self._reset_seeds()
        self._reset_options()
        self._returns[:] = 0.0
        self.reset_infos = [{} for _ in rows]
        return self._observe(rows)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = self.batch.check_actions(actions)

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async(actions)")
        result = self.batch.step(self._actions)
        self._actions = None
        self._returns += result.reward
        done = result.terminated | result.truncated
        ended = np.flatnonzero(done)
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if len(ended):
            terminal = self._inputs(ended)  # the last state, before the slot starts again
            lengths, returns = self.batch.steps[ended].copy(), self._returns[ended].copy()
            self.batch.reset(ended)
            self._returns[ended] = 0.0
            everyone = self._inputs(np.arange(self.num_envs))
            vectors = self._vectors(*(np.concatenate(pair) for pair in zip(everyone, terminal, strict=True)))
            observations, terminal_vectors = vectors[: self.num_envs], vectors[self.num_envs:]
            seconds = round(time.monotonic() - self._made, 6)
            for k, row in enumerate(ended):
                infos[row] = {"metrics": {"success": float(result.success[row])},
                              "terminal_observation": terminal_vectors[k],
                              "TimeLimit.truncated": bool(result.truncated[row]),
                              "episode": {"r": round(float(returns[k]), 6), "l": int(lengths[k]), "t": seconds}}
        else:
            observations = self._observe(np.arange(self.num_envs))
        return observations, result.reward.astype(np.float32), done, infos

    def action_masks(self) -> NDArray[np.bool_]:
        """(N, 5) bool: the actions each slot may take (MaskablePPO's ``get_action_masks`` stacks this)."""
        return self.batch.action_masks()

    def close(self) -> None:
        """Nothing to release (no renderer, no processes)."""

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """This env's attribute ``attr_name`` once per index (the N slots share their attributes)."""
        value = getattr(self, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(f"BatchedPoseVecEnv: set_attr({attr_name!r}) is not supported: its N episodes share "
                             f"one set of attributes")

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> Sequence[Any]:
        """``action_masks``: a (k, 5) array for the k ``indices`` (what ``np.stack`` of k masks would give)."""
        if method_name not in BATCHED_METHODS:
            raise AttributeError(f"BatchedPoseVecEnv: env_method({method_name!r}) is not available; the batched "
                                 f"env answers {', '.join(BATCHED_METHODS)}")
        return self.action_masks()[list(self._get_indices(indices))]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    # ---- observations ----------------------------------------------------------------------------------------
    def _inputs(self, rows: NDArray[np.int64]) -> tuple[np.ndarray, ...]:
        """What the observation of slots ``rows`` (M,) is made of: agent poses (M, 3), object positions (M, n, 2),
        held (M,) (n when none, the env's convention) and the goal (pick (M,) index, drop (M, 2) float32)."""
        world, n = self.batch.world, self.batch.n_objects
        held = world.held[rows]
        goal = self.batch.goal[rows] if self.task == "pick" else self.batch.goal_positions()[rows].astype(np.float32)
        return world.agent_pose[rows], world.object_positions()[rows], np.where(held >= 0, held, n), goal

    def _vectors(self, poses: np.ndarray, objects: np.ndarray, held: np.ndarray,
                 goal: np.ndarray) -> NDArray[np.float32]:
        return observation_vector(PoseBelief.from_truth(poses, objects), held, self.task, goal, self.layout,
                                  self.batch.arena)

    def _observe(self, rows: NDArray[np.int64]) -> NDArray[np.float32]:
        return self._vectors(*self._inputs(rows))
