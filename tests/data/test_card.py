"""The dataset card: coverage on hand-made trajectories, event counts, and a whole card from a tiny collection."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from PIL import Image

from mor.data.card import CARD_NAME, iter_card_links, write_dataset_card
from mor.data.card_figures import write_coverage_png
from mor.data.card_stats import (
    coverage_fraction,
    coverage_map,
    episode_events,
    inside_mask,
    mean_displacement,
    median_mean_displacement,
)
from mor.data.collect import CollectionSpec, ProfileShape
from mor.data.episode_io import EpisodeData, EpisodeHeader
from mor.data.manifest import build_manifest, manifest_version, write_manifest
from mor.data.schema import ACTION, AGENT_POSE, IMAGE, STATE, features
from mor.sim.arena import Arena


def _episode(xy: list[tuple[float, float]], held: list[int] | None = None, actions: list[int] | None = None,
             ) -> EpisodeData:
    """A hand-made episode with the agent at ``xy`` (metres) on successive frames, one object."""
    t = len(xy)
    poses = np.zeros((t, 3))
    poses[:, :2] = xy
    header = EpisodeHeader("hand", "sim", 0, 10.0, np.array([0]), np.zeros((1, 2)))
    return EpisodeData(header, np.zeros((0, 0, 0, 3), np.uint8), poses, np.zeros((t, 1, 2)),
                       np.asarray(held if held is not None else [-1] * t), np.asarray(actions or [0] * (t - 1) + [-1]))


def test_coverage_map_counts_a_hand_made_trajectory(square_arena: Arena) -> None:
    # cell (ix, iy) of the 0.25 m grid over [-3, 3]^2 has centre (-3 + 0.25 (ix + 0.5), -3 + 0.25 (iy + 0.5))
    first = _episode([(0.1, 0.1), (0.2, 0.2), (0.1, 0.1), (-2.9, -2.9)])  # 3 frames in (12, 12), 1 in (0, 0)
    second = _episode([(2.9, -2.9), (0.3, 0.1)])  # (23, 0) and (13, 12)
    counts, extent = coverage_map([first, second], square_arena)
    assert extent == (-3.0, 3.0, -3.0, 3.0)
    assert counts.shape == (24, 24)  # rows are y, columns x
    assert counts.sum() == 6
    assert counts[12, 12] == 3 and counts[0, 0] == 1 and counts[0, 23] == 1 and counts[12, 13] == 1
    assert inside_mask(counts.shape, extent, square_arena).all()
    assert coverage_fraction(counts, extent, square_arena) == pytest.approx(4 / 576)
    assert mean_displacement(second) == pytest.approx(np.hypot(2.6, 3.0) / 2)
    assert median_mean_displacement([first, second]) == pytest.approx(
        np.median([mean_displacement(first), mean_displacement(second)]))


def test_coverage_fraction_counts_only_cells_inside_a_polygon(polygon_arena: Arena) -> None:
    counts, extent = coverage_map([_episode([(0.0, 0.0)])], polygon_arena, cell_size=0.5)
    inside = inside_mask(counts.shape, extent, polygon_arena)
    assert 0 < inside.sum() < inside.size
    assert coverage_fraction(counts, extent, polygon_arena) == pytest.approx(1 / inside.sum())


def test_coverage_png_is_an_image(square_arena: Arena, tmp_path: Path) -> None:
    counts, extent = coverage_map([_episode([(0.1, 0.1), (1.0, 1.0)])], square_arena)
    path = write_coverage_png(counts, extent, square_arena, tmp_path / "coverage.png")
    with Image.open(path) as image:
        assert image.format == "PNG" and image.size[0] > 200
    assert not list(tmp_path.glob("*.partial*"))


def test_episode_events_count_actions_and_held_changes() -> None:
    held = [-1, -1, 0, 0, 0, -1, -1, 1, 1]
    actions = [3, 3, 0, 4, 4, 3, 3, 0, -1]  # a PICK with nothing pickable, then picks; a blocked DROP, then a drop
    events = episode_events(_episode([(0.0, 0.0)] * len(held), held, actions))
    assert (events.pick_actions, events.drop_actions, events.picks, events.drops) == (4, 2, 2, 1)


def _front_matter(card: str) -> dict:
    match = re.match(r"^---\n(.*?)\n---\n", card, re.S)
    assert match, "no YAML front matter"
    return yaml.safe_load(match.group(1))


def test_dataset_card_from_a_tiny_collection(tiny_collection: Path, tiny_spec: CollectionSpec,
                                             square_arena: Arena, tmp_path: Path) -> None:
    root, params = tiny_collection, tiny_spec.params()
    manifest = build_manifest(sorted(root.glob("*.mcap")), root, ProfileShape(tiny_spec))
    manifest_path = write_manifest(manifest, tmp_path / "manifest.parquet")
    out = tmp_path / "card"
    card_path = write_dataset_card(manifest_path, root, out, params, square_arena, "datasets", progress=False)
    assert card_path == out / CARD_NAME and card_path.is_file()
    card = card_path.read_text()
    table = pq.read_table(manifest_path)
    rows = table.to_pylist()

    meta = _front_matter(card)
    assert meta["task_categories"] == ["robotics"]
    assert meta["license"] == "apache-2.0" and "LeRobot" in meta["tags"]
    splits = {row["split"] for row in rows}
    assert {c["config_name"] for c in meta["configs"]} == splits and len(meta["configs"]) == len(splits)
    for config in meta["configs"]:
        assert config["data_files"] == f"datasets/{config['config_name']}/data/*/*.parquet"

    links = list(iter_card_links(card))
    assert {"coverage.png", "class_histogram.png", "wall_textures.png", "example_frames.png"} <= set(links)
    for link in links:
        with Image.open(out / link) as image:
            image.verify()
    assert not list(out.glob("*.partial*"))

    assert manifest_version(table) in card
    for split in splits:
        episodes = sum(row["split"] == split for row in rows)
        frames = sum(row["n_frames"] for row in rows if row["split"] == split)
        assert f"| {split} | {episodes} | {frames} |" in card
    assert f"| **total** | {len(rows)} | {sum(row['n_frames'] for row in rows)} |" in card
    assert f"| sim | {len(rows)} | {sum(row['n_frames'] for row in rows)} |" in card

    fraction = float(re.search(r"coverage fraction of ([0-9.]+)", card).group(1))
    assert 0.0 < fraction <= 1.0
    size = tiny_spec.sim.image_size
    assert f"| `{IMAGE}` | image | ({size}, {size}, 3) |" in card  # the shape, read from the frames
    for name, feature in features(size).items():
        assert f"| `{name}` | {feature.dtype} | {feature.shape} | {feature.units} | {feature.meaning} |" in card
    assert f"episode_steps: {tiny_spec.episode_steps}" in card  # the params block
    share = float(re.search(r"An object is in view on ([0-9.]+)% of its frames", card).group(1))
    assert 0.0 < share < 100.0


def test_card_configs_point_at_the_split_datasets(tiny_dataset: tuple[Path, Path, list[dict]],
                                                  tiny_collection: Path, tiny_spec: CollectionSpec,
                                                  square_arena: Arena, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The front matter's data_files globs, resolved from the card's folder, find every split's frames; the
    card's LeRobot snippet, run in the card's folder, loads a frame with the features it names."""
    from datasets import load_dataset  # noqa: PLC0415 - heavy import

    manifest_path, datasets_root, rows = tiny_dataset
    out = tmp_path / "card"
    relative = os.path.relpath(datasets_root, out)
    card = write_dataset_card(manifest_path, tiny_collection, out, tiny_spec.params(), square_arena, relative,
                              example_episodes=1, progress=False).read_text()
    configs = _front_matter(card)["configs"]
    assert {c["config_name"] for c in configs} == {row["split"] for row in rows}
    for config in configs:
        files = sorted(out.glob(config["data_files"]))
        assert files, config
        frames = load_dataset("parquet", data_files=[str(f) for f in files], split="train",
                              cache_dir=str(tmp_path / "hf"))
        assert len(frames) == sum(r["n_frames"] for r in rows if r["split"] == config["config_name"])
    snippet = re.search(r"```python\n(.*?)```", card, re.S).group(1)
    assert "LeRobotDataset" in snippet and IMAGE in snippet
    monkeypatch.chdir(out)
    namespace: dict = {}
    exec(snippet, namespace)  # noqa: S102 - the card's own example
    assert {IMAGE, STATE, ACTION, AGENT_POSE} <= set(namespace["frame"])
