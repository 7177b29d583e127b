"""The action rules of the world (paper Supplementary A), used by the env, oracle, collection and evaluation.

Everything here is planar geometry; MuJoCo only draws the result. Units: metres, radians. Each rule is written
once, over N worlds at a time (the arrays' first axis; ``mor.sim.batch_world`` steps N worlds with them), and its
``WorldState`` form for one world calls it with N = 1: the same float operations, so the same decisions.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mor.sim.arena import Arena
from mor.sim.catalog import OBJECT_RADIUS
from mor.sim.geometry import (
    Array,
    bearings,
    heading_vector,
    point_segment_distance,
    segment_segment_distance,
    vector_norm,
    wrap_angle,
)

#: (N, ...) bool, one row per world
Flags = NDArray[np.bool_]


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
        return float(self.move_distances(rng.standard_normal()))

    def turn_angle(self, rng: np.random.Generator) -> float:
        """A turn's magnitude, radians."""
        return float(self.turn_angles(rng.standard_normal()))

    def move_distances(self, standard: ArrayLike) -> Array:
        """MOVE distances (...,) metres from standard normal draws (...,): ``rng.normal(mean, std)`` is
        ``mean + std * rng.standard_normal()`` bit for bit, so one draw per MOVE from the env's generator."""
        return np.maximum(0.0, self.move_mean + self.move_std * np.asarray(standard, dtype=np.float64))

    def turn_angles(self, standard: ArrayLike) -> Array:
        """Turn magnitudes (...,) radians from standard normal draws (...,)."""
        return self.turn_mean + self.turn_std * np.asarray(standard, dtype=np.float64)


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

    def on_floor(self) -> Flags:
        """(n,) bool: objects in the scene (all but the held one)."""
        return floor_mask(self.held, self.n_objects)[0]

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


def floor_mask(held: ArrayLike, n_objects: int) -> Flags:
    """(N, n) bool: which objects lie on the floor (all but the held one; held (N,) index, -1 for none)."""
    return np.arange(n_objects) != np.asarray(held).reshape(-1, 1)


def paths_obstructed(agent_poses: Array, distances: Array, floor_positions: Array, on_floor: Flags, arena: Arena,
                     start_clearance: Array | None = None) -> Flags:
    """(N,) whether sweeping each agent ``distances`` (N,) metres straight ahead hits a wall or a floor object
    (``path_blockers``' walls or any of its objects)."""
    walls, objects = path_blockers(agent_poses, distances, floor_positions, on_floor, arena, start_clearance)
    return walls | objects.any(axis=-1)


def path_blockers(agent_poses: Array, distances: Array, floor_positions: Array, on_floor: Flags, arena: Arena,
                  start_clearance: Array | None = None) -> tuple[Flags, Flags]:
    """What sweeping each agent ``distances`` (N,) metres straight ahead hits: (N,) a wall, (N, n) each floor object.

    agent_poses (N, 3); floor_positions (N, n, 2); on_floor (N, n). start_clearance (N,), optional: each start's
    distance to the walls (``Arena.clearance``). Every point of a path lies within its distance of the start, so a
    start farther than distance + ``AGENT_RADIUS`` from every wall cannot hit one: the exact swept-disc test against
    the walls (~10x the rest for one world) then runs only for the others, which never changes an answer. Without
    it every path is tested against the walls (cheaper for many worlds at once: some are near a wall anyway).
    """
    start = agent_poses[:, :2]
    end = start + distances[:, None] * heading_vector(agent_poses[:, 2])
    near = (np.arange(len(start)) if start_clearance is None
            else np.flatnonzero(start_clearance < distances + AGENT_RADIUS + _SHORTCUT_SLACK))
    walls = np.zeros(len(start), dtype=bool)
    if len(near):
        gaps = segment_segment_distance(start[near, None], end[near, None], arena.wall_starts, arena.wall_ends)
        walls[near] = np.min(gaps, axis=-1) < AGENT_RADIUS
    gaps = point_segment_distance(floor_positions, start[:, None], end[:, None])  # (N, n)
    return walls, on_floor & (gaps < AGENT_RADIUS + OBJECT_RADIUS)


#: ``first_obstacle``'s answers other than an object's index
WALL, NO_OBSTACLE = -1, -2


def first_obstacle(state: WorldState, arena: Arena, max_distance: float, tolerance: float = 1e-4) -> int:
    """What a MOVE straight ahead would hit first within ``max_distance`` metres: a floor object's index, ``WALL``,
    or ``NO_OBSTACLE``; the shortest blocked sweep found by bisection to ``tolerance`` metres (``path_blockers``)."""
    def blockers(distance: float) -> tuple[Flags, Flags]:
        walls, objects = path_blockers(state.agent_pose[None], np.array([distance]), state.floor_positions[None],
                                       state.on_floor()[None], arena)
        return walls[0], objects[0]

    walls, objects = blockers(max_distance)
    if not (walls or objects.any()):
        return NO_OBSTACLE
    low, high = 0.0, max_distance  # free at low (or nothing moved), blocked at high
    while high - low > tolerance:
        middle = 0.5 * (low + high)
        walls_middle, objects_middle = blockers(middle)
        if walls_middle or objects_middle.any():
            high, walls, objects = middle, walls_middle, objects_middle
        else:
            low = middle
    return int(np.argmax(objects)) if objects.any() else WALL


def visible_objects(agent_poses: Array, floor_positions: Array, on_floor: Flags) -> Flags:
    """(N, n) whether each object lies on the floor, in the camera's horizontal field of view, and with no other
    floor object's footprint cutting the line from the agent to it. agent_poses (N, 3); floor_positions (N, n, 2)."""
    start = agent_poses[:, None, None, :2]
    # gaps[e, i, j]: how far object j lies from the line from agent e to object i
    gaps = point_segment_distance(floor_positions[:, None], start, floor_positions[:, :, None])
    others = ~np.eye(floor_positions.shape[1], dtype=bool)
    in_sight = ~np.any(on_floor[:, None] & others & (gaps < OBJECT_RADIUS), axis=-1)
    in_view = ~(np.abs(bearings(agent_poses[:, None], floor_positions)) > CAMERA_FOV / 2.0)
    return on_floor & in_view & in_sight


def pick_candidates(agent_poses: Array, floor_positions: Array, held: NDArray[np.int64]) -> NDArray[np.int64]:
    """(N,) the object PICK would take in each world: the nearest visible floor object within ``PICK_RANGE`` (the
    lowest index among equally near ones); -1 if none or if the agent already holds one. held (N,), -1 for none."""
    distances = np.linalg.norm(floor_positions - agent_poses[:, None, :2], axis=-1)
    on_floor = floor_mask(held, floor_positions.shape[1])
    reachable = visible_objects(agent_poses, floor_positions, on_floor) & (distances <= PICK_RANGE)
    nearest = np.argmin(np.where(reachable, distances, np.inf), axis=-1)
    return np.where(reachable.any(axis=-1) & (np.asarray(held) < 0), nearest, -1)


def drop_point(agent_pose: Array) -> Array:
    """Where DROP puts the held object: ``DROP_DISTANCE`` metres straight ahead, (..., 2) of poses (..., 3)."""
    return agent_pose[..., :2] + DROP_DISTANCE * heading_vector(agent_pose[..., 2])


def drops_free(agent_poses: Array, floor_positions: Array, on_floor: Flags, points: Array,
               point_clearance: Array) -> Flags:
    """(N,) whether an object fits at each of ``points`` (N, 2): inside the arena and clear of walls (its
    ``point_clearance`` (N,) to the walls, from ``Arena.clearance(s)``), floor objects and the agent."""
    clear_of_agent = ~(vector_norm(points - agent_poses[:, :2]) < AGENT_RADIUS + OBJECT_RADIUS)
    spacing = np.linalg.norm(floor_positions - points[:, None], axis=-1)  # (N, n)
    clear_of_objects = np.all(~on_floor | (spacing >= 2.0 * OBJECT_RADIUS), axis=-1)
    return (point_clearance >= OBJECT_RADIUS) & clear_of_agent & clear_of_objects


def move_obstructed(state: WorldState, arena: Arena, distance: float) -> bool:
    """Whether sweeping the agent ``distance`` metres straight ahead hits a wall or an object on the floor."""
    return bool(paths_obstructed(state.agent_pose[None], np.array([distance], dtype=np.float64),
                                 state.floor_positions[None], state.on_floor()[None], arena,
                                 np.array([arena.clearance(state.agent_pose[:2])]))[0])


def visible(state: WorldState, index: int) -> bool:
    """Whether floor object ``index`` is in the camera's horizontal field of view and not occluded."""
    return bool(visible_objects(state.agent_pose[None], state.floor_positions[None], state.on_floor()[None])[0, index])


def pick_candidate(state: WorldState) -> int:
    """The object PICK would take: the nearest visible floor object within ``PICK_RANGE``; -1 if none or busy."""
    return int(pick_candidates(state.agent_pose[None], state.floor_positions[None], np.array([state.held]))[0])


def drop_free(state: WorldState, arena: Arena, point: Array) -> bool:
    """Whether an object fits at ``point``: inside the arena and clear of walls, floor objects and the agent."""
    point = np.asarray(point, dtype=np.float64)
    return bool(drops_free(state.agent_pose[None], state.floor_positions[None], state.on_floor()[None], point[None],
                           np.array([arena.clearance(point)]))[0])


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
