"""The dataset card's figures, each written as a PNG through a temporary name and renamed.

- coverage: a log-scale heat map of agent positions over all frames, with the arena's walls
- class histogram: objects per class (24 bars, coloured by the object colour, labelled by shape)
- wall textures: how often each wall texture was drawn, one panel per wall side (sim episodes only)
- example frames: first-person frames of a few episodes (one row per episode), nearest-neighbour upscaled

The numbers they draw come from ``mor.data.card_stats``.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from mor.atomic import atomic_output
from mor.data.card_stats import Extent, coverage_fraction, inside_mask
from mor.data.episode_io import read_episode
from mor.sim.arena import Arena
from mor.sim.catalog import ALL_WALL_TEXTURES, COLOUR_NAMES, N_CLASSES, SHAPES, TEXTURE_INDEX, WALL_POOLS, object_class
from mor.sim.views import write_png

#: Upscaled size (pixels) of one example frame, at least.
FRAME_TILE: int = 128
_DPI = 110


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
