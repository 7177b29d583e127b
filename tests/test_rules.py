"""The action rules (mor.sim.rules, paper Supplementary A; docs/assumptions.md "Actions")."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from mor.sim.arena import Arena
from mor.sim.catalog import OBJECT_RADIUS
from mor.sim.episode import sample_layout
from mor.sim.geometry import heading_vector
from mor.sim.rules import (
    AGENT_RADIUS,
    CAMERA_FOV,
    DROP_DISTANCE,
    NO_OBSTACLE,
    PICK_RANGE,
    WALL,
    Action,
    MotionNoise,
    WorldState,
    apply_action,
    drop_point,
    first_obstacle,
    move_obstructed,
    pick_candidate,
    visible,
)

EXACT = MotionNoise(move_std=0.0, turn_std=0.0)  # noise-free steps for hand-built cases


def rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


def polar(distance: float, degrees: float, origin=(0.0, 0.0)) -> tuple[float, float]:
    """The point ``distance`` metres from ``origin`` at ``degrees`` counter-clockwise from +x."""
    a = np.deg2rad(degrees)
    return (origin[0] + distance * np.cos(a), origin[1] + distance * np.sin(a))


# ---- motion noise ----------------------------------------------------------------------------------------------
def test_move_distance_statistics() -> None:
    noise, generator = MotionNoise(), rng(1)
    samples = np.array([noise.move_distance(generator) for _ in range(100_000)])
    assert samples.min() >= 0.0  # clipped: the robot never reverses
    assert samples.mean() == pytest.approx(0.15, abs=0.005)
    assert samples.std() == pytest.approx(0.05, abs=0.005)


def test_turn_angle_statistics() -> None:
    noise, generator = MotionNoise(), rng(2)
    samples = np.rad2deg([noise.turn_angle(generator) for _ in range(100_000)])
    assert samples.mean() == pytest.approx(10.0, abs=0.1)
    assert samples.std() == pytest.approx(1.0, abs=0.1)


def test_noise_through_apply_action(square_arena: Arena, world) -> None:
    """The noise the rules apply: MOVE distance, and turns left positive / right negative, about 10 degrees each."""
    generator, noise = rng(3), MotionNoise()
    moved, left, right = [], [], []
    for _ in range(2000):
        state = world((0.0, 0.0, 0.3), [(2.5, 2.5)])
        events = apply_action(state, Action.MOVE, square_arena, noise, generator)
        assert not events.obstructed
        np.testing.assert_allclose(state.agent_pose[:2], events.moved * heading_vector(0.3), atol=1e-12)
        moved.append(events.moved)
        state = world((0.0, 0.0, 0.0), [(2.5, 2.5)])
        left.append(apply_action(state, Action.TURN_LEFT, square_arena, noise, generator).turned)
        assert state.agent_pose[2] == pytest.approx(left[-1])
        right.append(apply_action(state, Action.TURN_RIGHT, square_arena, noise, generator).turned)
    assert np.mean(moved) == pytest.approx(0.15, abs=0.005)
    assert np.std(moved) == pytest.approx(0.05, abs=0.005)
    assert np.rad2deg(np.mean(left)) == pytest.approx(10.0, abs=0.1)
    assert np.rad2deg(np.mean(right)) == pytest.approx(-10.0, abs=0.1)
    assert np.rad2deg(np.std(left)) == pytest.approx(1.0, abs=0.1)


def test_turns_wrap_heading(square_arena: Arena, world) -> None:
    state = world((0.0, 0.0, np.pi - 0.01), [(2.5, 2.5)])
    apply_action(state, Action.TURN_LEFT, square_arena, EXACT, rng())
    assert state.agent_pose[2] == pytest.approx(-np.pi - 0.01 + np.deg2rad(10.0))
    assert -np.pi <= state.agent_pose[2] < np.pi


def test_noise_is_reproducible_from_the_seed() -> None:
    def draws(seed: int) -> list[float]:
        generator = rng(seed)
        return [MotionNoise().move_distance(generator) for _ in range(20)]

    assert draws(7) == draws(7)
    assert draws(7) != draws(8)


# ---- PICK ------------------------------------------------------------------------------------------------------
def test_pick_takes_the_nearest_visible_object(square_arena: Arena, world) -> None:
    # Three objects in view at 0.9 m, 0.8 m and 0.5 m (listed far to near so that index order does not help).
    state = world((0.0, 0.0, 0.0), [polar(0.9, 20.0), polar(0.8, -15.0), polar(0.5, 5.0)])
    assert pick_candidate(state) == 2
    events = apply_action(state, Action.PICK, square_arena, EXACT, rng())
    assert events.picked == 2 and state.held == 2
    assert not state.on_floor()[2]
    np.testing.assert_allclose(state.object_positions()[2], state.agent_pose[:2])  # it travels with the agent
    # the next PICK takes the next nearest
    state.held = -1
    state.floor_positions[2] = (2.5, -2.5)
    assert pick_candidate(state) == 1


def test_pick_ignores_nearer_objects_out_of_view(square_arena: Arena, world) -> None:
    state = world((0.0, 0.0, 0.0), [polar(0.4, 180.0), polar(0.4, 90.0), polar(0.9, 0.0)])
    assert pick_candidate(state) == 2


@pytest.mark.parametrize(("distance", "expected"), [(0.3, 0), (0.99, 0), (PICK_RANGE, 0), (1.01, -1), (1.5, -1)])
def test_pick_range_is_one_metre(square_arena: Arena, world, distance, expected) -> None:
    state = world((0.5, -0.2, 0.7), [polar(distance, np.rad2deg(0.7), origin=(0.5, -0.2))])
    assert pick_candidate(state) == expected
    events = apply_action(state, Action.PICK, square_arena, EXACT, rng())
    assert events.picked == expected
    assert state.held == expected


@pytest.mark.parametrize(("degrees", "expected"), [(0.0, 0), (29.0, 0), (-29.0, 0), (31.0, -1), (-31.0, -1),
                                                   (90.0, -1), (180.0, -1)])
def test_pick_field_of_view_is_plus_minus_30_degrees(square_arena: Arena, world, degrees, expected) -> None:
    heading = np.deg2rad(-120.0)
    state = world((1.0, 1.0, heading), [polar(0.7, -120.0 + degrees, origin=(1.0, 1.0))])
    assert np.rad2deg(CAMERA_FOV) == pytest.approx(60.0)
    assert pick_candidate(state) == expected
    assert apply_action(state, Action.PICK, square_arena, EXACT, rng()).picked == expected


def test_pick_never_takes_an_occluded_object(square_arena: Arena, world) -> None:
    # Object 1 sits 0.149 m off the line of sight to object 0 (inside its 0.15 m footprint) with its own centre
    # just outside the field of view: object 0 is hidden and object 1 is not visible, so nothing is picked.
    occluder = (0.25, 0.149)
    assert np.rad2deg(np.arctan2(occluder[1], occluder[0])) > 30.0
    assert np.hypot(*occluder) >= AGENT_RADIUS + OBJECT_RADIUS  # a legal state: no overlap with the agent
    state = world((0.0, 0.0, 0.0), [(0.9, 0.0), occluder])
    assert not visible(state, 0)
    assert not visible(state, 1)
    assert pick_candidate(state) == -1
    events = apply_action(state, Action.PICK, square_arena, EXACT, rng())
    assert events.picked == -1 and state.held == -1
    # moved off the line (beyond the footprint), the far object is visible again
    state.floor_positions[1] = (0.25, 0.151)
    assert visible(state, 0)
    assert pick_candidate(state) == 0


def test_an_occluder_in_view_is_picked_instead_of_what_it_hides(world) -> None:
    state = world((0.0, 0.0, 0.0), [(0.9, 0.0), (0.45, 0.05)])
    assert not visible(state, 0)
    assert pick_candidate(state) == 1


def test_held_objects_neither_occlude_nor_get_picked(world) -> None:
    state = world((0.0, 0.0, 0.0), [(0.9, 0.0), (0.45, 0.0)], held=1)
    assert visible(state, 0)
    assert not visible(state, 1)


def test_pick_does_nothing_when_already_holding(square_arena: Arena, world) -> None:
    state = world((0.0, 0.0, 0.0), [(0.5, 0.0), (-2.0, -2.0)], held=1)
    assert pick_candidate(state) == -1
    events = apply_action(state, Action.PICK, square_arena, EXACT, rng())
    assert events.picked == -1
    assert state.held == 1
    np.testing.assert_allclose(state.floor_positions, [(0.5, 0.0), (-2.0, -2.0)])


# ---- DROP ------------------------------------------------------------------------------------------------------
def test_drop_lands_one_and_a_half_metres_ahead(square_arena: Arena, world) -> None:
    heading = np.deg2rad(35.0)
    state = world((-1.0, -0.5, heading), [(0.0, 0.0), (-2.0, 2.0)], held=0)
    expected = np.array([-1.0, -0.5]) + DROP_DISTANCE * heading_vector(heading)
    np.testing.assert_allclose(drop_point(state.agent_pose), expected)
    events = apply_action(state, Action.DROP, square_arena, EXACT, rng())
    assert events.dropped == 0 and not events.drop_blocked
    assert state.held == -1
    np.testing.assert_allclose(state.floor_positions[0], expected)
    np.testing.assert_allclose(state.agent_pose, (-1.0, -0.5, heading))  # the agent stays where it is


@pytest.mark.parametrize(("agent_x", "blocked"), [(1.3, False), (1.34, False), (1.36, True), (1.45, True), (1.6, True)])
def test_drop_is_blocked_near_and_beyond_walls(square_arena: Arena, world, agent_x, blocked) -> None:
    # drop point x = agent_x + 1.5; the east wall is at x = 3, so it must be <= 2.85 to fit
    state = world((agent_x, 0.0, 0.0), [(-2.0, -2.0), (-2.0, 2.0)], held=0)
    events = apply_action(state, Action.DROP, square_arena, EXACT, rng())
    assert events.drop_blocked is blocked
    if blocked:
        assert state.held == 0 and events.dropped == -1
        np.testing.assert_allclose(state.floor_positions[0], (-2.0, -2.0))  # untouched
    else:
        assert state.held == -1 and events.dropped == 0
        assert square_arena.clearance(state.floor_positions[0]) >= OBJECT_RADIUS


@pytest.mark.parametrize(("gap", "blocked"), [(0.0, True), (0.29, True), (0.31, False), (0.8, False)])
def test_drop_is_blocked_onto_objects(square_arena: Arena, world, gap, blocked) -> None:
    # object 1 lies ``gap`` metres (centre to centre) beside the drop point (0, 1.5)
    state = world((0.0, 0.0, np.pi / 2), [(-2.0, -2.0), (gap, DROP_DISTANCE)], held=0)
    events = apply_action(state, Action.DROP, square_arena, EXACT, rng())
    assert events.drop_blocked is blocked
    assert (state.held == 0) is blocked


def test_drop_blocked_in_polygon_arena(polygon_arena: Arena, world) -> None:
    # facing the east wall of the polygon from 1 m inside it
    wall_start, wall_end = polygon_arena.walls()[1]
    middle = (wall_start + wall_end) / 2.0
    direction = (wall_end - wall_start) / np.linalg.norm(wall_end - wall_start)
    inward = np.array([-direction[1], direction[0]])
    agent = middle + 1.0 * inward
    heading = float(np.arctan2(-inward[1], -inward[0]))
    state = world((*agent, heading), [(0.0, 0.0)], held=0)
    events = apply_action(state, Action.DROP, polygon_arena, EXACT, rng())
    assert events.drop_blocked and state.held == 0


def test_drop_with_nothing_held_does_nothing(square_arena: Arena, world) -> None:
    state = world((0.0, 0.0, 0.0), [(-2.0, -2.0)])
    events = apply_action(state, Action.DROP, square_arena, EXACT, rng())
    assert events.dropped == -1 and not events.drop_blocked
    np.testing.assert_allclose(state.floor_positions, [(-2.0, -2.0)])


# ---- MOVE ------------------------------------------------------------------------------------------------------
def _facing_wall(arena: Arena, k: int, clearance: float, along: bool = False) -> tuple[float, float, float]:
    """A pose ``clearance`` metres in front of wall k's middle, facing the wall (or running along it)."""
    start, end = arena.walls()[k]
    direction = (end - start) / np.linalg.norm(end - start)
    inward = np.array([-direction[1], direction[0]])  # counter-clockwise walls: the inside is on the left
    x, y = (start + end) / 2.0 + clearance * inward
    facing = direction if along else -inward
    return float(x), float(y), float(np.arctan2(facing[1], facing[0]))


@pytest.mark.parametrize("shape", ["square", "polygon"])
def test_move_into_a_wall_is_obstructed(shape, world) -> None:
    arena = Arena.build(shape, 6.0)
    for k in range(arena.n_walls):
        pose = _facing_wall(arena, k, AGENT_RADIUS + 0.05)
        state = world(pose, [(0.0, 0.0)])
        assert arena.clearance(state.agent_pose[:2]) == pytest.approx(AGENT_RADIUS + 0.05)
        events = apply_action(state, Action.MOVE, arena, EXACT, rng())
        assert events.obstructed, f"wall {k}"
        assert events.moved == 0.0
        np.testing.assert_allclose(state.agent_pose, pose)  # did not move at all
        # running along the same wall at the same clearance is free
        along = world(_facing_wall(arena, k, AGENT_RADIUS + 0.05, along=True), [(0.0, 0.0)])
        events = apply_action(along, Action.MOVE, arena, EXACT, rng())
        assert not events.obstructed
        assert events.moved == pytest.approx(0.15)


def test_move_cannot_leave_the_arena_even_with_a_long_step(square_arena: Arena, world) -> None:
    state = world((2.0, 0.0, 0.0), [(-2.0, -2.0)])
    assert move_obstructed(state, square_arena, 5.0)  # the end point is outside: the swept path crosses the wall
    assert move_obstructed(state, square_arena, 0.9)  # stops 0.1 m short of the wall: the disc would touch it
    assert not move_obstructed(state, square_arena, 0.85)


def test_move_into_an_object_is_obstructed(square_arena: Arena, world) -> None:
    state = world((0.0, 0.0, 0.0), [(0.35, 0.0), (-2.0, 2.0)])
    events = apply_action(state, Action.MOVE, square_arena, EXACT, rng())
    assert events.obstructed
    np.testing.assert_allclose(state.agent_pose, (0.0, 0.0, 0.0))


def test_move_checks_the_swept_path_not_only_the_end(square_arena: Arena, world) -> None:
    # the object sits midway along a 2 m step: the end point is clear, the path is not
    state = world((-1.0, 0.0, 0.0), [(0.0, 0.0)])
    assert move_obstructed(state, square_arena, 2.0)
    # passing 0.28 m beside it (more than the two radii, 0.27 m) is free
    state = world((-1.0, 0.0, 0.0), [(0.0, 0.28)])
    assert not move_obstructed(state, square_arena, 2.0)
    state = world((-1.0, 0.0, 0.0), [(0.0, 0.26)])
    assert move_obstructed(state, square_arena, 2.0)


def test_the_first_obstacle_is_what_the_shortest_blocked_move_hits(square_arena: Arena, world) -> None:
    # two objects straight ahead and the wall at x = 3 behind them: the nearer object is met first
    state = world((0.0, 0.0, 0.0), [(1.5, 0.0), (0.8, 0.05), (-2.0, 2.0)])
    assert first_obstacle(state, square_arena, 5.0) == 1
    # object 1's disc is touched after 0.8 - sqrt(0.27^2 - 0.05^2) = 0.535 m of the move
    assert first_obstacle(state, square_arena, 0.54) == 1
    assert first_obstacle(state, square_arena, 0.53) == NO_OBSTACLE
    # the same objects behind the agent: the wall ahead (x = 3, touched after 0.9 m) is what a move would hit
    state = world((2.0, 0.0, 0.0), [(1.5, 0.0), (0.8, 0.05), (-2.0, 2.0)])
    assert first_obstacle(state, square_arena, 5.0) == WALL
    assert first_obstacle(state, square_arena, 0.85) == NO_OBSTACLE
    # a held object is carried, not met
    state = world((0.0, 0.0, 0.0), [(0.8, 0.05), (-2.0, 2.0)], held=0)
    assert first_obstacle(state, square_arena, 5.0) == WALL


def test_held_object_is_not_an_obstacle(square_arena: Arena, world) -> None:
    state = world((0.0, 0.0, 0.0), [(0.35, 0.0)], held=0)
    events = apply_action(state, Action.MOVE, square_arena, EXACT, rng())
    assert not events.obstructed
    np.testing.assert_allclose(state.agent_pose[:2], (0.15, 0.0))


# ---- invariants under any action sequence ----------------------------------------------------------------------
@st.composite
def action_sequences(draw, max_runs: int = 25, max_repeat: int = 25) -> list[Action]:
    """Runs of repeated actions (so that long straight drives into walls and objects are likely)."""
    runs = draw(st.lists(st.tuples(st.sampled_from(list(Action)), st.integers(1, max_repeat)),
                         min_size=1, max_size=max_runs))
    return [action for action, repeat in runs for _ in range(repeat)]


ARENAS = {shape: Arena.build(shape, 6.0) for shape in ("square", "polygon")}


@pytest.mark.parametrize("shape", ["square", "polygon"])
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(actions=action_sequences(), seed=st.integers(0, 2**32 - 1), n_objects=st.integers(1, 5),
       start_holding=st.booleans())
def test_rules_keep_the_world_legal(legal_world, shape, actions, seed, n_objects, start_holding) -> None:
    arena = ARENAS[shape]
    generator = rng(seed)
    layout = sample_layout(generator, arena, n_objects, "per_side")
    state = WorldState(layout.agent_pose.copy(), layout.initial_positions.copy())
    if start_holding:  # the Drop task's start: holding object 0, standing where it lay
        state.held = 0
        state.agent_pose[:2] = state.floor_positions[0]
    legal_world(arena, state.agent_pose, state.floor_positions, state.held)
    for action in actions:
        before = state.copy()
        events = apply_action(state, action, arena, MotionNoise(), generator)
        legal_world(arena, state.agent_pose, state.floor_positions, state.held)
        if events.obstructed:
            np.testing.assert_array_equal(state.agent_pose, before.agent_pose)
        if events.drop_blocked:
            assert state.held == before.held >= 0


@pytest.mark.parametrize("shape", ["square", "polygon"])
@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_objects=st.integers(2, 5), near=st.integers(0, 4),
       offset=st.tuples(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6)), heading=st.floats(-np.pi, np.pi))
def test_drop_anywhere_keeps_the_world_legal(legal_world, shape, seed, n_objects, near, offset, heading) -> None:
    """Aim drops at (or near) another object or a wall: a DROP either lands legally or is blocked."""
    arena = ARENAS[shape]
    layout = sample_layout(rng(seed), arena, n_objects, "per_side")
    state = WorldState(np.zeros(3), layout.initial_positions.copy(), held=0)
    aim = state.floor_positions[1 + near % (n_objects - 1)] + np.asarray(offset)
    state.agent_pose[:] = (*(aim - DROP_DISTANCE * heading_vector(heading)), heading)
    floor = state.floor_positions[state.on_floor()]
    assume(arena.clearance(state.agent_pose[:2]) >= AGENT_RADIUS)
    assume(np.linalg.norm(floor - state.agent_pose[:2], axis=1).min() >= AGENT_RADIUS + OBJECT_RADIUS)
    events = apply_action(state, Action.DROP, arena, EXACT, rng())
    legal_world(arena, state.agent_pose, state.floor_positions, state.held)
    assert events.drop_blocked != (events.dropped == 0)
    if events.drop_blocked:
        assert state.held == 0
    else:
        np.testing.assert_allclose(state.floor_positions[0], aim, atol=1e-9)
