"""What ``mor policy train`` runs for a variant, decided in one place: each task's PPO parameters and where it
starts from. ``mor policy plan`` prints it; ``pipelines.train_policy`` runs it.

Starts (docs/assumptions.md, "Policies"):
- in a setting with ``finetune_from_main``: the main workspace's policy of the same variant and task (the decision
  only where its action space, one action per object, is the same);
- otherwise a variant with a ``warm_start`` (``mor.policy.variants``) starts from this workspace's policy of that
  variant when ``policy.lnet_warm_start``;
- a policy that starts from the main workspace's trains ``policy.finetune_steps[task]`` steps, one that starts from
  its warm-start variant's ``policy.lnet_steps[task]`` steps, not its task's ``steps``;
- the baselines train their own skills (``Variant.trains``) from scratch with ``policy.baseline``'s parameters,
  after its imitation start where ``policy.baseline.imitation.<task>.rounds`` > 0;
- with ``more_steps`` (``mor policy train --more-steps N``, a budget study) every task instead continues this
  workspace's committed policy of the same variant, task and seed for N more steps (not for the baselines, whose
  start is an imitation of the oracle).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mor.config import Profile
from mor.errors import ConfigError
from mor.policy.names import Task
from mor.policy.params import ImitationParams, PPOParams
from mor.policy.signature import read_signature
from mor.policy.variants import Variant, policy_folder

RANDOM_START = "from a random start"


@dataclass(frozen=True)
class TaskPlan:
    """One policy's training: ``params`` as it will run (after every override), ``start`` the committed policy
    folder it fine-tunes (None: a random start) and ``why`` in words."""

    task: Task
    params: PPOParams
    start: Path | None
    why: str


def _start(profile: Profile, variant: Variant, task: Task, own: Path, main: Path, seed: int
           ) -> tuple[Path | None, str, str | None]:
    """(the policy folder it starts from or None, why, the ``policy`` field naming its steps or None)."""
    setting, policy = profile.setting, profile.policy
    if setting is not None and setting.finetune_from_main:
        source = policy_folder(main, variant.name, task, seed)
        if task != "decision" or read_signature(source / "meta.json").n_objects == profile.sim.n_objects:
            return source, "fine-tunes the main workspace's policy (setting.finetune_from_main)", "finetune_steps"
    if variant.warm_start is not None and policy.lnet_warm_start:
        return (policy_folder(own, variant.warm_start, task, seed),
                f"fine-tunes this workspace's {variant.warm_start} policy (policy.lnet_warm_start)", "lnet_steps")
    return None, RANDOM_START, None


def _imitation_start(imitation: ImitationParams) -> str:
    """How a baseline skill starts, in words."""
    if not imitation.rounds:
        return RANDOM_START
    return (f"from {imitation.rounds} DAgger rounds of {imitation.round_steps:,} steps imitating the scripted "
            "oracle")


def training_plan(profile: Profile, variant: Variant, tasks: tuple[Task, ...], own: Path, main: Path, seed: int = 0,
                  more_steps: int | None = None) -> list[TaskPlan]:
    """The plan of ``tasks`` (in order) of ``variant``'s run with training seed ``seed``; ``own`` and ``main``: the
    committed policy folders (``cards/policy``) of this workspace and of the main one. A run starts from the
    policies of the same training seed; with ``more_steps``, from its own committed ones (ConfigError for a
    baseline or ``more_steps`` < 1)."""
    policy = profile.policy
    if more_steps is not None:
        if variant.is_baseline:
            raise ConfigError(f"--more-steps: {variant.name} is a baseline, whose skills start from an imitation of "
                              "the oracle; continue a variant that learns from poses instead")
        if more_steps < 1:
            raise ConfigError(f"--more-steps: {more_steps} is not a number of steps; give a positive integer")
        return [TaskPlan(task, getattr(policy, task).model_copy(update={"steps": more_steps}),
                         policy_folder(own, variant.name, task, seed),
                         f"continues this workspace's committed policy for {more_steps:,} more steps (--more-steps)")
                for task in tasks]
    if variant.is_baseline:
        baseline = policy.baseline
        return [TaskPlan(task, getattr(baseline, task), None,
                         f"{_imitation_start(getattr(baseline.imitation, task))}, encoder {baseline.encoder}")
                for task in variant.trains if task in tasks]
    plans = []
    for task in tasks:
        start, why, steps_field = _start(profile, variant, task, own, main, seed)
        params = getattr(policy, task)
        if steps_field is not None:
            steps = getattr(policy, steps_field)[task]
            params = params.model_copy(update={"steps": steps})
            why += f"; policy.{steps_field}.{task} = {steps:,} steps replace {task}.steps"
        plans.append(TaskPlan(task, params, start, why))
    return plans
