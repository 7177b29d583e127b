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
from mor.data.schema import MAX_OBJECTS
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
    np.testing.assert_allclose(item["state.agent_pose"].numpy(), episode.agent_poses[3], atol=1e-5)
    image = (item["observation.image"].permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)
    np.testing.assert_array_equal(image, episode.images[3])
    classes = item["observation.object_classes"].numpy()
    assert list(classes[: len(episode.header.object_classes)]) == list(episode.header.object_classes)
    assert np.all(classes[len(episode.header.object_classes):] == -1) and len(classes) == MAX_OBJECTS


def test_each_split_loads_with_hugging_face_datasets(tiny_dataset: tuple) -> None:
    from datasets import load_dataset

    _, root, rows = tiny_dataset
    train = load_dataset("parquet", data_files=str(root / "train" / "data" / "*" / "*.parquet"), split="train")
    assert len(train) == sum(r["n_frames"] for r in rows if r["split"] == "train")
    assert train.with_format("numpy")[0]["observation.image"].shape == (16, 16, 3)


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
        assert features == sorted(features) and "observation.image" in features


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
               for name, feature in features.items() if name != "observation.image"}
    dataset = datasets.Dataset.from_dict({"observation.image": paths, **columns}, features=features)

    ours = embed_images_batched(dataset).with_format("arrow")[:]
    theirs = io_utils.embed_images(dataset).with_format("arrow")[:]
    assert ours.equals(theirs)
    assert ours.column("observation.image")[0].as_py()["bytes"] == Path(paths[0]).read_bytes()
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
