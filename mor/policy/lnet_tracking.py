"""The L-Net as the policies' pose source: per environment (``LNetTracker``, batch 1) and over a vector of
environments (``LNetVecObservation``, one forward pass per vector step), each through the streaming loop
(``mor.lnet.streaming.StreamingTracker``)."""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices

from mor.data.schema import NO_ACTION
from mor.lnet.runtime import LNetRunner
from mor.lnet.stated import Estimates
from mor.lnet.search import SearchMap
from mor.lnet.streaming import StreamingTracker, stack_frames
from mor.policy.belief import PoseBelief, SearchBelief
from mor.policy.features import ObservationLayout, feature_names, observation_vector
from mor.policy.names import Task
from mor.policy.observations import SingleTracker, observation_space, task_goal
from mor.policy.pick_gate import PickGate
from mor.sim.arena import Arena


def belief_from_estimates(estimates: Estimates, search: SearchMap | None = None) -> PoseBelief:
    """The L-Net's calibrated estimates as a belief; the heading's variance is 1/κ of its von Mises. With the
    stream's ``search`` map (its estimates carry the search density), the search belief too."""
    searched = None
    if search is not None and estimates.search_density is not None:
        searched = SearchBelief(estimates.search_density, search.grid, search.cell_area,
                                estimates.object_searching.any(axis=1))
    return PoseBelief(estimates.agent_mean, estimates.agent_cov, estimates.heading,
                      (1.0 / np.maximum(estimates.heading_kappa, 1e-6)).astype(np.float32),
                      estimates.object_mean, estimates.object_cov,
                      object_found=(~estimates.object_searching).astype(np.float32),
                      object_lost=estimates.object_lost.astype(np.float32), object_visible=estimates.object_visible,
                      search=searched)


class LNetBatchTracker:
    """N environments' beliefs from the L-Net: one forward pass per ``observe`` (the ``BatchTracker`` protocol).
    With ``arena`` it keeps the search belief's looks, and its beliefs carry the search belief (``PoseBelief.search``;
    None without looks, or where the calibration fitted no search belief)."""

    needs_frames = True

    def __init__(self, runner: LNetRunner, n_envs: int, arena: Arena | None = None) -> None:
        self.stream = StreamingTracker(runner, n_envs, arena)  # arena: also the search belief's looks

    def observe(self, observations: list[dict[str, Any]], infos: list[dict[str, Any]], previous_actions: np.ndarray,
                starting: np.ndarray) -> PoseBelief:
        estimates = self.stream.step(stack_frames(observations), previous_actions, starting)
        return belief_from_estimates(estimates, self.stream.search)


class LNetTracker(SingleTracker):
    """One environment's belief from the L-Net (the ``Tracker`` protocol of ``mor.policy.observations``)."""

    def __init__(self, runner: LNetRunner, arena: Arena | None = None) -> None:
        super().__init__(LNetBatchTracker(runner, 1, arena))


class LNetVecObservation(VecEnvWrapper):
    """A vector of rendered MOR envs (Pick or Drop) whose observations become the policy vector of the L-Net's
    belief: one L-Net forward per vector step. Where an episode was truncated (its horizon reached), a second
    forward tracks its last frame too, and ``info["terminal_observation"]`` is that frame's vector: what SB3
    bootstraps the value from. Where it terminated (a PICK, a DROP, an obstruction), nothing bootstraps from its last
    state (SB3 reads ``terminal_observation`` only with ``TimeLimit.truncated``), so that frame is not tracked and
    the key is removed: one forward instead of two on most of a Pick run's vector steps (docs/performance.md).
    ``vectors``: the envs' current vectors, which the layout's PICK gate reads for ``action_masks``."""

    def __init__(self, venv: VecEnv, runner: LNetRunner, task: Task, n_objects: int, layout: ObservationLayout
                 ) -> None:
        super().__init__(venv, observation_space=observation_space(task, n_objects, layout))
        self.runner, self.task, self.layout = runner, task, layout
        self.gate = PickGate.of(feature_names(task, n_objects, layout), layout.pick_gate_probability(task))
        self.vectors = np.zeros((venv.num_envs, self.observation_space.shape[0]), np.float32)
        self.arena = venv.get_attr("arena")[0]
        self.stream = self._stream()
        self.actions = np.full(venv.num_envs, NO_ACTION)

    def reset(self) -> np.ndarray:
        observations = self.venv.reset()
        self.stream = self._stream()
        starting = np.ones(self.num_envs, dtype=bool)
        self.vectors = self._vectors(self.stream.step(observations, self.actions, starting), observations)
        return self.vectors

    def step_async(self, actions: np.ndarray) -> None:
        self.actions = np.asarray(actions)
        self.venv.step_async(actions)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        observations, rewards, dones, infos = self.venv.step_wait()
        ended = np.asarray(dones, dtype=bool)
        truncated = ended & np.array([bool(info.get("TimeLimit.truncated", False)) for info in infos])
        for index in np.flatnonzero(ended & ~truncated):
            del infos[index]["terminal_observation"]
        if not truncated.any():
            self.vectors = self._vectors(self.stream.step(observations, self.actions, ended), observations)
            return self.vectors, rewards, dones, infos
        last = {key: value.copy() for key, value in observations.items()}
        for index in np.flatnonzero(truncated):
            for key, value in infos[index]["terminal_observation"].items():
                last[key][index] = value
        now, last_estimates = self.stream.step_across_ends(last, observations, self.actions, ended)
        last_vectors = self._vectors(last_estimates, last)
        for index in np.flatnonzero(truncated):
            infos[index]["terminal_observation"] = last_vectors[index]
        self.vectors = self._vectors(now, observations)
        return self.vectors, rewards, dones, infos

    def _stream(self) -> StreamingTracker:
        return StreamingTracker(self.runner, self.num_envs, self.arena if self.layout.search else None)

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        """The envs' ``method_name``; ``action_masks`` less PICK where the layout's PICK gate forbids it (from each
        env's latest vector: what MaskablePPO asks before it acts)."""
        found = self.venv.env_method(method_name, *method_args, indices=indices, **method_kwargs)
        if method_name != "action_masks" or self.gate is None:
            return found
        rows = self._get_indices(indices)
        return list(self.gate.mask(self.vectors[list(rows)], np.stack(found)))

    def _vectors(self, estimates: Estimates, observations: dict[str, np.ndarray]) -> np.ndarray:
        goal = task_goal(observations, self.task)
        return observation_vector(belief_from_estimates(estimates, self.stream.search), observations["held"],
                                  self.task, goal, self.layout, self.arena)
