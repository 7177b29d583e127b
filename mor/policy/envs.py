"""Building the environments each policy trains and is evaluated on, from the profile's ``SimConfig``."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import gymnasium as gym
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv

from mor.errors import ConfigError
from mor.policy.batched_env import BATCHED_TASKS, BatchedPoseVecEnv
from mor.policy.features import ObservationLayout
from mor.policy.grouped_env import GroupedSubprocVecEnv
from mor.policy.hierarchy import HierarchicalRearrange, Skill
from mor.policy.names import PLAYS, Task, WorldTask
from mor.policy.observations import GroundTruthTracker, PoseObservation, SingleTracker
from mor.policy.params import ObservationParams, PPOParams
from mor.policy.variants import Variant
from mor.sim.arena import Arena
from mor.sim.config import SimConfig

if TYPE_CHECKING:
    from mor.lnet.runtime import LNetRunner

ENV_IDS: dict[WorldTask, str] = {"pick": "MOR/Pick-v0", "drop": "MOR/Drop-v0", "rearrange": "MOR/Rearrange-v0"}


def make_task_env(task: WorldTask, sim: SimConfig, render_frames: bool, **kwargs: object) -> gym.Env:
    """The MOR environment of the world's ``task``, with or without first-person frames; ConfigError naming the tasks
    for any other ``task`` (a policy's name: ``PLAYS`` says which task it plays)."""
    if task not in ENV_IDS:
        raise ConfigError(f"task: {task!r} is not one of the world's tasks; choose one of {', '.join(ENV_IDS)}")
    return gym.make(ENV_IDS[task], render_frames=render_frames, **sim.model_dump(), **kwargs).unwrapped


def make_policy_env(
    task: Task, sim: SimConfig, tracker: SingleTracker, layout: ObservationLayout,
    skills: tuple[Skill, Skill] | None = None, **env_kwargs: object,
) -> gym.Env:
    """One environment with the policy's observation vector in ``layout``: a ``PoseObservation`` of Pick/Drop, or,
    for the decision, the ``HierarchicalRearrange`` semi-MDP over the frozen ``skills`` (pick, drop). Frames are
    rendered only when the tracker reads them (never for the ground truth); ``env_kwargs`` go to the MOR env. A
    layout with the stated belief (``layout.search``) needs a tracker that keeps the search looks."""
    if task not in PLAYS:
        raise ConfigError(f"task: {task!r} is not a policy; choose one of {', '.join(PLAYS)}")
    env = make_task_env(PLAYS[task], sim, not isinstance(tracker, GroundTruthTracker), **env_kwargs)
    if task == "decision":
        if skills is None:
            raise ValueError("the decision policy's environment needs the trained pick and drop skills")
        return HierarchicalRearrange(env, tracker.batch, *skills, layout)
    return PoseObservation(env, tracker, layout)


def make_training_env(
    task: Task, variant: Variant, sim: SimConfig, params: PPOParams, features: ObservationParams,
    runner: LNetRunner | None = None, skills: tuple[Skill, Skill] | None = None,
) -> VecEnv:
    """``params.n_envs`` environments of ``task`` with ``variant``'s observation (a pose variant's layout with the
    profile's ``policy.observation`` settings, ``features``), for SB3.

    A baseline: rendered Pick or Drop envs seen through ``BaselineObservation`` (``variant_sim``'s world). The truth's
    variant: ``PoseObservation`` envs without rendering. L-Net variants: for Pick/Drop rendered envs under
    ``LNetVecObservation``, one batched L-Net forward per vector step in this process; for the decision each env
    tracks its own belief (decisions last different numbers of steps) in this process. The envs run in this process
    (``vec_env: dummy``) or one process each (``subproc``; not for the L-Net decision, whose tracker holds the model);
    rendered Pick and Drop envs (L-Net variants, baselines) run in ``env_workers`` processes when it is above 1.
    """
    from mor.policy.lnet_tracking import LNetTracker, LNetVecObservation  # noqa: PLC0415 - torch only for L-Net

    if variant.is_baseline:
        return _baseline_training_env(task, variant, sim, params)
    layout = ObservationLayout.of(variant, features)
    if variant.source == "truth":
        if params.vec_env == "batched" and task in BATCHED_TASKS:
            return BatchedPoseVecEnv(task, sim, params.n_envs, layout)
        return _per_env_processes(params)([lambda: make_policy_env(task, sim, GroundTruthTracker(), layout, skills)]
                                          * params.n_envs)
    if runner is None:
        raise ValueError(f"variant {variant.name!r} needs the trained L-Net (runner)")
    if task == "decision":
        arena = Arena.build(sim.arena, sim.arena_size) if layout.search else None
        return DummyVecEnv([lambda: make_policy_env(task, sim, LNetTracker(runner, arena), layout, skills)]
                           * params.n_envs)
    raw = _rendered([lambda: make_task_env(PLAYS[task], sim, render_frames=True)] * params.n_envs, params)
    return LNetVecObservation(raw, runner, task, sim.n_objects, layout)


def _rendered(env_fns: list[Callable[[], gym.Env]], params: PPOParams) -> VecEnv:
    """Rendered envs for SB3: in ``params.env_workers`` processes (``mor.policy.grouped_env``), else as
    ``params.vec_env`` says (one process each for ``subproc``, in this process otherwise)."""
    if params.env_workers > 1:
        return GroupedSubprocVecEnv(env_fns, params.env_workers)
    return _per_env_processes(params)(env_fns)


def _per_env_processes(params: PPOParams) -> type[DummyVecEnv] | type[SubprocVecEnv]:
    """SB3's vector env that ``params.vec_env`` names: one process per env for ``subproc``, else in this process."""
    return SubprocVecEnv if params.vec_env == "subproc" else DummyVecEnv


def variant_sim(variant: Variant, sim: SimConfig) -> SimConfig:
    """The world a variant plays in: ``sim``, with a marker at each drop target where the variant says ``landmark``."""
    return sim.model_copy(update={"landmark": True}) if variant.landmark else sim


def _baseline_training_env(task: Task, variant: Variant, sim: SimConfig, params: PPOParams) -> VecEnv:
    """``params.n_envs`` rendered Pick or Drop envs seen through ``BaselineObservation``, for SB3."""
    from mor.policy.baselines import BaselineObservation  # noqa: PLC0415 - torch only here

    world = variant_sim(variant, sim)
    return _rendered([lambda: BaselineObservation(make_task_env(PLAYS[task], world, render_frames=True),
                                                  variant.baseline_input)] * params.n_envs, params)
