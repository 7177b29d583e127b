"""A torch sequence loader for the L-Net: fixed-length windows of consecutive frames of one episode.

It reads a split's LeRobot Parquet files directly (pyarrow), indexes every window that lies wholly inside one
episode, and decodes a window's PNG frames only when it is asked for (so DataLoader workers share the work).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import torch
from torch.utils.data import Dataset

from mor.data.episode_io import decode_png
from mor.data.observations import held_from_state, images_to_tensor
from mor.data.schema import (
    ACTION,
    AGENT_POSE,
    IMAGE,
    MAX_OBJECTS,
    OBJECT_CLASSES,
    OBJECT_POSITIONS,
    OBJECT_VISIBLE,
    STATE,
    TARGET_POSITIONS,
)
from mor.errors import ConfigError

_COLUMNS = (IMAGE, STATE, OBJECT_CLASSES, TARGET_POSITIONS, AGENT_POSE, OBJECT_POSITIONS, OBJECT_VISIBLE, ACTION,
            "episode_index", "frame_index")


def _stacked(table: pa.Table, column: str) -> np.ndarray:
    """A fixed-length list column as one (rows, length) array."""
    return np.stack(table[column].to_numpy(zero_copy_only=False))


class SequenceWindows(Dataset):
    """Windows of ``window`` frames (every ``stride`` frames) of the LeRobot split at ``root``; with
    ``window=None``, one item per whole episode (lengths may differ: use batch_size=1).

    Item (T = window, K = MAX_OBJECTS = 5; metres, radians, world frame; ``mor.data.observations`` conventions):
      images (T, 3, H, W) float32 in [0, 1]; agent_pose (T, 3); object_positions (T, K, 2);
      visible (T, K) bool (in view by ``mor.sim.rules.visible``); held (T,) int64 (-1 none);
      actions (T,) int64 (taken after each frame, -1 after the last);
      object_classes (K,) int64 (-1 for absent slots); object_mask (K,) bool; target_positions (K, 2);
      episode_index, start_frame: int64 scalars.
    """

    def __init__(self, root: Path, window: int | None, stride: int = 1) -> None:
        if (window is not None and window < 1) or stride < 1:
            raise ValueError(f"window ({window}) and stride ({stride}) must be >= 1")
        files = sorted(Path(root).glob("data/*/*.parquet"))
        if not files:
            raise FileNotFoundError(f"{root}: no data/*/*.parquet; build the split with mor build-dataset")
        missing = sorted(set(_COLUMNS) - set(pq.read_schema(files[0]).names))
        if missing:
            raise ConfigError(f"{files[0]}: the dataset lacks {', '.join(missing)} (built by an older version); "
                              "rebuild it with mor build-dataset")
        self.table = pq.ParquetDataset(files).read(columns=list(_COLUMNS)).combine_chunks()
        self._images = pc.struct_field(self.table[IMAGE], "bytes")
        self.image_size = int(decode_png(self._images[0].as_py()).shape[0])
        episodes = self.table["episode_index"].to_numpy()
        self._labels = {
            "agent_pose": _stacked(self.table, AGENT_POSE).astype(np.float32),
            "object_positions": _stacked(self.table, OBJECT_POSITIONS).astype(np.float32).reshape(-1, MAX_OBJECTS, 2),
            "visible": _stacked(self.table, OBJECT_VISIBLE).astype(bool),
            "held": held_from_state(_stacked(self.table, STATE)),
            "actions": self.table[ACTION].to_numpy().astype(np.int64),  # shape (1,): lerobot stores a scalar
        }
        self._classes = _stacked(self.table, OBJECT_CLASSES)
        self._targets = _stacked(self.table, TARGET_POSITIONS).astype(np.float32).reshape(-1, MAX_OBJECTS, 2)
        self._episodes = episodes
        self._frames = self.table["frame_index"].to_numpy()
        starts, lengths = [], []
        boundaries = np.flatnonzero(np.diff(episodes)) + 1
        for first, end in zip(np.r_[0, boundaries], np.r_[boundaries, len(episodes)], strict=True):
            if window is None:
                starts.append(first)
                lengths.append(end - first)
            else:
                starts.extend(range(first, end - window + 1, stride))
        if not starts:
            longest = int(np.max(np.diff(np.r_[0, boundaries, len(episodes)])))
            raise ConfigError(f"{root}: the longest episode has {longest} frames, fewer than the window of {window}; "
                              "lower lnet.train.window or collect longer episodes (collect.episode_steps)")
        self.starts = np.asarray(starts, dtype=np.int64)
        self.lengths = np.asarray(lengths, dtype=np.int64) if window is None else np.full(len(starts), window)

    def __len__(self) -> int:
        return len(self.starts)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        start, length = int(self.starts[index]), int(self.lengths[index])
        rows = slice(start, start + length)
        images = np.stack([decode_png(self._images[i].as_py()) for i in range(start, start + length)])
        item = {name: torch.from_numpy(values[rows].copy()) for name, values in self._labels.items()}
        item["images"] = images_to_tensor(images)
        item["object_classes"] = torch.from_numpy(self._classes[start].copy())
        item["object_mask"] = item["object_classes"] >= 0
        item["target_positions"] = torch.from_numpy(self._targets[start].copy())
        item["episode_index"] = torch.tensor(int(self._episodes[start]))
        item["start_frame"] = torch.tensor(int(self._frames[start]))
        return item
