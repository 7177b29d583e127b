"""The simulator's fast paths give exactly what the plain forms give (docs/performance.md): the dataset version
depends on episodes being the same bit for bit, so "close" is not enough."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from mor.sim.arena import Arena
from mor.sim.geometry import heading_vector, point_in_polygon, point_segment_distance, segment_segment_distance
from mor.sim.rules import AGENT_RADIUS, WorldState, move_obstructed
from mor.sim.scene import Scene


def _reference_clearance(arena: Arena, point: np.ndarray) -> float:
    distance = float(np.min(point_segment_distance(point, arena.wall_starts, arena.wall_ends)))
    return distance if point_in_polygon(point, arena.vertex_array) else -distance


@pytest.mark.parametrize("shape", ["square", "polygon"])
def test_clearance_is_bitwise_the_vectorized_form(shape: str) -> None:
    arena = Arena.build(shape, 6.0)
    rng = np.random.default_rng(0)
    points = np.concatenate([rng.uniform(-3.5, 3.5, size=(3000, 2)), arena.vertex_array,
                             (arena.wall_starts + arena.wall_ends) / 2])
    for point in points:
        assert arena.clearance(point) == _reference_clearance(arena, point), point


@pytest.mark.parametrize("shape", ["square", "polygon"])
def test_move_obstructed_shortcut_never_changes_the_answer(shape: str) -> None:
    """Against the exact swept-disc test alone, also for paths that end within 1e-12 m of touching a wall."""
    arena = Arena.build(shape, 6.0)
    rng = np.random.default_rng(1)
    for _ in range(3000):
        pose = np.array([*rng.uniform(-3.0, 3.0, 2), rng.uniform(-np.pi, np.pi)])
        state = WorldState(pose, np.zeros((0, 2)))
        tangent = arena.clearance(pose[:2]) - AGENT_RADIUS
        distance = max(0.0, float(rng.choice([rng.uniform(0.0, 3.0), tangent + rng.choice([-1e-12, 0.0, 1e-12])])))
        end = pose[:2] + distance * heading_vector(pose[2])
        exact = bool(np.min(segment_segment_distance(pose[:2], end, arena.wall_starts, arena.wall_ends)) < AGENT_RADIUS)
        assert move_obstructed(state, arena, distance) == exact, (pose, distance)


def test_scene_draws_what_mujoco_renderer_draws(square_arena: Arena) -> None:
    """Same pixels as mujoco.Renderer, and two scenes rendered in turn in one thread each draw their own view."""
    scenes = [Scene(square_arena, 32, n_landmarks=0) for _ in range(2)]
    reference = mujoco.Renderer(scenes[0].model, 32, 32)
    option = mujoco.MjvOption()
    option.geomgroup[3] = 0  # the robot's own body, hidden from its camera
    try:
        for scene, heading in zip(scenes, (0.0, np.pi / 2), strict=True):
            scene.set_episode((0, 6, 12, 18), np.array([0, 7]))
            scene.set_state(WorldState(np.array([0.0, 0.0, heading]), np.array([[1.0, 0.2], [-0.3, 1.2]])))
        for _ in range(2):
            first, second = scenes[0].render_first_person(), scenes[1].render_first_person()
            assert first.shape == (32, 32, 3) and first.dtype == np.uint8 and not np.array_equal(first, second)
            reference.update_scene(scenes[0].data, camera="fpv", scene_option=option)
            assert np.array_equal(first, reference.render())
            assert first is not scenes[0].render_first_person()  # a new array every frame
    finally:
        reference.close()
        for scene in scenes:
            scene.close()
