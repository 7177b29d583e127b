"""The manifest (Parquet): one row per episode file, its split, and the dataset version.

Splits are 8:1:1 (train / validation / test) by a hash of the episode id alone, so adding episodes never moves an
existing one to another split. The dataset version is a hash of every (episode id, file sha256) pair and of the
profile's data-shaping params (``ProfileShape.data_params``).

A manifest lists only episodes that a build has read whole (every message decoded), and every one made with the
profile's data-shaping params: ``build_manifest`` checks each file and refuses the lot (one line) when any is bad,
so the pipeline writes the manifest only after the build has read every episode. A file keeps the bytes it was
listed with (``changed_since_listed``): build and validation both refuse one that changed.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from mor.atomic import atomic_output
from mor.data.collect import ProfileShape
from mor.data.episode_io import REDO, EpisodeFileError, read_metadata, verify_episode
from mor.data.parallel import ordered_map
from mor.data.schema import DATASET_LAYOUT
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


def dataset_version(episode_ids: list[str], hashes: list[str], data_params: dict[str, Any]) -> str:
    """A 12-hex-digit content hash of the episodes (order-independent), the params that shaped them and the
    dataset's layout (``schema.DATASET_LAYOUT``)."""
    digest = hashlib.sha256(f"layout {DATASET_LAYOUT}\n".encode())
    digest.update(json.dumps(data_params, sort_keys=True).encode() + b"\n")
    for episode, sha in sorted(zip(episode_ids, hashes, strict=True)):
        digest.update(f"{episode} {sha}\n".encode())
    return digest.hexdigest()[:12]


class EpisodesRejected(MorError):
    """Episode files a build cannot use (unreadable, or made with other data-shaping params); ``problems`` has
    one line per file, the message one line for all."""

    def __init__(self, problems: list[str], files: list[Path]) -> None:
        names = ", ".join(path.name for path in files[:5]) + (", ..." if len(files) > 5 else "")
        more = f" ({len(files)} bad files: {names})" if len(files) > 1 else ""
        super().__init__(f"{problems[0]}{more}; the manifest is unchanged")
        self.problems, self.files = problems, files


VERIFIED_KEY = b"episodes_decoded"  # schema metadata of manifests whose every episode was decoded by a build


@dataclass(frozen=True)
class ListedFiles:
    """What a previous manifest says of its episode files: {file: sha256}, and whether the build that wrote it
    decoded every one of them (only then may a later build skip decoding a file with the same sha256)."""

    sha256: dict[str, str] = field(default_factory=dict)
    decoded: bool = False


def listed_files(path: Path) -> ListedFiles:
    """The files the manifest at ``path`` lists (none if there is no manifest or it cannot be read)."""
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException):
        return ListedFiles()
    return ListedFiles(dict(zip(table["file"].to_pylist(), table["sha256"].to_pylist(), strict=True)),
                       (table.schema.metadata or {}).get(VERIFIED_KEY) == b"1")


def changed_since_listed(path: Path, sha256: str, listed_sha256: str | None) -> str | None:
    """The rule build and validation share: a file a manifest lists keeps the bytes it was listed with (a byte
    flipped where no reader looks still changes them). None if it does (or is not listed), else one line."""
    if listed_sha256 is None or sha256 == listed_sha256:
        return None
    return (f"{path}: its bytes changed since the build that listed it (sha256 differs from the manifest's); {REDO}"
            f", or delete the manifest if it was re-made on purpose")


def _inspect(job: tuple[Path, ProfileShape, str | None, bool]) -> tuple[dict[str, str] | None, str, str | None]:
    """(metadata, sha256, problem) of one episode file: decoded whole unless a decoding build (``decoded``) listed it
    with its sha256, then refused (as ``check_episode_file`` does) if it is listed with another sha256."""
    path, shape, listed_sha, decoded = job
    sha = file_sha256(path)
    try:
        metadata = read_metadata(path) if decoded and listed_sha == sha else verify_episode(path)
    except EpisodeFileError as error:
        return None, sha, str(error)
    return metadata, sha, changed_since_listed(path, sha, listed_sha) or shape.mismatch(path, metadata)


def build_manifest(episode_files: list[Path], root: Path, shape: ProfileShape, listed: ListedFiles | None = None,
                   workers: int = 1, progress: bool = False) -> pa.Table:
    """The manifest of ``episode_files`` (paths stored relative to ``root``), sorted by episode id.

    Every file is decoded whole (``verify_episode``, in ``workers`` processes) unless ``listed`` (``listed_files``
    of the previous manifest, written by a decoding build) lists it with the same sha256; one it lists with another
    sha256 is refused (``changed_since_listed``), and every file's params are compared with ``shape``'s. Raises
    EpisodesRejected naming the bad files when any is unreadable, changed or made with other data-shaping params.
    """
    listed = listed or ListedFiles()
    jobs = [(path, shape, listed.sha256.get(str(path.relative_to(root))), listed.decoded) for path in episode_files]
    rows, problems, bad = [], [], []
    for path, (metadata, sha, problem) in zip(
            episode_files, ordered_map(_inspect, jobs, workers, "manifest", progress), strict=True):
        if problem or metadata is None:
            problems.append(problem)
            bad.append(path)
            continue
        rows.append({
            "episode_id": metadata["episode_id"], "source": metadata["source"],
            "seed": int(metadata["seed"]) if metadata["seed"] else None,
            "file": str(path.relative_to(root)), "sha256": sha,
            "n_frames": int(metadata["n_frames"]), "split": episode_split(metadata["episode_id"]),
        })
    if problems:
        raise EpisodesRejected(problems, bad)
    rows.sort(key=lambda row: row["episode_id"])
    table = pa.Table.from_pylist(rows, schema=MANIFEST_SCHEMA)
    version = dataset_version(table["episode_id"].to_pylist(), table["sha256"].to_pylist(), shape.data_params())
    return table.replace_schema_metadata({"dataset_version": version, VERIFIED_KEY: "1"})


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
