"""Building the environments each policy trains and is evaluated on, from the profile's ``SimConfig``."""

from __future__ import annotations

from typing import TYPE_CHECKING

import gymnasium as gym
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv

from mor.errors import ConfigError
from mor.policy.hierarchy import HierarchicalRearrange, Skill
from mor.policy.names import BaselineVariant, Task, Variant
from mor.policy.observations import GroundTruthTracker, PoseObservation, SingleTracker, has_uncertainty
from mor.policy.params import PPOParams
from mor.sim.config import SimConfig

if TYPE_CHECKING:
    from mor.lnet.runtime import LNetRunner

ENV_IDS: dict[Task, str] = {"pick": "MOR/Pick-v0", "drop": "MOR/Drop-v0", "decision": "MOR/Rearrange-v0"}


def make_task_env(task: Task, sim: SimConfig, render_frames: bool, **kwargs: object) -> gym.Env:
    """The MOR environment of ``task`` (decision: the full task), with or without first-person frames; ConfigError
    naming the policy tasks for any other ``task``."""
    if task not in ENV_IDS:
        raise ConfigError(f"task: {task!r} is not a policy's task; choose one of {', '.join(ENV_IDS)} "
                          f"(decision plays the full rearrangement)")
    return gym.make(ENV_IDS[task], render_frames=render_frames, **sim.model_dump(), **kwargs).unwrapped


def make_policy_env(
    task: Task, sim: SimConfig, tracker: SingleTracker, uncertainty: bool, skills: tuple[Skill, Skill] | None = None,
    **env_kwargs: object,
) -> gym.Env:
    """One environment with the policy's observation vector: a ``PoseObservation`` of Pick/Drop, or, for the
    decision, the ``HierarchicalRearrange`` semi-MDP over the frozen ``skills`` (pick, drop). Frames are rendered
    only when the tracker reads them (never for the ground truth); ``env_kwargs`` go to the MOR env."""
    env = make_task_env(task, sim, not isinstance(tracker, GroundTruthTracker), **env_kwargs)
    if task == "decision":
        if skills is None:
            raise ValueError("the decision policy's environment needs the trained pick and drop skills")
        return HierarchicalRearrange(env, tracker.batch, *skills, uncertainty)
    return PoseObservation(env, tracker, uncertainty)


def make_training_env(
    task: Task, variant: Variant, sim: SimConfig, params: PPOParams, runner: LNetRunner | None = None,
    skills: tuple[Skill, Skill] | None = None,
) -> VecEnv:
    """``params.n_envs`` environments of ``task`` with ``variant``'s observation vector, for SB3.

    gt_pose: ``PoseObservation`` envs without rendering. L-Net variants: for Pick/Drop rendered envs under
    ``LNetVecObservation``, one batched L-Net forward per vector step in this process; for the decision each env
    tracks its own belief (decisions last different numbers of steps) in this process. The envs run in this process
    (``vec_env: dummy``) or one process each (``subproc``; not for the L-Net decision, whose tracker holds the model).
    """
    from mor.policy.lnet_tracking import LNetTracker, LNetVecObservation  # noqa: PLC0415 - torch only for L-Net

    uncertainty = has_uncertainty(variant)
    vec_env = SubprocVecEnv if params.vec_env == "subproc" else DummyVecEnv
    if variant == "gt_pose":
        return vec_env([lambda: make_policy_env(task, sim, GroundTruthTracker(), uncertainty, skills)] * params.n_envs)
    if runner is None:
        raise ValueError(f"variant {variant!r} needs the trained L-Net (runner)")
    if task == "decision":
        return DummyVecEnv([lambda: make_policy_env(task, sim, LNetTracker(runner), uncertainty, skills)]
                           * params.n_envs)
    raw = vec_env([lambda: make_task_env(task, sim, render_frames=True)] * params.n_envs)
    return LNetVecObservation(raw, runner, task, sim.n_objects, uncertainty)


def baseline_sim(variant: BaselineVariant, sim: SimConfig) -> SimConfig:
    """The world a baseline plays in: ``baseline_landmark`` shows a marker at each drop target."""
    return sim.model_copy(update={"landmark": True}) if variant == "baseline_landmark" else sim


def make_baseline_training_env(task: Task, variant: BaselineVariant, sim: SimConfig, params: PPOParams) -> VecEnv:
    """``params.n_envs`` rendered Pick or Drop envs seen through ``BaselineObservation``, for SB3."""
    from mor.policy.baselines import BASELINE_INPUTS, BaselineObservation  # noqa: PLC0415 - torch only here

    world = baseline_sim(variant, sim)
    vec_env = SubprocVecEnv if params.vec_env == "subproc" else DummyVecEnv
    return vec_env([lambda: BaselineObservation(make_task_env(task, world, render_frames=True),
                                                BASELINE_INPUTS[variant])] * params.n_envs)
