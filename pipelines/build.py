"""Stage ``build``: the manifest, one LeRobot dataset per split, and the dataset card."""

from __future__ import annotations

import os
from typing import Any

from mor.config import Profile
from mor.data.lerobot_build import build_splits
from mor.data.manifest import build_manifest, listed_files, manifest_version, write_manifest
from mor.locking import writer_lock
from mor.timing import timed
from pipelines import paths
from pipelines.shapes import profile_shape
from pipelines.io import write_json


def run(profile: Profile, workers: int | None = None) -> dict[str, Any]:
    """Manifest of every episode file (simulated and real), the LeRobot splits, the dataset card; writes the
    counts and each part's wall time (seconds) to ``datasets/build_stats.json``.

    A file the manifest lists whose bytes changed is refused (as ``mor validate`` does); every new episode file is
    decoded whole and every file's params are compared with the profile's before anything is written (a bad file
    stops the build with one line naming it); the manifest is replaced only after the splits are built, so it never
    lists a file the build could not read. One build at a time
    (``writer_lock`` on ``datasets/lerobot``).
    """
    with writer_lock(paths.LEROBOT, "mor build-dataset"):
        return _build(profile, workers)


def _build(profile: Profile, workers: int | None) -> dict[str, Any]:
    """``run``'s work, under the lock."""
    from mor.data.card import write_dataset_card
    from mor.sim.arena import Arena

    workers = workers or profile.build.workers
    seconds: dict[str, float] = {}
    with timed(seconds, "manifest"):
        files = [path for folder in paths.EPISODE_FOLDERS for path in sorted(folder.glob("*.mcap"))]
        table = build_manifest(files, paths.DATASETS, profile_shape(profile), listed_files(paths.MANIFEST),
                               workers, progress=True)
        version = manifest_version(table)
    with timed(seconds, "lerobot"):
        counts = build_splits(table.to_pylist(), paths.DATASETS, paths.LEROBOT, version, profile.sim.image_size,
                              profile.collect.fps, workers, profile.build.shard_episodes)
        write_manifest(table, paths.MANIFEST)
    with timed(seconds, "card"):
        arena = Arena.build(profile.sim.arena, profile.sim.arena_size)
        card = write_dataset_card(paths.MANIFEST, paths.DATASETS, paths.DATASET_CARD,
                                  profile.model_dump(mode="json"), arena,
                                  datasets_root_rel=os.path.relpath(paths.LEROBOT, paths.DATASET_CARD), workers=workers)
    result = {"dataset_version": version, "episodes": counts, "frames": int(sum(table.column("n_frames").to_pylist())),
              "workers": workers, "seconds": {**seconds, "total": sum(seconds.values())}}
    write_json(paths.BUILD_STATS, result)
    return {**result, "card": str(card)}
