"""Validation of the episode files against the manifest, and of each split's LeRobot dataset.

Every problem is one line naming the file; checking goes on after a bad file, and nothing is dropped silently:
the report lists the rejected files, which ``mor collect --rejected-from`` re-collects.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import make_reader
from tqdm import tqdm

from mor.data import schema
from mor.data.lerobot_build import BUILD_STAMP
from mor.data.manifest import SPLITS, file_sha256


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


def check_episode_file(path: Path, expected_sha256: str, expected_frames: int) -> str | None:
    """None if ``path`` is a whole, indexed episode matching the manifest; else what is wrong (one line)."""
    if not path.is_file():
        return f"{path}: missing; re-collect (mor collect) or re-import (mor import-real) it"
    try:
        with open(path, "rb") as stream:
            reader = make_reader(stream)
            summary = reader.get_summary()
            if summary is None or summary.statistics is None or not summary.chunk_indexes:
                return f"{path}: no summary or chunk index (truncated?); re-collect (sim) or re-import (real) it"
            counts = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
            metadata = {m.name: m.metadata for m in reader.iter_metadata()}.get("episode", {})
    except (McapError, OSError, ValueError, EOFError, KeyError) as error:
        return f"{path}: unreadable MCAP ({type(error).__name__}: {error}); re-collect (sim) or re-import (real) it"
    missing = [topic for topic in schema.ALL_TOPICS if topic not in counts]
    if missing:
        return f"{path}: missing channels {', '.join(missing)}; re-collect (sim) or re-import (real) it"
    frames = int(metadata.get("n_frames", -1))
    uneven = {t: counts[t] for t in schema.PER_FRAME_TOPICS if counts[t] != frames}
    if frames != expected_frames or uneven:
        return (f"{path}: frame counts disagree (metadata {frames}, manifest {expected_frames}, channels {uneven}); "
                "re-collect it")
    if file_sha256(path) != expected_sha256:
        return f"{path}: sha256 differs from the manifest (file changed after build); rebuild or re-collect it"
    return None


def check_split(root: Path, split: str, episodes: int, frames: int) -> tuple[dict[str, int], str | None]:
    """Compare a built split's episode and frame totals with the manifest's."""
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


def validate(manifest: list[dict], episodes_root: Path, episode_folders: tuple[Path, ...], datasets_root: Path,
             progress: bool = True) -> ValidationReport:
    """Check every manifest episode (paths relative to ``episodes_root``), that every episode file in
    ``episode_folders`` is in the manifest, and every split; returns the report (does not raise on bad data)."""
    report = ValidationReport()
    for row in tqdm(manifest, desc="validate", unit="ep", disable=not progress):
        problem = check_episode_file(episodes_root / row["file"], row["sha256"], row["n_frames"])
        report.episodes_checked += 1
        if problem:
            report.problems.append(problem)
            report.rejected.append(row["file"])
    listed = {row["file"] for row in manifest}
    for path in sorted(p for folder in episode_folders for p in folder.glob("*.mcap")):
        if str(path.relative_to(episodes_root)) not in listed:
            report.problems.append(f"{path}: not in the manifest; run mor build-dataset to include it")
    for split in SPLITS:
        rows = [row for row in manifest if row["split"] == split]
        found, problem = check_split(datasets_root / split, split, len(rows), sum(r["n_frames"] for r in rows))
        report.splits[split] = found
        if problem:
            report.problems.append(problem)
    return report
