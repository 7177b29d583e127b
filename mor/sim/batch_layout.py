"""Drawing many episodes' layouts at once, each from its own generator, exactly as ``sample_layout`` draws them.

``sample_layout`` is rejection sampling: uniform points until one lies far enough from the walls and from the
points placed before it. What it draws depends on what it rejected, so a generator cannot be drawn ahead in bulk
blindly. Here each generator's next uniforms are drawn in one call (more than a layout needs, almost always), every
candidate point of every generator is tested at once, and one vectorised pass per point to place finds which
candidate ``sample_layout`` would take, and so how many uniforms it used. Each generator is then put back and
advanced by exactly that many, and the discrete draws that follow (classes, textures) are made by the very calls
``sample_layout`` makes. A generator whose layout the pass cannot settle (it ran out of candidates, or a retry
limit of ``sample_layout`` was reached) is put back and given to ``sample_layout`` itself. So the same generator
states give the same layouts, and leave the same generator states, as ``sample_layout`` one by one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mor.sim import episode
from mor.sim.arena import SAMPLE_POINT_TRIES, Arena
from mor.sim.episode import (
    OBJECT_SEPARATION,
    SPAWN_OBJECT_GAP,
    SPAWN_WALL_MARGIN,
    TARGET_MIN_DISTANCE,
    WALL_MARGIN,
    sample_appearance,
    sample_layout,
)
from mor.sim.geometry import Array, shorter_than
from mor.sim.rules import Flags

#: Candidate points drawn per point to place (at most ``MAX_LAYOUT_TRIES`` in all): a layout needs about 1.5 per
#: point in the square arena, 2.5 in the polygon; running out (then ``sample_layout`` draws the layout) is rare.
_CANDIDATES_PER_POINT: int = 8


@dataclass(frozen=True)
class Layouts:
    """M episodes' layouts (``EpisodeLayout`` stacked): object_classes (M, n) int64; initial_positions and
    target_positions (M, n, 2) metres; agent_pose (M, 3) [x m, y m, theta rad]; wall_textures (M, walls) int64."""

    object_classes: NDArray[np.int64]
    initial_positions: Array
    target_positions: Array
    agent_pose: Array
    wall_textures: NDArray[np.int64]


class _Candidates:
    """Each generator's candidate points, in the order it would draw them, and the walk that places one point per
    generator at a time, every candidate of every generator tested at once.

    x, y (M, C): the candidates; next (M,): each generator's first candidate not yet used; settled (M,): whether the
    walk still follows ``sample_layout`` (False once a generator ran out of candidates).
    """

    def __init__(self, points: Array, arena: Arena) -> None:
        self.x, self.y = points[..., 0].copy(), points[..., 1].copy()
        self.clearance = arena.clearances(points)
        m, c = self.x.shape
        self.rows, self.index = np.arange(m), np.arange(c)
        self.next = np.zeros(m, dtype=np.int64)
        self.settled = np.ones(m, dtype=bool)

    def take(self, margin: float, allowed: Flags) -> Array:
        """The next point (M, 2) of each generator: its first unused candidate ``margin`` from the walls (each such
        one is what ``Arena.sample_point`` returns next) that is also ``allowed`` (M, C). There are at most
        ``MAX_LAYOUT_TRIES`` candidates, so no point can need more tries than ``sample_layout`` allows."""
        accepted = (self.clearance >= margin) & allowed & (self.index >= self.next[:, None])
        chosen = np.argmax(accepted, axis=1)
        self.settled &= accepted[self.rows, chosen]
        self.next = chosen + 1
        return np.stack([self.x[self.rows, chosen], self.y[self.rows, chosen]], axis=-1)

    def farther_than(self, points: Array, distance: float) -> Flags:
        """(M, C) whether each candidate lies ``distance`` or more from its generator's point (M, 2), measured as
        ``np.linalg.norm(candidate - point)`` is."""
        return ~shorter_than(self.x - points[:, :1], self.y - points[:, 1:], distance)

    def spaced(self, count: int, avoid: Array | None = None) -> Array:
        """``count`` points (M, count, 2) as ``episode._spaced_points`` places them."""
        placed: list[Array] = []
        apart = np.ones(self.x.shape, dtype=bool)
        for i in range(count):
            if placed:
                apart &= self.farther_than(placed[-1], OBJECT_SEPARATION)
            allowed = apart if avoid is None else apart & self.farther_than(avoid[:, i], TARGET_MIN_DISTANCE)
            placed.append(self.take(WALL_MARGIN, allowed))
        return np.stack(placed, axis=1)

    def spawn(self, obstacles: Array) -> Array:
        """The agent's spawn points (M, 2), as ``episode.spawn_pose`` chooses them among the obstacles (M, n, 2)."""
        dx, dy = obstacles[:, None, :, 0] - self.x[..., None], obstacles[:, None, :, 1] - self.y[..., None]
        gaps = np.sqrt(dx * dx + dy * dy)  # np.linalg.norm(obstacles - point, axis=1), the same operations
        return self.take(SPAWN_WALL_MARGIN, ~(gaps.min(axis=-1) < SPAWN_OBJECT_GAP))


def sample_layouts(
    rngs: Sequence[np.random.Generator], arena: Arena, n_objects: int, texture_pool: str
) -> Layouts:
    """One layout per generator, each exactly ``sample_layout(rng, arena, n_objects, texture_pool)`` (the same
    values, and the generator left in the same state); raises ConfigError as it does."""
    pairs = min(SAMPLE_POINT_TRIES, episode.MAX_LAYOUT_TRIES, _CANDIDATES_PER_POINT * (2 * n_objects + 1))
    states = [rng.bit_generator.state for rng in rngs]
    uniforms = np.empty((len(rngs), 2 * pairs + 1))  # + 1: the spawn heading
    for rng, row in zip(rngs, uniforms, strict=True):
        rng.random(out=row)
    low, high = arena.bounds
    # Arena.sample_point: rng.uniform(low, high) is low + (high - low) * rng.random(), elementwise, bit for bit
    candidates = _Candidates(low + (high - low) * uniforms[:, : 2 * pairs].reshape(len(rngs), pairs, 2), arena)
    initial = candidates.spaced(n_objects)
    targets = candidates.spaced(n_objects, avoid=initial)
    spawn = candidates.spawn(initial)
    # spawn_pose: rng.uniform(-pi, pi) right after the spawn point's pair
    heading = -np.pi + (np.pi - -np.pi) * uniforms[candidates.rows, 2 * candidates.next]
    agent = np.concatenate([spawn, heading[:, None]], axis=1)
    classes = np.empty((len(rngs), n_objects), dtype=np.int64)
    textures = np.empty((len(rngs), arena.n_walls), dtype=np.int64)
    for row, (rng, state) in enumerate(zip(rngs, states, strict=True)):
        rng.bit_generator.state = state
        if candidates.settled[row]:
            rng.random(2 * candidates.next[row] + 1)  # exactly the uniforms sample_layout used
            classes[row], textures[row] = sample_appearance(rng, n_objects, arena.n_walls, texture_pool)
        else:
            layout = sample_layout(rng, arena, n_objects, texture_pool)
            initial[row], targets[row], agent[row] = layout.initial_positions, layout.target_positions, layout.agent_pose
            classes[row], textures[row] = layout.object_classes, layout.wall_textures
    return Layouts(classes, initial, targets, agent, textures)
