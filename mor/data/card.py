"""The dataset card: a Hugging Face ``README.md`` with every number computed from the episodes, and its figures.

``write_dataset_card`` computes the statistics (``mor.data.card_stats``: no image is decoded except for the few
example frames), draws the figures (``mor.data.card_figures``) and writes the Markdown (this module) into
``out_dir``:

- ``README.md``            the card (YAML front matter, then the sections; figures linked relatively)
- ``coverage.png``         where the agent went: a log-scale heat map of agent positions over all frames
- ``class_histogram.png``  objects per class (24 bars, coloured by the object colour, labelled by shape)
- ``wall_textures.png``    how often each wall texture was drawn, one panel per wall side (sim episodes only)
- ``example_frames.png``   first-person frames of a few episodes (one row per episode), nearest-neighbour upscaled

Every file is written through a temporary name and renamed.
"""

from __future__ import annotations

import json
import math
import posixpath
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from mor.atomic import atomic_output
from mor.data.card_figures import (
    example_frames,
    write_class_histogram_png,
    write_coverage_png,
    write_frames_png,
    write_texture_histogram_png,
)
from mor.data.card_stats import COVERAGE_CELL, CardStats, compute_stats, describe, plain
from mor.data.manifest import SPLITS
from mor.data.schema import (
    ACTION,
    AGENT_POSE,
    GROUND_TRUTH,
    IMAGE,
    MAX_OBJECTS,
    OBJECT_VISIBLE,
    OBSERVATION,
    STATE,
    features,
)
from mor.sim.arena import Arena
from mor.sim.catalog import N_CLASSES
from mor.sim.rules import AGENT_RADIUS, Action

CARD_NAME = "README.md"
COVERAGE_PNG = "coverage.png"
CLASS_PNG = "class_histogram.png"
TEXTURE_PNG = "wall_textures.png"
FRAMES_PNG = "example_frames.png"
LICENSE = "apache-2.0"
TAGS: tuple[str, ...] = ("LeRobot", "mor", "mobile-manipulation", "localization", "mujoco")

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
             f"the held object (in `{STATE}`) between consecutive frames.", "",
             "| per episode | mean | median | min | max | total |", "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for name, values in quantities:
        d = describe(values)
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
    frames = describe([e.n_frames for e in s])
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
    given = plain(params)
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
    coverage = stats.coverage
    x_min, x_max, y_min, y_max = coverage.extent
    splits, sources = stats.per("split"), stats.per("source")
    n_episodes, n_frames = len(stats.rows), sum(int(r["n_frames"]) for r in stats.rows)
    fps = sorted({s.fps for s in stats.summaries})
    yaml_text = yaml.safe_dump(front_matter(stats, root), sort_keys=False, default_flow_style=False)
    n_objects = sorted({len(s.object_classes) for s in stats.summaries})
    n_sim = sources.get("sim", (0, 0))[0]
    never = coverage.inside_cells - coverage.visited_cells
    covered = ("simulated episodes (real runs left out: the random-action scheme drives only the simulator)"
               if coverage.sim_only else "episodes")
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
        for name, feature in features(stats.image_size).items():
            lines.append(f"| `{name}` | {feature.dtype} | {feature.shape} | {feature.units} | {feature.meaning} |")
        lines += ["", f"`{OBSERVATION}.*` is what an agent that sees only the camera is given (`{IMAGE}`, `{STATE}` "
                  f"and `{ACTION}` are the names LeRobot's policies read); `{GROUND_TRUTH}.*` is the simulator's "
                  "truth, which such an agent does not observe (the L-Net's training labels)."]
    else:
        lines.append("No episode image could be read, so the image size (and the feature shapes) is unknown.")
    lines += [""] + _event_section(stats) + ["", "## Coverage", ""]
    lines += [
        f"Agent positions over all {int(coverage.counts.sum())} frames of {coverage.episodes} {covered} "
        f"on a {coverage.cell_size:g} m grid over the arena's bounding box "
        f"({x_max - x_min:g} m x {y_max - y_min:g} m). "
        f"Visited at least once: {coverage.visited_cells} of the {coverage.inside_cells} cells whose centre is inside "
        f"the arena, a **coverage fraction of {coverage.coverage_fraction:.3f}**. The median over episodes of the "
        f"mean distance from the episode's start is **{coverage.median_mean_displacement:.2f} m** (median of the "
        f"largest distance: {coverage.median_max_displacement:.2f} m).", "",
        f"Away from the walls (the {coverage.interior_cells} cells whose centre is at least {coverage.cell_size:g} m "
        f"from every wall) the coverage fraction is {coverage.interior_fraction:.3f}. The cells within "
        f"{coverage.band_width:g} m of a wall are {100 * coverage.band_cell_share:.1f}% of the inside cells and hold "
        f"{100 * coverage.band_frame_share:.1f}% of the frames. The agent's centre never comes closer than its radius "
        f"({AGENT_RADIUS:g} m) to a wall, so the outermost cells can only be partly reached.", "",
    ]
    if figures.get("coverage"):
        lines += [f"![Coverage map: frames per {coverage.cell_size:g} m cell, log scale]({figures['coverage']})", ""]
    if stats.visibility is not None:
        v = stats.visibility
        lines += ["## Visibility", "",
                  "Per frame, which objects the camera sees by the simulator's rule (`mor.sim.rules.visible`: in the "
                  "60° field of view and not occluded; a held object is not in view), stored as "
                  f"`{OBJECT_VISIBLE}`.", "",
                  f"- An object is in view on {100 * v.object_frame_share:.1f}% of its frames; some object is in view "
                  f"on {100 * v.any_frame_share:.1f}% of all frames.",
                  f"- {100 * v.never_seen_share:.1f}% of the objects are never in view during their episode.",
                  f"- Median agent-object distance when in view: {v.median_distance:.2f} m.", ""]
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
        f'frame = dataset[0]  # dict of tensors: "{IMAGE}" (3, H, W) float32 in [0, 1], "{STATE}", "{ACTION}", '
        f'"{AGENT_POSE}", ...',
        "```", "",
        "or the Parquet frames alone (images as PNG bytes), with `datasets`:", "",
        "```python",
        "from datasets import load_dataset",
        "",
        f"splits = load_dataset(\"parquet\", data_files={json.dumps(data_files)})",
        "```", "",
        "## Parameters", "",
        "The exact parameters this dataset was produced with:", "",
        "```yaml", yaml.safe_dump(plain(params), sort_keys=False, default_flow_style=False).rstrip(), "```", "",
        *_recorded_params_lines(stats, params),
        "## Limitations", "",
        f"- {n_sim} of {n_episodes} episodes are simulated; sim-to-real transfer is not measured here. Physics is "
        "abstracted to planar geometry: no contact dynamics, no wheel slip beyond the Gaussian motion noise.",
        "- Actions come from a random-action scheme, not from a task policy: the episodes show exploration, "
        "picks and drops, not purposeful rearrangement, and the action distribution (above) is the scheme's.",
        f"- Coverage: {never} of {coverage.inside_cells} cells inside the arena were never visited, and frames are "
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
    coverage = stats.coverage
    write_coverage_png(coverage.counts, coverage.extent, arena, out_dir / COVERAGE_PNG, coverage.coverage_fraction)
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
