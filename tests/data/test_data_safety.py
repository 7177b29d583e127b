"""Data safety: corrupt episodes are named and rejected, the manifest is replaced only after a whole build, data of
one profile is never used under another, and killed builds leave no scratch behind."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from mor.config import BuildParams, CollectParams, Profile, load_profile
from mor.data import lerobot_build, schema
from mor.data.collect import CollectionSpec, ProfileMismatch, ProfileShape, collect
from mor.data.episode_io import EpisodeFileError, read_episode, verify_episode
from mor.data.exploration import ExplorationParams
from mor.data.manifest import EpisodesRejected, build_manifest, file_sha256, listed_files, write_manifest
from mor.data.sequences import SequenceWindows
from mor.data.validate import validate
from mor.errors import ConfigError
from mor.sim.config import SimConfig

#: Other data-shaping params than the tiny collection's (image_size 16, episode_steps 40).
OTHER_SPEC = CollectionSpec(SimConfig(image_size=32), ExplorationParams(), seed=3, episode_steps=30, fps=10.0)


def _corrupt_message(src: Path, dst: Path, topic: str, payload: bytes, index: int = 3) -> Path:
    """Copy the episode ``src`` to ``dst`` with message ``index`` of ``topic`` replaced by ``payload``.

    The copy is a well-formed MCAP (summary, indexes and CRCs agree with its bytes): only decoding the message can
    tell that it is bad, as with a file corrupted before it was ever built.
    """
    with open(src, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        metadata = list(reader.iter_metadata())
        messages = list(reader.iter_messages())
    with open(dst, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start(profile="", library="test")
        schema_ids = {sid: writer.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channel_ids = {cid: writer.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id], c.metadata)
                       for cid, c in summary.channels.items()}
        seen = 0
        for _, channel, message in messages:
            data = message.data
            if channel.topic == topic:
                data = payload if seen == index else data
                seen += 1
            writer.add_message(channel_ids[channel.id], message.log_time, data, message.publish_time, message.sequence)
        for record in metadata:
            writer.add_metadata(record.name, record.metadata)
        writer.finish()
    return dst


BAD_MESSAGES = {
    "protobuf": (schema.TOPIC_AGENT_POSE, b"\xff\xff\xff\xff"),
    "png": (schema.TOPIC_IMAGE, CompressedImage(data=b"not a png", format="png").SerializeToString()),
    "json": (schema.TOPIC_STATE, b"{not json"),
    "json field": (schema.TOPIC_STATE, b"{}"),
}


@pytest.mark.parametrize("kind", sorted(BAD_MESSAGES))
def test_any_message_that_fails_to_decode_is_one_line_naming_the_file(
    kind: str, tiny_collection: Path, tmp_path: Path
) -> None:
    topic, payload = BAD_MESSAGES[kind]
    bad = _corrupt_message(sorted(tiny_collection.glob("*.mcap"))[0], tmp_path / "bad.mcap", topic, payload)
    for read in (read_episode, verify_episode):
        with pytest.raises(EpisodeFileError, match=str(bad)) as error:
            read(bad)
        assert "\n" not in str(error.value) and "re-collect" in str(error.value)


def test_byte_flips_anywhere_are_named_or_harmless(tiny_collection: Path, tmp_path: Path) -> None:
    # Chunk CRCs are checked, so a flipped byte is an EpisodeFileError (never another exception) or lies where the
    # reader never looks (index records): then the episode reads back unchanged.
    source = sorted(tiny_collection.glob("*.mcap"))[0]
    original, expected = source.read_bytes(), read_episode(source)
    caught = 0
    for position in range(8, len(original) - 8, len(original) // 40):
        data = bytearray(original)
        data[position] ^= 0xFF
        flipped = tmp_path / "flipped.mcap"
        flipped.write_bytes(bytes(data))
        try:
            verify_episode(flipped)
        except EpisodeFileError as error:
            assert "\n" not in str(error)
            caught += 1
            continue
        episode = read_episode(flipped)
        for name in ("images", "agent_poses", "object_positions", "held", "actions"):
            np.testing.assert_array_equal(getattr(episode, name), getattr(expected, name))
    assert caught >= 20


def _profile(spec: CollectionSpec) -> Profile:
    return Profile(sim=spec.sim, collect=CollectParams(episodes=12, episode_steps=spec.episode_steps, seed=spec.seed,
                                                       fps=spec.fps, workers=1, exploration=spec.exploration),
                   build=BuildParams(workers=1, shard_episodes=6))


@pytest.fixture
def project(tiny_collection: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A project folder (the current directory) whose datasets/episodes holds a copy of the tiny collection."""
    shutil.copytree(tiny_collection, tmp_path / "datasets" / "episodes")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_build_refuses_a_corrupt_episode_and_leaves_the_manifest_alone(project: Path, tiny_spec: CollectionSpec,
                                                                      ) -> None:
    from pipelines import build, paths

    files = sorted(paths.EPISODES.glob("*.mcap"))
    write_manifest(build_manifest(files, paths.DATASETS, ProfileShape(tiny_spec)), paths.MANIFEST)
    before = paths.MANIFEST.read_bytes()
    bad = files[4]
    _corrupt_message(bad, project / "copy.mcap", *BAD_MESSAGES["protobuf"]).replace(bad)
    with pytest.raises(EpisodesRejected, match=f"^{bad}: unreadable messages .*DecodeError") as error:
        build.run(_profile(tiny_spec))
    assert "\n" not in str(error.value) and "manifest is unchanged" in str(error.value)
    assert paths.MANIFEST.read_bytes() == before
    assert not paths.LEROBOT.exists()


def test_build_never_readmits_a_listed_file_whose_bytes_changed(project: Path, tiny_spec: CollectionSpec,
                                                                tiny_episodes: int) -> None:
    from pipelines import build, paths

    files = sorted(paths.EPISODES.glob("*.mcap"))
    write_manifest(build_manifest(files, paths.DATASETS, ProfileShape(tiny_spec)), paths.MANIFEST)
    before, bad = paths.MANIFEST.read_bytes(), files[2]
    data = bytearray(bad.read_bytes())
    data[9] ^= 0xFF  # the header record's length: every message still decodes through the index
    bad.write_bytes(bytes(data))
    verify_episode(bad)
    expected = f"^{bad}: its bytes changed since the build that listed it .*; delete it and re-collect"
    with pytest.raises(EpisodesRejected, match=expected) as error:
        build.run(_profile(tiny_spec))
    assert "\n" not in str(error.value) and paths.MANIFEST.read_bytes() == before
    rows = pq.read_table(paths.MANIFEST).to_pylist()
    report = validate(rows, paths.DATASETS, (paths.EPISODES,), paths.LEROBOT, ProfileShape(tiny_spec), progress=False)
    assert report.rejected == [str(bad.relative_to(paths.DATASETS))]
    assert report.problems[0] == str(error.value).removesuffix("; the manifest is unchanged")
    # Re-collected, it has its listed bytes again and is admitted.
    collect(tiny_spec, paths.EPISODES, tiny_episodes, workers=1, progress=False, rejected={bad.name})
    build_manifest(files, paths.DATASETS, ProfileShape(tiny_spec), listed_files(paths.MANIFEST))


def test_manifest_is_replaced_only_after_the_splits_are_built(project: Path, tiny_spec: CollectionSpec,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    from pipelines import build, paths

    files = sorted(paths.EPISODES.glob("*.mcap"))
    write_manifest(build_manifest(files[:-1], paths.DATASETS, ProfileShape(tiny_spec)), paths.MANIFEST)

    def killed(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt  # as if the build died while writing the splits

    monkeypatch.setattr(build, "build_splits", killed)
    with pytest.raises(KeyboardInterrupt):
        build.run(_profile(tiny_spec))
    assert pq.read_table(paths.MANIFEST).num_rows == len(files) - 1


def test_build_decodes_only_what_no_finished_build_has_decoded(project: Path, tiny_spec: CollectionSpec,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    from mor.data import manifest as manifest_module
    from pipelines import paths

    files = sorted(paths.EPISODES.glob("*.mcap"))
    write_manifest(build_manifest(files[:-1], paths.DATASETS, ProfileShape(tiny_spec)), paths.MANIFEST)
    decoded: list[Path] = []
    monkeypatch.setattr(manifest_module, "verify_episode", lambda path: decoded.append(path) or verify_episode(path))
    build_manifest(files, paths.DATASETS, ProfileShape(tiny_spec), listed_files(paths.MANIFEST))
    assert decoded == [files[-1]]


def test_validate_decodes_every_message(tiny_dataset: tuple, episodes_copy: Path, tiny_spec: CollectionSpec) -> None:
    # A file corrupted before its first build: the manifest's sha256 and frame count match it.
    _, root, rows = tiny_dataset
    bad = episodes_copy / rows[2]["file"]
    _corrupt_message(bad, episodes_copy / "copy.tmp", *BAD_MESSAGES["png"]).replace(bad)
    rows = [dict(row, sha256=file_sha256(bad)) if row["file"] == bad.name else row for row in rows]
    report = validate(rows, episodes_copy, (episodes_copy,), root, ProfileShape(tiny_spec), progress=False)
    assert report.rejected == [rows[2]["file"]]
    assert len(report.problems) == 1 and report.problems[0].startswith(f"{bad}: unreadable messages")


def test_collect_refuses_a_folder_of_another_profiles_episodes(episodes_copy: Path, tiny_spec: CollectionSpec) -> None:
    before = sorted(episodes_copy.iterdir())
    shape = ProfileShape(OTHER_SPEC, "default", (("tiny", tiny_spec), ("default", OTHER_SPEC)))
    with pytest.raises(ProfileMismatch) as error:
        collect(OTHER_SPEC, episodes_copy, 20, workers=1, progress=False, shape=shape)
    first = sorted(episodes_copy.glob("*.mcap"))[0]
    assert str(error.value) == (f"{first} was collected with episode_steps=40, sim.image_size=16 but profile "
                                f"'default' asks 30, 32: delete {episodes_copy} or run with --profile tiny")
    assert sorted(episodes_copy.iterdir()) == before
    # Without a matching named profile the remedy still says what to do.
    with pytest.raises(ProfileMismatch, match="but the active profile asks 30, 32: delete .* or run with the param"):
        collect(OTHER_SPEC, episodes_copy, 20, workers=1, progress=False)


def test_build_and_validate_refuse_another_profiles_episodes(tiny_dataset: tuple, tiny_collection: Path) -> None:
    _, root, rows = tiny_dataset
    files = sorted(tiny_collection.glob("*.mcap"))
    with pytest.raises(EpisodesRejected, match=f"{len(files)} bad files") as error:
        build_manifest(files, tiny_collection, ProfileShape(OTHER_SPEC))
    assert "\n" not in str(error.value) and "sim.image_size=16" in str(error.value)
    report = validate(rows, tiny_collection, (tiny_collection,), root, ProfileShape(OTHER_SPEC), progress=False)
    assert len(report.rejected) == len(rows)
    assert all("was collected with episode_steps=40, sim.image_size=16" in p for p in report.problems)


def test_a_real_episode_of_another_image_size_is_refused(tiny_spec: CollectionSpec, tmp_path: Path) -> None:
    path = tmp_path / "real-run.mcap"
    metadata = {"source": "real", "params": json.dumps({"import": {"image_size": 32, "fps": 10.0}})}
    assert ProfileShape(tiny_spec, "tiny").mismatch(path, metadata) == (
        f"{path} was imported with image_size=32 but profile 'tiny' asks 16: "
        "re-import it with --image-size 16 --fps 10, or delete it")
    same = {"source": "real", "params": json.dumps({"import": {"image_size": 16, "fps": 10.0}})}
    assert ProfileShape(tiny_spec).mismatch(path, same) is None


def test_profile_shape_is_named_after_params_yaml(repo_root: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from pipelines.shapes import profile_shape

    monkeypatch.chdir(repo_root)
    shape = profile_shape(load_profile("tiny"))
    assert shape.name == "tiny" and {name for name, _ in shape.others} == {"tiny", "default", "paper"}


def test_a_window_longer_than_every_episode_is_one_clear_line(tiny_dataset: tuple) -> None:
    _, root, rows = tiny_dataset
    longest = max(row["n_frames"] for row in rows if row["split"] == "train")
    with pytest.raises(ConfigError, match=f"longest episode has {longest} frames, fewer than the window of 500") as error:
        SequenceWindows(root / "train", window=500)
    assert "\n" not in str(error.value)


def _dead_pid() -> int:
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def test_a_killed_builds_scratch_is_removed_and_live_ones_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                                               ) -> None:
    scratch = tmp_path / "shm"
    stale = scratch / f"mor-build-{_dead_pid()}-abc" / "train"
    live = scratch / f"{lerobot_build.scratch_prefix()}xyz"
    unknown = scratch / "mor-build-nopid"
    for folder in (stale, live, unknown):
        folder.mkdir(parents=True)
    monkeypatch.setattr(lerobot_build, "scratch_dir", lambda: scratch)
    monkeypatch.setattr(lerobot_build.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    lerobot_build.build_splits([], tmp_path, tmp_path / "lerobot", "v", 16, 10.0, workers=1, progress=False)
    assert not stale.parent.exists()
    assert live.is_dir() and unknown.is_dir()


def test_collect_under_another_profile_is_one_line_and_exit_2(repo_root: Path, tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    from typer.testing import CliRunner

    from pipelines.cli import app

    shutil.copy(repo_root / "params.yaml", tmp_path / "params.yaml")
    monkeypatch.chdir(tmp_path)
    assert CliRunner().invoke(app, ["collect", "--profile", "tiny", "--episodes", "1"]).exit_code == 0
    result = CliRunner().invoke(app, ["collect", "--profile", "default", "--episodes", "1"])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "profile 'default' asks" in lines[0], result.output
    assert lines[0].endswith("delete datasets/episodes or run with --profile tiny")
