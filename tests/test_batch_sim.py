"""The batched world (mor.sim.batch_layout, batch_world, batch_tasks) against the per-environment one: the same
generators give the same layouts and generator states, and the same actions the same states, rewards and ends, bit
for bit (discrete decisions must agree exactly, so "close" is not enough)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from mor.sim import batch_layout
from mor.sim.arena import Arena
from mor.sim.batch_layout import sample_layouts
from mor.sim.batch_tasks import TaskBatch
from mor.sim.config import SimConfig
from mor.sim.episode import sample_layout
from mor.sim.geometry import shorter_than, vector_norm
from mor.sim.rules import Action

ENV_IDS = {"pick": "MOR/Pick-v0", "drop": "MOR/Drop-v0"}


def _generators(count: int, seed: int) -> list[np.random.Generator]:
    """Generators part-way into their streams, some with a buffered 32-bit half (as after an env's integers())."""
    generators = [np.random.default_rng([seed, i]) for i in range(count)]
    for i, rng in enumerate(generators):
        rng.standard_normal(i % 3)
        rng.integers(5, size=i % 2)
    return generators


@pytest.mark.parametrize("shape", ["square", "polygon"])
@pytest.mark.parametrize(("n_objects", "texture_pool"), [(1, "per_side"), (3, "symmetric"), (5, "per_side")])
def test_layouts_are_sample_layouts_and_leave_the_same_generator_states(shape, n_objects, texture_pool) -> None:
    arena = Arena.build(shape, 6.0)
    ours, theirs = _generators(60, n_objects), _generators(60, n_objects)
    for _ in range(3):  # consecutive resets continue each stream
        layouts = sample_layouts(ours, arena, n_objects, texture_pool)
        for i, rng in enumerate(theirs):
            layout = sample_layout(rng, arena, n_objects, texture_pool)
            assert np.array_equal(layouts.initial_positions[i], layout.initial_positions)
            assert np.array_equal(layouts.target_positions[i], layout.target_positions)
            assert np.array_equal(layouts.agent_pose[i], layout.agent_pose)
            assert np.array_equal(layouts.object_classes[i], layout.object_classes)
            assert tuple(layouts.wall_textures[i]) == layout.wall_textures
            assert ours[i].bit_generator.state == rng.bit_generator.state


def test_layouts_the_walk_cannot_settle_are_drawn_by_sample_layout(monkeypatch: pytest.MonkeyPatch) -> None:
    """Too few candidates for most layouts: those fall back to sample_layout, and every result is still exact."""
    monkeypatch.setattr(batch_layout, "_CANDIDATES_PER_POINT", 1)
    arena = Arena.build("polygon", 6.0)
    ours, theirs = _generators(40, 7), _generators(40, 7)
    layouts = sample_layouts(ours, arena, 3, "per_side")
    for i, rng in enumerate(theirs):
        assert np.array_equal(layouts.agent_pose[i], sample_layout(rng, arena, 3, "per_side").agent_pose)
        assert ours[i].bit_generator.state == rng.bit_generator.state


@pytest.mark.parametrize("shape", ["square", "polygon"])
def test_clearances_are_bitwise_clearance(shape: str) -> None:
    arena = Arena.build(shape, 6.0)
    points = np.concatenate([np.random.default_rng(0).uniform(-3.5, 3.5, size=(3000, 2)), arena.vertex_array,
                             (arena.wall_starts + arena.wall_ends) / 2])
    together = arena.clearances(points[: len(points) // 4 * 4].reshape(-1, 4, 2)).ravel()  # any leading shape
    points = points[: len(together)]
    assert [arena.clearance(point) for point in points] == together.tolist()
    assert arena.clearances(points[0]).shape == ()


def test_shorter_than_answers_as_the_blas_norm_also_at_the_bound() -> None:
    rng = np.random.default_rng(0)
    angle = rng.uniform(-np.pi, np.pi, 20000)
    length = 0.6 * (1.0 + rng.integers(-4, 5, 20000) * np.finfo(float).eps)  # within a few ulps of the bound
    length[::2] = rng.uniform(0.0, 2.0, 10000)
    dx, dy = length * np.cos(angle), length * np.sin(angle)
    expected = vector_norm(np.stack([dx, dy], axis=-1)) < 0.6
    assert np.array_equal(shorter_than(dx, dy, 0.6), expected)
    assert np.array_equal(expected, [np.linalg.norm([x, y]) < 0.6 for x, y in zip(dx, dy, strict=True)])


@pytest.mark.parametrize(
    ("task", "shape", "n_objects", "horizon", "rewards"),
    [("pick", "square", 3, None, {}), ("drop", "square", 3, 12, {"success": 5.0, "collision": 2.0}),
     ("pick", "polygon", 5, 12, {"success": 5.0, "collision": 2.0}), ("drop", "polygon", 1, None, {})],
)
def test_task_batch_plays_the_envs_episodes_exactly(task, shape, n_objects, horizon, rewards) -> None:
    """The batch pays ``sim.rewards`` as the env does (the defaults, or others)."""
    sim = SimConfig(arena=shape, n_objects=n_objects, rewards=rewards)
    n_envs, seeds = 6, [11 * i + 3 for i in range(6)]
    envs = [gym.make(ENV_IDS[task], render_frames=False, horizon=horizon, **sim.model_dump()).unwrapped
            for _ in range(n_envs)]
    batch = TaskBatch(task, n_envs, sim, horizon)
    batch.reset(np.arange(n_envs), seeds)
    for env, seed in zip(envs, seeds, strict=True):
        env.reset(seed=seed)
    rng = np.random.default_rng(1)
    ends = {"terminated": 0, "truncated": 0, "success": 0}
    for _ in range(600):
        actions = rng.choice(len(Action), size=n_envs, p=[0.4, 0.25, 0.25, 0.05, 0.05])  # masked ones included
        result = batch.step(actions)
        positions = batch.world.object_positions()
        for i, env in enumerate(envs):
            _, reward, terminated, truncated, info = env.step(int(actions[i]))
            assert np.array_equal(batch.world.agent_pose[i], info["agent_pose"])
            assert np.array_equal(positions[i], info["object_positions"])
            assert batch.world.held[i] == info["held"]
            assert (result.reward[i], result.terminated[i], result.truncated[i]) == (reward, terminated, truncated)
            if terminated or truncated:
                assert float(result.success[i]) == info["metrics"]["success"]
                ends["terminated"] += terminated
                ends["truncated"] += truncated
                ends["success"] += bool(result.success[i])
                env.reset()
        batch.reset(np.flatnonzero(result.terminated | result.truncated))
    assert ends["terminated"] > 0 and (horizon is None or ends["truncated"] > 0)
    assert task == "drop" or ends["success"] > 0
