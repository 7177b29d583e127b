"""A scripted expert that reads ground truth from ``info``: turn to the goal, drive around obstacles, act.

Pick: drive to the goal object and PICK once ``pick_candidate`` is the goal. Drop: choose a free standing point
1.5 m short of the target facing it, drive there, turn, and DROP once ``drop_point`` lands near the target.
Rearrange: a greedy order (nearest misplaced object first), chaining the two.
It uses the very rules the environment applies (``mor.sim.rules``), so it can only exploit what the world allows.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mor.sim.arena import Arena
from mor.sim.catalog import OBJECT_RADIUS
from mor.sim.geometry import Array, bearing, heading_vector, point_segment_distance
from mor.sim.metrics import is_fixed
from mor.sim.rules import (
    AGENT_RADIUS,
    DROP_DISTANCE,
    Action,
    MotionNoise,
    WorldState,
    drop_free,
    drop_point,
    move_obstructed,
    pick_candidate,
)

_HEADING_TOLERANCE = np.deg2rad(8.0)
_CLEARANCE = AGENT_RADIUS + OBJECT_RADIUS + 0.2  # how wide the oracle passes objects (metres)
_WALL_CLEARANCE = AGENT_RADIUS + 0.25
_PICK_APPROACH = 0.7  # drive until the goal object is this close (metres)
_DROP_TOLERANCE = 0.35  # drop once the drop point is this close to the aim point (metres)
_STAND_TOLERANCE = 0.15


class Oracle:
    """``act(observation, info) -> action`` for any MOR task, from the ground truth in ``info``."""

    def __init__(self, arena: Arena, noise: MotionNoise | None = None) -> None:
        self.arena = arena
        self.noise = noise or MotionNoise()
        self._stand: Array | None = None
        self._aim: Array | None = None

    def reset(self) -> None:
        """Forget the current drop plan (call at every episode start)."""
        self._stand = self._aim = None

    def __call__(self, observation: dict[str, Any], info: dict[str, Any]) -> int:
        return self.act(observation, info)

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> int:
        state = WorldState(np.asarray(info["agent_pose"], float), np.asarray(info["object_positions"], float),
                           int(info["held"]))
        if "goal_object" in observation:
            return self.pick(state, int(observation["goal_object"]))
        targets = np.asarray(info["target_positions"], float)
        if state.held >= 0:
            return self.drop(state, targets[state.held])
        self.reset()
        misplaced = [i for i in np.flatnonzero(~is_fixed(state.floor_positions, targets))]
        if not misplaced:
            return int(Action.TURN_LEFT)
        distances = np.linalg.norm(state.floor_positions[misplaced] - state.agent_pose[:2], axis=1)
        return self.pick(state, int(misplaced[int(np.argmin(distances))]))

    # ---- skills ----------------------------------------------------------------------------------------------
    def pick(self, state: WorldState, goal: int) -> int:
        """Next action towards picking object ``goal``."""
        if pick_candidate(state) == goal:
            return int(Action.PICK)
        position = state.floor_positions[goal]
        if np.linalg.norm(position - state.agent_pose[:2]) > _PICK_APPROACH:
            return self.navigate(state, position, ignore=goal)
        return self._face_or_creep(state, position)

    def drop(self, state: WorldState, target: Array) -> int:
        """Next action towards dropping the held object within the success radius of ``target``."""
        if self._aim is None or not self._plan_valid(state):
            self._plan_drop(state, target)
        if self._aim is None or self._stand is None:
            return self.navigate(state, target)  # no plan fits from here: get closer and try again
        landing = drop_point(state.agent_pose)
        if np.linalg.norm(landing - self._aim) < _DROP_TOLERANCE and drop_free(state, self.arena, landing):
            return int(Action.DROP)
        if np.linalg.norm(self._stand - state.agent_pose[:2]) > _STAND_TOLERANCE:
            return self.navigate(state, self._stand)
        return self._turn_towards(state, self._aim)

    def navigate(self, state: WorldState, goal: Array, ignore: int = -1) -> int:
        """Next action driving towards ``goal``, detouring around floor objects (except ``ignore``)."""
        waypoint = self._waypoint(state, goal, ignore)
        if abs(bearing(state.agent_pose, waypoint)) > _HEADING_TOLERANCE:
            return self._turn_towards(state, waypoint)
        lookahead = self.noise.move_mean + 3.0 * self.noise.move_std
        if move_obstructed(state, self.arena, lookahead):
            return int(Action.TURN_LEFT)
        return int(Action.MOVE)

    # ---- helpers ---------------------------------------------------------------------------------------------
    def _face_or_creep(self, state: WorldState, position: Array) -> int:
        if abs(bearing(state.agent_pose, position)) > _HEADING_TOLERANCE:
            return self._turn_towards(state, position)
        if move_obstructed(state, self.arena, self.noise.move_mean + 3.0 * self.noise.move_std):
            return int(Action.TURN_LEFT)
        return int(Action.MOVE)

    @staticmethod
    def _turn_towards(state: WorldState, point: Array) -> int:
        return int(Action.TURN_LEFT if bearing(state.agent_pose, point) > 0 else Action.TURN_RIGHT)

    def _obstacles(self, state: WorldState, ignore: int) -> Array:
        keep = state.on_floor()
        if ignore >= 0:
            keep[ignore] = False
        return state.floor_positions[keep]

    def _waypoint(self, state: WorldState, goal: Array, ignore: int) -> Array:
        """``goal`` if the straight path is clear, else a point beside the first object in the way."""
        start = state.agent_pose[:2]
        obstacles = self._obstacles(state, ignore)
        if len(obstacles) == 0:
            return goal
        gaps = point_segment_distance(obstacles, start, goal)
        blocking = np.flatnonzero(gaps < _CLEARANCE)
        if len(blocking) == 0:
            return goal
        nearest = blocking[np.argmin(np.linalg.norm(obstacles[blocking] - start, axis=1))]
        centre = obstacles[nearest]
        direction = goal - start
        side = np.array([-direction[1], direction[0]]) / max(np.linalg.norm(direction), 1e-9)
        candidates = [centre + s * (_CLEARANCE + 0.15) * side for s in (1.0, -1.0)]
        candidates.sort(key=lambda p: np.linalg.norm(p - start) + np.linalg.norm(goal - p))
        for candidate in candidates:
            if self.arena.contains(candidate, _WALL_CLEARANCE):
                return candidate
        return candidates[0]

    def _plan_valid(self, state: WorldState) -> bool:
        return bool(drop_free(state, self.arena, self._aim)) and self._stand_free(state, self._stand)

    def _stand_free(self, state: WorldState, stand: Array) -> bool:
        if not self.arena.contains(stand, _WALL_CLEARANCE):
            return False
        floor = state.floor_positions[state.on_floor()]
        return len(floor) == 0 or bool(np.min(np.linalg.norm(floor - stand, axis=1)) >= _CLEARANCE)

    def _plan_drop(self, state: WorldState, target: Array) -> None:
        """Choose an aim point (the target, or a free spot near it) and a standing point facing it."""
        self._aim = self._stand = None
        approach = np.arctan2(*(target - state.agent_pose[:2])[::-1])
        offsets = [np.zeros(2)] + [r * heading_vector(a) for r in (0.35, 0.6) for a in np.linspace(0, 2 * np.pi, 8, False)]
        turns = np.deg2rad([0, 25, -25, 50, -50, 80, -80, 120, -120, 180])
        for offset in offsets:
            aim = target + offset
            if not drop_free(state, self.arena, aim):
                continue
            for turn in turns:
                stand = aim - DROP_DISTANCE * heading_vector(approach + turn)
                if self._stand_free(state, stand):
                    self._aim, self._stand = aim, stand
                    return
