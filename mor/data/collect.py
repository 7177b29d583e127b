"""Collecting random-action episodes into MCAP files: resumable, seeded, in parallel processes or Ray tasks.

Episode ``index`` of a collection with seed ``seed`` is ``sim-<seed>-<index:06d>.mcap``; its env seed is
``episode_seed(seed, index)``. A finished episode is never redone; a ``.partial`` file is discarded.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
from tqdm import tqdm

from mor.data.episode_io import EpisodeFileError, EpisodeHeader, EpisodeWriter, encode_png, read_metadata
from mor.data.exploration import ExplorationParams, ExplorationPolicy
from mor.data.parallel import unordered_map
from mor.errors import MorError
from mor.sim.config import SimConfig
from mor.sim.rollout import episode_seed

EPISODE_SUFFIX = ".mcap"
ENV_ID = "MOR/Rearrange-v0"


@dataclass(frozen=True)
class CollectionSpec:
    """Everything that determines a collection's episodes."""

    sim: SimConfig
    exploration: ExplorationParams
    seed: int
    episode_steps: int
    fps: float

    def params(self) -> dict[str, Any]:
        """What an episode file records of its making. Not the sim's rewards: the exploration policy never reads
        them, so they shape no frame (and data collected before they were parameters keeps its version)."""
        return {"sim": self.sim.model_dump(exclude={"rewards"}), "exploration": self.exploration.model_dump(),
                "seed": self.seed, "episode_steps": self.episode_steps, "fps": self.fps, "env_id": ENV_ID}


def _json(value: Any) -> Any:
    """``value`` as it reads back from an episode's JSON params (tuples become lists)."""
    return json.loads(json.dumps(value, sort_keys=True))


def _leaves(params: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested dicts flattened to dotted keys."""
    out: dict[str, Any] = {}
    for key, value in params.items():
        if isinstance(value, dict):
            out.update(_leaves(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


@dataclass(frozen=True)
class ProfileShape:
    """The data-shaping parameters a profile asks of every episode file, and names for one-line messages.

    A collected episode's data-shaping params are its recorded ``CollectionSpec.params()`` less ``seed`` (the seed
    only names the files, so collections of several seeds may share a dataset); an imported real run's, and a robot
    controller's run (real or simulated, ``mor.robot``), are the image size and frame rate of its frames (its params'
    ``import`` section). ``name`` is the profile's name ('' when unknown); ``others`` are
    (name, spec) of the named profiles, to suggest one that matches a file.
    """

    spec: CollectionSpec
    name: str = ""
    others: tuple[tuple[str, CollectionSpec], ...] = ()

    def data_params(self) -> dict[str, Any]:
        """What shapes simulated data (JSON-normalised): hashed into the dataset version."""
        return sim_data_params(self.spec.params())

    def mismatch(self, path: Path, metadata: dict[str, str]) -> str | None:
        """None if the episode at ``path`` (its ``metadata`` record) was made with this profile's data-shaping
        params; else one line saying what differs and what to do."""
        recorded = json.loads(metadata.get("params") or "{}")
        asked = f"profile '{self.name}'" if self.name else "the active profile"
        if metadata.get("source") == "sim" and "import" not in recorded:
            got, want = _leaves(sim_data_params(recorded)), _leaves(self.data_params())
            verb = "collected"
            match = [name for name, spec in self.others if _leaves(sim_data_params(spec.params())) == got]
            remedy = f"delete {path.parent} or run with --profile {match[0]}" if match else (
                f"delete {path.parent} (and re-collect) or run with the parameters it was collected with")
        else:
            imported = recorded.get("import", {})
            got = {"image_size": imported.get("image_size"), "fps": imported.get("fps")}
            want = {"image_size": self.spec.sim.image_size, "fps": self.spec.fps}
            verb = "imported"
            remedy = f"re-import it with --image-size {want['image_size']} --fps {want['fps']:g}, or delete it"
        differing = sorted(key for key in got.keys() | want.keys() if got.get(key) != want.get(key))
        if not differing:
            return None
        recorded_text = ", ".join(f"{key}={got.get(key, '(absent)')}" for key in differing)
        asked_text = ", ".join(str(want.get(key, "(absent)")) for key in differing)
        return f"{path} was {verb} with {recorded_text} but {asked} asks {asked_text}: {remedy}"


def sim_data_params(params: dict[str, Any]) -> dict[str, Any]:
    """The data-shaping part of a simulated episode's params (``CollectionSpec.params()``): all but the seed."""
    return {key: value for key, value in _json(params).items() if key != "seed"}


class ProfileMismatch(MorError):
    """Episode files made with other data-shaping parameters than the active profile's."""


def check_collection(out_dir: Path, shape: ProfileShape) -> None:
    """Raise ProfileMismatch (one line) if an episode file in ``out_dir`` was collected with other data-shaping
    params than ``shape``'s. Unreadable files are left to ``mor validate`` (and re-collection)."""
    for path in sorted(out_dir.glob(f"*{EPISODE_SUFFIX}")):
        try:
            problem = shape.mismatch(path, read_metadata(path))
        except EpisodeFileError:
            continue
        if problem:
            raise ProfileMismatch(problem)


def episode_id(seed: int, index: int) -> str:
    return f"sim-{seed}-{index:06d}"


def episode_path(out_dir: Path, seed: int, index: int) -> Path:
    return out_dir / f"{episode_id(seed, index)}{EPISODE_SUFFIX}"


def pending_indices(out_dir: Path, seed: int, episodes: int, rejected: set[str] = frozenset()) -> list[int]:
    """Indices still to collect: missing files, and files named in ``rejected`` (deleted here). Removes
    leftover ``.partial`` files of interrupted runs."""
    out_dir.mkdir(parents=True, exist_ok=True)
    for leftover in out_dir.glob(f"*{EPISODE_SUFFIX}.partial"):
        leftover.unlink()
    for name in rejected:
        (out_dir / name).unlink(missing_ok=True)
    return [i for i in range(episodes) if not episode_path(out_dir, seed, i).exists()]


class EpisodeCollector:
    """Owns one env (one renderer) and writes episodes with it; one per worker process."""

    def __init__(self, spec: CollectionSpec, out_dir: Path) -> None:
        self.spec, self.out_dir = spec, out_dir
        self.env = gym.make(ENV_ID, horizon=spec.episode_steps, **spec.sim.model_dump())

    def collect(self, index: int) -> int:
        """Write episode ``index``; returns its frame count."""
        spec, env = self.spec, self.env
        seed = episode_seed(spec.seed, index)
        policy = ExplorationPolicy(env.unwrapped.arena, spec.exploration, seed, env.unwrapped.noise)
        observation, info = env.reset(seed=seed)
        layout = env.unwrapped.layout
        header = EpisodeHeader(
            episode_id=episode_id(spec.seed, index), source="sim", seed=seed, fps=spec.fps,
            object_classes=layout.object_classes, target_positions=layout.target_positions,
            wall_textures=layout.wall_textures, params=spec.params(),
        )
        with EpisodeWriter(episode_path(self.out_dir, spec.seed, index), header) as writer:
            done = False
            while not done:
                action = policy(observation, info)
                writer.add_frame(encode_png(observation["image"]), info["agent_pose"], info["object_positions"],
                                 info["held"], action)
                observation, _, terminated, truncated, info = env.step(action)
                done = terminated or truncated
            writer.add_frame(encode_png(observation["image"]), info["agent_pose"], info["object_positions"],
                             info["held"], -1)
            return writer.n_frames

    def close(self) -> None:
        self.env.close()


def _collect_batch(job: tuple[CollectionSpec, Path, list[int]]) -> list[int]:
    """One worker job: a fresh collector (one renderer) for a batch of episodes -> their frame counts."""
    spec, out_dir, batch = job
    os.environ.setdefault("LP_NUM_THREADS", "1")  # one llvmpipe render thread per worker
    collector = EpisodeCollector(spec, out_dir)
    try:
        return [collector.collect(index) for index in batch]
    finally:
        collector.close()


def _run(spec: CollectionSpec, out_dir: Path, indices: list[int], workers: int, backend: str) -> Iterator[int]:
    """Each collected episode's frame count, as it finishes: in this process (one worker, no Ray), else in
    batches of up to 16 episodes as ``unordered_map`` jobs (worker processes or Ray tasks)."""
    if workers <= 1 and backend == "process":
        yield from _collect_batch((spec, out_dir, indices))
        return
    size = max(1, min(16, len(indices) // (4 * workers) or 1))
    jobs = [(spec, out_dir, indices[i:i + size]) for i in range(0, len(indices), size)]
    for frames in unordered_map(_collect_batch, jobs, workers, backend):
        yield from frames


def collect(spec: CollectionSpec, out_dir: Path, episodes: int, workers: int, backend: str = "process",
            rejected: set[str] = frozenset(), progress: bool = True, shape: ProfileShape | None = None
            ) -> dict[str, Any]:
    """Collect every missing episode of ``spec`` into ``out_dir``; returns counts and throughput.

    Refuses (ProfileMismatch, before collecting anything) when ``out_dir`` holds episodes collected with other
    data-shaping params (``shape``: ``spec``'s, named for the message when given).
    """
    shape = shape or ProfileShape(spec)
    if shape.spec != spec:
        raise ValueError("shape: must describe the spec being collected")
    out_dir.mkdir(parents=True, exist_ok=True)
    check_collection(out_dir, shape)
    indices = pending_indices(out_dir, spec.seed, episodes, rejected)
    if backend not in ("process", "ray"):
        raise ValueError(f"backend: unknown backend {backend!r}; choose 'process' or 'ray'")
    frames = 0
    start = time.perf_counter()
    with tqdm(total=episodes, initial=episodes - len(indices), desc="collect", unit="ep", disable=not progress) as bar:
        for count in _run(spec, out_dir, indices, workers, backend) if indices else ():
            frames += count
            bar.update(1)
            bar.set_postfix(frames_per_s=f"{frames / (time.perf_counter() - start):.0f}", refresh=False)
    elapsed = time.perf_counter() - start
    return {"collected": len(indices), "skipped": episodes - len(indices), "frames": frames,
            "seconds": elapsed, "frames_per_s": frames / elapsed if frames else 0.0}

