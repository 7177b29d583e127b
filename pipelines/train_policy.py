"""Stage ``train_policy``: phase I (pick, drop) then phase II (decision) for one observation variant.

Training runs in ``datasets/policy/<variant>/<task>/`` (checkpoints, logs, TensorBoard); the finished policy
(policy.pth, meta.json, log.csv, learning_curve.png, summary.json) is copied to ``cards/policy/<variant>/<task>/``,
committed so that a fresh clone can evaluate without retraining.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from mor.atomic import atomic_folder
from mor.config import Profile
from mor.eval.results import repoint_policy_digests
from mor.locking import writer_lock
from mor.policy.envs import make_baseline_training_env, make_training_env
from mor.policy.hierarchy import POLICY_FILE, Skill
from mor.policy.names import BASELINE_VARIANTS, TASKS, BaselineVariant, Task, Variant
from mor.policy.plan import TaskPlan, training_plan
from mor.policy.signature import PolicySignature, read_signature
from mor.policy.train import train_policy
from pipelines import paths
from pipelines.io import write_json
from pipelines.committed_lnet import lnet_runner

PUBLISHED = (POLICY_FILE, "meta.json", "summary.json", "log.csv", "learning_curve.png")  # the last two if trained


def publish(run_dir: Path, card_dir: Path) -> None:
    """Copy a finished policy's small files (those of ``PUBLISHED`` its run made) to its committed card folder,
    published as a whole (``atomic_folder``: the card's other files stay): neither a reader nor a kill ever sees a
    truncated file, or a new policy beside the old meta.json."""
    with atomic_folder(card_dir, keep_existing=True) as folder:
        for name in PUBLISHED:
            if (run_dir / name).is_file():
                shutil.copyfile(run_dir / name, folder / name)


def run_baseline(profile: Profile, variant: BaselineVariant, plans: list[TaskPlan], progress: bool = True
                 ) -> list[dict]:
    """Train the baseline's own skills (``plans``: the others reuse baseline_img's Pick; a baseline has no decision
    policy); resumable."""
    from mor.policy.baselines import BaselineExtractor  # noqa: PLC0415 - torch only here

    settings, sim, summaries = profile.policy.baseline, profile.sim, []
    extractor = {"features_extractor_class": BaselineExtractor,
                 "features_extractor_kwargs": {"encoder": settings.encoder, "image_features": settings.image_features}}
    for plan in plans:
        task, params = plan.task, plan.params
        signature = PolicySignature.of_baseline(task, variant, sim.n_objects, sim.arena, sim.image_size)
        run_dir = paths.POLICIES / variant / task
        summary = train_policy(lambda: make_baseline_training_env(task, variant, sim, params),  # noqa: B023
                               params, signature, run_dir, profile.policy.seed, f"{variant} {task}", progress,
                               policy_kwargs=extractor)
        publish(run_dir, paths.POLICY_CARD / variant / task)
        summaries.append({**summary, "encoder": settings.encoder})
    return summaries


def plan(profile: Profile, variant: Variant | BaselineVariant, tasks: tuple[Task, ...] = TASKS) -> list[TaskPlan]:
    """What ``run`` trains (``mor.policy.plan.training_plan`` with this workspace's and the main one's policies)."""
    return training_plan(profile, variant, tasks, paths.POLICY_CARD, paths.MAIN / paths.POLICY_CARD)


def run(profile: Profile, variant: Variant | BaselineVariant, tasks: tuple[Task, ...] = TASKS, progress: bool = True
        ) -> list[dict]:
    """Train ``tasks`` of ``variant`` in order (the decision needs the pick and drop skills); resumable. One
    training of a variant at a time (``writer_lock`` on its run folder)."""
    with writer_lock(paths.POLICIES / variant, f"mor policy train --variant {variant}"):
        return _train(profile, variant, tasks, progress)


def _train(profile: Profile, variant: Variant | BaselineVariant, tasks: tuple[Task, ...], progress: bool
           ) -> list[dict]:
    """``run``'s work, under the variant's lock."""
    plans = plan(profile, variant, tasks)
    if variant in BASELINE_VARIANTS:
        return run_baseline(profile, variant, plans, progress)
    runner = lnet_runner(variant, profile)
    version = runner.identity if runner is not None else None
    summaries = []
    policy = profile.policy
    for task_plan in plans:
        task, params, source = task_plan.task, task_plan.params, task_plan.start
        init_from = None if source is None else (source / POLICY_FILE,
                                                 read_signature(source / "meta.json").observation)
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


def convert_policies(files: list[Path]) -> list[tuple[Path, str, str]]:
    """Rewrite each SB3-pickled policy file of ``files`` in MOR's safe format (weights bit-identical; this unpickles
    them: the user trusts them), and re-point the results rows that recorded the old files' digests
    (``cards/results/rows`` of this workspace and of every setting) at the new ones. Returns (file, old digest,
    new digest) for each file converted; files already safe are skipped."""
    from mor.lnet.runtime import file_digest  # noqa: PLC0415 - torch only where needed
    from mor.policy.policy_file import convert_sb3_policy, is_sb3_pickle  # noqa: PLC0415

    converted = []
    for path in files:
        if is_sb3_pickle(path):
            old = file_digest(path)
            convert_sb3_policy(path)
            converted.append((path, old, file_digest(path)))
    renamed = {old: new for _, old, new in converted}
    for rows in (paths.RESULTS_CARD / "rows", *sorted(paths.SETTINGS.glob(f"*/{paths.RESULTS_CARD}/rows"))):
        for path in sorted(rows.glob("*.json")):
            row = json.loads(path.read_text())
            if repoint_policy_digests(row, renamed):
                write_json(path, row)
    return converted
