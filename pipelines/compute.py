"""The wall time of every stage, read from the files the stages write, for the results card: the `default`
profile's target is an empty checkout to the four tables in at most 2 hours on 2 CPU cores.

Kept in ``cards/results/compute.json`` (committed): a stage's time is replaced when its source file is there
and kept otherwise, so a fresh clone (whose ``datasets/`` is empty) still shows what the last full run took.
``total_seconds`` sums what ``dvc repro`` runs; ``extra_seconds`` the runs beside it that the results also hold
(other training seeds, held-out episodes, variants no stage of ``dvc.yaml`` names), listed in ``extra_runs``.
"""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

from mor.policy.names import IMITATION_LOG, TASKS
from pipelines import paths
from pipelines.io import write_json

TARGET_SECONDS = 2 * 3600

#: stage -> (its file, the seconds in it)
FILE_SOURCES: dict[str, tuple[Path, Callable[[dict[str, Any]], float]]] = {
    "collect": (paths.COLLECT_STATS, lambda d: d["seconds"]),
    "build-dataset": (paths.BUILD_STATS, lambda d: d["seconds"]["total"]),
    "validate": (paths.VALIDATION_REPORT, lambda d: d["seconds"]),
    "train-lnet": (paths.LNET / "train_summary.json", lambda d: d["seconds"]),
    "calibrate-lnet": (paths.LNET_CALIBRATION, lambda d: d["seconds"]),
    "eval-lnet": (paths.LNET_CARD / "metrics.json", lambda d: d["seconds"]),
    "pretrain-encoder": (paths.ENCODER_CARD / "summary.json", lambda d: d["seconds"]),
}


def _read(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def stage_seconds(root: Path) -> dict[str, float]:
    """Each stage's wall seconds in the workspace at ``root``, where its file says (a policy's or an evaluation's
    last run: a resumed one counts from its restart; another training seed's run is ``policy train lnet.seed_2
    pick``)."""
    found: dict[str, float] = {}
    for stage, (path, seconds) in FILE_SOURCES.items():
        document = _read(root / path)
        if document is not None and _has(document, seconds):
            found[stage] = float(seconds(document))
    policies = root / paths.POLICY_CARD
    for log in sorted([*policies.glob("*/*/log.csv"), *policies.glob("*/seed_*/*/log.csv")]):
        skill = log.parent
        if skill.name not in TASKS:
            continue
        variant = skill.parent.name if skill.parent.parent == policies else (
            f"{skill.parent.parent.name}.{skill.parent.name}")  # lnet.seed_2
        seconds = training_seconds(skill)
        if seconds is not None:
            found[f"policy train {variant} {skill.name}"] = seconds
    for row_file in sorted((root / paths.RESULTS_CARD / "rows").glob("*.json")):
        document = _read(row_file) or {}
        if document.get("wall_seconds") is not None:
            found[f"eval run {row_file.stem}"] = document["wall_seconds"]
    return found


def training_seconds(skill: Path) -> float | None:
    """The wall seconds of a skill's last training run (``cards/policy/VARIANT[/seed_S]/TASK``): its summary's, with
    a baseline's imitation start; where a copied run kept no summary, the last row of its ``log.csv``."""
    summary = _read(skill / "summary.json") or {}
    if summary.get("wall_seconds_this_run") is not None:
        return float(summary["wall_seconds_this_run"]) + imitation_seconds(skill / IMITATION_LOG)
    with (skill / "log.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    return float(rows[-1]["wall_seconds"]) if rows and rows[-1].get("wall_seconds") else None


def imitation_seconds(log: Path) -> float:
    """The wall seconds of a baseline's imitation start before its PPO run (the last row of its ``imitation.csv``;
    0 where it had none)."""
    if not log.is_file():
        return 0.0
    with log.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    return float(rows[-1]["seconds"]) if rows else 0.0


def _has(document: dict[str, Any], seconds: Callable[[dict[str, Any]], float]) -> bool:
    try:
        seconds(document)
    except (KeyError, TypeError):
        return False
    return True


def pipeline_words(dvc_yaml: Path = Path("dvc.yaml")) -> set[str]:
    """Every word of ``dvc.yaml``'s commands and matrix values: the variants and methods ``dvc repro`` runs."""
    if not dvc_yaml.is_file():
        return set()
    stages = yaml.safe_load(dvc_yaml.read_text())["stages"].values()
    text = " ".join(f"{stage.get('cmd', '')} {stage.get('matrix', '')}" for stage in stages)
    return set(re.findall(r"[A-Za-z0-9_]+", text))


def is_extra_run(stage: str, words: set[str]) -> bool:
    """A run ``dvc repro`` does not make: another training seed's or held-out episodes' (``eval run lnet.seed_2``),
    or one of a variant or method no stage names (``policy train lnet_search pick``)."""
    names = stage.split(": ", 1)[-1].split()
    if names[:2] not in (["policy", "train"], ["eval", "run"]):
        return False
    name = names[2]
    return "." in name or (bool(words) and name.removesuffix("_zero_shot") not in words)


def update_compute(path: Path, profile: str) -> dict[str, Any]:
    """Merge this workspace's and every setting's stage times into ``path`` (compute.json) and return it."""
    existing = _read(path) or {}
    stages = dict(existing.get("stages", {})) if existing.get("profile") == profile else {}
    stages.update(stage_seconds(Path(".")))
    for folder in sorted(paths.SETTINGS.glob("*")):
        stages.update({f"{folder.name}: {stage}": s for stage, s in stage_seconds(folder).items()})
    words = pipeline_words()
    extra = sorted(stage for stage in stages if is_extra_run(stage, words))
    pipelined = {stage: seconds for stage, seconds in stages.items() if stage not in extra}
    workspaces: dict[str, float] = {}
    for stage, seconds in pipelined.items():
        name = stage.split(": ", 1)[0] if ": " in stage else "main"  # a setting's stages are "NAME: stage"
        workspaces[name] = round(workspaces.get(name, 0.0) + seconds, 1)
    result = {"profile": profile, "stages": dict(sorted(stages.items())),
              "total_seconds": round(sum(pipelined.values()), 1), "workspace_seconds": dict(sorted(workspaces.items())),
              "extra_runs": extra, "extra_seconds": round(sum(stages[stage] for stage in extra), 1),
              "target_seconds": TARGET_SECONDS}
    write_json(path, result)
    return result
