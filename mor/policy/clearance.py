"""Free space around the agent: how far it could drive along a few headings before touching a wall or a floor
object, from a belief's means and the arena's known walls (derived features: they tell the policy nothing the
belief and the fixed arena do not, but PPO learns obstruction-free driving from them far sooner)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from mor.policy.belief import PoseBelief
from mor.sim.arena import Arena
from mor.sim.catalog import OBJECT_RADIUS
from mor.sim.rules import AGENT_RADIUS


def clearance(belief: PoseBelief, held: NDArray, arena: Arena, rays_deg: Sequence[float], max_clearance: float
              ) -> NDArray[np.float32]:
    """(N, R) distance, metres, the agent's centre can travel along each of the R rays (``rays_deg``, degrees
    from the heading, left positive) before its disc touches a wall or a floor object's disc (held objects are
    carried, not obstacles), capped at ``max_clearance`` metres (``policy.observation`` in params.yaml).

    The arrays run (rays, walls or objects, N): the N environments innermost, so that each operation is one long
    loop however small the arena or the scene."""
    origin = belief.agent_mean.astype(np.float64).T[:, None, None]  # (2, 1, 1, N)
    angles = belief.heading.astype(np.float64)[None] + np.deg2rad(np.asarray(rays_deg, np.float64))[:, None]  # (R, N)
    direction = np.stack([np.cos(angles), np.sin(angles)])[:, :, None]  # (2, R, 1, N)
    distance = np.minimum(_to_walls(origin, direction, arena) - AGENT_RADIUS, max_clearance)  # (R, N)
    floor = np.arange(belief.n_objects)[:, None] != np.asarray(held, int)[None]  # (n, N)
    offset = belief.object_mean.astype(np.float64).transpose(2, 1, 0)[:, None] - origin  # (2, 1, n, N) agent -> object
    along = direction[0] * offset[0] + direction[1] * offset[1]  # (R, n, N) along each ray
    across_sq = (offset[0] ** 2 + offset[1] ** 2) - along**2
    reach = (AGENT_RADIUS + OBJECT_RADIUS) ** 2 - across_sq
    hit = floor & (reach > 0) & (along > 0)
    object_distance = np.where(hit, along - np.sqrt(np.maximum(reach, 0.0)), np.inf)
    distance = np.minimum(distance, object_distance.min(axis=1))
    return np.maximum(distance, 0.0).astype(np.float32).T


def _to_walls(origin: NDArray, direction: NDArray, arena: Arena) -> NDArray:
    """(R, N) distance along each ray to the first wall it crosses; origin (2, 1, 1, N), direction (2, R, 1, N)."""
    shape = (2, 1, arena.n_walls, 1)
    start, end = arena.wall_starts.T.reshape(shape), arena.wall_ends.T.reshape(shape)
    wall = end - start
    denominator = direction[0] * wall[1] - direction[1] * wall[0]  # (R, W, N)
    delta = start - origin
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (delta[0] * wall[1] - delta[1] * wall[0]) / denominator
        u = (delta[0] * direction[1] - delta[1] * direction[0]) / denominator
    valid = (np.abs(denominator) > 1e-12) & (t >= 0) & (u >= 0) & (u <= 1)
    return np.where(valid, t, np.inf).min(axis=1)
