"""Objects not found yet: a belief that keeps where the agent has looked (negative information).

Until the tracker finds an object its Gaussian is the arena prior, which says nothing about where the agent has
already looked and seen nothing. A deployed searcher knows more: the object is less likely where the camera has
pointed. The *search belief* states it on the arena grid (``mor.lnet.lost.arena_grid``): a point that was inside
the estimated camera cone (``rules.CAMERA_FOV``, from the tracked agent pose) in c frames so far has density

    p(x) proportional to (1 - q)^c(x)        (q: the probability that one look finds the object)

so q = 0 is the uniform arena and q = 1 rules out every place looked at. q is fitted on validation
(``mor.lnet.calibration_fit``: ``search_find`` in ``calibration.json``, by the calibration's criterion); occlusion
and the PoseNet's misses of far objects are what keep it below 1. Which beliefs have not found their object, and so
are stated by this belief, is the stated belief's call (``mor.lnet.stated.not_found``).

The belief is flat wherever the look counts tie, so its highest-density region of mass p is not unique: the truth
is counted inside it by the randomized probability integral transform (Czado, Gneiting & Held 2009), mass =
P(density > the truth's) + u P(density = the truth's) with u ~ U(0, 1) from a fixed seed, which is uniform on
[0, 1] exactly when the belief is right, so the k-sigma coverage is nominal when the belief is honest.

Shapes: N frames, K object slots, M grid points, C + 1 look-count bins (C = ``max_looks``,
``StatedParams.search_max_looks``: counts above it are lumped with it). Positions in metres, headings in radians.
The grid's spacing (m) is ``StatedParams.arena_grid_spacing``; both are chosen in the profile (``lnet.*``) and
recorded in ``calibration.json``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mor.lnet.lost import arena_grid
from mor.sim.arena import Arena
from mor.sim.rules import CAMERA_FOV

#: The one-look find probabilities q the calibration chooses from.
FIND_GRID = np.linspace(0.0, 0.98, 50)
_TIE_SEED = 0


def in_view(points: np.ndarray, agent_xy: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """(T, M) whether each point (M, 2) lies inside the camera's horizontal field of view (``rules.CAMERA_FOV``,
    any distance, as ``rules.visible`` without occlusion) of each pose: agent_xy (T, 2), heading (T,)."""
    delta = points[None] - agent_xy[:, None]                                           # (T, M, 2)
    forward = np.stack([np.cos(heading), np.sin(heading)], -1)[:, None]                # (T, 1, 2)
    along = (delta * forward).sum(-1)
    across = delta[..., 1] * forward[..., 0] - delta[..., 0] * forward[..., 1]
    return np.abs(np.arctan2(across, along)) <= CAMERA_FOV / 2.0


@dataclass(frozen=True)
class SearchLooks:
    """For a set of predictions: per frame (N,) the grid's look-count histogram ``histogram`` (N, C + 1) (how many
    grid points were in view in 0, 1, ..., C or more frames of the episode so far, this one included), per frame
    and slot the truth's own count ``truth_looks`` (N, K), a tie-breaking draw ``tie`` (N, K) in [0, 1), and the
    area (m^2) one grid point stands for."""

    histogram: np.ndarray
    truth_looks: np.ndarray
    tie: np.ndarray
    cell_area: float

    @property
    def max_looks(self) -> int:
        """C: the look count the histogram's last bin stands for (and every count above it)."""
        return self.histogram.shape[1] - 1

    def select(self, rows: np.ndarray) -> SearchLooks:
        """The looks of the frames ``rows`` (as ``Predictions.select``)."""
        return SearchLooks(self.histogram[rows], self.truth_looks[rows], self.tie[rows], self.cell_area)


def episode_looks(grid: np.ndarray, agent_xy: np.ndarray, heading: np.ndarray, truth: np.ndarray, max_looks: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """One episode's (histogram (T, C + 1), truth_looks (T, K)) of ``SearchLooks`` from the tracked agent pose
    (agent_xy (T, 2) m, heading (T,) rad) and the objects' true positions truth (T, K, 2) m on the grid points
    ``grid`` (M, 2) m, counts capped at C = ``max_looks``."""
    length = len(agent_xy)
    counts = np.minimum(np.cumsum(in_view(grid, agent_xy, heading), 0), max_looks)       # (T, M)
    index = counts + (max_looks + 1) * np.arange(length)[:, None]
    histogram = np.bincount(index.ravel(), minlength=length * (max_looks + 1)).reshape(length, max_looks + 1)
    truth_looks = np.empty(truth.shape[:2], np.int64)
    seen_by = np.tril(np.ones((length, length), bool))                                   # frame s <= t
    for slot in range(truth.shape[1]):
        viewed = in_view(truth[:, slot], agent_xy, heading)                               # (s, t): t's truth, pose s
        truth_looks[:, slot] = np.minimum((viewed & seen_by.T).sum(0), max_looks)
    return histogram, truth_looks


def search_looks(agent_xy: np.ndarray, heading: np.ndarray, truth: np.ndarray, episode: np.ndarray, arena: Arena,
                 max_looks: int, spacing: float) -> SearchLooks:
    """``SearchLooks`` of frames of many episodes: tracked agent_xy (N, 2) m, heading (N,) rad, true object
    positions truth (N, K, 2) m, episode (N,) (each episode's frames contiguous and in order), on the arena grid of
    ``spacing`` metres (``mor.lnet.lost.arena_grid``), counts capped at ``max_looks``."""
    grid = arena_grid(arena, spacing)
    parts = [episode_looks(grid, agent_xy[rows], heading[rows], truth[rows], max_looks)
             for rows in np.split(np.arange(len(episode)), np.flatnonzero(np.diff(episode)) + 1) if len(rows)]
    histogram, truth_looks = (np.concatenate(column) for column in zip(*parts, strict=True))
    tie = np.random.default_rng(_TIE_SEED).random(truth_looks.shape)
    return SearchLooks(histogram, truth_looks, tie, arena.area() / len(grid))


def _weights(find: float, max_looks: int) -> np.ndarray:
    """(C + 1,) the unnormalized density (1 - q)^c of a point looked at c times, C = ``max_looks``."""
    return (1.0 - find) ** np.arange(max_looks + 1, dtype=np.float64)


def search_mass(looks: SearchLooks, find: float) -> np.ndarray:
    """(N, K) the randomized mass of the search belief's highest-density region that reaches the truth (module
    docstring): the truth is counted inside the k-sigma-equivalent region when this is <= the k-sigma mass."""
    weights = _weights(find, looks.max_looks)
    mass = looks.histogram * weights                                                   # (N, C + 1)
    total = mass.sum(1, keepdims=True)
    above = np.concatenate([np.zeros((len(mass), 1)), np.cumsum(mass, 1)], 1)           # mass of counts < c
    rows = np.arange(len(mass))[:, None]
    return (above[rows, looks.truth_looks] + looks.tie * mass[rows, looks.truth_looks]) / total


def search_log_density(looks: SearchLooks, find: float) -> np.ndarray:
    """(N, K) log p(truth) (per m^2) under the search belief; -inf where q = 1 rules the truth out."""
    weights = _weights(find, looks.max_looks)
    total = (looks.histogram * weights).sum(1, keepdims=True)
    with np.errstate(divide="ignore"):
        return np.log(weights[looks.truth_looks] / total) - math.log(looks.cell_area)


class SearchMap:
    """The search belief in a running loop: per environment, the look counts of the arena grid, updated once per
    frame from the streaming step's estimated pose (kept by ``mor.lnet.streaming.StreamingTracker`` given the
    arena), for the objects whose ``Estimates.object_searching`` is True.

    grid (M, 2) the points (m) of the arena grid of ``spacing`` metres; counts (N, M) how many frames of the episode
    so far each point was in view (capped at ``max_looks``); cell_area (m^2) the area one point stands for.
    ``StatedParams.search_map`` makes one with the calibration's settings.
    """

    def __init__(self, arena: Arena, n_envs: int, max_looks: int, spacing: float) -> None:
        self.grid = arena_grid(arena, spacing)
        self.cell_area = arena.area() / len(self.grid)
        self.max_looks = max_looks
        self.counts = np.zeros((n_envs, len(self.grid)), np.int64)

    def update(self, agent_mean: np.ndarray, heading: np.ndarray) -> None:
        """Count this frame's looks: agent_mean (N, 2) m and heading (N,) rad, the estimated poses."""
        self.counts = np.minimum(self.counts + in_view(self.grid, agent_mean, heading), self.max_looks)

    def reset(self, done: np.ndarray) -> None:
        """Forget the looks of the environments where ``done`` (N,) bool is True (a new episode)."""
        self.counts[np.asarray(done, bool)] = 0

    def density(self, find: float) -> np.ndarray:
        """(N, M) the search belief's density (per m^2) at the grid points, for one-look find probability ``find``
        (``mor.lnet.stated.StatedParams.search_find``)."""
        weights = (1.0 - find) ** self.counts
        return weights / (weights.sum(1, keepdims=True) * self.cell_area)
