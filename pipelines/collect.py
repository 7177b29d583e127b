"""Stage ``collect``: random-action episodes as MCAP files (resumable; re-collects rejected files)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from mor.config import Profile
from mor.data.collect import CollectionSpec, collect
from pipelines import paths
from pipelines.io import write_json


def rejected_files(report: Path | None, out_dir: Path) -> set[str]:
    """Names of the files in ``out_dir`` that a validation report rejected (empty when there is no report)."""
    if report is None or not report.is_file():
        return set()
    rejected = [paths.DATASETS / name for name in json.loads(report.read_text()).get("rejected", [])]
    return {path.name for path in rejected if path.parent == out_dir}


def run(profile: Profile, out_dir: Path, stats: Path, rejected_from: Path | None, workers: int | None = None,
        backend: str | None = None, episodes: int | None = None) -> dict[str, Any]:
    params = profile.collect
    spec = CollectionSpec(profile.sim, params.exploration, params.seed, params.episode_steps, params.fps)
    result = collect(spec, out_dir, episodes or params.episodes, workers or params.workers,
                     backend or params.backend, rejected_files(rejected_from, out_dir))
    write_json(stats, {**result, "params": spec.params()})
    return result
