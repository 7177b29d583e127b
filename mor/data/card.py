"""The dataset card: a Hugging Face ``README.md`` with every number computed from the episodes, and its figures.

``write_dataset_card`` reads the manifest, summarises every episode (poses, held, actions and header only: no image
is decoded except for the few example frames), and writes into ``out_dir``:

- ``README.md``            the card (YAML front matter, then the sections; figures linked relatively)
- ``coverage.png``         where the agent went: a log-scale heat map of agent positions over all frames
- ``class_histogram.png``  objects per class (24 bars, coloured by the object colour, labelled by shape)
- ``wall_textures.png``    how often each wall texture was drawn, one panel per wall side (sim episodes only)
- ``example_frames.png``   first-person frames of a few episodes (one row per episode), nearest-neighbour upscaled

Coverage is the evidence that the random-action scheme (``mor.data.exploration``) covers the arena: the share of
grid cells (cell centres inside the arena) visited at least once, and how far episodes wander from their start.
Every file is written through a temporary name and renamed.
"""

from __future__ import annotations

import json
import math
import multiprocessing as mp
import posixpath
import re
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import yaml
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from tqdm import tqdm

from mor.atomic import atomic_output
from mor.data.episode_io import EpisodeData, read_episode
from mor.data.manifest import SPLITS, manifest_version
from mor.data.schema import MAX_OBJECTS, lerobot_features
from mor.errors import MorError
from mor.sim.arena import Arena
from mor.sim.catalog import ALL_WALL_TEXTURES, COLOUR_NAMES, N_CLASSES, SHAPES, TEXTURE_INDEX, WALL_POOLS, object_class
from mor.sim.rules import AGENT_RADIUS, Action
from mor.sim.views import write_png

#: Side of a coverage-grid cell, metres.
COVERAGE_CELL: float = 0.25
CARD_NAME = "README.md"
COVERAGE_PNG = "coverage.png"
CLASS_PNG = "class_histogram.png"
TEXTURE_PNG = "wall_textures.png"
FRAMES_PNG = "example_frames.png"
#: Upscaled size (pixels) of one example frame, at least.
FRAME_TILE: int = 128
LICENSE = "apache-2.0"
TAGS: tuple[str, ...] = ("LeRobot", "mor", "mobile-manipulation", "localization", "mujoco")
_DPI = 110
SIM_SOURCE = "sim"

#: Units and meaning of each LeRobot feature (``mor.data.schema.lerobot_features``).
FEATURE_UNITS: dict[str, tuple[str, str]] = {
    "observation.image": ("uint8 RGB", "first-person camera image"),
    "observation.object_classes": ("class id", "class of each object slot, -1 for an empty slot"),
    "observation.held": ("object index", "index of the held object, -1 when none"),
    "observation.target_positions": ("m, world frame", "target (x, y) of each object slot, 0 for an empty slot"),
    "state.agent_pose": ("m, m, rad; world frame", "ground-truth agent pose (x, y, heading)"),
    "state.object_positions": ("m, world frame", "ground-truth (x, y) of each object slot (held: the agent's)"),
    "action": ("action id", "action taken after this frame: 0 MOVE, 1 TURN_LEFT, 2 TURN_RIGHT, 3 PICK, 4 DROP; "
                            "-1 on an episode's last frame"),
}


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


def summarize_episode(episode: EpisodeData) -> EpisodeSummary:
    distances = displacement_from_start(episode.agent_poses)
    actions = np.asarray(episode.actions)
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
        params_json=json.dumps(_plain(episode.header.params), sort_keys=True),
    )


def _summarize_path(path: Path) -> EpisodeSummary:
    return summarize_episode(read_episode(path, with_images=False))


def summarize_files(paths: Sequence[Path], workers: int = 1, progress: bool = True) -> list[EpisodeSummary]:
    """Summaries of ``paths`` in order, read without images, in ``workers`` processes; a tqdm bar over episodes."""
    missing = [str(p) for p in paths if not Path(p).is_file()]
    if missing:
        raise CardError(f"{missing[0]}: episode file named in the manifest is missing ({len(missing)} in all); "
                        "re-collect or rebuild the manifest")
    with tqdm(total=len(paths), desc="card", unit="ep", disable=not progress) as bar:
        if workers <= 1 or len(paths) < 2 * workers:
            out = []
            for path in paths:
                out.append(_summarize_path(path))
                bar.update(1)
            return out
        with mp.get_context("spawn").Pool(workers) as pool:
            out = []
            for summary in pool.imap(_summarize_path, paths, chunksize=8):
                out.append(summary)
                bar.update(1)
            return out


# --------------------------------------------------------------------------------------------- figures


def _save(figure: Figure, path: Path) -> Path:
    with atomic_output(path) as partial:
        figure.savefig(partial, format="png", dpi=_DPI, bbox_inches="tight")
    return Path(path)


def _draw_walls(axes: Any, arena: Arena, label: bool = True) -> None:
    for k, (a, b) in enumerate(arena.walls()):
        axes.plot([a[0], b[0]], [a[1], b[1]], color="black", linewidth=2.5, solid_capstyle="round")
        if label:
            middle = (a + b) / 2
            inward = np.array([-(b - a)[1], (b - a)[0]]) / max(np.linalg.norm(b - a), 1e-9)
            x, y = middle + 0.1 * arena.half_extent * inward
            axes.text(x, y, f"wall {k}", ha="center", va="center", fontsize=8, color="black",
                      bbox={"boxstyle": "round,pad=0.2", "facecolor": "white", "alpha": 0.8, "linewidth": 0})


def write_coverage_png(counts: np.ndarray, extent: Extent, arena: Arena, path: Path,
                       fraction: float | None = None) -> Path:
    """Heat map of ``counts`` (log colour scale, frames per cell) with the arena's walls, axes in metres, a colour
    bar, and the coverage fraction in the title (computed when ``fraction`` is None). Cells inside the arena that
    were never visited are grey; cells outside are blank."""
    fraction = coverage_fraction(counts, extent, arena) if fraction is None else fraction
    inside = inside_mask(counts.shape, extent, arena)
    visited = np.ma.masked_where(~inside | (counts <= 0), counts.astype(np.float64))
    unvisited = np.ma.masked_where(~(inside & (counts <= 0)), np.ones(counts.shape))
    figure = Figure(figsize=(6.4, 5.6))
    axes = figure.add_subplot()
    axes.imshow(unvisited, origin="lower", extent=extent, cmap="Greys", vmin=0, vmax=2.5,
                interpolation="nearest")
    image = axes.imshow(visited, origin="lower", extent=extent, cmap="viridis", interpolation="nearest",
                        norm=LogNorm(vmin=1, vmax=max(2.0, float(counts.max()))))
    _draw_walls(axes, arena)
    cell = (extent[1] - extent[0]) / counts.shape[1]
    axes.set_title(f"Agent position coverage: {100 * fraction:.1f}% of {np.count_nonzero(inside)} cells "
                   f"({cell:g} m) visited\n{int(counts.sum())} frames", fontsize=10)
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.set_aspect("equal")
    pad = 0.05 * (extent[1] - extent[0])
    axes.set_xlim(extent[0] - pad, extent[1] + pad)
    axes.set_ylim(extent[2] - pad, extent[3] + pad)
    figure.colorbar(image, ax=axes, label="frames per cell (log scale)")
    if np.any(inside & (counts <= 0)):
        axes.legend(handles=[Patch(color="0.6", label="never visited")], loc="upper right", fontsize=8,
                    framealpha=0.9)
    return _save(figure, path)


def class_histogram(summaries: Iterable[EpisodeSummary]) -> np.ndarray:
    """(N_CLASSES,) int: objects of each class over all episodes."""
    counts = np.zeros(N_CLASSES, np.int64)
    for summary in summaries:
        for class_id in summary.object_classes:
            if 0 <= class_id < N_CLASSES:
                counts[class_id] += 1
    return counts


def write_class_histogram_png(counts: np.ndarray, path: Path, episodes: int) -> Path:
    """24 bars (objects per class over ``episodes`` episodes), each in its object's colour, labelled by shape;
    a dashed line marks the uniform expectation."""
    figure = Figure(figsize=(9.0, 3.6))
    axes = figure.add_subplot()
    classes = [object_class(c) for c in range(N_CLASSES)]
    axes.bar(np.arange(N_CLASSES), counts, color=[c.rgb for c in classes], edgecolor="black", linewidth=0.5)
    axes.axhline(counts.sum() / N_CLASSES, color="black", linestyle="--", linewidth=1,
                 label=f"uniform: {counts.sum() / N_CLASSES:.1f}")
    group = len(COLOUR_NAMES)  # class id = shape_index * 6 + colour_index: one group of bars per shape
    axes.set_xticks(np.arange(N_CLASSES), [str(c) for c in range(N_CLASSES)], fontsize=7)
    for index, shape in enumerate(SHAPES):
        axes.text(index * group + (group - 1) / 2, -0.09, shape, transform=axes.get_xaxis_transform(),
                  ha="center", va="top", fontsize=10)
        if index:
            axes.axvline(index * group - 0.5, color="0.6", linewidth=0.8)
    axes.set_xlim(-0.6, N_CLASSES - 0.4)
    axes.set_ylabel("objects")
    axes.set_xlabel("class id, grouped by shape", labelpad=20)
    axes.set_title(f"Object classes: {int(counts.sum())} objects in {episodes} episodes "
                   "(bar colour = object colour)", fontsize=10)
    axes.legend(fontsize=8, loc="lower right")
    return _save(figure, path)


def texture_histograms(summaries: Iterable[EpisodeSummary]) -> list[Counter[int]]:
    """Per wall side k, a Counter of texture indices drawn (sim episodes with wall textures only)."""
    sides: list[Counter[int]] = []
    for summary in summaries:
        for k, texture in enumerate(summary.wall_textures):
            while len(sides) <= k:
                sides.append(Counter())
            sides[k][texture] += 1
    return sides


def _side_textures(k: int, observed: Counter[int]) -> list[int]:
    pool = {TEXTURE_INDEX[t.name] for t in WALL_POOLS[k]} if k < len(WALL_POOLS) else set()
    return sorted(pool | set(observed))


def write_texture_histogram_png(sides: Sequence[Counter[int]], path: Path) -> Path:
    """One panel per wall side: how often each texture (its side's pool, plus any other drawn) was drawn; bars in
    the texture's dark colour."""
    n = len(sides)
    columns = max(1, math.ceil(math.sqrt(n)))
    rows = math.ceil(n / columns)
    figure = Figure(figsize=(4.2 * columns, 3.0 * rows))
    for k, counter in enumerate(sides):
        axes = figure.add_subplot(rows, columns, k + 1)
        textures = _side_textures(k, counter)
        values = [counter.get(t, 0) for t in textures]
        colours = [ALL_WALL_TEXTURES[t].rgb1 if 0 <= t < len(ALL_WALL_TEXTURES) else (0.5, 0.5, 0.5)
                   for t in textures]
        names = [ALL_WALL_TEXTURES[t].name if 0 <= t < len(ALL_WALL_TEXTURES) else str(t) for t in textures]
        axes.bar(np.arange(len(textures)), values, color=colours, edgecolor="black", linewidth=0.5)
        axes.set_xticks(np.arange(len(textures)), names, rotation=60, ha="right",
                        fontsize=7 if len(textures) <= 12 else 5)
        axes.set_title(f"wall {k}: {sum(values)} draws, {np.count_nonzero(values)} textures", fontsize=9)
        axes.set_ylabel("episodes", fontsize=8)
    figure.suptitle("Wall textures per side (header.wall_textures; side k counter-clockwise from the south wall)",
                    fontsize=10)
    figure.tight_layout()
    return _save(figure, path)


def frame_grid(rows: Sequence[Sequence[np.ndarray]], tile: int = FRAME_TILE, gap: int = 4) -> np.ndarray:
    """One image of ``rows`` of (H, W, 3) uint8 frames, each upscaled by an integer factor (nearest neighbour)
    to at least ``tile`` pixels, separated by white ``gap`` pixel lines."""
    frames = [f for row in rows for f in row]
    if not frames:
        raise ValueError("frame_grid: no frames")
    height, width = frames[0].shape[:2]
    factor = max(1, math.ceil(tile / max(height, width)))
    th, tw = height * factor, width * factor
    columns = max(len(row) for row in rows)
    grid = np.full((len(rows) * (th + gap) - gap, columns * (tw + gap) - gap, 3), 255, np.uint8)
    for r, row in enumerate(rows):
        for c, frame in enumerate(row):
            big = np.repeat(np.repeat(np.asarray(frame, np.uint8)[:th // factor, :tw // factor], factor, 0),
                            factor, 1)
            grid[r * (th + gap): r * (th + gap) + big.shape[0], c * (tw + gap): c * (tw + gap) + big.shape[1]] = big
    return grid


def write_frames_png(rows: Sequence[Sequence[np.ndarray]], path: Path, tile: int = FRAME_TILE) -> Path:
    """``frame_grid(rows)`` as a PNG (through a temporary name)."""
    return write_png(Path(path), frame_grid(rows, tile))


def example_frames(paths: Sequence[Path], episodes: int = 4, frames: int = 4,
                   ) -> tuple[list[list[np.ndarray]], list[tuple[str, list[int]]]]:
    """Frames of ``episodes`` episodes spread evenly over ``paths`` (``frames`` per episode, evenly spaced in
    time, first and last included): (rows of frames, [(episode id, frame indices)])."""
    if not paths:
        return [], []
    chosen = sorted({int(round(i)) for i in np.linspace(0, len(paths) - 1, min(episodes, len(paths)))})
    rows, captions = [], []
    for index in chosen:
        episode = read_episode(paths[index], with_images=True)
        if not len(episode.images):
            continue
        times = sorted({int(round(t)) for t in np.linspace(0, len(episode.images) - 1, frames)})
        rows.append([episode.images[t] for t in times])
        captions.append((episode.header.episode_id, times))
    return rows, captions


# --------------------------------------------------------------------------------------------- statistics


def _describe(values: Sequence[float]) -> dict[str, float]:
    array = np.asarray(values, np.float64)
    if not len(array):
        return {"mean": float("nan"), "median": float("nan"), "min": float("nan"), "max": float("nan")}
    return {"mean": float(array.mean()), "median": float(np.median(array)), "min": float(array.min()),
            "max": float(array.max())}


@dataclass
class CardStats:
    """Everything the card reports, computed from the manifest and the episodes."""

    version: str
    rows: list[dict[str, Any]]  # manifest rows
    summaries: list[EpisodeSummary]
    counts: np.ndarray
    extent: Extent
    cell_size: float
    coverage_fraction: float
    inside_cells: int
    visited_cells: int
    median_mean_displacement: float
    median_max_displacement: float
    classes: np.ndarray
    textures: list[Counter[int]]
    interior_fraction: float  # coverage of the cells at least one cell from every wall
    interior_cells: int
    band_width: float  # metres: the wall band of the two figures below
    band_frame_share: float  # share of frames in the cells whose centre is within band_width of a wall
    band_cell_share: float  # share of the inside cells that are in that band
    coverage_episodes: int = 0  # episodes in the coverage statistics
    coverage_sim_only: bool = False  # whether real episodes were left out of them
    recorded_params: list[tuple[str, int]] = field(default_factory=list)  # (params JSON, episodes), most first
    image_size: int | None = None
    frame_captions: list[tuple[str, list[int]]] = field(default_factory=list)

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
    """Read the manifest and summarise every episode it lists (without images)."""
    table = pq.read_table(manifest_path)
    rows = table.to_pylist()
    if not rows:
        raise CardError(f"{manifest_path}: the manifest lists no episode; collect episodes first")
    try:
        version = manifest_version(table)
    except (KeyError, TypeError):
        raise CardError(f"{manifest_path}: no dataset_version in the manifest's metadata; rebuild it") from None
    summaries = summarize_files([Path(episodes_root) / row["file"] for row in rows], workers, progress)
    # Coverage is the evidence for the random-action scheme, which drives the simulator only: real runs (another
    # arena, another policy) are left out when there are simulated episodes.
    covered = [s for s in summaries if s.source == SIM_SOURCE] or summaries
    counts, extent = coverage_counts((s.positions for s in covered), arena, cell_size)
    inside = inside_mask(counts.shape, extent, arena)
    clearance = cell_clearance(counts.shape, extent, arena)
    interior = clearance >= cell_size
    band_width = 2 * cell_size
    band = inside & (clearance < band_width)
    return CardStats(
        version=version, rows=rows, summaries=summaries, counts=counts, extent=extent, cell_size=cell_size,
        coverage_fraction=coverage_fraction(counts, extent, arena), inside_cells=int(np.count_nonzero(inside)),
        visited_cells=int(np.count_nonzero(inside & (counts > 0))),
        median_mean_displacement=float(np.median([s.mean_displacement for s in covered])),
        median_max_displacement=float(np.median([s.max_displacement for s in covered])),
        coverage_episodes=len(covered), coverage_sim_only=len(covered) < len(summaries),
        classes=class_histogram(summaries), textures=texture_histograms(summaries),
        interior_fraction=float(np.count_nonzero(interior & (counts > 0)) / max(1, np.count_nonzero(interior))),
        interior_cells=int(np.count_nonzero(interior)), band_width=band_width,
        band_frame_share=float(counts[band].sum() / max(1, counts.sum())),
        band_cell_share=float(np.count_nonzero(band) / max(1, np.count_nonzero(inside))),
        recorded_params=sorted(Counter(s.params_json for s in summaries).items(), key=lambda kv: -kv[1]),
    )


# ---------------------------------------------------------------------------------------------- rendering


def _plain(value: Any) -> Any:
    """``value`` as plain YAML/JSON types (pydantic models, paths, numpy values, tuples)."""
    if hasattr(value, "model_dump"):
        return _plain(value.model_dump())
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


def size_category(n: int) -> str:
    """The Hub's ``size_categories`` bucket of ``n`` examples (frames)."""
    bounds = [(1_000, "n<1K"), (10_000, "1K<n<10K"), (100_000, "10K<n<100K"), (1_000_000, "100K<n<1M"),
              (10_000_000, "1M<n<10M"), (100_000_000, "10M<n<100M"), (1_000_000_000, "100M<n<1B")]
    return next((label for bound, label in bounds if n < bound), "n>1B")


def split_data_files(split: str, datasets_root_rel: str) -> str:
    """The glob of a split's LeRobot v3.0 Parquet files, relative to the card."""
    return posixpath.normpath(posixpath.join(datasets_root_rel or ".", split, "data", "*", "*.parquet"))


def front_matter(stats: CardStats, datasets_root_rel: str) -> dict[str, Any]:
    splits = stats.per("split")
    order = [s for s in SPLITS if s in splits] + sorted(set(splits) - set(SPLITS))
    return {
        "license": LICENSE,
        "task_categories": ["robotics"],
        "tags": list(TAGS),
        "pretty_name": "MOR random-exploration episodes",
        "size_categories": [size_category(sum(f for _, f in splits.values()))],
        "dataset_version": stats.version,
        "configs": [{"config_name": split, "data_files": split_data_files(split, datasets_root_rel)}
                    for split in order],
    }


def _fmt(x: float, digits: int = 2) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def _event_section(stats: CardStats) -> list[str]:
    s = stats.summaries
    n = len(s)
    quantities = [
        ("PICK actions (3)", [e.events.pick_actions for e in s]),
        ("DROP actions (4)", [e.events.drop_actions for e in s]),
        ("picks (held: none -> object)", [e.events.picks for e in s]),
        ("drops (held: object -> none)", [e.events.drops for e in s]),
        ("PICK actions without a pick", [e.events.pick_actions - e.events.picks for e in s]),
        ("DROP actions without a drop", [e.events.drop_actions - e.events.drops for e in s]),
    ]
    lines = ["## Events", "",
             "Per episode. Actions are what the random-action scheme chose; picks and drops are the changes of "
             "`observation.held` between consecutive frames.", "",
             "| per episode | mean | median | min | max | total |", "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for name, values in quantities:
        d = _describe(values)
        lines.append(f"| {name} | {_fmt(d['mean'])} | {_fmt(d['median'], 1)} | {int(d['min'])} | {int(d['max'])} "
                     f"| {int(sum(values))} |")
    with_pick = sum(e.events.picks > 0 for e in s)
    with_drop = sum(e.events.drops > 0 for e in s)
    with_both = sum(e.events.picks > 0 and e.events.drops > 0 for e in s)
    lines += ["", f"- Episodes with at least one pick: {with_pick} of {n} ({100 * with_pick / n:.1f}%).",
              f"- Episodes with at least one drop: {with_drop} of {n} ({100 * with_drop / n:.1f}%).",
              f"- Episodes with at least one pick and one drop: {with_both} of {n} ({100 * with_both / n:.1f}%)."]
    totals = np.sum([e.action_counts for e in s], axis=0)
    if totals.sum():
        shares = ", ".join(f"{a.name} {100 * c / totals.sum():.1f}%" for a, c in zip(Action, totals, strict=True))
        lines.append(f"- Share of all {int(totals.sum())} actions: {shares}.")
    horizons = {e.episode_steps for e in s if e.episode_steps is not None}
    frames = _describe([e.n_frames for e in s])
    lines.append(f"- Frames per episode: mean {_fmt(frames['mean'], 1)}, min {int(frames['min'])}, "
                 f"max {int(frames['max'])}.")
    if horizons:
        short = sum(e.episode_steps is not None and e.n_frames < e.episode_steps + 1 for e in s)
        lines.append(f"- Episodes ended before their horizon ({', '.join(str(h) for h in sorted(horizons))} "
                     f"steps; an obstruction or a finished rearrangement ends an episode): {short} of {n}.")
    return lines


def _recorded_params_lines(stats: CardStats, params: dict[str, Any]) -> list[str]:
    """Whether the episodes' own recorded parameters (MCAP metadata) agree with ``params``."""
    recorded = stats.recorded_params
    if not recorded:
        return []
    given = _plain(params)
    matching = sum(n for text, n in recorded if _is_subset(json.loads(text), given))
    lines = [f"The episodes record {len(recorded)} distinct parameter set(s) in their MCAP metadata; "
             f"{matching} of {len(stats.summaries)} episodes record parameters that agree with the block above "
             "(every recorded key has the value given above)."]
    if matching < len(stats.summaries):
        lines += ["", "The most common recorded set:", "", "```yaml",
                  yaml.safe_dump(json.loads(recorded[0][0]), sort_keys=False, default_flow_style=False).rstrip(),
                  "```"]
    return lines + [""]


def _is_subset(recorded: Any, given: Any) -> bool:
    """Whether every key of ``recorded`` appears in ``given`` (searched at any depth) with the same value."""
    if isinstance(recorded, dict):
        if not isinstance(given, dict):
            return False
        if all(k in given and _is_subset(v, given[k]) for k, v in recorded.items()):
            return True
        return any(_is_subset(recorded, v) for v in given.values() if isinstance(v, dict))
    return recorded == given


def render_card(stats: CardStats, params: dict[str, Any], datasets_root_rel: str, figures: dict[str, str | None],
                ) -> str:
    """The card's Markdown (front matter included). ``figures`` maps coverage / classes / textures / frames to
    the PNG's file name relative to the card, or None when it was not drawn."""
    root = datasets_root_rel or "."
    splits, sources = stats.per("split"), stats.per("source")
    n_episodes, n_frames = len(stats.rows), sum(int(r["n_frames"]) for r in stats.rows)
    fps = sorted({s.fps for s in stats.summaries})
    yaml_text = yaml.safe_dump(front_matter(stats, root), sort_keys=False, default_flow_style=False)
    n_objects = sorted({len(s.object_classes) for s in stats.summaries})
    n_sim = sources.get("sim", (0, 0))[0]
    never = stats.inside_cells - stats.visited_cells
    covered = ("simulated episodes (real runs left out: the random-action scheme drives only the simulator)"
               if stats.coverage_sim_only else "episodes")
    lines = [
        "---", yaml_text.rstrip(), "---", "",
        "# MOR random-exploration dataset", "",
        "## Summary", "",
        f"{n_episodes} episodes ({n_frames} frames at {', '.join(f'{f:g}' for f in fps)} fps) of a simulated "
        "TurtleBot-sized robot in the MOR MuJoCo arena (Mobile Object Rearrangement), driven by a random-action "
        "scheme (a persistent random walk with random picks and drops, `mor.data.exploration`). Each frame holds "
        "the first-person RGB image, the object classes, the held object, the objects' targets, the ground-truth "
        f"agent pose and object positions, and the action taken. Objects per episode: "
        f"{', '.join(str(k) for k in n_objects)}. The data trains and evaluates localization from first-person "
        "RGB alone.", "",
        f"One LeRobot v3.0 dataset per split (repo id `mor/<split>`) lives in `{root}/<split>/` relative to "
        f"this card; its frames are in `{split_data_files('<split>', root)}`. The source of truth is one MCAP "
        "file per episode, listed in the manifest.", "",
        "## Version", "",
        f"Dataset version `{stats.version}`: a content hash of every (episode id, MCAP sha256) pair in the "
        "manifest. Splits are assigned by a hash of the episode id (8:1:1), so adding episodes never moves one.", "",
        "## Counts", "",
        "| split | source | episodes | frames |", "| --- | --- | ---: | ---: |",
    ]
    lines += [f"| {split} | {source} | {e} | {f} |" for split, source, e, f in stats.split_table()]
    lines += ["", "| split | episodes | frames |", "| --- | ---: | ---: |"]
    lines += [f"| {split} | {splits[split][0]} | {splits[split][1]} |" for split in SPLITS if split in splits]
    lines += [f"| **total** | {n_episodes} | {n_frames} |", ""]
    lines += ["| source | episodes | frames |", "| --- | ---: | ---: |"]
    lines += [f"| {source} | {e} | {f} |" for source, (e, f) in sorted(sources.items())]
    empty = [s for s in SPLITS if s not in splits]
    if empty:
        lines += ["", f"Empty splits (no config above): {', '.join(empty)}."]
    lines += ["", "## Features", ""]
    if stats.image_size is not None:
        lines += [f"Per frame (LeRobot features; objects padded to {MAX_OBJECTS} slots; positions flattened "
                  "x0, y0, x1, y1, ...). World frame: metres, radians, counter-clockwise from +x.", "",
                  "| feature | dtype | shape | units | meaning |", "| --- | --- | --- | --- | --- |"]
        for name, spec in lerobot_features(stats.image_size).items():
            units, meaning = FEATURE_UNITS.get(name, ("", ""))
            lines.append(f"| `{name}` | {spec['dtype']} | {tuple(spec['shape'])} | {units} | {meaning} |")
    else:
        lines.append("No episode image could be read, so the image size (and the feature shapes) is unknown.")
    lines += [""] + _event_section(stats) + ["", "## Coverage", ""]
    lines += [
        f"Agent positions over all {int(stats.counts.sum())} frames of {stats.coverage_episodes} {covered} "
        f"on a {stats.cell_size:g} m grid over the "
        f"arena's bounding box ({stats.extent[1] - stats.extent[0]:g} m x {stats.extent[3] - stats.extent[2]:g} m). "
        f"Visited at least once: {stats.visited_cells} of the {stats.inside_cells} cells whose centre is inside "
        f"the arena, a **coverage fraction of {stats.coverage_fraction:.3f}**. The median over episodes of the "
        f"mean distance from the episode's start is **{stats.median_mean_displacement:.2f} m** (median of the "
        f"largest distance: {stats.median_max_displacement:.2f} m).", "",
        f"Away from the walls (the {stats.interior_cells} cells whose centre is at least {stats.cell_size:g} m "
        f"from every wall) the coverage fraction is {stats.interior_fraction:.3f}. The cells within "
        f"{stats.band_width:g} m of a wall are {100 * stats.band_cell_share:.1f}% of the inside cells and hold "
        f"{100 * stats.band_frame_share:.1f}% of the frames. The agent's centre never comes closer than its radius "
        f"({AGENT_RADIUS:g} m) to a wall, so the outermost cells can only be partly reached.", "",
    ]
    if figures.get("coverage"):
        lines += [f"![Coverage map: frames per {stats.cell_size:g} m cell, log scale]({figures['coverage']})", ""]
    lines += ["## Object classes and wall textures", ""]
    if figures.get("classes"):
        present = int(np.count_nonzero(stats.classes))
        lines += [f"{int(stats.classes.sum())} objects; {present} of {N_CLASSES} classes appear "
                  f"(fewest: {int(stats.classes.min())}, most: {int(stats.classes.max())} objects).", "",
                  f"![Objects per class]({figures['classes']})", ""]
    if figures.get("textures"):
        draws = sum(sum(c.values()) for c in stats.textures)
        lines += [f"{len(stats.textures)} wall sides, {draws} texture draws in {n_sim} simulated episodes.", "",
                  f"![Wall textures per side]({figures['textures']})", ""]
    else:
        lines += ["No episode records wall textures (real episodes have none), so there is no texture histogram.",
                  ""]
    lines += ["## Example frames", ""]
    if figures.get("frames") and stats.frame_captions:
        lines += ["One row per episode; frames evenly spaced in time, upscaled with nearest neighbour.", "",
                  f"![Example first-person frames]({figures['frames']})", ""]
        lines += [f"- row {r + 1}: `{episode}`, frames {', '.join(str(t) for t in times)}"
                  for r, (episode, times) in enumerate(stats.frame_captions)]
        lines.append("")
    else:
        lines += ["No example frame could be read.", ""]
    data_files = {s: split_data_files(s, root) for s in SPLITS if s in splits}
    first = next(iter(data_files), "train")
    lines += [
        "## How to load", "",
        "Offline, with the paths relative to this card's directory:", "",
        "```python",
        "import os",
        'os.environ["HF_HUB_OFFLINE"] = "1"  # never reach the Hub',
        "from lerobot.datasets.lerobot_dataset import LeRobotDataset",
        "",
        f'dataset = LeRobotDataset("mor/{first}", root="{posixpath.normpath(posixpath.join(root, first))}")',
        'frame = dataset[0]  # dict of tensors: "observation.image", "state.agent_pose", ...',
        "```", "",
        "or the Parquet frames alone (images as PNG bytes), with `datasets`:", "",
        "```python",
        "from datasets import load_dataset",
        "",
        f"splits = load_dataset(\"parquet\", data_files={json.dumps(data_files)})",
        "```", "",
        "## Parameters", "",
        "The exact parameters this dataset was produced with:", "",
        "```yaml", yaml.safe_dump(_plain(params), sort_keys=False, default_flow_style=False).rstrip(), "```", "",
        *_recorded_params_lines(stats, params),
        "## Limitations", "",
        f"- {n_sim} of {n_episodes} episodes are simulated; sim-to-real transfer is not measured here. Physics is "
        "abstracted to planar geometry: no contact dynamics, no wheel slip beyond the Gaussian motion noise.",
        "- Actions come from a random-action scheme, not from a task policy: the episodes show exploration, "
        "picks and drops, not purposeful rearrangement, and the action distribution (above) is the scheme's.",
        f"- Coverage: {never} of {stats.inside_cells} cells inside the arena were never visited, and frames are "
        "not spread evenly (turning in place stacks frames on one cell); see the heat map.",
        "- Poses are the simulator's ground truth; images are rendered without sensor noise, blur or "
        "exposure changes.",
        "",
    ]
    return "\n".join(lines)


def _write_text(path: Path, text: str) -> Path:
    with atomic_output(path) as partial:
        partial.write_text(text, encoding="utf-8")
    return path


def write_dataset_card(manifest_path: Path, episodes_root: Path, out_dir: Path, params: dict[str, Any],
                       arena: Arena, datasets_root_rel: str = ".", *, cell_size: float = COVERAGE_CELL,
                       example_episodes: int = 4, frames_per_episode: int = 4, workers: int = 1,
                       progress: bool = True) -> Path:
    """Write ``out_dir/README.md`` and its PNGs; returns the card's path.

    manifest_path: the manifest Parquet; episodes_root: what its ``file`` column is relative to; params: the
    exact parameters (written as a YAML block); arena: the episodes' arena (coverage); datasets_root_rel: where
    the split datasets (``<split>/data/*/*.parquet``) live, relative to ``out_dir``. Episodes are read without
    images (in ``workers`` processes) except ``example_episodes`` of them, for the example frames.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    stats = compute_stats(Path(manifest_path), Path(episodes_root), arena, cell_size, workers, progress)
    figures: dict[str, str | None] = {}
    write_coverage_png(stats.counts, stats.extent, arena, out_dir / COVERAGE_PNG, stats.coverage_fraction)
    figures["coverage"] = COVERAGE_PNG
    write_class_histogram_png(stats.classes, out_dir / CLASS_PNG, len(stats.summaries))
    figures["classes"] = CLASS_PNG
    if stats.textures:
        write_texture_histogram_png(stats.textures, out_dir / TEXTURE_PNG)
        figures["textures"] = TEXTURE_PNG
    paths = [Path(episodes_root) / row["file"] for row in stats.rows]
    rows, captions = example_frames(paths, example_episodes, frames_per_episode)
    if rows:
        write_frames_png(rows, out_dir / FRAMES_PNG)
        figures["frames"] = FRAMES_PNG
        stats.image_size = int(rows[0][0].shape[0])
        stats.frame_captions = captions
    return _write_text(out_dir / CARD_NAME, render_card(stats, params, datasets_root_rel, figures))


def iter_card_links(card: str) -> Iterator[str]:
    """The relative image links of a card's Markdown (``![...](link)``)."""
    yield from re.findall(r"!\[[^\]]*\]\(([^)]+)\)", card)
