"""The L-Net as the policies' pose source: per environment (``LNetTracker``, batch 1) and over a vector of
environments (``LNetVecObservation``, one forward pass per vector step)."""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from mor.lnet.runtime import Estimates, LNetRunner
from mor.policy.belief import PoseBelief
from mor.policy.features import observation_vector
from mor.policy.names import Task
from mor.policy.observations import SingleTracker, observation_space, task_goal

NO_ACTION = -1  # the "previous action" of an episode's first frame


def belief_from_estimates(estimates: Estimates) -> PoseBelief:
    """The L-Net's calibrated estimates as a belief; the heading's variance is 1/κ of its von Mises."""
    return PoseBelief(estimates.agent_mean, estimates.agent_cov, estimates.heading,
                      (1.0 / np.maximum(estimates.heading_kappa, 1e-6)).astype(np.float32),
                      estimates.object_mean, estimates.object_cov)


def _step(runner: LNetRunner, observations: dict[str, np.ndarray], previous: np.ndarray, state: Any
          ) -> tuple[PoseBelief, Any]:
    """One forward pass over the stacked observations (N, ...) of N environments."""
    estimates, state = runner.step(observations["image"], observations["object_classes"],
                                   np.asarray(observations["held"]), previous, state)
    return belief_from_estimates(estimates), state


class LNetBatchTracker:
    """N environments' beliefs from the L-Net: one forward pass per ``observe`` (the ``BatchTracker`` protocol)."""

    needs_frames = True

    def __init__(self, runner: LNetRunner, n_envs: int) -> None:
        self.runner = runner
        self.state = runner.initial_state(n_envs)

    def observe(self, observations: list[dict[str, Any]], infos: list[dict[str, Any]], previous_actions: np.ndarray,
                starting: np.ndarray) -> PoseBelief:
        starting = np.asarray(starting, dtype=bool)
        stacked = {key: np.stack([np.asarray(o[key]) for o in observations]) for key in ("image", "object_classes",
                                                                                         "held")}
        previous = np.where(starting, NO_ACTION, np.asarray(previous_actions))
        belief, self.state = _step(self.runner, stacked, previous, self.runner.reset(self.state, starting))
        return belief


class LNetTracker(SingleTracker):
    """One environment's belief from the L-Net (the ``Tracker`` protocol of ``mor.policy.observations``)."""

    def __init__(self, runner: LNetRunner) -> None:
        super().__init__(LNetBatchTracker(runner, 1))


class LNetVecObservation(VecEnvWrapper):
    """A vector of rendered MOR envs (Pick or Drop) whose observations become the policy vector of the L-Net's
    belief: one L-Net forward per vector step (two when an episode ends: its last frame, then the next
    episode's first; ``info["terminal_observation"]`` is the last frame's vector, as SB3 expects)."""

    def __init__(self, venv: VecEnv, runner: LNetRunner, task: Task, n_objects: int, uncertainty: bool) -> None:
        super().__init__(venv, observation_space=observation_space(task, n_objects, uncertainty))
        self.runner, self.task, self.uncertainty = runner, task, uncertainty
        self.arena = venv.get_attr("arena")[0]
        self.state = runner.initial_state(venv.num_envs)
        self.actions = np.full(venv.num_envs, NO_ACTION)

    def reset(self) -> np.ndarray:
        observations = self.venv.reset()
        self.state = self.runner.initial_state(self.num_envs)
        belief, self.state = _step(self.runner, observations, np.full(self.num_envs, NO_ACTION), self.state)
        return self._vectors(belief, observations)

    def step_async(self, actions: np.ndarray) -> None:
        self.actions = np.asarray(actions)
        self.venv.step_async(actions)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        observations, rewards, dones, infos = self.venv.step_wait()
        if not dones.any():
            belief, self.state = _step(self.runner, observations, self.actions, self.state)
            return self._vectors(belief, observations), rewards, dones, infos
        done = np.flatnonzero(dones)
        last = {key: value.copy() for key, value in observations.items()}
        for index in done:
            for key, value in infos[index]["terminal_observation"].items():
                last[key][index] = value
        last_belief, last_state = _step(self.runner, last, self.actions, self.state)
        last_vectors = self._vectors(last_belief, last)
        for index in done:
            infos[index]["terminal_observation"] = last_vectors[index]
        first_belief, first_state = _step(self.runner, observations, np.where(dones, NO_ACTION, self.actions),
                                          self.runner.reset(last_state, dones.astype(bool)))
        self.state = self.runner.select(last_state, first_state, dones.astype(bool))
        vectors = np.where(dones[:, None], self._vectors(first_belief, observations), last_vectors)
        return vectors, rewards, dones, infos

    def _vectors(self, belief: PoseBelief, observations: dict[str, np.ndarray]) -> np.ndarray:
        goal = task_goal(observations, self.task)
        return observation_vector(belief, observations["held"], self.task, goal, self.uncertainty, self.arena)
