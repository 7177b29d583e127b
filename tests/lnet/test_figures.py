"""Figures of the L-Net's estimates: contour and sector geometry, and that every writer leaves a readable image."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from matplotlib.figure import Figure
from PIL import Image

from mor.lnet.figures import (
    Truth,
    as_frames,
    draw_estimate_panel,
    ellipse_points,
    HEADING_MASS,
    heading_halfwidth,
    learning_curve_figure,
    write_estimate_gif,
    write_estimate_strip,
    write_learning_curve,
    write_reliability_diagram,
)

T, K = 12, 5
CLASSES = np.array([0, 8, 21, -1, -1])  # red cube, blue sphere, yellow capsule; two absent slots


@pytest.fixture(scope="module")
def episode() -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], np.ndarray]:
    """(truth, estimate, images): the agent drives a 1.5 m circle counter-clockwise in the 6 m arena; objects 0 and 2
    stand still, object 1 slides east; the estimate is off by a little, with growing uncertainty."""
    phase = np.linspace(0.0, 2.0 * np.pi, T, endpoint=False)
    poses = np.stack([1.5 * np.cos(phase), 1.5 * np.sin(phase), phase + np.pi / 2], axis=-1)
    objects = np.zeros((T, K, 2))
    objects[:, 0] = (-2.0, 2.0)
    objects[:, 1] = np.stack([np.linspace(-1.0, 1.0, T), np.full(T, -2.2)], axis=-1)
    objects[:, 2] = (2.2, 1.8)
    scale = np.linspace(0.1, 0.4, T)
    agent_tril = np.zeros((T, 2, 2))
    agent_tril[:, 0, 0], agent_tril[:, 1, 1], agent_tril[:, 1, 0] = scale, 0.5 * scale, 0.3 * scale
    object_tril = np.repeat(np.diag([0.25, 0.15])[None, None], T, 0).repeat(K, 1)
    object_tril[:, :, 1, 0] = 0.1
    estimate = {
        "agent_mean": poses[:, :2] + 0.15,
        "agent_tril": agent_tril,
        "heading": poses[:, 2] + 0.2,
        "kappa": np.geomspace(200.0, 2.0, T),
        "object_mean": objects + np.array([0.2, -0.1]),
        "object_tril": object_tril,
    }
    truth = {"agent_poses": poses, "object_positions": objects, "object_classes": CLASSES}
    images = np.random.default_rng(0).integers(0, 256, (T, 16, 16, 3), dtype=np.uint8)
    return truth, estimate, images


def test_ellipse_points_lie_at_mahalanobis_n_sigma() -> None:
    rng = np.random.default_rng(1)
    for n_sigma in (1.0, 2.0, 3.0):
        tril = np.array([[rng.uniform(0.1, 1.0), 0.0], [rng.normal(), rng.uniform(0.1, 1.0)]])
        mean = rng.normal(size=2)
        points = ellipse_points(mean, tril, n_sigma, n=50)
        assert points.shape == (50, 2)
        inverse = np.linalg.inv(tril @ tril.T)
        delta = points - mean
        distances = np.sqrt(np.einsum("ni,ij,nj->n", delta, inverse, delta))
        np.testing.assert_allclose(distances, n_sigma, rtol=1e-10)


def test_ellipse_points_of_an_axis_aligned_gaussian_reach_n_sigma_along_each_axis() -> None:
    points = ellipse_points(np.array([1.0, -1.0]), np.diag([0.5, 0.2]), 2.0, n=360)
    np.testing.assert_allclose(points.max(axis=0) - [1.0, -1.0], [1.0, 0.4], atol=1e-9)
    np.testing.assert_allclose(points.min(axis=0) - [1.0, -1.0], [-1.0, -0.4], atol=1e-9)


def test_heading_halfwidth_shrinks_with_kappa_like_two_over_sqrt_kappa() -> None:
    kappas = np.geomspace(1e-3, 1e5, 30)
    widths = heading_halfwidth(kappas, HEADING_MASS)
    assert widths.shape == kappas.shape
    assert np.all(np.diff(widths) < 0)
    for kappa in (1e3, 1e4, 1e5):
        assert heading_halfwidth(kappa, HEADING_MASS) == pytest.approx(2.0 / math.sqrt(kappa), rel=0.01)
    assert heading_halfwidth(0.0, HEADING_MASS) == pytest.approx(0.954 * math.pi)  # uniform: the sector is mass * 360 degrees
    assert heading_halfwidth(1e-15, HEADING_MASS) == pytest.approx(0.954 * math.pi)
    with pytest.raises(ValueError):
        heading_halfwidth(-1.0, HEADING_MASS)


def test_panel_draws_stars_for_present_objects_only(episode, square_arena) -> None:
    truth, estimate, _ = episode
    ax = Figure().add_subplot()
    draw_estimate_panel(ax, square_arena, truth, estimate, 3)
    stars = [line for line in ax.lines if line.get_marker() == "*"]
    assert len(stars) == 1 + 3
    assert ax.get_title() == "t = 3"
    assert ax.get_xlim() == pytest.approx((-3.12, 3.12)) and ax.get_aspect() == 1.0
    assert sum(type(p).__name__ == "Wedge" for p in ax.patches) == 1


def test_panel_rejects_a_batched_estimate(episode, square_arena) -> None:
    truth, estimate, _ = episode
    batched = {key: value[None] for key, value in estimate.items()}
    with pytest.raises(ValueError, match="shapes"):
        draw_estimate_panel(Figure().add_subplot(), square_arena, truth, batched, 0)


def test_strip_is_a_png_one_column_per_frame(episode, square_arena, tmp_path) -> None:
    truth, estimate, images = episode
    plain = write_estimate_strip(tmp_path / "strip.png", square_arena, truth, estimate, [0, 5])
    with_images = write_estimate_strip(tmp_path / "strip_fpv.png", square_arena, Truth.of(truth), estimate,
                                       [0, 5, 11], images=images)
    with Image.open(plain) as a, Image.open(with_images) as b:
        assert a.format == b.format == "PNG"
        assert b.width > a.width and b.height > a.height
    assert sorted(p.name for p in tmp_path.iterdir()) == ["strip.png", "strip_fpv.png"]


def test_gif_has_one_frame_per_selected_time(episode, square_arena, tmp_path) -> None:
    truth, estimate, images = episode
    path = write_estimate_gif(tmp_path / "track.gif", square_arena, truth, estimate, fps=5)
    with Image.open(path) as gif:
        assert gif.format == "GIF" and gif.n_frames == T
        plain_width = gif.width
    path = write_estimate_gif(tmp_path / "track_fpv.gif", square_arena, truth, estimate, images=images, every=5)
    with Image.open(path) as gif:
        assert gif.n_frames == math.ceil(T / 5) and gif.width > plain_width


def test_images_in_torch_layout_are_converted(episode) -> None:
    _, _, images = episode
    chw = images.transpose(0, 3, 1, 2).astype(np.float32) / 255.0
    np.testing.assert_array_equal(as_frames(chw), images)


def test_reliability_diagram_is_a_png(tmp_path) -> None:
    nominal = np.linspace(0.05, 0.95, 10)
    observed = {"agent position (before calibration)": nominal ** 2, "agent position (after)": nominal * 0.98}
    path = write_reliability_diagram(tmp_path / "reliability.png", nominal, observed, "Agent position")
    with Image.open(path) as image:
        assert image.format == "PNG"
    with pytest.raises(ValueError):
        write_reliability_diagram(tmp_path / "bad.png", nominal, {"short": nominal[:3]}, "bad")


def test_learning_curve_log_scale_only_for_positive_losses(tmp_path) -> None:
    rows = [{"step": s, "split": "train", "loss": 2.0 / s} for s in range(1, 201)]
    rows += [{"step": s, "split": "validation", "loss": 2.5 / s} for s in range(50, 201, 50)]
    assert learning_curve_figure(rows).axes[0].get_yscale() == "log"
    negative = rows + [{"step": 201, "split": "validation", "loss": -0.5}]
    assert learning_curve_figure(negative).axes[0].get_yscale() == "linear"
    # The training's log.csv read back with csv.DictReader: every value a string.
    log = tmp_path / "log.csv"
    with log.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=["step", "split", "loss", "seconds"])
        writer.writeheader()
        writer.writerows({**row, "seconds": 0.1} for row in negative)
    with log.open() as handle:
        path = write_learning_curve(tmp_path / "curve.png", list(csv.DictReader(handle)))
    with Image.open(path) as image:
        assert image.format == "PNG"
    with pytest.raises(ValueError):
        write_learning_curve(tmp_path / "empty.png", [])


def test_truth_accepts_a_sequence_window_item_and_checks_shapes(episode) -> None:
    truth, _, _ = episode
    item = {"agent_pose": truth["agent_poses"].astype(np.float32), "object_positions": truth["object_positions"],
            "object_classes": truth["object_classes"]}
    assert Truth.of(item).n_frames == T
    with pytest.raises(ValueError, match="truth"):
        Truth.of({**item, "object_positions": truth["object_positions"][:, :3]})


def test_an_ego_frame_estimate_is_refused(episode, square_arena) -> None:
    truth, estimate, _ = episode

    class EgoEstimate:
        frame = "ego"

        def to_numpy(self) -> dict[str, np.ndarray]:
            return estimate

    with pytest.raises(ValueError, match="world frame"):
        draw_estimate_panel(Figure().add_subplot(), square_arena, truth, EgoEstimate(), 0)


def test_since_seen_figure_skips_empty_bins(tmp_path) -> None:
    from mor.lnet.figures import write_since_seen  # noqa: PLC0415

    curve = {"bin_start": [0, 1, 2], "median_m": [0.2, None, 0.5], "count": [3, 0, 2]}
    path = write_since_seen(tmp_path / "s.png", {"lstm": curve, "filter": curve}, "t")
    assert path.read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(ValueError, match="no curve"):
        write_since_seen(tmp_path / "e.png", {}, "t")
