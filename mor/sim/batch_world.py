"""N worlds held as arrays and changed by one action each, together: the batched form of ``rules.apply_action``.

Every rule is ``mor.sim.rules``' own (written once, over N worlds); this module only holds the N states and routes
each action to its rule. The motion noise comes in as one standard normal draw per MOVE or turn, drawn by the
caller from each world's own generator (``MotionNoise.move_distances``, ``turn_angles``), so a world's trajectory
is the one ``apply_action`` gives it with the same generator. Units: metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mor.sim.arena import Arena
from mor.sim.geometry import Array, heading_vector, wrap_angle
from mor.sim.rules import (
    Action,
    Flags,
    MotionNoise,
    drop_point,
    drops_free,
    floor_mask,
    paths_obstructed,
    pick_candidates,
)

#: ``apply_actions``' action for a world that does nothing this step (the env's masked action)
NO_ACTION: int = -1
#: the actions that draw motion noise
NOISY_ACTIONS: NDArray[np.int64] = np.array([Action.MOVE, Action.TURN_LEFT, Action.TURN_RIGHT])


@dataclass
class WorldBatch:
    """N worlds' states (``WorldState`` stacked).

    agent_pose (N, 3) [x m, y m, theta rad]; floor_positions (N, n, 2) metres, a held object's row keeping its last
    floor position; held (N,) int64, the held object's index or -1.
    """

    agent_pose: Array
    floor_positions: Array
    held: NDArray[np.int64]

    @property
    def n_worlds(self) -> int:
        return int(self.agent_pose.shape[0])

    def on_floor(self) -> Flags:
        """(N, n) the objects lying on the floor (all but the held one)."""
        return floor_mask(self.held, self.floor_positions.shape[1])

    def object_positions(self) -> Array:
        """(N, n, 2) where each object is now: a held one travels with its agent."""
        positions = self.floor_positions.copy()
        holding = np.flatnonzero(self.held >= 0)
        positions[holding, self.held[holding]] = self.agent_pose[holding, :2]
        return positions


@dataclass(frozen=True)
class EventBatch:
    """What N actions did (``Events`` stacked), each (N,): obstructed, picked (-1: nothing), dropped (-1: nothing),
    drop_blocked."""

    obstructed: Flags
    picked: NDArray[np.int64]
    dropped: NDArray[np.int64]
    drop_blocked: Flags


def apply_actions(world: WorldBatch, actions: NDArray[np.int64], arena: Arena, noise: MotionNoise,
                  standard: Array) -> EventBatch:
    """Carry out one action per world on ``world`` in place, as ``rules.apply_action`` does for one world.

    actions (N,) ``Action`` values, or ``NO_ACTION``; standard (N,) a standard normal draw for each world whose
    action is in ``NOISY_ACTIONS`` (ignored elsewhere).
    """
    n_worlds = world.n_worlds
    obstructed = np.zeros(n_worlds, dtype=bool)
    picked = np.full(n_worlds, -1, dtype=np.int64)
    dropped = np.full(n_worlds, -1, dtype=np.int64)
    drop_blocked = np.zeros(n_worlds, dtype=bool)

    rows = np.flatnonzero(actions == Action.MOVE)
    if len(rows):
        pose = world.agent_pose[rows]
        distance = noise.move_distances(standard[rows])
        hit = paths_obstructed(pose, distance, world.floor_positions[rows], world.on_floor()[rows], arena)
        obstructed[rows] = hit
        free = rows[~hit]
        world.agent_pose[free, :2] += distance[~hit, None] * heading_vector(pose[~hit, 2])

    rows = np.flatnonzero((actions == Action.TURN_LEFT) | (actions == Action.TURN_RIGHT))
    if len(rows):
        sign = np.where(actions[rows] == Action.TURN_LEFT, 1.0, -1.0)
        world.agent_pose[rows, 2] = wrap_angle(world.agent_pose[rows, 2] + sign * noise.turn_angles(standard[rows]))

    rows = np.flatnonzero(actions == Action.PICK)
    if len(rows):
        candidate = pick_candidates(world.agent_pose[rows], world.floor_positions[rows], world.held[rows])
        taken = candidate >= 0
        world.held[rows[taken]] = picked[rows[taken]] = candidate[taken]

    rows = np.flatnonzero((actions == Action.DROP) & (world.held >= 0))
    if len(rows):
        pose = world.agent_pose[rows]
        point = drop_point(pose)
        fits = drops_free(pose, world.floor_positions[rows], world.on_floor()[rows], point, arena.clearances(point))
        released = rows[fits]
        dropped[released] = world.held[released]
        world.floor_positions[released, world.held[released]] = point[fits]
        world.held[released] = -1
        drop_blocked[rows[~fits]] = True
    return EventBatch(obstructed, picked, dropped, drop_blocked)
