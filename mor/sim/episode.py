"""Sampling one episode's layout: object classes, initial and target configurations, agent spawn, wall textures."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mor.errors import ConfigError
from mor.sim.arena import Arena
from mor.sim.catalog import ALL_WALL_TEXTURES, N_CLASSES, OBJECT_RADIUS, TEXTURE_INDEX, WALL_POOLS
from mor.sim.geometry import Array
from mor.sim.metrics import SUCCESS_RADIUS
from mor.sim.rules import AGENT_RADIUS

#: Objects and targets keep this far (metres) from every wall, so that the agent can reach all sides.
WALL_MARGIN: float = 0.5
#: Minimum distance (metres) between the centres of two objects of one configuration.
OBJECT_SEPARATION: float = 0.6
#: Every target lies at least this far (metres) from its object's initial position: no object starts fixed.
TARGET_MIN_DISTANCE: float = SUCCESS_RADIUS + 0.5
#: The agent spawns at least this far (metres) from walls and, beyond its and the objects' radii, from objects.
SPAWN_CLEARANCE: float = 0.2
#: The agent's spawn point keeps this far (metres) from every wall ...
SPAWN_WALL_MARGIN: float = AGENT_RADIUS + SPAWN_CLEARANCE
#: ... and this far (metres) from every object's centre.
SPAWN_OBJECT_GAP: float = AGENT_RADIUS + OBJECT_RADIUS + SPAWN_CLEARANCE
#: Tries of each rejection loop (per point, per spawn, per layout) before it gives up.
MAX_LAYOUT_TRIES: int = 50


@dataclass(frozen=True)
class EpisodeLayout:
    """Everything random about one episode, fixed at reset.

    object_classes: (n,) int class ids in [0, 24), distinct.
    initial_positions, target_positions: (n, 2) metres.
    agent_pose: (3,) x, y metres, theta radians.
    wall_textures: one index into ``ALL_WALL_TEXTURES`` per wall.
    """

    object_classes: np.ndarray
    initial_positions: Array
    target_positions: Array
    agent_pose: Array
    wall_textures: tuple[int, ...]


def _spaced_points(rng: np.random.Generator, arena: Arena, n: int, avoid: Array | None = None) -> Array | None:
    """n points, each ``WALL_MARGIN`` from walls and ``OBJECT_SEPARATION`` apart; None if they did not fit.

    ``avoid`` (n, 2): point i must also lie ``TARGET_MIN_DISTANCE`` from avoid[i].
    """
    points: list[Array] = []
    for i in range(n):
        for _ in range(MAX_LAYOUT_TRIES):
            point = arena.sample_point(rng, WALL_MARGIN)
            if point is None:
                return None
            if any(np.linalg.norm(point - q) < OBJECT_SEPARATION for q in points):
                continue
            if avoid is not None and np.linalg.norm(point - avoid[i]) < TARGET_MIN_DISTANCE:
                continue
            points.append(point)
            break
        else:
            return None
    return np.asarray(points)


def spawn_pose(rng: np.random.Generator, arena: Arena, obstacles: Array) -> Array | None:
    """A free agent pose (3,) clear of walls and of ``obstacles`` (k, 2); None if none was found."""
    for _ in range(MAX_LAYOUT_TRIES):
        point = arena.sample_point(rng, SPAWN_WALL_MARGIN)
        if point is None:
            return None
        if len(obstacles) and np.min(np.linalg.norm(obstacles - point, axis=1)) < SPAWN_OBJECT_GAP:
            continue
        return np.array([point[0], point[1], rng.uniform(-np.pi, np.pi)])
    return None


def sample_wall_textures(rng: np.random.Generator, n_walls: int, texture_pool: str) -> tuple[int, ...]:
    """One texture index per wall: wall k from its own sub-pool (``per_side``) or all from one (``symmetric``)."""
    if texture_pool == "per_side":
        pools = [WALL_POOLS[k] for k in range(n_walls)]
        return tuple(TEXTURE_INDEX[pool[rng.integers(len(pool))].name] for pool in pools)
    if texture_pool == "symmetric":
        return tuple(int(i) for i in rng.integers(len(ALL_WALL_TEXTURES), size=n_walls))
    raise ConfigError(f"texture_pool: unknown pool {texture_pool!r}; choose 'per_side' or 'symmetric'")


def sample_appearance(
    rng: np.random.Generator, n_objects: int, n_walls: int, texture_pool: str
) -> tuple[np.ndarray, tuple[int, ...]]:
    """What a layout draws after its positions: (n,) distinct object class ids, int64, and one texture per wall."""
    classes = rng.choice(N_CLASSES, size=n_objects, replace=False).astype(np.int64)
    return classes, sample_wall_textures(rng, n_walls, texture_pool)


def sample_layout(rng: np.random.Generator, arena: Arena, n_objects: int, texture_pool: str) -> EpisodeLayout:
    """Draw one episode's layout from ``rng``; raises ConfigError when the objects cannot fit in the arena."""
    for _ in range(MAX_LAYOUT_TRIES):
        initial = _spaced_points(rng, arena, n_objects)
        if initial is None:
            continue
        targets = _spaced_points(rng, arena, n_objects, avoid=initial)
        if targets is None:
            continue
        agent = spawn_pose(rng, arena, initial)
        if agent is None:
            continue
        classes, textures = sample_appearance(rng, n_objects, arena.n_walls, texture_pool)
        return EpisodeLayout(classes, initial, targets, agent, textures)
    raise ConfigError(
        f"arena_size: a {arena.shape} arena of {arena.area():.1f} m^2 is too small for n_objects={n_objects} "
        f"(objects need {OBJECT_SEPARATION} m spacing, {WALL_MARGIN} m from walls and targets "
        f"{TARGET_MIN_DISTANCE} m from their start); use a larger arena_size or fewer objects"
    )
