"""Fixtures of the data-pipeline tests: a tiny collection, its manifest and its LeRobot splits, made once."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from mor.data.collect import CollectionSpec, collect
from mor.data.exploration import ExplorationParams
from mor.data.lerobot_build import build_splits
from mor.data.manifest import build_manifest, manifest_version, write_manifest
from mor.sim.config import SimConfig

TINY_SPEC = CollectionSpec(SimConfig(image_size=16), ExplorationParams(), seed=3, episode_steps=40, fps=10.0)
TINY_EPISODES = 12


@pytest.fixture(scope="session")
def tiny_spec() -> CollectionSpec:
    """The collection parameters of ``tiny_collection``."""
    return TINY_SPEC


@pytest.fixture(scope="session")
def tiny_episodes() -> int:
    return TINY_EPISODES


@pytest.fixture(scope="session")
def tiny_collection(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder of TINY_EPISODES episode files (do not modify it: copy it first)."""
    out = tmp_path_factory.mktemp("episodes")
    collect(TINY_SPEC, out, TINY_EPISODES, workers=1, progress=False)
    return out


@pytest.fixture(scope="session")
def tiny_dataset(tiny_collection: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, list[dict]]:
    """(manifest path, datasets root, manifest rows) for the tiny collection (read-only)."""
    root = tmp_path_factory.mktemp("lerobot")
    table = build_manifest(sorted(tiny_collection.glob("*.mcap")), tiny_collection)
    manifest = write_manifest(table, root / "manifest.parquet")
    build_splits(table.to_pylist(), tiny_collection, root, manifest_version(table), 16, 10.0, workers=1,
                 shard_episodes=4, progress=False)
    return manifest, root, table.to_pylist()


@pytest.fixture
def episodes_copy(tiny_collection: Path, tmp_path: Path) -> Path:
    """A private copy of the tiny collection that a test may damage."""
    return Path(shutil.copytree(tiny_collection, tmp_path / "episodes"))
