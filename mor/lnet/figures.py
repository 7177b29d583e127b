"""Figures of the L-Net's estimates: paper Figure 1 (right) panels over time, calibration and learning curves.

A panel is a top-down view of the arena at one frame: the ground truth as stars (the agent black, each object in its
class colour) with the agent's true heading as a black straight line, and the estimate as contours, the agent's
position as a grey ``n_sigma`` ellipse with a grey translucent sector for its heading (a von Mises interval), each
object's position as an ellipse in its class colour with its mean as a small dot.

Inputs are numpy arrays (torch CPU tensors work too) in the world frame: x east, y north, metres; headings
counter-clockwise from +x, radians. T frames, K object slots (absent slots have class -1 and are never drawn):

- truth: agent_poses (T, 3) [x, y, theta]; object_positions (T, K, 2); object_classes (K,)  (``Truth``)
- estimate: ``PoseEstimate.to_numpy()`` of one episode (batch index taken): agent_mean (T, 2), agent_tril (T, 2, 2)
  (Cholesky factor L, covariance L L^T), heading (T,), kappa (T,), object_mean (T, K, 2), object_tril (T, K, 2, 2)
- images: optional first-person frames, (T, H, W, 3) uint8 or (T, 3, H, W) float in [0, 1]

Figures are drawn on ``matplotlib.figure.Figure`` objects (no pyplot, no global state), rendered with Agg to RGB
arrays and written with ``mor.sim.views.write_png`` / ``write_video`` (a partial name, then a rename).
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Polygon, Wedge
from tqdm import tqdm

from mor.data.observations import tensor_to_images
from mor.lnet.likelihoods import heading_halfwidth
from mor.sim.arena import Arena
from mor.sim.catalog import object_class
from mor.sim.geometry import heading_vector
from mor.sim.views import side_by_side, write_png, write_video

#: Probability mass of the drawn heading sector: the central interval of a normal distribution within 2 sigma.
HEADING_MASS: float = 0.954
#: Radius (metres) of the heading sector and length of the true-heading line.
SECTOR_RADIUS: float = 0.8
#: Mahalanobis radius of the drawn position ellipses.
N_SIGMA: float = 2.0
DPI: int = 110
_GIF_PANEL_INCHES = 4.0
_GIF_DPI = 80
_ESTIMATE_GREY = (0.35, 0.35, 0.35)
_ESTIMATE_KEYS = ("agent_mean", "agent_tril", "heading", "kappa", "object_mean", "object_tril")


# ------------------------------------------------------------------------------------------------ distributions


def ellipse_points(mean: np.ndarray, tril: np.ndarray, n_sigma: float, n: int = 64) -> np.ndarray:
    """(n, 2) points of the ``n_sigma`` contour of the 2-D Gaussian N(mean, L L^T): every point x has Mahalanobis
    distance sqrt((x - mean)^T (L L^T)^-1 (x - mean)) = n_sigma. mean (2,) metres; tril (2, 2) L (metres).

    The points go once around the contour (the last does not repeat the first). In 2-D a Mahalanobis radius r holds
    1 - exp(-r^2 / 2) of the probability: 86.5% for r = 2, 98.9% for r = 3.
    """
    if n_sigma < 0:
        raise ValueError(f"n_sigma: must be >= 0 (got {n_sigma})")
    angles = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    unit = np.stack([np.cos(angles), np.sin(angles)], axis=-1)
    return np.asarray(mean, np.float64)[None, :] + n_sigma * unit @ np.asarray(tril, np.float64).T


# ----------------------------------------------------------------------------------------------------- inputs


@dataclass(frozen=True)
class Truth:
    """Ground truth of one episode: agent_poses (T, 3) [x m, y m, theta rad]; object_positions (T, K, 2) metres;
    object_classes (K,) class ids, -1 for an absent slot."""

    agent_poses: np.ndarray
    object_positions: np.ndarray
    object_classes: np.ndarray

    @classmethod
    def of(cls, value: Truth | Mapping[str, Any]) -> Truth:
        """A ``Truth``, or a mapping with agent_poses (or agent_pose, as in a ``SequenceWindows`` item),
        object_positions and object_classes (numpy arrays or CPU tensors); shapes are checked."""
        if isinstance(value, Truth):
            return value
        poses = value["agent_poses"] if "agent_poses" in value else value["agent_pose"]
        truth = cls(np.asarray(poses, np.float64), np.asarray(value["object_positions"], np.float64),
                    np.asarray(value["object_classes"], np.int64))
        t, k = len(truth.agent_poses), len(truth.object_classes)
        shapes = (truth.agent_poses.shape, truth.object_positions.shape, truth.object_classes.shape)
        if shapes != ((t, 3), (t, k, 2), (k,)):
            raise ValueError(f"truth: expected agent_poses (T, 3), object_positions (T, K, 2), object_classes (K,); "
                             f"got {shapes}")
        return truth

    @property
    def n_frames(self) -> int:
        return len(self.agent_poses)


def as_estimate(estimate: Mapping[str, Any] | Any, n_frames: int, n_objects: int) -> dict[str, np.ndarray]:
    """The estimate as float64 arrays with the shapes of the module docstring; a ``PoseEstimate`` is converted with
    ``to_numpy()`` and must be in the world frame. Raises ValueError on a wrong shape (index a batch first)."""
    if hasattr(estimate, "to_numpy"):
        if getattr(estimate, "frame", "world") != "world":
            raise ValueError(f"estimate: must be in the world frame (got {estimate.frame!r}); draw the LSTM's estimate")
        estimate = estimate.to_numpy()
    arrays = {key: np.asarray(estimate[key], np.float64) for key in _ESTIMATE_KEYS}
    t, k = n_frames, n_objects
    expected = {"agent_mean": (t, 2), "agent_tril": (t, 2, 2), "heading": (t,), "kappa": (t,),
                "object_mean": (t, k, 2), "object_tril": (t, k, 2, 2)}
    wrong = {key: arrays[key].shape for key, shape in expected.items() if arrays[key].shape != shape}
    if wrong:
        raise ValueError(f"estimate: shapes {wrong} do not match T={t} frames and K={k} objects; expected {expected}")
    return arrays


def as_frames(images: Any) -> np.ndarray:
    """(T, H, W, 3) uint8 from (T, H, W, 3) uint8 or the network's (T, 3, H, W) floats in [0, 1] (a
    ``SequenceWindows`` item), converted by ``mor.data.observations.tensor_to_images``."""
    frames = np.asarray(images)
    if frames.ndim == 4 and frames.shape[3] == 3 and frames.dtype == np.uint8:
        return np.ascontiguousarray(frames)
    if frames.ndim == 4 and frames.shape[1] == 3 and frames.dtype.kind == "f":
        return tensor_to_images(frames)
    raise ValueError(f"images: expected (T, H, W, 3) uint8 or (T, 3, H, W) floats; got {frames.dtype} {frames.shape}")


def _check_frame(t: int, n_frames: int) -> int:
    if not 0 <= t < n_frames:
        raise ValueError(f"frame {t} is outside [0, {n_frames})")
    return int(t)


# ------------------------------------------------------------------------------------------------------ panels


def draw_estimate_panel(ax: Axes, arena: Arena, truth: Truth | Mapping[str, Any], estimate: Mapping[str, Any] | Any,
                        t: int, n_sigma: float = N_SIGMA, *, heading_mass: float = HEADING_MASS,
                        sector_radius: float = SECTOR_RADIUS) -> None:
    """Draw frame ``t`` on ``ax`` as in paper Figure 1 (right).

    Arena walls; ground truth as stars (the agent black, each present object in its class colour) and the true
    heading as a black line of ``sector_radius`` metres; the agent's estimated position as a grey ``n_sigma``
    ellipse (Mahalanobis radius) and its heading as a grey translucent sector of radius ``sector_radius`` metres
    between heading -+ ``heading_halfwidth(kappa, heading_mass)``; each present object's ellipse in its class colour
    with its mean as a small dot. Equal aspect, limits the arena's bounds, title "t = {t}".
    """
    truth = Truth.of(truth)
    est = as_estimate(estimate, truth.n_frames, len(truth.object_classes))
    t = _check_frame(t, truth.n_frames)

    floor = Polygon(arena.vertex_array, closed=True, facecolor="white", edgecolor="none", zorder=0)
    ax.add_patch(floor)
    for a, b in arena.walls():
        ax.plot([a[0], b[0]], [a[1], b[1]], color="black", linewidth=2.5, solid_capstyle="round", zorder=1)

    # The estimate: heading sector, then ellipses and means.
    centre = est["agent_mean"][t]
    half = math.degrees(heading_halfwidth(est["kappa"][t], heading_mass))
    heading = math.degrees(est["heading"][t])
    ax.add_patch(Wedge(tuple(centre), sector_radius, heading - half, heading + half, facecolor=_ESTIMATE_GREY,
                       alpha=0.3, edgecolor="none", zorder=2))
    ax.plot(*(centre[:, None] + np.outer(heading_vector(est["heading"][t]), [0.0, sector_radius])),
            color=_ESTIMATE_GREY, linewidth=0.8, linestyle=":", zorder=2)
    ax.add_patch(Polygon(ellipse_points(centre, est["agent_tril"][t], n_sigma), closed=True, facecolor=_ESTIMATE_GREY,
                         alpha=0.15, edgecolor="none", zorder=3))
    ax.add_patch(Polygon(ellipse_points(centre, est["agent_tril"][t], n_sigma), closed=True, fill=False,
                         edgecolor=_ESTIMATE_GREY, linewidth=1.6, zorder=3))
    ax.plot(*centre, "o", color=_ESTIMATE_GREY, markersize=3, zorder=4)
    present = [k for k, c in enumerate(truth.object_classes) if c >= 0]
    for k in present:
        colour = object_class(int(truth.object_classes[k])).rgb
        contour = ellipse_points(est["object_mean"][t, k], est["object_tril"][t, k], n_sigma)
        ax.add_patch(Polygon(contour, closed=True, facecolor=colour, alpha=0.12, edgecolor="none", zorder=3))
        ax.add_patch(Polygon(contour, closed=True, fill=False, edgecolor=colour, linewidth=1.6, zorder=3))
        ax.plot(*est["object_mean"][t, k], "o", color=colour, markeredgecolor="black", markeredgewidth=0.4,
                markersize=3.5, zorder=4)

    # The ground truth on top.
    pose = truth.agent_poses[t]
    tip = pose[:2] + sector_radius * heading_vector(pose[2])
    ax.plot([pose[0], tip[0]], [pose[1], tip[1]], color="black", linewidth=1.8, zorder=5)
    ax.plot(*pose[:2], "*", color="black", markersize=14, zorder=6)
    for k in present:
        colour = object_class(int(truth.object_classes[k])).rgb
        ax.plot(*truth.object_positions[t, k], "*", color=colour, markeredgecolor="black", markeredgewidth=0.6,
                markersize=13, zorder=6)

    low, high = arena.vertex_array.min(axis=0), arena.vertex_array.max(axis=0)
    pad = 0.02 * float(np.max(high - low))
    ax.set_xlim(low[0] - pad, high[0] + pad)
    ax.set_ylim(low[1] - pad, high[1] + pad)
    ax.set_aspect("equal")
    ax.set_facecolor((0.93, 0.93, 0.93))
    ax.tick_params(labelsize=7)
    ax.set_title(f"t = {t}", fontsize=10)


def legend_handles(n_sigma: float = N_SIGMA, heading_mass: float = HEADING_MASS) -> list[Any]:
    """Proxy artists explaining a panel's symbols (for ``Figure.legend``)."""
    return [
        Line2D([], [], marker="*", color="black", linestyle="none", markersize=12,
               label="ground truth (colour = class)"),
        Line2D([], [], color="black", linewidth=1.8, label="true heading"),
        Patch(facecolor=(0.35, 0.35, 0.35, 0.15), edgecolor=_ESTIMATE_GREY, linewidth=1.6,
              label=f"estimate, {n_sigma:g}σ contour"),
        Patch(facecolor=(0.35, 0.35, 0.35, 0.3), edgecolor="none",
              label=f"estimated heading, {100 * heading_mass:.1f}%"),
    ]


def render(figure: Figure) -> np.ndarray:
    """The figure drawn with Agg: (H, W, 3) uint8, H x W = figure size in inches x its dpi."""
    canvas = figure.canvas if isinstance(figure.canvas, FigureCanvasAgg) else FigureCanvasAgg(figure)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def estimate_strip_figure(arena: Arena, truth: Truth | Mapping[str, Any], estimate: Mapping[str, Any] | Any,
                          frames: Sequence[int], images: Any = None, n_sigma: float = N_SIGMA) -> Figure:
    """One column per frame of ``frames``: the panel, with the first-person image above it when ``images`` is given;
    a legend of the symbols below."""
    truth = Truth.of(truth)
    frames = [_check_frame(t, truth.n_frames) for t in frames]
    if not frames:
        raise ValueError("frames: select at least one frame")
    pictures = None if images is None else as_frames(images)
    if pictures is not None and len(pictures) != truth.n_frames:
        raise ValueError(f"images: {len(pictures)} frames for a {truth.n_frames}-frame episode")
    rows = 1 if pictures is None else 2
    handles = legend_handles(n_sigma)
    legend_columns = min(len(handles), len(frames))  # about one legend entry per 3-inch column fits
    legend_rows = math.ceil(len(handles) / legend_columns)
    figure = Figure(figsize=(3.0 * len(frames), 3.0 * rows + 0.3 + 0.25 * legend_rows), dpi=DPI,
                    layout="constrained")
    grid = figure.subplots(rows, len(frames), squeeze=False)
    for column, t in enumerate(frames):
        if pictures is not None:
            grid[0, column].imshow(pictures[t], interpolation="nearest")
            grid[0, column].set_axis_off()
            grid[0, column].set_title(f"first-person view, t = {t}", fontsize=9)
        draw_estimate_panel(grid[-1, column], arena, truth, estimate, t, n_sigma)
    grid[-1, 0].set_ylabel("y (m)", fontsize=8)
    for ax in grid[-1]:
        ax.set_xlabel("x (m)", fontsize=8)
    figure.legend(handles=handles, loc="outside lower center", ncols=legend_columns, fontsize=8, frameon=False)
    return figure


def write_estimate_strip(path: Path, arena: Arena, truth: Truth | Mapping[str, Any], estimate: Mapping[str, Any] | Any,
                         frames: list[int], images: Any = None, n_sigma: float = N_SIGMA) -> Path:
    """Write ``estimate_strip_figure`` as a PNG (through a partial name); returns ``path``."""
    return write_png(Path(path), render(estimate_strip_figure(arena, truth, estimate, frames, images, n_sigma)))


def write_estimate_gif(path: Path, arena: Arena, truth: Truth | Mapping[str, Any], estimate: Mapping[str, Any] | Any,
                       images: Any = None, fps: int = 5, every: int = 1, n_sigma: float = N_SIGMA,
                       annotate: Callable[[Axes, int], None] | None = None, progress: str | None = None) -> Path:
    """A GIF (or MP4, by ``path``'s suffix) of the panel at frames 0, every, 2 * every, ... (ceil(T / every) frames),
    the first-person image (scaled to the panel's height) to its left when ``images`` is given. ``annotate(ax, t)``
    draws more on frame t's panel (e.g. a policy's targets and actions); ``progress``: a progress bar's label."""
    if every < 1:
        raise ValueError(f"every: must be >= 1 (got {every})")
    truth = Truth.of(truth)
    estimate = as_estimate(estimate, truth.n_frames, len(truth.object_classes))
    pictures = None if images is None else as_frames(images)
    if pictures is not None and len(pictures) != truth.n_frames:
        raise ValueError(f"images: {len(pictures)} frames for a {truth.n_frames}-frame episode")
    figure = Figure(figsize=(_GIF_PANEL_INCHES, _GIF_PANEL_INCHES), dpi=_GIF_DPI, layout="constrained")
    FigureCanvasAgg(figure)
    ax = figure.add_subplot()

    def frame(t: int) -> np.ndarray:
        ax.clear()
        draw_estimate_panel(ax, arena, truth, estimate, t, n_sigma)
        if annotate is not None:
            annotate(ax, t)
        panel = render(figure)
        return panel if pictures is None else side_by_side(pictures[t], panel)

    frames = range(0, truth.n_frames, every)
    bar = tqdm(frames, desc=progress, unit="frame", disable=progress is None, dynamic_ncols=True)
    return write_video(Path(path), (frame(t) for t in bar), fps)


# -------------------------------------------------------------------------------------------- calibration, loss


def reliability_figure(nominal: np.ndarray, observed: Mapping[str, np.ndarray], title: str) -> Figure:
    """Observed coverage (share of ground truths inside the predicted region) against the nominal probability of the
    region, one line per entry of ``observed`` (each (P,), like ``nominal``), with the diagonal of perfect
    calibration; both axes [0, 1]."""
    nominal = np.asarray(nominal, np.float64)
    if nominal.ndim != 1 or not observed:
        raise ValueError("reliability: nominal must be (P,) and observed must name at least one curve")
    figure = Figure(figsize=(4.8, 4.8), dpi=DPI, layout="constrained")
    ax = figure.add_subplot()
    ax.plot([0, 1], [0, 1], color="grey", linestyle="--", linewidth=1, label="perfect calibration")
    for name, values in observed.items():
        values = np.asarray(values, np.float64)
        if values.shape != nominal.shape:
            raise ValueError(f"reliability: curve {name!r} has shape {values.shape}, nominal {nominal.shape}")
        ax.plot(nominal, values, marker="o", markersize=3.5, linewidth=1.5, label=name)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_aspect("equal")
    ax.set_xlabel("nominal probability of the region")
    ax.set_ylabel("observed coverage (share of ground truths inside)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    return figure


def write_reliability_diagram(path: Path, nominal: np.ndarray, observed: dict[str, np.ndarray], title: str) -> Path:
    """Write ``reliability_figure`` as a PNG (through a partial name); returns ``path``."""
    return write_png(Path(path), render(reliability_figure(nominal, observed, title)))


def _running_mean(values: np.ndarray, window: int) -> np.ndarray:
    kernel = np.ones(window) / window
    return np.convolve(values, kernel, mode="valid")


def learning_curve_figure(log_rows: Sequence[Mapping[str, Any]], title: str = "L-Net learning curve",
                          key: str = "loss") -> Figure:
    """``key`` against step per split: train and pretrain (single frames, at negative steps) as thin lines (with
    running means when there are 100 rows or more), validation as markers, any other split as markers too. Rows may hold strings (``csv.DictReader`` of the
    training's log.csv); rows without a finite ``key`` are skipped. Log y axis when every value is positive."""
    curves: dict[str, tuple[list[float], list[float]]] = {}
    for row in log_rows:
        try:
            step, value = float(row["step"]), float(row[key])
        except (KeyError, TypeError, ValueError):
            continue
        if math.isfinite(value):
            steps, values = curves.setdefault(str(row.get("split", "train")), ([], []))
            steps.append(step)
            values.append(value)
    if not curves:
        raise ValueError(f"learning curve: no row has a step and a finite {key!r}")
    figure = Figure(figsize=(6.4, 4.0), dpi=DPI, layout="constrained")
    ax = figure.add_subplot()
    order = sorted(curves, key=lambda s: (s != "train", s != "validation", s))
    per_step = {"train": "tab:blue", "pretrain": "tab:green"}  # one row per optimizer step
    for split in order:
        steps, values = (np.asarray(v) for v in curves[split])
        if split in per_step:
            window = len(values) // 50 if len(values) >= 100 else 1
            colour = per_step[split]
            ax.plot(steps, values, linewidth=0.8, alpha=0.4 if window > 1 else 1.0, color=colour, label=split)
            if window > 1:
                ax.plot(steps[window - 1:], _running_mean(values, window), linewidth=1.8, color=colour,
                        label=f"{split} (running mean of {window})")
        else:
            colour = "tab:orange" if split == "validation" else None
            ax.plot(steps, values, marker="o", markersize=4, linewidth=0.8, color=colour, label=split)
    everything = np.concatenate([np.asarray(v) for _, v in curves.values()])
    ax.set_yscale("log" if np.all(everything > 0) else "linear")
    ax.set_xlabel("step")
    ax.set_ylabel(key)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return figure


def write_learning_curve(path: Path, log_rows: list[dict[str, Any]], title: str = "L-Net learning curve",
                         key: str = "loss") -> Path:
    """Write ``learning_curve_figure`` as a PNG (through a partial name); returns ``path``."""
    return write_png(Path(path), render(learning_curve_figure(log_rows, title, key)))


def since_seen_figure(curves: Mapping[str, Mapping[str, Sequence[Any]]], title: str) -> Figure:
    """Median object error (m) against frames since the object was last visible or held, one line per entry of
    ``curves`` (each an ``evaluate.error_by_steps_since_seen`` result); bins without frames are left out."""
    if not curves:
        raise ValueError("since-seen: no curve given")
    figure = Figure(figsize=(6.0, 4.0), dpi=DPI, layout="constrained")
    ax = figure.add_subplot()
    for name, curve in curves.items():
        points = [(start, median) for start, median in zip(curve["bin_start"], curve["median_m"], strict=True)
                  if median is not None]
        ax.plot([start + 1 for start, _ in points], [median for _, median in points], marker="o", label=name)
    ax.set_xscale("log")
    starts = list(next(iter(curves.values()))["bin_start"])
    ax.set_xticks([start + 1 for start in starts], [str(start) for start in starts])
    ax.set_xlabel("frames since the object was last visible or held (bin start)")
    ax.set_ylabel("median position error (m)")
    ax.set_title(textwrap.fill(title, 72), fontsize=10)  # long study titles wrap instead of being cut
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return figure


def write_since_seen(path: Path, curves: Mapping[str, Mapping[str, Sequence[Any]]], title: str) -> Path:
    """Write ``since_seen_figure`` as a PNG (through a partial name); returns ``path``."""
    return write_png(Path(path), render(since_seen_figure(curves, title)))
