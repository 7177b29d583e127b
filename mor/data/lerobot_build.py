"""One LeRobot v3.0 dataset per split, written with lerobot's own ``LeRobotDataset`` API (PNG frames, no video)."""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import logging
import multiprocessing as mp
import os
import shutil
import tempfile
import types
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from tqdm import tqdm

if TYPE_CHECKING:
    import datasets

os.environ.setdefault("HF_HUB_OFFLINE", "1")
# lerobot warns on import that torchcodec is missing; image datasets never decode video, so say it once, not per shard.
logging.getLogger("lerobot.utils.import_utils").setLevel(logging.ERROR)

from mor.atomic import atomic_folder, remove_if_orphaned  # noqa: E402
from mor.data import schema  # noqa: E402
from mor.data.episode_io import EpisodeData, read_episode  # noqa: E402
from mor.data.manifest import SPLITS  # noqa: E402
from mor.data.observations import observation_state, pad_classes  # noqa: E402
from mor.data.schema import MAX_OBJECTS, NO_ACTION, lerobot_features  # noqa: E402
from mor.data.visibility import visible_per_frame  # noqa: E402

TASK_TEXT = "rearrange the objects to their targets"
ROBOT_TYPE = "mor_turtlebot"
BUILD_STAMP = "mor_build.json"


def _padded(values: np.ndarray, fill: float, dtype: type) -> np.ndarray:
    """Pad the object axis (first) of ``values`` to MAX_OBJECTS and flatten."""
    out = np.full((MAX_OBJECTS, *values.shape[1:]), fill, dtype=dtype)
    out[: len(values)] = values
    return out.reshape(-1)


def episode_frames(episode: EpisodeData) -> list[dict[str, np.ndarray | str]]:
    """The LeRobot frames of one episode, in ``lerobot_features`` layout."""
    header = episode.header
    classes = pad_classes(header.object_classes)
    targets = _padded(np.asarray(header.target_positions), 0.0, np.float32)
    visible = visible_per_frame(episode.agent_poses, episode.object_positions, episode.held)
    actions = np.asarray(episode.actions, np.int64)
    state = observation_state(episode.held, np.r_[NO_ACTION, actions[:-1]])
    return [
        {
            schema.IMAGE: episode.images[t],
            schema.STATE: state[t],
            schema.OBJECT_CLASSES: classes,
            schema.TARGET_POSITIONS: targets,
            schema.AGENT_POSE: episode.agent_poses[t].astype(np.float32),
            schema.OBJECT_POSITIONS: _padded(episode.object_positions[t], 0.0, np.float32),
            schema.OBJECT_VISIBLE: _padded(visible[t], 0, np.int64),
            schema.ACTION: actions[t:t + 1],
            "task": TASK_TEXT,
        }
        for t in range(episode.n_frames)
    ]


def embed_images_batched(dataset: datasets.Dataset) -> datasets.Dataset:
    """lerobot's ``embed_images``, one Arrow batch per call instead of one row per call.

    lerobot 0.6.1 embeds PNG bytes with ``Dataset.map(embed_table_storage, batched=False)``: the function is
    applied to one-row tables, and each call rebuilds the feature schema (in a profile of a shard build, more than
    half of its time, and nearly all of the aggregation's). ``embed_table_storage`` is a per-row function of the table,
    so applying it to whole batches writes the same table; ``tests/data/test_build.py`` checks that it does.
    """
    from datasets.table import embed_table_storage  # noqa: PLC0415 - heavy import

    original_format = dataset.format
    embedded = dataset.with_format("arrow").map(embed_table_storage, batched=True)
    return embedded.with_format(**original_format)


@contextlib.contextmanager
def batched_image_embedding() -> Iterator[None]:
    """Within the block, lerobot's dataset writer and aggregation embed images with ``embed_images_batched``."""
    from lerobot.datasets import dataset_writer, io_utils  # noqa: PLC0415 - heavy import

    originals = {module: module.embed_images for module in (dataset_writer, io_utils)}
    for module in originals:
        module.embed_images = embed_images_batched
    try:
        yield
    finally:
        for module, original in originals.items():
            module.embed_images = original


#: The loggers of the libraries a build drives; during a build they pass errors only (``quiet_libraries``).
LIBRARY_LOGGERS: tuple[str, ...] = ("lerobot", "datasets")


@contextlib.contextmanager
def quiet_libraries() -> Iterator[None]:
    """Within the block, lerobot and Hugging Face ``datasets`` draw no progress bars of their own and log errors
    only, so that a build shows one bar per step, its own.

    Without it, lerobot's aggregation draws "Validate all meta data" and "Copy data and videos" per split, and
    ``datasets`` a "Generating train split" and a "Map" bar per shard (named "train" whatever the split).
    ``datasets.utils.logging.disable_progress_bar`` alone does not hold: lerobot 0.6.1 wraps each Parquet load in
    its ``SuppressProgressBars``, which turns ``datasets``' bars back on when it exits, so within the block that
    wrapper does nothing (the bars are off already). Errors still reach the log, and exceptions pass through
    unchanged. Everything is restored on leaving the block.
    """
    from datasets.utils import logging as datasets_logging  # noqa: PLC0415 - heavy import
    from lerobot.datasets import aggregate, io_utils  # noqa: PLC0415 - heavy import

    bars_were_enabled = datasets_logging.is_progress_bar_enabled()
    levels = {name: logging.getLogger(name).level for name in LIBRARY_LOGGERS}
    originals = {(aggregate, "tqdm"): aggregate.tqdm,
                 (io_utils, "SuppressProgressBars"): io_utils.SuppressProgressBars}
    datasets_logging.disable_progress_bar()
    for name in LIBRARY_LOGGERS:
        logging.getLogger(name).setLevel(logging.ERROR)
    aggregate.tqdm = types.SimpleNamespace(tqdm=functools.partial(tqdm, disable=True))  # it calls tqdm.tqdm(...)
    io_utils.SuppressProgressBars = contextlib.nullcontext
    try:
        yield
    finally:
        for (module, name), original in originals.items():
            setattr(module, name, original)
        for name, level in levels.items():
            logging.getLogger(name).setLevel(level)
        if bars_were_enabled:
            datasets_logging.enable_progress_bar()


def sort_stats(root: Path) -> None:
    """Rewrite the LeRobot dataset's ``meta/stats.json`` with its features in sorted order.

    lerobot's ``aggregate_stats`` orders the features by iterating a set, so the order (and the file's bytes)
    changes with ``PYTHONHASHSEED``; sorted, the same episodes always give the same dataset bytes.
    """
    from lerobot.datasets.io_utils import load_stats, write_stats  # noqa: PLC0415 - heavy import

    stats = load_stats(root)
    if stats is not None:
        write_stats(dict(sorted(stats.items())), root)


def _stamp(root: Path) -> dict:
    stamp = root / BUILD_STAMP
    return json.loads(stamp.read_text()) if stamp.is_file() else {}


SCRATCH_MIN_FREE_BYTES = 1 << 30  # a shard in progress needs tens of MB per worker; containers often cap /dev/shm at 64 MB


def scratch_dir() -> Path | None:
    """A RAM-backed folder for the files lerobot writes per frame, where the machine has one with at least
    ``SCRATCH_MIN_FREE_BYTES`` free (else None: the system's temporary folder).

    lerobot writes every frame to its own PNG file and reads it back when the episode is saved. Creating a file
    on these machines' disks costs far more than on tmpfs, and a shard creates one per frame.
    """
    shm = Path("/dev/shm")
    if shm.is_dir() and os.access(shm, os.W_OK) and shutil.disk_usage(shm).free >= SCRATCH_MIN_FREE_BYTES:
        return shm
    return None


SCRATCH_PREFIX = "mor-build-"


def scratch_prefix() -> str:
    """The name prefix of this process's scratch folders: ``mor-build-<pid>-`` (the pid tells whose it is)."""
    return f"{SCRATCH_PREFIX}{os.getpid()}-"


def remove_stale_scratch(folders: tuple[Path | None, ...] | None = None) -> list[Path]:
    """Delete the scratch folders that builds killed mid-shard (kill -9) left behind; returns them.

    A folder is stale when its name is ``mor-build-<pid>-*``, this user owns it, and process ``pid`` is gone (on
    this machine); a live build's folders, other users' and names without a pid are left alone. ``folders``
    defaults to both places a build writes scratch: ``scratch_dir()`` and the system's temporary folder.
    """
    if folders is None:
        folders = (scratch_dir(), Path(tempfile.gettempdir()))
    removed = []
    for folder in {Path(f) for f in folders if f is not None}:
        for path in folder.glob(f"{SCRATCH_PREFIX}*"):
            if remove_if_orphaned(path, path.name.removeprefix(SCRATCH_PREFIX).split("-", 1)[0]):
                removed.append(path)
    return removed


def write_lerobot_dataset(
    episode_files: list[Path], root: Path, repo_id: str, stamp: dict, image_size: int, fps: float
) -> Path:
    """Write ``episode_files`` as one LeRobot dataset at ``root``.

    The dataset is written in a scratch folder (``scratch_dir``), then published at ``root`` as a whole
    (``atomic_folder``), so ``root`` is either absent or whole.
    """
    from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: PLC0415 - heavy import

    with tempfile.TemporaryDirectory(prefix=scratch_prefix(), dir=scratch_dir()) as scratch:
        work = Path(scratch) / root.name
        dataset = LeRobotDataset.create(repo_id=repo_id, fps=int(round(fps)), root=work,
                                        features=lerobot_features(image_size), robot_type=ROBOT_TYPE,
                                        use_videos=False)
        with batched_image_embedding():
            for path in episode_files:
                for frame in episode_frames(read_episode(path)):
                    dataset.add_frame(frame)
                dataset.save_episode()
            dataset.finalize()
        (work / BUILD_STAMP).write_text(json.dumps(stamp) + "\n")
        with atomic_folder(root) as folder:
            shutil.copytree(work, folder, dirs_exist_ok=True)
    return root


@dataclass(frozen=True)
class ShardJob:
    """A slice of one split, built as its own LeRobot dataset and aggregated afterwards."""

    split: str
    index: int
    files: tuple[Path, ...]
    root: Path
    stamp: dict

    def done(self) -> bool:
        return _stamp(self.root) == self.stamp


def _build_shard(job: ShardJob, image_size: int, fps: float) -> int:
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    with quiet_libraries():  # one bar per episode from lerobot's internals would drown ours
        write_lerobot_dataset(list(job.files), job.root, f"mor/{job.split}-shard{job.index:03d}", job.stamp,
                              image_size, fps)
    return len(job.files)


def _build_shard_job(args: tuple[ShardJob, int, float]) -> int:
    return _build_shard(*args)


def _shard_jobs(split: str, files: list[Path], hashes: list[str], shards_dir: Path, shard_episodes: int,
                version: str) -> list[ShardJob]:
    jobs = []
    for index, start in enumerate(range(0, len(files), shard_episodes)):
        chunk = files[start:start + shard_episodes]
        content = hashlib.sha256("".join(hashes[start:start + shard_episodes]).encode()).hexdigest()[:16]
        jobs.append(ShardJob(split, index, tuple(chunk), shards_dir / split / f"shard-{index:03d}",
                             {"dataset_version": version, "split": split, "shard": index, "content": content,
                              "episodes": len(chunk)}))
    return jobs


def _aggregate_split(split_root: Path, split: str, jobs: list[ShardJob], stamp: dict) -> None:
    """Join the shards ``jobs`` of ``split`` into one LeRobot dataset at ``split_root``, stamped with ``stamp``."""
    from lerobot.datasets.aggregate import aggregate_datasets  # noqa: PLC0415 - heavy import

    with atomic_folder(split_root) as folder:
        if jobs:
            folder.rmdir()  # lerobot makes the folder it aggregates into
            # One Parquet file per shard: concatenating image tables re-reads and rewrites the growing file
            # for every shard (quadratic), while a new file per shard is linear and loads the same way.
            with batched_image_embedding():
                aggregate_datasets([f"mor/{split}-shard{job.index:03d}" for job in jobs], f"mor/{split}",
                                   roots=[job.root for job in jobs], aggr_root=folder, concatenate_data=False)
            sort_stats(folder)
        (folder / BUILD_STAMP).write_text(json.dumps(stamp) + "\n")


def build_splits(
    manifest: list[dict], episodes_root: Path, out_root: Path, version: str, image_size: int, fps: float,
    workers: int, shard_episodes: int = 100, progress: bool = True,
) -> dict[str, int]:
    """Build ``out_root/<split>`` for every split of ``manifest`` (rows as dicts); returns episodes per split.

    Each split is built in shards of ``shard_episodes`` episodes, in ``workers`` processes, then aggregated with
    lerobot's ``aggregate_datasets``. Finished shards and splits of the same version are kept, so an interrupted
    build resumes where it stopped; scratch folders that killed builds left behind are deleted first
    (``remove_stale_scratch``). With ``progress``, one bar per step (``build``: episodes written into shards;
    ``aggregate``: shards joined into splits), and none of lerobot's or ``datasets``' own (``quiet_libraries``).
    """
    remove_stale_scratch()

    shards_dir = out_root / ".shards"
    counts: dict[str, int] = {}
    stamps: dict[str, dict] = {}
    jobs_by_split: dict[str, list[ShardJob]] = {}
    for split in SPLITS:
        rows = [row for row in manifest if row["split"] == split]
        counts[split] = len(rows)
        stamps[split] = {"dataset_version": version, "split": split, "episodes": len(rows)}
        if _stamp(out_root / split) == stamps[split]:
            continue
        files = [episodes_root / row["file"] for row in rows]
        jobs_by_split[split] = _shard_jobs(split, files, [row["sha256"] for row in rows], shards_dir,
                                           shard_episodes, version)
    pending = [job for jobs in jobs_by_split.values() for job in jobs if not job.done()]
    total = sum(len(job.files) for jobs in jobs_by_split.values() for job in jobs)
    with tqdm(total=total, initial=total - sum(len(j.files) for j in pending), desc="build", unit="ep",
              disable=not progress) as bar:
        if workers <= 1 or len(pending) <= 1:
            for job in pending:
                bar.update(_build_shard(job, image_size, fps))
        else:
            with mp.get_context("spawn").Pool(min(workers, len(pending))) as pool:
                for done in pool.imap_unordered(_build_shard_job, [(job, image_size, fps) for job in pending]):
                    bar.update(done)
                pool.close()  # let the workers exit on their own: terminated ones leak their tqdm locks' semaphores
                pool.join()
    with (quiet_libraries(), tqdm(total=sum(len(jobs) for jobs in jobs_by_split.values()), desc="aggregate",
                                  unit="shard", disable=not progress or not jobs_by_split) as bar):
        for split, jobs in jobs_by_split.items():
            bar.set_postfix_str(split)
            _aggregate_split(out_root / split, split, jobs, stamps[split])
            shutil.rmtree(shards_dir / split, ignore_errors=True)
            bar.update(len(jobs))
    shutil.rmtree(shards_dir, ignore_errors=True)
    return counts
