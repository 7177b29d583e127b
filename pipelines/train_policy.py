"""Stage ``train_policy``: phase I (pick, drop) then phase II (decision) for one observation variant.

Training runs in ``datasets/policy/<variant>/<task>/`` (checkpoints, logs, TensorBoard); the finished policy
(policy.pth, meta.json, log.csv, learning_curve.png, summary.json) is copied to ``cards/policy/<variant>/<task>/``,
committed so that a fresh clone can evaluate without retraining.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

from mor.config import Profile
from mor.policy.envs import make_baseline_training_env, make_training_env
from mor.policy.hierarchy import POLICY_FILE, Skill
from mor.policy.names import BASELINE_VARIANTS, TASKS, BaselineVariant, Task, Variant
from mor.policy.signature import PolicySignature, read_signature
from mor.policy.train import train_policy
from pipelines import paths

PUBLISHED = (POLICY_FILE, "meta.json", "summary.json", "log.csv", "learning_curve.png")  # the last two if trained


def lnet_runner(variant: Variant, profile: Profile) -> Any:
    """The committed L-Net (``cards/lnet/model.pt`` + calibration; the main workspace's where the setting says
    ``lnet_from_main``; compiled when the profile's ``lnet.compile_step``, with its ``lnet.encoder_precision``) for the L-Net variants; None for
    gt_pose."""
    if variant == "gt_pose":
        return None
    from mor.lnet.runtime import load_lnet  # noqa: PLC0415 - torch model only where needed

    from_main = profile.setting is not None and profile.setting.lnet_from_main
    return load_lnet((paths.MAIN / paths.LNET_CARD if from_main else paths.LNET_CARD) / "model.pt",
                     compiled=profile.lnet.compile_step, data_association=profile.lnet.data_association,
                     encoder_precision=profile.lnet.encoder_precision)


def starting_policy(profile: Profile, variant: Variant, task: Task) -> Path | None:
    """The committed policy folder a new ``variant`` ``task`` policy starts from, None for a random start.

    In a setting with ``finetune_from_main``: the main workspace's policy of the same variant and task (the
    decision only where its action space, one action per object, is the same). Otherwise the L-Net variants start
    from this workspace's gt_pose policy when ``lnet_warm_start`` (docs/assumptions.md, "Policies").
    """
    setting, policy = profile.setting, profile.policy
    if setting is not None and setting.finetune_from_main:
        main = paths.MAIN / paths.POLICY_CARD / variant / task
        if task != "decision" or read_signature(main / "meta.json").n_objects == profile.sim.n_objects:
            return main
    if variant != "gt_pose" and policy.lnet_warm_start:
        return paths.POLICY_CARD / "gt_pose" / task
    return None


def publish(run_dir: Path, card_dir: Path) -> None:
    """Copy a finished policy's small files to its committed card folder."""
    card_dir.mkdir(parents=True, exist_ok=True)
    for name in PUBLISHED:
        if (run_dir / name).is_file():
            shutil.copyfile(run_dir / name, card_dir / name)


def run_baseline(profile: Profile, variant: BaselineVariant, tasks: tuple[Task, ...], progress: bool = True
                 ) -> list[dict]:
    """Train the baseline's own skills among ``tasks`` (``baseline_tasks``: the others reuse baseline_img's Pick;
    a baseline has no decision policy); resumable."""
    from mor.policy.baselines import BaselineExtractor, baseline_tasks  # noqa: PLC0415 - torch only here

    settings, sim, summaries = profile.policy.baseline, profile.sim, []
    extractor = {"features_extractor_class": BaselineExtractor,
                 "features_extractor_kwargs": {"encoder": settings.encoder, "image_features": settings.image_features}}
    for task in (t for t in baseline_tasks(variant) if t in tasks):
        params = getattr(settings, task)
        signature = PolicySignature.of_baseline(task, variant, sim.n_objects, sim.arena, sim.image_size)
        run_dir = paths.POLICIES / variant / task
        summary = train_policy(lambda: make_baseline_training_env(task, variant, sim, params),  # noqa: B023
                               params, signature, run_dir, profile.policy.seed, f"{variant} {task}", progress,
                               policy_kwargs=extractor)
        publish(run_dir, paths.POLICY_CARD / variant / task)
        summaries.append({**summary, "encoder": settings.encoder})
    return summaries


def run(profile: Profile, variant: Variant | BaselineVariant, tasks: tuple[Task, ...] = TASKS, progress: bool = True
        ) -> list[dict]:
    """Train ``tasks`` of ``variant`` in order (the decision needs the pick and drop skills); resumable."""
    if variant in BASELINE_VARIANTS:
        return run_baseline(profile, variant, tasks, progress)
    runner = lnet_runner(variant, profile)
    version = runner.identity if runner is not None else None
    summaries = []
    policy = profile.policy
    for task in tasks:
        params, init_from = getattr(policy, task), None
        source = starting_policy(profile, variant, task)
        if source is not None:
            params = params.model_copy(update={"steps": policy.lnet_steps[task]})
            init_from = (source / POLICY_FILE, read_signature(source / "meta.json").observation)
        skills = None
        if task == "decision":
            skills = tuple(Skill.load(paths.POLICY_CARD / variant / name / POLICY_FILE,
                                      policy.skills_deterministic) for name in ("pick", "drop"))
        signature = PolicySignature.of(task, variant, profile.sim.n_objects, profile.sim.arena, version)
        run_dir = paths.POLICIES / variant / task
        summary = train_policy(
            lambda: make_training_env(task, variant, profile.sim, params, runner, skills),  # noqa: B023
            params, signature, run_dir, policy.seed, f"{variant} {task}", progress, init_from)
        publish(run_dir, paths.POLICY_CARD / variant / task)
        summaries.append(summary)
    return summaries
