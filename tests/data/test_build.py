"""Manifest, splits, dataset version and the LeRobot datasets: loadable offline and with HF datasets."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from mor.data.collect import CollectionSpec, ProfileShape
from mor.data.episode_io import read_episode
from mor.data.manifest import (
    SPLITS,
    build_manifest,
    dataset_version,
    episode_split,
    manifest_version,
    read_manifest,
)
from mor.data.observations import NOT_HELD, held_from_state, observation_state
from mor.data.schema import (
    ACTION,
    AGENT_POSE,
    GROUND_TRUTH,
    IMAGE,
    MAX_OBJECTS,
    NO_ACTION,
    OBJECT_CLASSES,
    OBJECT_POSITIONS,
    OBJECT_VISIBLE,
    STATE,
    STATE_NAMES,
    TARGET_POSITIONS,
)
from mor.errors import MorError


def test_manifest_lists_every_episode_with_hash_and_frames(tiny_collection: Path, tiny_dataset: tuple,
                                                           tiny_spec: CollectionSpec) -> None:
    manifest_path, _, rows = tiny_dataset
    table = read_manifest(manifest_path)
    assert table.column_names == ["episode_id", "source", "seed", "file", "sha256", "n_frames", "split"]
    assert len(rows) == len(list(tiny_collection.glob("*.mcap")))
    assert all(row["source"] == "sim" and len(row["sha256"]) == 64 for row in rows)
    assert manifest_version(table) == dataset_version([r["episode_id"] for r in rows], [r["sha256"] for r in rows],
                                                      ProfileShape(tiny_spec).data_params())


def test_splits_are_8_1_1_and_never_move_when_episodes_are_added() -> None:
    ids = [f"sim-0-{i:06d}" for i in range(5000)]
    splits = [episode_split(i) for i in ids]
    shares = {s: splits.count(s) / len(ids) for s in SPLITS}
    assert abs(shares["train"] - 0.8) < 0.03 and abs(shares["validation"] - 0.1) < 0.02
    assert [episode_split(i) for i in ids[:100]] == splits[:100]  # a function of the id alone


def test_version_changes_with_content_and_data_params_not_order() -> None:
    params = {"sim": {"image_size": 32}, "episode_steps": 30}
    assert dataset_version(["a", "b"], ["1", "2"], params) == dataset_version(["b", "a"], ["2", "1"], params)
    assert dataset_version(["a", "b"], ["1", "2"], params) != dataset_version(["a", "b"], ["1", "3"], params)
    other = {"sim": {"image_size": 64}, "episode_steps": 30}
    assert dataset_version(["a", "b"], ["1", "2"], params) != dataset_version(["a", "b"], ["1", "2"], other)


def test_missing_manifest_is_one_clear_line(tmp_path: Path) -> None:
    with pytest.raises(MorError, match="no manifest; run mor build-dataset") as error:
        read_manifest(tmp_path / "manifest.parquet")
    assert "\n" not in str(error.value)


def test_each_split_loads_with_lerobot_offline(tiny_dataset: tuple, tiny_collection: Path) -> None:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    _, root, rows = tiny_dataset
    for split in SPLITS:
        split_rows = [r for r in rows if r["split"] == split]
        if not split_rows:
            continue
        dataset = LeRobotDataset(f"mor/{split}", root=root / split)
        assert dataset.num_episodes == len(split_rows)
        assert len(dataset) == sum(r["n_frames"] for r in split_rows)
    # Frame 3 of the first training episode matches its MCAP record.
    first = next(r for r in rows if r["split"] == "train")
    episode = read_episode(tiny_collection / first["file"])
    item = LeRobotDataset("mor/train", root=root / "train")[3]
    np.testing.assert_allclose(item[AGENT_POSE].numpy(), episode.agent_poses[3], atol=1e-5)
    image = (item[IMAGE].permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)
    np.testing.assert_array_equal(image, episode.images[3])
    classes = item[OBJECT_CLASSES].numpy()
    assert list(classes[: len(episode.header.object_classes)]) == list(episode.header.object_classes)
    assert np.all(classes[len(episode.header.object_classes):] == -1) and len(classes) == MAX_OBJECTS
    # observation.state: the held slot, then the action taken before the frame (one-hot each).
    np.testing.assert_array_equal(item[STATE].numpy(), observation_state(episode.held[3:4], episode.actions[2:3])[0])
    assert int(item[ACTION]) == episode.actions[3]


def test_a_split_loads_with_lerobot_and_a_stock_dataloader(tiny_dataset: tuple) -> None:
    # LeRobot's names: the camera under observation.images.<camera>, the robot's own state as observation.state,
    # the discrete action as action; the ground truth under its own keys, which no LeRobot policy reads.
    import torch
    from lerobot.configs import FeatureType
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.utils.feature_utils import dataset_to_policy_features
    from torch.utils.data import DataLoader

    _, root, _ = tiny_dataset
    dataset = LeRobotDataset("mor/train", root=root / "train")
    batch = next(iter(DataLoader(dataset, batch_size=4, shuffle=True, generator=torch.Generator().manual_seed(0))))
    assert batch[IMAGE].shape == (4, 3, 16, 16) and batch[IMAGE].dtype == torch.float32
    assert 0.0 <= float(batch[IMAGE].min()) and float(batch[IMAGE].max()) <= 1.0
    assert batch[STATE].shape == (4, len(STATE_NAMES)) and batch[STATE].dtype == torch.float32
    assert set(batch[STATE].unique().tolist()) <= {0.0, 1.0}
    assert batch[ACTION].shape == (4,) and batch[ACTION].dtype == torch.int64  # a (1,) feature: one value a frame
    assert batch[AGENT_POSE].shape == (4, 3) and batch[OBJECT_POSITIONS].shape == (4, 2 * MAX_OBJECTS)
    assert batch[OBJECT_VISIBLE].shape == (4, MAX_OBJECTS)
    assert {name for name in batch if name.startswith("observation.")} == {IMAGE, STATE, OBJECT_CLASSES,
                                                                           TARGET_POSITIONS}

    policy = dataset_to_policy_features(dataset.meta.features)
    assert (policy[IMAGE].type, policy[IMAGE].shape) == (FeatureType.VISUAL, (3, 16, 16))
    assert (policy[STATE].type, policy[STATE].shape) == (FeatureType.STATE, (len(STATE_NAMES),))
    assert (policy[ACTION].type, policy[ACTION].shape) == (FeatureType.ACTION, (1,))
    assert not any(name.startswith(GROUND_TRUTH) for name in policy)  # the truth is never a policy's input
    assert dataset.meta.features[STATE]["names"] == list(STATE_NAMES)


def test_observation_state_is_the_held_slot_and_the_previous_action() -> None:
    held = np.array([NOT_HELD, 0, 4, NOT_HELD])
    previous = np.array([NO_ACTION, 3, 0, 4])
    state = observation_state(held, previous)
    assert state.shape == (4, len(STATE_NAMES)) and state.dtype == np.float32
    assert state[0].sum() == 0  # nothing held, no action yet
    assert [STATE_NAMES[i] for i in np.flatnonzero(state[1])] == ["held0", "previous_pick"]
    assert [STATE_NAMES[i] for i in np.flatnonzero(state[2])] == ["held4", "previous_move"]
    assert [STATE_NAMES[i] for i in np.flatnonzero(state[3])] == ["previous_drop"]
    np.testing.assert_array_equal(held_from_state(state), held)


def test_each_split_loads_with_hugging_face_datasets(tiny_dataset: tuple) -> None:
    from datasets import load_dataset

    _, root, rows = tiny_dataset
    train = load_dataset("parquet", data_files=str(root / "train" / "data" / "*" / "*.parquet"), split="train")
    assert len(train) == sum(r["n_frames"] for r in rows if r["split"] == "train")
    frame = train.with_format("numpy")[0]
    assert frame[IMAGE].shape == (16, 16, 3) and frame[STATE].shape == (len(STATE_NAMES),)
    assert frame[AGENT_POSE].shape == (3,) and frame[ACTION].shape == ()


def test_build_is_stamped_with_the_dataset_version(tiny_dataset: tuple) -> None:
    manifest_path, root, _ = tiny_dataset
    version = manifest_version(read_manifest(manifest_path))
    for split in SPLITS:
        assert json.loads((root / split / "mor_build.json").read_text())["dataset_version"] == version
    assert not (root / ".shards").exists()


def test_split_statistics_are_in_a_fixed_order(tiny_dataset: tuple) -> None:
    # lerobot orders aggregated statistics by a set's iteration order; the build sorts them so that the same
    # episodes give the same bytes (DVC hashes them) whatever PYTHONHASHSEED is.
    _, root, _ = tiny_dataset
    for split in SPLITS:
        features = list(json.loads((root / split / "meta" / "stats.json").read_text()))
        assert features == sorted(features) and IMAGE in features


def test_build_manifest_names_a_corrupt_file(episodes_copy: Path, tiny_spec: CollectionSpec) -> None:
    bad = sorted(episodes_copy.glob("*.mcap"))[0]
    bad.write_bytes(b"not an mcap file")
    with pytest.raises(MorError, match=bad.name):
        build_manifest(sorted(episodes_copy.glob("*.mcap")), episodes_copy, ProfileShape(tiny_spec))


def test_manifest_parquet_is_plain(tiny_dataset: tuple) -> None:
    manifest_path, _, _ = tiny_dataset
    assert pq.read_metadata(manifest_path).num_rows > 0


def test_batched_image_embedding_writes_the_table_lerobot_writes(tmp_path: Path) -> None:
    import datasets
    from lerobot.datasets import dataset_writer, io_utils
    from lerobot.datasets.feature_utils import get_hf_features_from_features
    from PIL import Image

    from mor.data.lerobot_build import batched_image_embedding, embed_images_batched
    from mor.data.schema import lerobot_features

    rng = np.random.default_rng(0)
    paths = []
    for index in range(7):
        paths.append(str(tmp_path / f"frame-{index}.png"))
        Image.fromarray(rng.integers(0, 256, (16, 16, 3), dtype=np.uint8)).save(paths[-1])
    features = get_hf_features_from_features(lerobot_features(16))
    columns = {name: [_feature_example(feature, index) for index in range(len(paths))]
               for name, feature in features.items() if name != IMAGE}
    dataset = datasets.Dataset.from_dict({IMAGE: paths, **columns}, features=features)

    ours = embed_images_batched(dataset).with_format("arrow")[:]
    theirs = io_utils.embed_images(dataset).with_format("arrow")[:]
    assert ours.equals(theirs)
    assert ours.column(IMAGE)[0].as_py()["bytes"] == Path(paths[0]).read_bytes()
    # The substitution holds only inside the block.
    with batched_image_embedding():
        assert dataset_writer.embed_images is embed_images_batched is io_utils.embed_images
    assert dataset_writer.embed_images is not embed_images_batched and io_utils.embed_images is not embed_images_batched


def _feature_example(feature: object, index: int) -> object:
    """A value of the datasets ``feature`` (a scalar Value or a fixed-length List of Values)."""
    import datasets

    if isinstance(feature, datasets.Value):
        return index
    return [index] * feature.length


def test_scratch_falls_back_to_the_temporary_folder_when_shared_memory_is_small(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import shutil
    from collections import namedtuple

    from mor.data import lerobot_build

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda _: usage(64 << 20, 0, 64 << 20))  # Docker's default /dev/shm
    assert lerobot_build.scratch_dir() is None
    monkeypatch.setattr(shutil, "disk_usage", lambda _: usage(8 << 30, 0, 8 << 30))
    assert lerobot_build.scratch_dir() in (None, Path("/dev/shm"))  # None only where there is no /dev/shm


def test_a_build_shows_one_bar_per_step_and_none_of_the_libraries(tiny_collection: Path, tiny_spec: CollectionSpec,
                                                                   tmp_path: Path, capfd: pytest.CaptureFixture
                                                                   ) -> None:
    # lerobot's aggregation and datasets' loaders draw bars of their own ("Generating train split" while it
    # builds validation, "Map", "Copy data and videos"); a build shows only its own, one per step.
    from mor.data.lerobot_build import build_splits

    files = sorted(tiny_collection.glob("*.mcap"))[:6]
    table = build_manifest(files, tiny_collection, ProfileShape(tiny_spec))
    capfd.readouterr()
    build_splits(table.to_pylist(), tiny_collection, tmp_path, manifest_version(table), 16, 10.0, workers=1,
                 shard_episodes=2, progress=True)
    err = capfd.readouterr().err
    bars = {line.split(":")[0].strip() for line in err.replace("\r", "\n").splitlines() if line.strip()}
    assert bars == {"build", "aggregate"}, err


def test_quiet_libraries_keeps_errors_and_restores_what_it_changed(caplog: pytest.LogCaptureFixture) -> None:
    import logging

    from datasets.utils import logging as datasets_logging
    from lerobot.datasets import aggregate, io_utils

    from mor.data.lerobot_build import LIBRARY_LOGGERS, quiet_libraries

    def state() -> tuple:
        return (datasets_logging.is_progress_bar_enabled(), aggregate.tqdm, io_utils.SuppressProgressBars,
                [logging.getLogger(name).level for name in LIBRARY_LOGGERS])

    before = state()
    with caplog.at_level(logging.INFO), pytest.raises(ValueError, match="kept"), quiet_libraries():
        logging.getLogger("lerobot.datasets.aggregate").info("Start aggregate_datasets")
        logging.getLogger("lerobot.datasets.aggregate").error("an error")
        with io_utils.SuppressProgressBars():  # lerobot's wrapper turns datasets' bars back on when it exits
            pass
        assert not datasets_logging.is_progress_bar_enabled()
        raise ValueError("an exception is kept")
    assert [record.getMessage() for record in caplog.records] == ["an error"]
    assert state() == before
