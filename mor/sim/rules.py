"""The action rules of the world (paper Supplementary A), used by the env, oracle, collection and evaluation.

Everything here is planar geometry on a ``WorldState``; MuJoCo only draws the result. Units: metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from mor.sim.arena import Arena
from mor.sim.catalog import OBJECT_RADIUS
from mor.sim.geometry import (
    Array,
    bearing,
    heading_vector,
    point_segment_distance,
    segment_segment_distance,
    wrap_angle,
)


class Action(IntEnum):
    """The five discrete actions; the integer is the Gymnasium action."""

    MOVE = 0
    TURN_LEFT = 1
    TURN_RIGHT = 2
    PICK = 3
    DROP = 4


N_ACTIONS: int = len(Action)
#: Footprint radius of the TurtleBot-sized agent (metres).
AGENT_RADIUS: float = 0.12
#: PICK reaches objects whose centre is at most this far from the agent's centre (metres).
PICK_RANGE: float = 1.0
#: DROP puts the held object this far straight ahead of the agent's centre (metres).
DROP_DISTANCE: float = 1.5
#: Horizontal field of view of the first-person camera (radians); also what "visible" means for PICK.
CAMERA_FOV: float = np.deg2rad(60.0)


@dataclass(frozen=True)
class MotionNoise:
    """MOVE distance ~ N(move_mean, move_std^2) metres, turn angle ~ N(turn_mean, turn_std^2) radians."""

    move_mean: float = 0.15
    move_std: float = 0.05
    turn_mean: float = float(np.deg2rad(10.0))
    turn_std: float = float(np.deg2rad(1.0))

    def move_distance(self, rng: np.random.Generator) -> float:
        """A MOVE's distance, metres; a negative draw (p ~ 0.1%) is clipped to 0 (the robot does not reverse)."""
        return max(0.0, float(rng.normal(self.move_mean, self.move_std)))

    def turn_angle(self, rng: np.random.Generator) -> float:
        """A turn's magnitude, radians."""
        return float(rng.normal(self.turn_mean, self.turn_std))


@dataclass
class WorldState:
    """The full state of one episode.

    agent_pose: (3,) x, y (metres), theta (radians).
    floor_positions: (n, 2) where each object lies; the held object's row keeps its last floor position.
    held: index of the held object, or -1.
    """

    agent_pose: Array
    floor_positions: Array
    held: int = -1

    def copy(self) -> WorldState:
        return WorldState(self.agent_pose.copy(), self.floor_positions.copy(), self.held)

    @property
    def n_objects(self) -> int:
        return len(self.floor_positions)

    def on_floor(self) -> Array:
        """(n,) bool: objects in the scene (all but the held one)."""
        mask = np.ones(self.n_objects, dtype=bool)
        if self.held >= 0:
            mask[self.held] = False
        return mask

    def object_positions(self) -> Array:
        """(n, 2) where each object is now: the held one travels with the agent."""
        positions = self.floor_positions.copy()
        if self.held >= 0:
            positions[self.held] = self.agent_pose[:2]
        return positions


@dataclass
class Events:
    """What one action did."""

    action: Action
    obstructed: bool = False
    picked: int = -1
    dropped: int = -1
    drop_blocked: bool = False
    moved: float = 0.0
    turned: float = 0.0


#: Slack (metres) of ``move_obstructed``'s shortcut: far above float rounding (~1e-15 m), far below any distance
#: that matters, so the shortcut never changes an answer.
_SHORTCUT_SLACK: float = 1e-9


def move_obstructed(state: WorldState, arena: Arena, distance: float) -> bool:
    """Whether sweeping the agent ``distance`` metres straight ahead hits a wall or an object on the floor."""
    start = state.agent_pose[:2]
    end = start + distance * heading_vector(state.agent_pose[2])
    # Every point of the path lies within ``distance`` of its start, so when the start is farther than
    # distance + AGENT_RADIUS from every wall the exact test below must say "clear": skip it (it costs ~10x more).
    near_wall = arena.clearance(start) < distance + AGENT_RADIUS + _SHORTCUT_SLACK
    if near_wall and np.min(segment_segment_distance(start, end, arena.wall_starts, arena.wall_ends)) < AGENT_RADIUS:
        return True
    floor = state.floor_positions[state.on_floor()]
    if len(floor) == 0:
        return False
    return bool(np.any(point_segment_distance(floor, start, end) < AGENT_RADIUS + OBJECT_RADIUS))


def line_of_sight(state: WorldState, index: int) -> bool:
    """Whether no other floor object's footprint cuts the line from the agent to object ``index``."""
    start, end = state.agent_pose[:2], state.floor_positions[index]
    others = [j for j in np.flatnonzero(state.on_floor()) if j != index]
    if not others:
        return True
    return bool(np.all(point_segment_distance(state.floor_positions[others], start, end) >= OBJECT_RADIUS))


def visible(state: WorldState, index: int) -> bool:
    """Whether floor object ``index`` is in the camera's horizontal field of view and not occluded."""
    if not state.on_floor()[index]:
        return False
    if abs(bearing(state.agent_pose, state.floor_positions[index])) > CAMERA_FOV / 2.0:
        return False
    return line_of_sight(state, index)


def pick_candidate(state: WorldState) -> int:
    """The object PICK would take: the nearest visible floor object within ``PICK_RANGE``; -1 if none or busy."""
    if state.held >= 0:
        return -1
    distances = np.linalg.norm(state.floor_positions - state.agent_pose[:2], axis=1)
    for index in np.argsort(distances, kind="stable"):
        if distances[index] > PICK_RANGE:
            break
        if visible(state, int(index)):
            return int(index)
    return -1


def drop_point(agent_pose: Array) -> Array:
    """Where DROP puts the held object: ``DROP_DISTANCE`` metres straight ahead, (2,)."""
    return agent_pose[:2] + DROP_DISTANCE * heading_vector(agent_pose[2])


def drop_free(state: WorldState, arena: Arena, point: Array) -> bool:
    """Whether an object fits at ``point``: inside the arena and clear of walls, floor objects and the agent."""
    if not arena.contains(point, OBJECT_RADIUS):
        return False
    if np.linalg.norm(point - state.agent_pose[:2]) < AGENT_RADIUS + OBJECT_RADIUS:
        return False
    floor = state.floor_positions[state.on_floor()]
    return bool(np.all(np.linalg.norm(floor - point, axis=1) >= 2.0 * OBJECT_RADIUS))


def apply_action(
    state: WorldState, action: Action, arena: Arena, noise: MotionNoise, rng: np.random.Generator
) -> Events:
    """Carry out ``action`` on ``state`` in place and say what happened.

    MOVE: noisy forward step; if its swept path hits a wall or object the agent stays put (obstructed).
    TURN_LEFT / TURN_RIGHT: noisy rotation by about 10 degrees.
    PICK: takes ``pick_candidate``; nothing happens when there is none.
    DROP: puts the held object at ``drop_point`` if it fits there, else keeps it (drop_blocked).
    """
    events = Events(action=action)
    if action == Action.MOVE:
        distance = noise.move_distance(rng)
        if move_obstructed(state, arena, distance):
            events.obstructed = True
        else:
            state.agent_pose[:2] += distance * heading_vector(state.agent_pose[2])
            events.moved = distance
    elif action in (Action.TURN_LEFT, Action.TURN_RIGHT):
        sign = 1.0 if action == Action.TURN_LEFT else -1.0
        angle = sign * noise.turn_angle(rng)
        state.agent_pose[2] = float(wrap_angle(state.agent_pose[2] + angle))
        events.turned = angle
    elif action == Action.PICK:
        candidate = pick_candidate(state)
        if candidate >= 0:
            state.held = candidate
            events.picked = candidate
    elif action == Action.DROP and state.held >= 0:
        point = drop_point(state.agent_pose)
        if drop_free(state, arena, point):
            events.dropped = state.held
            state.floor_positions[state.held] = point
            state.held = -1
        else:
            events.drop_blocked = True
    return events
