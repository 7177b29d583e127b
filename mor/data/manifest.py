"""The manifest (Parquet): one row per episode file, its split, and the dataset version.

Splits are 8:1:1 (train / validation / test) by a hash of the episode id alone, so adding episodes never moves an
existing one to another split. The dataset version is a hash of every (episode id, file sha256) pair.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from mor.atomic import atomic_output
from mor.data.episode_io import read_metadata
from mor.errors import MorError

SPLITS: tuple[str, ...] = ("train", "validation", "test")
MANIFEST_SCHEMA = pa.schema([
    ("episode_id", pa.string()),
    ("source", pa.string()),
    ("seed", pa.int64()),
    ("file", pa.string()),
    ("sha256", pa.string()),
    ("n_frames", pa.int64()),
    ("split", pa.string()),
])


def episode_split(episode_id: str) -> str:
    """train for 8 of every 10 hash buckets, validation for 1, test for 1; depends on the id only."""
    bucket = int(hashlib.sha256(episode_id.encode()).hexdigest()[:8], 16) % 10
    return "train" if bucket < 8 else ("validation" if bucket == 8 else "test")


def file_sha256(path: Path) -> str:
    """Hex sha256 of a file's bytes."""
    with open(path, "rb") as stream:
        return hashlib.file_digest(stream, "sha256").hexdigest()


def dataset_version(episode_ids: list[str], hashes: list[str]) -> str:
    """A 12-hex-digit content hash of the episodes (order-independent)."""
    digest = hashlib.sha256()
    for episode, sha in sorted(zip(episode_ids, hashes, strict=True)):
        digest.update(f"{episode} {sha}\n".encode())
    return digest.hexdigest()[:12]


def build_manifest(episode_files: list[Path], root: Path) -> pa.Table:
    """The manifest of ``episode_files`` (paths stored relative to ``root``), sorted by episode id."""
    rows = []
    for path in episode_files:
        metadata = read_metadata(path)
        rows.append({
            "episode_id": metadata["episode_id"], "source": metadata["source"],
            "seed": int(metadata["seed"]) if metadata["seed"] else None,
            "file": str(path.relative_to(root)), "sha256": file_sha256(path),
            "n_frames": int(metadata["n_frames"]), "split": episode_split(metadata["episode_id"]),
        })
    rows.sort(key=lambda row: row["episode_id"])
    table = pa.Table.from_pylist(rows, schema=MANIFEST_SCHEMA)
    version = dataset_version(table["episode_id"].to_pylist(), table["sha256"].to_pylist())
    return table.replace_schema_metadata({"dataset_version": version})


def manifest_version(table: pa.Table) -> str:
    return table.schema.metadata[b"dataset_version"].decode()


def write_manifest(table: pa.Table, path: Path) -> Path:
    """Write through a temporary name, then rename."""
    with atomic_output(path) as partial:
        pq.write_table(table, partial)
    return path


def read_manifest(path: Path) -> pa.Table:
    """The manifest at ``path``; a missing file is a one-line MorError saying how to make it."""
    if not path.is_file():
        raise MorError(f"{path}: no manifest; run mor build-dataset first")
    return pq.read_table(path)
