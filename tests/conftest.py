"""Shared fixtures of the simulator tests: the repository root, small environments, hand-built world states."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
if os.environ.get("PYTEST_XDIST_WORKER"):
    # `pytest -n 2` on 2 cores: one thread per worker, and per process a worker starts (the tiny `dvc repro`),
    # instead of torch's one per core in each, which oversubscribes the cores.
    os.environ.setdefault("OMP_NUM_THREADS", "1")

from collections.abc import Callable, Iterator  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import mor  # noqa: E402, F401  (registers the environments)
from mor.sim.arena import Arena  # noqa: E402
from mor.sim.catalog import OBJECT_RADIUS  # noqa: E402
from mor.sim.rules import AGENT_RADIUS, WorldState  # noqa: E402

REPO_ROOT: Path = Path(__file__).resolve().parents[1]
ENV_IDS: dict[str, str] = {"pick": "MOR/Pick-v0", "drop": "MOR/Drop-v0", "rearrange": "MOR/Rearrange-v0"}
#: Small images: rendering is exercised but costs next to nothing.
SMALL_IMAGE: int = 16


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """The repository root (where params.yaml lives)."""
    return REPO_ROOT


@pytest.fixture
def make_env() -> Iterator[Callable[..., gym.Env]]:
    """``make_env(task_or_id, **kwargs)``: a gym.make'd MOR env with small images, closed after the test."""
    made: list[gym.Env] = []

    def factory(task: str, **kwargs: Any) -> gym.Env:
        kwargs.setdefault("image_size", SMALL_IMAGE)
        env = gym.make(ENV_IDS.get(task, task), **kwargs)
        made.append(env)
        return env

    yield factory
    for env in made:
        env.close()


@pytest.fixture(scope="session")
def square_arena() -> Arena:
    """The default 6 m x 6 m square arena, walls at x, y = +-3."""
    return Arena.build("square", 6.0)


@pytest.fixture(scope="session")
def polygon_arena() -> Arena:
    return Arena.build("polygon", 6.0)


def _world(agent: tuple[float, float, float], objects: list[tuple[float, float]], held: int = -1) -> WorldState:
    return WorldState(np.array(agent, dtype=np.float64), np.array(objects, dtype=np.float64).reshape(-1, 2), held)


@pytest.fixture(scope="session")
def world() -> Callable[..., WorldState]:
    """``world(agent=(x, y, theta), objects=[(x, y), ...], held=-1)``: a hand-built world state (metres, radians)."""
    return _world


def assert_world_is_legal(arena: Arena, agent_pose: np.ndarray, positions: np.ndarray, held: int) -> None:
    """No floor object within its radius of a wall or outside; no two overlap; the agent overlaps nothing.

    positions: (n, 2) object positions (the held object's row is ignored); held: its index or -1.
    """
    eps = 1e-9
    positions = np.asarray(positions, dtype=np.float64)
    on_floor = np.ones(len(positions), dtype=bool)
    if held >= 0:
        on_floor[held] = False
    floor = positions[on_floor]
    for p in floor:
        assert arena.clearance(p) >= OBJECT_RADIUS - eps, f"object at {p} is {arena.clearance(p):.3f} m from a wall"
    if len(floor) > 1:
        gaps = np.linalg.norm(floor[:, None] - floor[None], axis=-1)[np.triu_indices(len(floor), 1)]
        assert gaps.min() >= 2.0 * OBJECT_RADIUS - eps, f"objects overlap: {gaps.min():.3f} m apart"
    agent = np.asarray(agent_pose, dtype=np.float64)[:2]
    assert arena.clearance(agent) >= AGENT_RADIUS - eps, f"agent {arena.clearance(agent):.3f} m from a wall"
    if len(floor):
        assert np.linalg.norm(floor - agent, axis=1).min() >= AGENT_RADIUS + OBJECT_RADIUS - eps, "agent hits object"


@pytest.fixture(scope="session")
def legal_world() -> Callable[..., None]:
    """``legal_world(arena, agent_pose, positions, held)`` asserts the world's geometric invariants."""
    return assert_world_is_legal


# ---- the tiny dataset shared by the data and L-Net tests ----------------------------------------------------
from mor.data.collect import CollectionSpec, ProfileShape, collect  # noqa: E402
from mor.data.exploration import ExplorationParams  # noqa: E402
from mor.data.lerobot_build import build_splits  # noqa: E402
from mor.data.manifest import build_manifest, manifest_version, write_manifest  # noqa: E402
from mor.sim.config import SimConfig  # noqa: E402
import shutil  # noqa: E402

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
    table = build_manifest(sorted(tiny_collection.glob("*.mcap")), tiny_collection, ProfileShape(TINY_SPEC))
    manifest = write_manifest(table, root / "manifest.parquet")
    build_splits(table.to_pylist(), tiny_collection, root, manifest_version(table), 16, 10.0, workers=1,
                 shard_episodes=4, progress=False)
    return manifest, root, table.to_pylist()


@pytest.fixture
def episodes_copy(tiny_collection: Path, tmp_path: Path) -> Path:
    """A private copy of the tiny collection that a test may damage."""
    return Path(shutil.copytree(tiny_collection, tmp_path / "episodes"))


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The long ``pipeline`` tests first, so that under ``pytest -n 2`` one worker runs them while the other runs
    the rest, instead of everything waiting for them at the end."""
    items.sort(key=lambda item: item.get_closest_marker("pipeline") is None)
