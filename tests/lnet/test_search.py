"""The search belief of objects not found yet (mor.lnet.search, stated by mor.lnet.stated): the camera cone, the look
counts, and that an honest belief gets nominal coverage and its find probability back from the calibration."""

from __future__ import annotations

import numpy as np
import pytest

from mor.lnet.calibration_fit import _search_fit
from mor.lnet.evaluate import NOMINAL_2D, SIGMAS
from mor.lnet.lost import arena_grid
from mor.lnet.search import (
    SearchLooks,
    SearchMap,
    episode_looks,
    in_view,
    search_log_density,
    search_mass,
)
from mor.lnet.stated import StatedParams, not_found
from mor.sim.arena import Arena

ARENA = Arena.build("square", 6.0)
SPACING, MAX_LOOKS = StatedParams.arena_grid_spacing, StatedParams.search_max_looks  # the defaults: 0.1 m, 64


def test_in_view_is_the_cameras_60_degree_cone_at_any_distance() -> None:
    angles = np.deg2rad([0.0, 29.0, -29.0, 31.0, 180.0])
    points = 2.5 * np.stack([np.cos(angles), np.sin(angles)], -1)
    assert in_view(points, np.zeros((1, 2)), np.zeros(1))[0].tolist() == [True, True, True, False, False]
    turned = in_view(points, np.zeros((1, 2)), np.array([np.pi]))[0]   # facing -x: only the point behind
    assert turned.tolist() == [False, False, False, False, True]


def test_look_counts_accumulate_over_the_episode() -> None:
    grid = arena_grid(ARENA, SPACING)
    truth = np.array([[[2.0, 0.0]], [[2.0, 0.0]], [[2.0, 0.0]]])          # (T, K=1, 2): straight ahead at first
    heading = np.array([0.0, np.pi, 0.0])
    histogram, truth_looks = episode_looks(grid, np.zeros((3, 2)), heading, truth, MAX_LOOKS)
    assert truth_looks[:, 0].tolist() == [1, 1, 2]
    assert histogram.sum(1).tolist() == [len(grid)] * 3
    assert histogram[0, 0] > histogram[0, 1] > 0 and histogram[2, 2] == histogram[0, 1]  # the same cone twice


def _honest(find: float, rows: int = 4000, seed: int = 0) -> SearchLooks:
    """Frames whose truth is drawn from the search belief itself (grid points looked at 0-3 times)."""
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, 4, (rows, 200))                               # 200 grid points per frame
    weights = (1.0 - find) ** counts
    chosen = [rng.choice(200, p=w / w.sum()) for w in weights]
    truth_looks = counts[np.arange(rows), chosen][:, None]
    histogram = np.stack([np.bincount(c, minlength=65) for c in counts])
    return SearchLooks(histogram, truth_looks, rng.random((rows, 1)), 0.01)


def test_an_honest_search_belief_covers_nominally_and_a_uniform_one_does_not() -> None:
    looks = _honest(0.6)
    nominal = np.array([NOMINAL_2D[k] for k in SIGMAS])
    coverage = (search_mass(looks, 0.6)[:, 0][:, None] <= nominal).mean(0)
    assert np.all(np.abs(coverage - nominal) < 0.03)
    uniform = (search_mass(looks, 0.0)[:, 0][:, None] <= nominal).mean(0)
    assert np.abs(uniform - nominal).max() > 0.05                            # the test can fail
    rows = np.ones((len(looks.truth_looks), 1), bool)
    assert _search_fit("coverage", looks, rows) == pytest.approx(0.6, abs=0.07)
    assert _search_fit("nll", looks, rows) == pytest.approx(0.6, abs=0.07)


def test_log_density_integrates_to_one_and_rules_out_looked_places_at_find_one() -> None:
    looks = _honest(0.5, rows=3)
    for find in (0.0, 0.5):
        density = np.exp(search_log_density(SearchLooks(looks.histogram, np.arange(65)[None].repeat(3, 0),
                                                        np.zeros((3, 65)), 0.01), find))
        assert np.allclose((density * looks.histogram * 0.01).sum(1), 1.0)
    certain = SearchLooks(looks.histogram, np.array([[0], [1], [2]]), np.zeros((3, 1)), 0.01)
    assert np.isneginf(search_log_density(certain, 1.0)[1:]).all()
    assert np.all(search_mass(certain, 1.0)[1:] == 1.0)


def test_not_found_is_a_belief_wider_than_the_chosen_width() -> None:
    tril = np.stack([np.eye(2) * 1.5, np.eye(2) * 0.3, np.diag([4.0, 0.2])])
    assert not_found(tril, StatedParams.not_found_sigma).tolist() == [True, False, False]  # 1 m
    assert not_found(tril, 0.25).tolist() == [True, True, True]


def test_the_streaming_search_map_counts_what_the_episode_looks_count() -> None:
    rng = np.random.default_rng(1)
    agent_xy, heading = rng.uniform(-2.0, 2.0, (6, 2)), rng.uniform(-np.pi, np.pi, 6)
    histogram, _ = episode_looks(arena_grid(ARENA, SPACING), agent_xy, heading, np.zeros((6, 1, 2)), MAX_LOOKS)
    search = StatedParams().search_map(ARENA, n_envs=2)
    for t in range(6):
        search.update(np.stack([agent_xy[t], agent_xy[0]]), np.array([heading[t], heading[0]]))
        assert np.bincount(search.counts[0], minlength=65).tolist() == histogram[t].tolist()
    assert search.counts[1].max() == 6                                     # the second env kept looking one way
    density = search.density(0.5)
    assert np.allclose(density.sum(1) * search.cell_area, 1.0)
    assert density[1].min() < density[1].max()                             # looked-at places are less likely
    search.reset(np.array([False, True]))
    assert search.counts[1].sum() == 0 and search.counts[0].sum() > 0


def test_a_smaller_look_cap_and_a_coarser_grid_take_effect() -> None:
    grid = arena_grid(ARENA, 0.5)
    assert len(grid) == 144                                                # (6 m / 0.5 m)^2 points
    truth = np.tile([[[2.0, 0.0]]], (10, 1, 1))                             # straight ahead, 10 frames
    histogram, truth_looks = episode_looks(grid, np.zeros((10, 2)), np.zeros(10), truth, 8)
    assert histogram.shape == (10, 9) and truth_looks[:, 0].tolist() == [*range(1, 9), 8, 8]
    every_count = SearchLooks(histogram, np.arange(9)[None].repeat(10, 0), np.zeros((10, 9)), 0.25)
    assert every_count.max_looks == 8                                      # the weights have 9 bins: a density
    assert np.allclose((np.exp(search_log_density(every_count, 0.5)) * histogram * 0.25).sum(1), 1.0)
    search = SearchMap(ARENA, 1, 8, 0.5)
    for _ in range(10):
        search.update(np.zeros((1, 2)), np.zeros(1))
    assert search.counts.max() == 8 and np.bincount(search.counts[0], minlength=9).tolist() == histogram[-1].tolist()
    assert np.allclose(search.density(0.5).sum(1) * search.cell_area, 1.0) and search.cell_area == 0.25
