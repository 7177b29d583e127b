"""The dataset card's statistics: every number the card reports, computed from the manifest and the episodes.

``compute_stats`` reads the manifest, summarises every episode (poses, held, actions and header only: no image is
decoded) into an ``EpisodeSummary``, and aggregates the summaries into a ``CardStats``. Coverage is the evidence
that the random-action scheme (``mor.data.exploration``) covers the arena: the share of grid cells (cell centres
inside the arena) visited at least once, and how far episodes wander from their start.

To add a statistic: put what it needs from one episode in ``EpisodeSummary`` (filled by ``summarize_episode``,
which runs in worker processes, so keep it small), aggregate it in a function of the summaries and store the
result in a new ``CardStats`` field set by ``compute_stats`` (``coverage_stats`` is the pattern), and write its
section in ``mor.data.card.render_card``. Figures live in ``mor.data.card_figures``.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq

from mor.data.episode_io import EpisodeData, read_episode
from mor.data.manifest import SPLITS, manifest_version
from mor.data.parallel import ordered_map
from mor.data.visibility import visible_per_frame
from mor.errors import MorError
from mor.sim.arena import Arena
from mor.sim.catalog import N_CLASSES
from mor.sim.rules import Action

#: Side of a coverage-grid cell, metres.
COVERAGE_CELL: float = 0.25
SIM_SOURCE = "sim"


class CardError(MorError):
    """The card cannot be written from what was given (empty manifest, missing episode file)."""


# --------------------------------------------------------------------------------------------------- coverage


Extent = tuple[float, float, float, float]


def coverage_grid(arena: Arena, cell_size: float = COVERAGE_CELL) -> tuple[np.ndarray, np.ndarray, Extent]:
    """Cell edges covering the arena's bounding box: (x edges (nx+1,), y edges (ny+1,), extent
    (x_min, x_max, y_min, y_max) metres). The grid starts at the box's lower-left corner."""
    if cell_size <= 0:
        raise ValueError(f"cell_size: must be positive (got {cell_size})")
    low, high = arena.vertex_array.min(axis=0), arena.vertex_array.max(axis=0)
    nx, ny = (max(1, math.ceil((h - lo) / cell_size - 1e-9)) for lo, h in zip(low, high, strict=True))
    x_edges = low[0] + cell_size * np.arange(nx + 1)
    y_edges = low[1] + cell_size * np.arange(ny + 1)
    return x_edges, y_edges, (float(x_edges[0]), float(x_edges[-1]), float(y_edges[0]), float(y_edges[-1]))


def coverage_counts(positions: Iterable[np.ndarray], arena: Arena, cell_size: float = COVERAGE_CELL,
                    ) -> tuple[np.ndarray, Extent]:
    """Sum of 2-D histograms of ``positions`` (each (T, >=2) array, x and y in its first columns, metres).

    Returns (counts (ny, nx) int64, indexed [row = y, column = x] so that ``imshow(counts, origin="lower",
    extent=extent)`` draws it north up; extent). Positions outside the grid (should not happen) are dropped.
    """
    x_edges, y_edges, extent = coverage_grid(arena, cell_size)
    counts = np.zeros((len(y_edges) - 1, len(x_edges) - 1), np.int64)
    for xy in positions:
        xy = np.asarray(xy, np.float64)
        if xy.size:
            histogram, _, _ = np.histogram2d(xy[:, 1], xy[:, 0], bins=(y_edges, x_edges))
            counts += histogram.astype(np.int64)
    return counts, extent


def coverage_map(episodes: Iterable[EpisodeData], arena: Arena, cell_size: float = COVERAGE_CELL,
                 ) -> tuple[np.ndarray, Extent]:
    """2-D histogram of agent positions over every frame of ``episodes`` (images not needed) on a grid of
    ``cell_size`` metre cells over the arena's bounding box: (counts (ny, nx), extent); see ``coverage_counts``."""
    return coverage_counts((episode.agent_poses[:, :2] for episode in episodes), arena, cell_size)


def cell_centres(counts_shape: tuple[int, int], extent: Extent) -> tuple[np.ndarray, np.ndarray]:
    """(x (ny, nx), y (ny, nx)) metres: the centre of every cell of a grid of ``counts_shape`` over ``extent``."""
    ny, nx = counts_shape
    x_min, x_max, y_min, y_max = extent
    xs = x_min + (np.arange(nx) + 0.5) * (x_max - x_min) / nx
    ys = y_min + (np.arange(ny) + 0.5) * (y_max - y_min) / ny
    return np.meshgrid(xs, ys)


def inside_mask(counts_shape: tuple[int, int], extent: Extent, arena: Arena) -> np.ndarray:
    """(ny, nx) bool: the cells whose centre lies inside the arena (``arena.contains``)."""
    xs, ys = cell_centres(counts_shape, extent)
    return np.array([[arena.contains((x, y)) for x, y in zip(row_x, row_y, strict=True)]
                     for row_x, row_y in zip(xs, ys, strict=True)], dtype=bool).reshape(counts_shape)


def coverage_fraction(counts: np.ndarray, extent: Extent, arena: Arena) -> float:
    """Share of the cells inside the arena (centre inside) visited at least once, in [0, 1]."""
    inside = inside_mask(counts.shape, extent, arena)
    if not inside.any():
        raise ValueError("coverage_fraction: no grid cell centre lies inside the arena; use a smaller cell_size")
    return float(np.count_nonzero((counts > 0) & inside) / np.count_nonzero(inside))


def cell_clearance(counts_shape: tuple[int, int], extent: Extent, arena: Arena) -> np.ndarray:
    """(ny, nx) metres: each cell centre's distance to the nearest wall (negative outside the arena)."""
    xs, ys = cell_centres(counts_shape, extent)
    return np.array([arena.clearance(np.array((x, y))) for x, y in zip(xs.ravel(), ys.ravel(), strict=True)]
                    ).reshape(counts_shape)


def displacement_from_start(agent_poses: np.ndarray) -> np.ndarray:
    """(T,) metres: distance of the agent from its first position at every frame."""
    xy = np.asarray(agent_poses, np.float64)[:, :2]
    return np.linalg.norm(xy - xy[:1], axis=1) if len(xy) else np.zeros(0)


def mean_displacement(episode: EpisodeData) -> float:
    """Mean over the episode's frames of the agent's distance from its start (metres)."""
    distances = displacement_from_start(episode.agent_poses)
    return float(distances.mean()) if len(distances) else 0.0


def median_mean_displacement(episodes: Iterable[EpisodeData]) -> float:
    """Median over episodes of each episode's mean displacement from its start (metres)."""
    values = [mean_displacement(episode) for episode in episodes]
    return float(np.median(values)) if values else float("nan")


# ------------------------------------------------------------------------------------------------ events


@dataclass(frozen=True)
class EpisodeEvents:
    """Per-episode counts: PICK / DROP actions taken, and actual picks / drops (changes of ``held``)."""

    pick_actions: int
    drop_actions: int
    picks: int
    drops: int


def episode_events(episode: EpisodeData) -> EpisodeEvents:
    """PICK (3) and DROP (4) actions in ``episode.actions``; picks = frames where ``held`` goes from -1 to an
    object, drops = from an object to -1 (a direct swap, impossible in the simulator, would count as both)."""
    actions, held = np.asarray(episode.actions), np.asarray(episode.held)
    before, after = held[:-1], held[1:]
    changed = before != after
    return EpisodeEvents(
        pick_actions=int(np.count_nonzero(actions == Action.PICK)),
        drop_actions=int(np.count_nonzero(actions == Action.DROP)),
        picks=int(np.count_nonzero(changed & (after >= 0))),
        drops=int(np.count_nonzero(changed & (before >= 0))),
    )


# ------------------------------------------------------------------------------------------- summaries


@dataclass(frozen=True)
class EpisodeSummary:
    """What the card needs from one episode (no images): small enough to send between processes."""

    episode_id: str
    source: str
    n_frames: int
    fps: float
    positions: np.ndarray  # (T, 2) float32, metres
    mean_displacement: float
    max_displacement: float
    events: EpisodeEvents
    action_counts: tuple[int, ...]  # per Action value
    object_classes: tuple[int, ...]
    wall_textures: tuple[int, ...]
    episode_steps: int | None  # the collection's horizon, when the episode's params record it
    params_json: str  # the parameters recorded in the episode's metadata, as sorted JSON
    visible_frames: tuple[int, ...] = ()  # per object: frames it is in view (``mor.data.visibility``)
    any_visible_frames: int = 0  # frames with at least one object in view
    visible_distances: tuple[float, ...] = ()  # agent-object distance (m) on every (frame, object) in view


def summarize_episode(episode: EpisodeData) -> EpisodeSummary:
    """What the card needs from ``episode`` (its images are not used)."""
    distances = displacement_from_start(episode.agent_poses)
    actions = np.asarray(episode.actions)
    visible = visible_per_frame(episode.agent_poses, episode.object_positions, episode.held)
    ranges = np.linalg.norm(episode.object_positions - episode.agent_poses[:, None, :2], axis=-1)
    steps = episode.header.params.get("episode_steps") if isinstance(episode.header.params, dict) else None
    return EpisodeSummary(
        episode_id=episode.header.episode_id, source=episode.header.source, n_frames=episode.n_frames,
        fps=float(episode.header.fps), positions=episode.agent_poses[:, :2].astype(np.float32),
        mean_displacement=float(distances.mean()) if len(distances) else 0.0,
        max_displacement=float(distances.max()) if len(distances) else 0.0,
        events=episode_events(episode),
        action_counts=tuple(int(np.count_nonzero(actions == a)) for a in Action),
        object_classes=tuple(int(c) for c in episode.header.object_classes),
        wall_textures=tuple(int(t) for t in episode.header.wall_textures),
        episode_steps=int(steps) if isinstance(steps, int | float) else None,
        params_json=json.dumps(plain(episode.header.params), sort_keys=True),
        visible_frames=tuple(int(v) for v in visible.sum(0)), any_visible_frames=int(visible.any(1).sum()),
        visible_distances=tuple(float(d) for d in ranges[visible]),
    )


def _summarize_path(path: Path) -> EpisodeSummary:
    return summarize_episode(read_episode(path, with_images=False))


def summarize_files(paths: Sequence[Path], workers: int = 1, progress: bool = True) -> list[EpisodeSummary]:
    """Summaries of ``paths`` in order, read without images, in ``workers`` processes; a tqdm bar over episodes."""
    missing = [str(p) for p in paths if not Path(p).is_file()]
    if missing:
        raise CardError(f"{missing[0]}: episode file named in the manifest is missing ({len(missing)} in all); "
                        "re-collect or rebuild the manifest")
    return ordered_map(_summarize_path, paths, workers, "card", progress, chunksize=8)


def class_histogram(summaries: Iterable[EpisodeSummary]) -> np.ndarray:
    """(N_CLASSES,) int: objects of each class over all episodes."""
    counts = np.zeros(N_CLASSES, np.int64)
    for summary in summaries:
        for class_id in summary.object_classes:
            if 0 <= class_id < N_CLASSES:
                counts[class_id] += 1
    return counts


def texture_histograms(summaries: Iterable[EpisodeSummary]) -> list[Counter[int]]:
    """Per wall side k, a Counter of texture indices drawn (sim episodes with wall textures only)."""
    sides: list[Counter[int]] = []
    for summary in summaries:
        for k, texture in enumerate(summary.wall_textures):
            while len(sides) <= k:
                sides.append(Counter())
            sides[k][texture] += 1
    return sides


# --------------------------------------------------------------------------------------------- statistics


def describe(values: Sequence[float]) -> dict[str, float]:
    """Mean, median, min and max of ``values`` (NaN for each when empty)."""
    array = np.asarray(values, np.float64)
    if not len(array):
        return {"mean": float("nan"), "median": float("nan"), "min": float("nan"), "max": float("nan")}
    return {"mean": float(array.mean()), "median": float(np.median(array)), "min": float(array.min()),
            "max": float(array.max())}


@dataclass(frozen=True)
class CoverageStats:
    """Where the agent went: the coverage grid and the numbers the card reports about it (metres)."""

    counts: np.ndarray  # (ny, nx) frames per cell, see ``coverage_counts``
    extent: Extent
    cell_size: float
    coverage_fraction: float
    inside_cells: int
    visited_cells: int
    median_mean_displacement: float
    median_max_displacement: float
    interior_fraction: float  # coverage of the cells at least one cell from every wall
    interior_cells: int
    band_width: float  # metres: the wall band of the two figures below
    band_frame_share: float  # share of frames in the cells whose centre is within band_width of a wall
    band_cell_share: float  # share of the inside cells that are in that band
    episodes: int  # episodes in these statistics
    sim_only: bool  # whether real episodes were left out of them


def coverage_stats(summaries: Sequence[EpisodeSummary], arena: Arena, cell_size: float = COVERAGE_CELL,
                   ) -> CoverageStats:
    """Coverage of ``summaries``' agent positions on a ``cell_size`` metre grid over ``arena``.

    Coverage is the evidence for the random-action scheme, which drives the simulator only: real runs (another
    arena, another policy) are left out when there are simulated episodes.
    """
    covered = [s for s in summaries if s.source == SIM_SOURCE] or list(summaries)
    counts, extent = coverage_counts((s.positions for s in covered), arena, cell_size)
    inside = inside_mask(counts.shape, extent, arena)
    clearance = cell_clearance(counts.shape, extent, arena)
    interior = clearance >= cell_size
    band_width = 2 * cell_size
    band = inside & (clearance < band_width)
    return CoverageStats(
        counts=counts, extent=extent, cell_size=cell_size,
        coverage_fraction=coverage_fraction(counts, extent, arena), inside_cells=int(np.count_nonzero(inside)),
        visited_cells=int(np.count_nonzero(inside & (counts > 0))),
        median_mean_displacement=float(np.median([s.mean_displacement for s in covered])),
        median_max_displacement=float(np.median([s.max_displacement for s in covered])),
        interior_fraction=float(np.count_nonzero(interior & (counts > 0)) / max(1, np.count_nonzero(interior))),
        interior_cells=int(np.count_nonzero(interior)), band_width=band_width,
        band_frame_share=float(counts[band].sum() / max(1, counts.sum())),
        band_cell_share=float(np.count_nonzero(band) / max(1, np.count_nonzero(inside))),
        episodes=len(covered), sim_only=len(covered) < len(summaries),
    )


@dataclass(frozen=True)
class VisibilityStats:
    """How often the objects are in view (``mor.sim.rules.visible``, the dataset's ``ground_truth.object_visible``)."""

    object_frame_share: float  # share of (frame, object) pairs with the object in view
    any_frame_share: float  # share of frames with at least one object in view
    never_seen_share: float  # share of (episode, object) pairs never in view in the episode
    median_distance: float  # median agent-object distance (m) when in view
    episodes: int


def visibility_stats(summaries: Sequence[EpisodeSummary]) -> VisibilityStats:
    """Visibility over all ``summaries`` (episodes without visibility records count as none in view)."""
    pairs = sum(s.n_frames * len(s.object_classes) for s in summaries)
    per_object = [v for s in summaries for v in s.visible_frames]
    distances = [d for s in summaries for d in s.visible_distances]
    return VisibilityStats(
        object_frame_share=sum(per_object) / max(1, pairs),
        any_frame_share=sum(s.any_visible_frames for s in summaries) / max(1, sum(s.n_frames for s in summaries)),
        never_seen_share=sum(v == 0 for v in per_object) / max(1, len(per_object)),
        median_distance=float(np.median(distances)) if distances else float("nan"), episodes=len(summaries))


@dataclass
class CardStats:
    """Everything the card reports, computed from the manifest and the episodes."""

    version: str
    rows: list[dict[str, Any]]  # manifest rows
    summaries: list[EpisodeSummary]
    coverage: CoverageStats
    classes: np.ndarray  # (N_CLASSES,) objects per class
    textures: list[Counter[int]]  # per wall side, texture index -> draws
    visibility: VisibilityStats | None = None
    recorded_params: list[tuple[str, int]] = field(default_factory=list)  # (params JSON, episodes), most first
    image_size: int | None = None  # read from the example frames
    frame_captions: list[tuple[str, list[int]]] = field(default_factory=list)  # (episode id, frame indices)

    def split_table(self) -> list[tuple[str, str, int, int]]:
        """(split, source, episodes, frames) for every split x source present, in SPLITS order."""
        table: dict[tuple[str, str], list[int]] = {}
        for row in self.rows:
            entry = table.setdefault((row["split"], row["source"]), [0, 0])
            entry[0] += 1
            entry[1] += int(row["n_frames"])
        order = {s: i for i, s in enumerate(SPLITS)}
        return [(split, source, e, f) for (split, source), (e, f)
                in sorted(table.items(), key=lambda kv: (order.get(kv[0][0], len(order)), kv[0]))]

    def per(self, key: str) -> dict[str, tuple[int, int]]:
        """{value of ``key`` (split or source): (episodes, frames)}."""
        out: dict[str, list[int]] = {}
        for row in self.rows:
            entry = out.setdefault(row[key], [0, 0])
            entry[0] += 1
            entry[1] += int(row["n_frames"])
        return {k: (e, f) for k, (e, f) in out.items()}


def compute_stats(manifest_path: Path, episodes_root: Path, arena: Arena, cell_size: float = COVERAGE_CELL,
                  workers: int = 1, progress: bool = True) -> CardStats:
    """Read the manifest and summarise every episode it lists (without images, in ``workers`` processes)."""
    table = pq.read_table(manifest_path)
    rows = table.to_pylist()
    if not rows:
        raise CardError(f"{manifest_path}: the manifest lists no episode; collect episodes first")
    try:
        version = manifest_version(table)
    except (KeyError, TypeError):
        raise CardError(f"{manifest_path}: no dataset_version in the manifest's metadata; rebuild it") from None
    summaries = summarize_files([Path(episodes_root) / row["file"] for row in rows], workers, progress)
    return CardStats(
        version=version, rows=rows, summaries=summaries, coverage=coverage_stats(summaries, arena, cell_size),
        classes=class_histogram(summaries), textures=texture_histograms(summaries),
        visibility=visibility_stats(summaries),
        recorded_params=sorted(Counter(s.params_json for s in summaries).items(), key=lambda kv: -kv[1]),
    )


def plain(value: Any) -> Any:
    """``value`` as plain YAML/JSON types (pydantic models, paths, numpy values, tuples)."""
    if hasattr(value, "model_dump"):
        return plain(value.model_dump())
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value
