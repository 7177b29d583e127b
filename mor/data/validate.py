"""Validation of the episode files against the manifest, and of each split's LeRobot dataset.

Every problem is one line naming the file; checking goes on after a bad file, and nothing is dropped silently:
the report lists the rejected files, which ``mor collect --rejected-from`` re-collects. Every message of every
episode is decoded (a file corrupted before its first build is caught), and each episode's params are compared
with the active profile's data-shaping params.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mor.data.collect import ProfileShape
from mor.data.episode_io import REDO, EpisodeFileError, verify_episode
from mor.data.manifest import SPLITS, changed_since_listed, file_sha256
from mor.data.parallel import ordered_map


@dataclass
class ValidationReport:
    """What validation found; ``problems`` are one-line messages, ``rejected`` the episode files to redo."""

    episodes_checked: int = 0
    rejected: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    splits: dict[str, dict[str, int]] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.problems

    def to_json(self) -> dict[str, Any]:
        return {"ok": self.ok, "episodes_checked": self.episodes_checked, "rejected": self.rejected,
                "problems": self.problems, "splits": self.splits}


def check_episode_file(path: Path, shape: ProfileShape, expected_sha256: str | None = None,
                       expected_frames: int | None = None) -> str | None:
    """None if ``path`` is a whole episode (``verify_episode``: indexed, CRCs, every message decoded) made with
    ``shape``'s data-shaping params and, where given, with the manifest's frame count and sha256; else what is
    wrong (one line naming the file)."""
    if not path.is_file():
        return f"{path}: missing; re-collect (mor collect) or re-import (mor import-real) it"
    try:
        metadata = verify_episode(path)
    except EpisodeFileError as error:
        return str(error)
    frames = int(metadata["n_frames"])
    if expected_frames is not None and frames != expected_frames:
        return f"{path}: {frames} frames but the manifest says {expected_frames}; {REDO}"
    return changed_since_listed(path, file_sha256(path), expected_sha256) or shape.mismatch(path, metadata)


def check_split(root: Path, split: str, episodes: int, frames: int) -> tuple[dict[str, int], str | None]:
    """Compare a built split's episode and frame totals with the manifest's."""
    from mor.data.lerobot_build import BUILD_STAMP  # noqa: PLC0415 - it imports torch, which checking workers need not

    found = {"episodes": 0, "frames": 0}
    info_path = root / "meta" / "info.json"
    if episodes == 0 and (root / BUILD_STAMP).is_file():
        return found, None
    if not info_path.is_file():
        return found, f"{root}: split '{split}' has no meta/info.json; run mor build-dataset"
    info = json.loads(info_path.read_text())
    found = {"episodes": int(info.get("total_episodes", -1)), "frames": int(info.get("total_frames", -1))}
    if found != {"episodes": episodes, "frames": frames}:
        return found, (f"{root}: split '{split}' has {found['episodes']} episodes / {found['frames']} frames, "
                       f"the manifest {episodes} / {frames}; run mor build-dataset")
    return found, None


def _check(job: tuple[Path, ProfileShape, tuple[str, int] | tuple[()]]) -> str | None:
    path, shape, expected = job
    return check_episode_file(path, shape, *expected)


def validate(manifest: list[dict], episodes_root: Path, episode_folders: tuple[Path, ...], datasets_root: Path,
             shape: ProfileShape, progress: bool = True, workers: int = 1) -> ValidationReport:
    """Check every manifest episode (paths relative to ``episodes_root``; each decoded whole, in ``workers``
    processes, and compared with ``shape``), that every episode file in ``episode_folders`` is in the manifest (a
    bad unlisted file is rejected too), and every split; returns the report (does not raise on bad data)."""
    report = ValidationReport()
    listed = {row["file"] for row in manifest}
    unlisted = sorted(p for folder in episode_folders for p in folder.glob("*.mcap")
                      if str(p.relative_to(episodes_root)) not in listed)
    checks = [(episodes_root / row["file"], row) for row in manifest] + [(path, None) for path in unlisted]
    jobs = [(path, shape, (row["sha256"], row["n_frames"]) if row else ()) for path, row in checks]
    problems = ordered_map(_check, jobs, workers, "validate", progress)
    for (path, row), problem in zip(checks, problems, strict=True):
        report.episodes_checked += row is not None
        if problem:
            report.problems.append(problem)
            report.rejected.append(str(path.relative_to(episodes_root)))
        elif row is None:
            report.problems.append(f"{path}: not in the manifest; run mor build-dataset to include it")
    for split in SPLITS:
        rows = [row for row in manifest if row["split"] == split]
        found, problem = check_split(datasets_root / split, split, len(rows), sum(r["n_frames"] for r in rows))
        report.splits[split] = found
        if problem:
            report.problems.append(problem)
    return report
