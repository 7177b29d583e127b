"""Gymnasium wrappers that turn a MOR environment's observation into the policy's flat observation vector.

``PoseObservation(env, tracker, layout)`` works for any tracker with batch 1 (any Gymnasium or SB3 user
can train on it); ``mor.policy.vec_lnet.LNetVecObservation`` is the batched form for the L-Net, one forward per
vector step. Both build the vector with ``mor.policy.features.observation_vector`` from a ``PoseBelief``.
"""

from __future__ import annotations

from typing import Any, Protocol

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from mor.policy.belief import PoseBelief
from mor.policy.features import ObservationLayout, feature_names, observation_size, observation_vector
from mor.policy.pick_gate import PickGate
from mor.policy.names import Task
from mor.sim.tasks import DropEnv, PickEnv, RearrangeEnv



def task_of(env: gym.Env) -> Task:
    """The policy task a MOR environment trains: pick, drop, or (for the full task) decision."""
    base = env.unwrapped
    for cls, task in ((PickEnv, "pick"), (DropEnv, "drop"), (RearrangeEnv, "decision")):
        if isinstance(base, cls):
            return task
    raise TypeError(f"{type(base).__name__} is not a MOR task environment (MOR/Pick-v0, Drop-v0, Rearrange-v0)")


def task_goal(observation: dict[str, Any], task: Task) -> np.ndarray:
    """The goal as the paper gives it, from a MOR observation: pick () index, drop (2,), decision (n, 2)."""
    key = {"pick": "goal_object", "drop": "goal_position", "decision": "target_positions"}[task]
    return np.asarray(observation[key])


def observation_space(task: Task, n_objects: int, layout: ObservationLayout) -> spaces.Box:
    return spaces.Box(-np.inf, np.inf, (observation_size(task, n_objects, layout),), np.float32)


class BatchTracker(Protocol):
    """Keeps N environments' beliefs. ``observe`` after every step of all N (``starting`` marks the envs whose
    observation is an episode's first; ``previous_actions`` is -1 there) -> the belief of each (N)."""

    needs_frames: bool

    def observe(self, observations: list[dict[str, Any]], infos: list[dict[str, Any]], previous_actions: np.ndarray,
                starting: np.ndarray) -> PoseBelief: ...


class GroundTruthBatchTracker:
    """The simulator's truth from each env's ``info``: zero uncertainty, nothing rendered."""

    needs_frames = False

    def observe(self, observations: list[dict[str, Any]], infos: list[dict[str, Any]], previous_actions: np.ndarray,
                starting: np.ndarray) -> PoseBelief:
        return PoseBelief.from_truth(np.stack([i["agent_pose"] for i in infos]),
                                     np.stack([i["object_positions"] for i in infos]))


class RenderingTruthTracker(GroundTruthBatchTracker):
    """For the pixel-fed baselines: the frames are rendered; the truth it returns is not what they read
    (``mor.policy.baselines.baseline_inputs`` ignores the belief)."""

    needs_frames = True


class Tracker(Protocol):
    """Keeps one environment's belief: ``start`` at an episode's first observation, ``update`` after each step."""

    def start(self, observation: dict[str, Any], info: dict[str, Any]) -> PoseBelief: ...

    def update(self, observation: dict[str, Any], info: dict[str, Any], action: int) -> PoseBelief: ...


class SingleTracker:
    """One environment's ``Tracker`` over a ``BatchTracker`` of one."""

    def __init__(self, batch: BatchTracker) -> None:
        self.batch = batch

    def start(self, observation: dict[str, Any], info: dict[str, Any]) -> PoseBelief:
        return self.batch.observe([observation], [info], np.array([-1]), np.array([True]))

    def update(self, observation: dict[str, Any], info: dict[str, Any], action: int) -> PoseBelief:
        return self.batch.observe([observation], [info], np.array([action]), np.array([False]))


class GroundTruthTracker(SingleTracker):
    """The simulator's truth from ``info`` (the paper's "Policy w/ GT poses"): zero uncertainty."""

    def __init__(self) -> None:
        super().__init__(GroundTruthBatchTracker())


class PoseObservation(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """A MOR env whose observation is the flat policy vector (``mor.policy.features``) of a tracker's belief.

    observation_space: Box (D,) float32; ``action_masks()`` is the env's, less PICK where the layout's PICK gate
    forbids it; ``belief`` and ``vector``: the tracker's latest belief and its observation
    (``info`` stays the env's plain values); layout: what the vector holds (a variant's:
    ``ObservationLayout.of(variant, profile.policy.observation)``). Its constructor's arguments are recorded in
    ``spec``, so that ``spec.make()`` (Gymnasium's ``check_env``) builds it again.
    """

    def __init__(self, env: gym.Env, tracker: Tracker, layout: ObservationLayout) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, tracker=tracker, layout=layout)
        super().__init__(env)
        self.task: Task = task_of(env)
        self.tracker, self.layout = tracker, layout
        n_objects = env.unwrapped.config.n_objects
        self.observation_space = observation_space(self.task, n_objects, layout)
        self.gate = PickGate.of(feature_names(self.task, n_objects, layout), layout.pick_gate_probability(self.task))
        self.belief: PoseBelief | None = None
        self.vector: np.ndarray | None = None

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        observation, info = self.env.reset(**kwargs)
        self.belief = self.tracker.start(observation, info)
        return self._vector(observation), info

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.belief = self.tracker.update(observation, info, int(action))
        return self._vector(observation), reward, terminated, truncated, info

    def action_masks(self) -> np.ndarray:
        """(A,) the env's mask, with PICK cleared where the layout's PICK gate forbids it (``mor.policy.pick_gate``)."""
        mask = self.env.unwrapped.action_masks()
        return mask if self.gate is None else self.gate.mask(self.vector[None], mask[None])[0]

    def _vector(self, observation: dict[str, Any]) -> np.ndarray:
        goal = task_goal(observation, self.task)[None]
        self.vector = observation_vector(self.belief, np.array([observation["held"]]), self.task, goal, self.layout,
                                         self.env.unwrapped.arena)[0]
        return self.vector
