"""Stage ``collect``: random-action episodes as MCAP files (resumable; re-collects rejected files)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from mor.config import Profile
from mor.data.collect import collect
from mor.locking import writer_lock
from pipelines import paths
from pipelines.io import write_json
from pipelines.shapes import profile_shape


def rejected_files(report: Path | None, out_dir: Path) -> set[str]:
    """Names of the files in ``out_dir`` that a validation report rejected (empty when there is no report)."""
    if report is None or not report.is_file():
        return set()
    rejected = [paths.DATASETS / name for name in json.loads(report.read_text()).get("rejected", [])]
    return {path.name for path in rejected if path.parent == out_dir}


def run(profile: Profile, out_dir: Path, stats: Path, rejected_from: Path | None, workers: int | None = None,
        backend: str | None = None, episodes: int | None = None) -> dict[str, Any]:
    """Collect the profile's missing episodes into ``out_dir`` (refusing a folder of another profile's episodes);
    writes the counts and params to ``stats`` (a run that found every episode there keeps the stats of the run that
    collected them, whose time ``compute.json`` reports). One collection into ``out_dir`` at a time
    (``writer_lock``)."""
    params = profile.collect
    shape = profile_shape(profile)
    with writer_lock(out_dir, "mor collect"):
        result = collect(shape.spec, out_dir, episodes or params.episodes, workers or params.workers,
                         backend or params.backend, rejected_files(rejected_from, out_dir), shape=shape)
        if result["collected"] or not stats.is_file():
            write_json(stats, {**result, "params": shape.spec.params()})
    return result
