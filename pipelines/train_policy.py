"""Stage ``train_policy``: phase I (pick, drop) then phase II (decision) for one observation variant.

Training runs in ``datasets/policy/<variant>/<task>/`` (checkpoints, logs, TensorBoard); the finished policy
(policy.pth, meta.json, log.csv, learning_curve.png, summary.json) is copied to ``cards/policy/<variant>/<task>/``,
committed so that a fresh clone can evaluate without retraining.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from mor.atomic import atomic_folder
from mor.config import Profile
from mor.locking import writer_lock
from mor.policy.baselines import baseline_extractor, load_pretrained_encoder
from mor.policy.envs import make_training_env
from mor.policy.frame_encoder import ENCODER_FILE
from mor.policy.hierarchy import POLICY_FILE, Skill
from mor.policy.imitation import clone_oracle
from mor.policy.names import IMITATION_LOG, TASKS, Task
from mor.policy.params import ImitationParams, PPOParams
from mor.policy.plan import TaskPlan, training_plan
from mor.policy.signature import PolicySignature, warm_start_names
from mor.policy.train import train_policy
from mor.data.parallel import unordered_map
from mor.policy.variants import VARIANTS, Variant, policy_folder, seed_folder
from mor.policy.workspace import committed_lnet
from pipelines import paths
from pipelines.workspaces import workspace_record

if TYPE_CHECKING:
    import torch

PUBLISHED = (POLICY_FILE, "meta.json", "summary.json", "log.csv", "learning_curve.png",  # the last two if trained
             IMITATION_LOG)  # a baseline's, if it imitated the oracle first


def publish(run_dir: Path, card_dir: Path) -> None:
    """Copy a finished policy's small files (those of ``PUBLISHED`` its run made) to its committed card folder,
    published as a whole (``atomic_folder``: the card's other files stay): neither a reader nor a kill ever sees a
    truncated file, or a new policy beside the old meta.json."""
    with atomic_folder(card_dir, keep_existing=True) as folder:
        for name in PUBLISHED:
            if (run_dir / name).is_file():
                shutil.copyfile(run_dir / name, folder / name)


def plan(profile: Profile, variant: Variant, tasks: tuple[Task, ...] = TASKS, seed: int = 0,
         more_steps: int | None = None) -> list[TaskPlan]:
    """What ``run`` trains (``mor.policy.plan.training_plan`` with this workspace's and the main one's policies)."""
    return training_plan(profile, variant, tasks, paths.POLICY_CARD, paths.MAIN / paths.POLICY_CARD, seed, more_steps)


def run(profile: Profile, variant: Variant, tasks: tuple[Task, ...] = TASKS, seed: int = 0, progress: bool = True,
        more_steps: int | None = None) -> list[dict]:
    """Train ``tasks`` of ``variant`` with training seed ``seed``, in order (the decision needs the pick and drop
    skills); resumable. One training of a variant's seed at a time (``writer_lock`` on its run folder). With
    ``more_steps``, each task continues its committed policy in a run folder of its own (``<task>.more_<N>``), and
    the card's policy is replaced by the continued one."""
    with writer_lock(seed_folder(paths.POLICIES, variant.name, seed), f"mor policy train --variant {variant.name} --seed {seed}"):
        return _train(profile, variant, tasks, seed, progress, more_steps)


def run_seeds(profile: Profile, variant: Variant, tasks: tuple[Task, ...], seeds: list[int], jobs: int = 1,
              backend: str = "process", more_steps: int | None = None) -> Iterator[list[dict]]:
    """``run`` for each training seed of ``seeds``: in this process (``jobs`` 1), or as parallel jobs in worker
    processes or Ray tasks (``mor.data.parallel.unordered_map``); yields each seed's summaries as it finishes."""
    for seed in seeds:  # a wrong --more-steps is one error line before any training starts
        plan(profile, variant, tasks, seed, more_steps)
    if jobs <= 1 and backend == "process":
        yield from (run(profile, variant, tasks, seed, more_steps=more_steps) for seed in seeds)
        return
    yield from unordered_map(_seed_job, [(Path.cwd(), profile, variant.name, tasks, seed, more_steps)
                                         for seed in seeds], jobs, backend)


def _seed_job(job: tuple[Path, Profile, str, tuple[Task, ...], int, int | None]) -> list[dict]:
    """One parallel training job (a worker process or a Ray task): one seed of a variant, without progress bars."""
    workspace, profile, name, tasks, seed, more_steps = job
    os.chdir(workspace)  # the workspace's relative paths (a Ray worker starts elsewhere)
    return run(profile, VARIANTS[name], tasks, seed, progress=False, more_steps=more_steps)


def _train(profile: Profile, variant: Variant, tasks: tuple[Task, ...], seed: int, progress: bool,
           more_steps: int | None) -> list[dict]:
    """``run``'s work, under the lock of the seed's run: each task of the plan trained, then published to its card."""
    policy, sim = profile.policy, profile.sim
    runner = committed_lnet(workspace_record(Path("."), profile), variant, profile.lnet)
    version, stated = (runner.identity, runner.stated_identity) if runner is not None else (None, None)
    pretrained = (load_pretrained_encoder(paths.ENCODER_CARD / ENCODER_FILE)
                  if variant.is_baseline and policy.baseline.encoder == "autoencoder" else None)
    summaries = []
    for task_plan in plan(profile, variant, tasks, seed, more_steps):
        task, params, source = task_plan.task, task_plan.params, task_plan.start
        skills = None
        if task == "decision":
            skills = tuple(Skill.load(policy_folder(paths.POLICY_CARD, variant.name, name, seed) / POLICY_FILE,
                                      policy.skills_deterministic) for name in ("pick", "drop"))
        signature = (PolicySignature.of_baseline(task, variant, sim.n_objects, sim.arena, sim.image_size)
                     if variant.is_baseline else PolicySignature.of(task, variant, sim.n_objects, sim.arena, version,
                                                                   policy.observation, stated))
        init_from = None if source is None else (source / POLICY_FILE,
                                                 warm_start_names(source / "meta.json", signature))
        run_dir = policy_folder(paths.POLICIES, variant.name, task, seed)
        if more_steps is not None:  # not the original run's folder, whose finished checkpoint would be resumed
            run_dir = run_dir.with_name(f"{task}.more_{more_steps}")
        extractor, initialize, recipe = None, None, None
        if variant.is_baseline:  # a baseline skill (pick or drop): its own network, start and recorded recipe
            extractor = baseline_extractor(policy.baseline, task)
            imitation = getattr(policy.baseline.imitation, task)
            initialize = _baseline_start(profile, variant, task, params, imitation, seed, run_dir, pretrained,
                                         progress)
            recipe = {"encoder": policy.baseline.encoder, "imitation": imitation.model_dump(),
                      "goal_gating": extractor["features_extractor_kwargs"]["goal_gating"]}
        summary = train_policy(
            lambda: make_training_env(task, variant, sim, params, policy.observation, runner, skills),  # noqa: B023
            params, signature, run_dir, seed, f"{variant.name} {task}" + (f" seed {seed}" if seed else ""),
            progress, init_from, policy_kwargs=extractor, initialize=initialize, recipe=recipe)
        publish(run_dir, policy_folder(paths.POLICY_CARD, variant.name, task, seed))
        summaries.append(summary)
    return summaries


def _baseline_start(profile: Profile, variant: Variant, task: Task, params: PPOParams, imitation: ImitationParams,
                    seed: int, run_dir: Path, pretrained: Callable[[torch.nn.Module], None] | None, progress: bool
                    ) -> Callable[[torch.nn.Module], None]:
    """What a new baseline policy gets before PPO: the pretrained encoder (``pretrained``, if any), then, with
    ``imitation.rounds`` (``policy.baseline.imitation.<task>``), behaviour cloning from the oracle on in-process
    envs of its task."""

    def initialize(model_policy: torch.nn.Module) -> None:
        if pretrained is not None:
            pretrained(model_policy)
        if imitation.rounds:
            env = make_training_env(task, variant, profile.sim,
                                    params.model_copy(update={"vec_env": "dummy", "env_workers": 1}),
                                    profile.policy.observation)
            try:
                clone_oracle(model_policy, env, imitation, params.gamma, seed, run_dir / IMITATION_LOG, progress)
            finally:
                env.close()

    return initialize
