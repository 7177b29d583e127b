"""Free space around the agent: how far it could drive along a few headings before touching a wall or a floor
object, from a belief's means and the arena's known walls (derived features: they tell the policy nothing the
belief and the fixed arena do not, but PPO learns obstruction-free driving from them far sooner)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from mor.policy.belief import PoseBelief
from mor.sim.arena import Arena
from mor.sim.catalog import OBJECT_RADIUS
from mor.sim.rules import AGENT_RADIUS

RAY_ANGLES = np.deg2rad([-60.0, -30.0, 0.0, 30.0, 60.0])  # left positive, from the heading
MAX_CLEARANCE = 3.0  # metres: rays are cut here


def clearance(belief: PoseBelief, held: NDArray, arena: Arena) -> NDArray[np.float32]:
    """(N, len(RAY_ANGLES)) distance, metres, the agent's centre can travel along each ray before its disc
    touches a wall or a floor object's disc (held objects are carried, not obstacles), capped at MAX_CLEARANCE."""
    origin = belief.agent_mean.astype(np.float64)[:, None, :]  # (N, 1, 2)
    angles = belief.heading.astype(np.float64)[:, None] + RAY_ANGLES[None]  # (N, R)
    direction = np.stack([np.cos(angles), np.sin(angles)], -1)  # (N, R, 2)
    distance = np.minimum(_to_walls(origin, direction, arena) - AGENT_RADIUS, MAX_CLEARANCE)
    n_objects = belief.n_objects
    floor = np.arange(n_objects)[None] != np.asarray(held, int)[:, None]  # (N, n)
    offset = belief.object_mean.astype(np.float64) - origin  # (N, n, 2) from the agent to each object
    along = np.einsum("nrd,nod->nro", direction, offset)  # (N, R, n) along each ray
    across_sq = np.sum(offset**2, -1)[:, None] - along**2
    reach = (AGENT_RADIUS + OBJECT_RADIUS) ** 2 - across_sq
    hit = floor[:, None] & (reach > 0) & (along > 0)
    object_distance = np.where(hit, along - np.sqrt(np.maximum(reach, 0.0)), np.inf)
    distance = np.minimum(distance, object_distance.min(-1))
    return np.maximum(distance, 0.0).astype(np.float32)


def _to_walls(origin: NDArray, direction: NDArray, arena: Arena) -> NDArray:
    """(N, R) distance along each ray to the first wall it crosses."""
    start, end = arena.wall_starts[None, None], arena.wall_ends[None, None]  # (1, 1, W, 2)
    wall = end - start
    o, d = origin[:, :, None], direction[:, :, None]  # (N, R|1, 1, 2)
    denominator = d[..., 0] * wall[..., 1] - d[..., 1] * wall[..., 0]
    delta = start - o
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (delta[..., 0] * wall[..., 1] - delta[..., 1] * wall[..., 0]) / denominator
        u = (delta[..., 0] * d[..., 1] - delta[..., 1] * d[..., 0]) / denominator
    valid = (np.abs(denominator) > 1e-12) & (t >= 0) & (u >= 0) & (u <= 1)
    return np.where(valid, t, np.inf).min(-1)
