"""Stage ``build``: the manifest, one LeRobot dataset per split, and the dataset card."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mor.config import Profile
from mor.data.lerobot_build import build_splits
from mor.data.manifest import build_manifest, manifest_version, write_manifest


def run(profile: Profile, episodes_dir: Path, manifest_path: Path, datasets_root: Path, card_dir: Path,
        workers: int | None = None) -> dict[str, Any]:
    from mor.data.card import write_dataset_card
    from mor.sim.arena import Arena

    table = build_manifest(sorted(episodes_dir.glob("*.mcap")), episodes_dir)
    write_manifest(table, manifest_path)
    version = manifest_version(table)
    counts = build_splits(table.to_pylist(), episodes_dir, datasets_root, version, profile.sim.image_size,
                          profile.collect.fps, workers or profile.build.workers, profile.build.shard_episodes)
    arena = Arena.build(profile.sim.arena, profile.sim.arena_size)
    card = write_dataset_card(manifest_path, episodes_dir, card_dir, profile.model_dump(mode="json"), arena)
    return {"dataset_version": version, "episodes": counts, "card": str(card)}
