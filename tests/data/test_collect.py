"""Collection: MCAP episodes that hold what the env did, seeded, resumable and lossless."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from mor.data import schema
from mor.data.collect import EpisodeCollector, collect, episode_path, pending_indices
from mor.data.episode_io import read_episode
from mor.sim.rules import Action
from mor.data.collect import CollectionSpec


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_every_episode_is_written_with_all_channels(tiny_collection: Path, tiny_episodes: int) -> None:
    files = sorted(tiny_collection.glob("*.mcap"))
    assert len(files) == tiny_episodes
    with open(files[0], "rb") as stream:
        summary = make_reader(stream).get_summary()
    topics = {channel.topic for channel in summary.channels.values()}
    assert topics == set(schema.ALL_TOPICS)
    assert {index.compression for index in summary.chunk_indexes} == {"zstd"}
    schemas = {s.name for s in summary.schemas.values()}
    assert {"foxglove.CompressedImage", "foxglove.PoseInFrame", "foxglove.PosesInFrame",
            "foxglove.FrameTransforms"} <= schemas


def test_episode_round_trips_what_the_env_did(tiny_collection: Path, tmp_path: Path, tiny_spec: CollectionSpec) -> None:
    episode = read_episode(episode_path(tiny_collection, tiny_spec.seed, 0))
    assert episode.n_frames == tiny_spec.episode_steps + 1
    assert episode.images.shape == (episode.n_frames, 16, 16, 3)
    assert episode.actions[-1] == schema.NO_ACTION and np.all(episode.actions[:-1] >= 0)
    assert episode.header.source == "sim" and len(episode.header.object_classes) == tiny_spec.sim.n_objects
    # Replaying the recorded actions in a fresh env reproduces the recorded poses and images.
    collector = EpisodeCollector(tiny_spec, tmp_path)
    env = collector.env
    observation, info = env.reset(seed=episode.header.seed)
    for t, action in enumerate(episode.actions):
        np.testing.assert_allclose(info["agent_pose"], episode.agent_poses[t], atol=1e-6)
        np.testing.assert_allclose(info["object_positions"], episode.object_positions[t], atol=1e-6)
        np.testing.assert_array_equal(observation["image"], episode.images[t])
        assert info["held"] == episode.held[t]
        if action < 0:
            break
        observation, _, _, _, info = env.step(int(action))
    collector.close()


def test_same_seed_gives_identical_files(tiny_collection: Path, tmp_path: Path, tiny_spec: CollectionSpec) -> None:
    collect(tiny_spec, tmp_path, 2, workers=1, progress=False)
    for index in range(2):
        assert _digest(episode_path(tmp_path, tiny_spec.seed, index)) == _digest(
            episode_path(tiny_collection, tiny_spec.seed, index))


def test_interrupted_collection_resumes_and_keeps_finished_episodes(
    episodes_copy: Path, tiny_spec: CollectionSpec, tiny_episodes: int
) -> None:
    kept = episode_path(episodes_copy, tiny_spec.seed, 0)
    kept_digest, kept_mtime = _digest(kept), kept.stat().st_mtime_ns
    lost = episode_path(episodes_copy, tiny_spec.seed, 5)
    # A run killed mid-episode leaves a .partial file and no final file.
    lost.rename(lost.with_name(lost.name + ".partial"))
    assert pending_indices(episodes_copy, tiny_spec.seed, tiny_episodes) == [5]
    assert not list(episodes_copy.glob("*.partial"))
    result = collect(tiny_spec, episodes_copy, tiny_episodes, workers=1, progress=False)
    assert result["collected"] == 1 and result["skipped"] == tiny_episodes - 1
    assert kept.stat().st_mtime_ns == kept_mtime and _digest(kept) == kept_digest
    assert read_episode(lost, with_images=False).n_frames == tiny_spec.episode_steps + 1


def test_rejected_files_are_collected_again(episodes_copy: Path, tiny_spec: CollectionSpec, tiny_episodes: int) -> None:
    bad = episode_path(episodes_copy, tiny_spec.seed, 2)
    good_digest = _digest(bad)
    bad.write_bytes(bad.read_bytes()[:100])
    result = collect(tiny_spec, episodes_copy, tiny_episodes, workers=1, progress=False, rejected={bad.name})
    assert result["collected"] == 1
    assert _digest(bad) == good_digest


def test_writer_error_leaves_no_episode(tmp_path: Path) -> None:
    from mor.data.episode_io import EpisodeHeader, EpisodeWriter

    header = EpisodeHeader("x", "sim", 0, 10.0, np.array([0]), np.zeros((1, 2)))
    with pytest.raises(RuntimeError), EpisodeWriter(tmp_path / "x.mcap", header):
        raise RuntimeError("killed")
    assert list(tmp_path.iterdir()) == []


def test_episodes_show_picks_and_drops(tiny_collection: Path) -> None:
    episodes = [read_episode(path, with_images=False) for path in sorted(tiny_collection.glob("*.mcap"))]
    picks = sum(int(np.sum(np.diff(e.held) != 0) > 0) for e in episodes)
    assert picks > 0, "no episode ever picked anything up"
    assert any(np.any(e.actions == Action.DROP) for e in episodes)


def test_parallel_and_ray_backends_write_the_same_episodes(
    tiny_collection: Path, tmp_path: Path, tiny_spec: CollectionSpec
) -> None:
    processes, ray_dir = tmp_path / "processes", tmp_path / "ray"
    collect(tiny_spec, processes, 3, workers=2, backend="process", progress=False)
    collect(tiny_spec, ray_dir, 3, workers=2, backend="ray", progress=False)
    for index in range(3):
        expected = _digest(episode_path(tiny_collection, tiny_spec.seed, index))
        assert _digest(episode_path(processes, tiny_spec.seed, index)) == expected
        assert _digest(episode_path(ray_dir, tiny_spec.seed, index)) == expected
