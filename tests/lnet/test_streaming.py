"""The streaming tracker's one loop (mor.lnet.streaming): episode starts, the SB3 double step across episode ends,
and the search belief's looks kept per environment."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

import mor.sim  # noqa: F401 - registers the envs
from mor.lnet.calibration_file import FittedCalibration
from mor.lnet.model import LNet
from mor.lnet.params import LNetConfig
from mor.lnet.runtime import LNetRunner
from mor.lnet.stated import Estimates, StatedParams
from mor.lnet.streaming import StreamingTracker, stack_frames
from mor.sim.arena import Arena

CONFIG = LNetConfig(feature_dim=16, mlp_hidden=16, lstm_hidden=16, tracker="filter", visibility=True)
SIZE = 16
ARENA = Arena.build("square", 6.0)


def _runner(stated: StatedParams = StatedParams()) -> LNetRunner:
    torch.manual_seed(0)
    return LNetRunner(LNet(CONFIG), FittedCalibration(stated=stated), SIZE, "test")


def _frames(n_frames: int, seed: int) -> list[dict[str, np.ndarray]]:
    """One env's observations (2 objects) under random moves and turns: (frame, action taken after it)."""
    env = gym.make("MOR/Rearrange-v0", image_size=SIZE, n_objects=2)
    observation, rng, out = env.reset(seed=seed)[0], np.random.default_rng(seed), []
    for _ in range(n_frames):
        action = int(rng.integers(0, 3))
        out.append({**observation, "action": action})
        observation = env.step(action)[0]
    env.close()
    return out


def _single(runner: LNetRunner, frames: list[dict[str, np.ndarray]]) -> Estimates:
    """One env's episode from its start, alone in a stream: the estimates of its last frame."""
    stream = StreamingTracker(runner, 1)
    for t, frame in enumerate(frames):
        estimates = stream.step(stack_frames([frame]), np.array([frames[t - 1]["action"] if t else -1]),
                                np.array([t == 0]))
    return estimates


def _close(first: Estimates, second: Estimates, row: int) -> None:
    for name in ("agent_mean", "agent_cov", "heading", "object_mean", "object_cov"):
        np.testing.assert_allclose(getattr(first, name)[row], getattr(second, name)[0], atol=1e-5)


def test_a_stream_restarts_the_episodes_that_start_and_ignores_their_previous_action() -> None:
    runner = _runner()
    a, b = _frames(4, seed=0), _frames(3, seed=1)
    stream = StreamingTracker(runner, 2)
    for t in range(3):
        stream.step(stack_frames([a[t], a[t]]), np.array([a[t - 1]["action"] if t else -1] * 2), np.array([t == 0] * 2))
    # env 0 goes on with a[3]; env 1 starts b's episode at b[0] (its stale previous action must not count)
    estimates = stream.step(stack_frames([a[3], b[0]]), np.array([a[2]["action"], 2]), np.array([False, True]))
    _close(estimates, _single(runner, a), 0)
    _close(estimates, _single(runner, b[:1]), 1)


def test_the_double_step_across_an_episode_end_gives_each_env_the_state_of_its_own() -> None:
    runner = _runner()
    a, b, c = _frames(4, seed=0), _frames(4, seed=1), _frames(2, seed=2)
    stream = StreamingTracker(runner, 2)
    for t in range(3):  # env 0 plays a, env 1 plays b
        previous = np.array([a[t - 1]["action"], b[t - 1]["action"]]) if t else np.full(2, -1)
        stream.step(stack_frames([a[t], b[t]]), previous, np.array([t == 0] * 2))
    # env 0's episode ends on a[3] and c starts; env 1 goes on with b[3] (its frame in both halves)
    previous = np.array([a[2]["action"], b[2]["action"]])
    now, last = stream.step_across_ends(stack_frames([a[3], b[3]]), stack_frames([c[0], b[3]]), previous,
                                        np.array([True, False]))
    _close(last, _single(runner, a), 0)
    _close(now, _single(runner, c[:1]), 0)
    _close(now, _single(runner, b), 1)
    _close(last, _single(runner, b), 1)
    after = stream.step(stack_frames([c[1], b[3]]), np.array([c[0]["action"], b[3]["action"]]), np.zeros(2, bool))
    _close(after, _single(runner, c), 0)
    _close(after, _single(runner, b + [b[3]]), 1)  # b[3] once in the double step, then once more here


@pytest.mark.parametrize("find", [None, 0.5])
def test_given_the_arena_a_stream_keeps_each_envs_looks_for_the_search_density(find: float | None) -> None:
    runner = _runner(StatedParams(search_find=find))
    a, b, c = _frames(4, seed=0), _frames(4, seed=1), _frames(1, seed=2)
    stream, maps = StreamingTracker(runner, 2, ARENA), [runner.fitted.stated.search_map(ARENA, 1) for _ in range(2)]

    def look(estimates: Estimates, envs: range = range(2)) -> None:
        for i in envs:  # the estimated poses (the calibration leaves the means alone)
            maps[i].update(estimates.agent_mean[i:i + 1], estimates.heading[i:i + 1])

    for t in range(3):
        previous = np.array([a[t - 1]["action"], b[t - 1]["action"]]) if t else np.full(2, -1)
        look(stream.step(stack_frames([a[t], b[t]]), previous, np.array([t == 0] * 2)))
    now, last = stream.step_across_ends(stack_frames([a[3], b[3]]), stack_frames([c[0], b[3]]),
                                        np.array([a[2]["action"], b[2]["action"]]), np.array([True, False]))
    look(last)  # both envs' last frames, env 1's counted once; then env 0 starts over at c[0]
    maps[0].reset(np.array([True]))
    look(now, range(1))
    np.testing.assert_array_equal(stream.search.counts, np.concatenate([m.counts for m in maps]))
    if find is None:
        assert now.search_density is None
    else:
        assert now.search_density.shape == (2, len(maps[0].grid)) and now.search_density.dtype == np.float32
        np.testing.assert_allclose(now.search_density, np.concatenate([m.density(find) for m in maps]), rtol=1e-6)


def test_the_streams_looks_follow_the_calibrations_look_cap_and_grid() -> None:
    stream = StreamingTracker(_runner(StatedParams(search_max_looks=8, arena_grid_spacing=0.5)), 1, ARENA)
    assert stream.search.max_looks == 8 and len(stream.search.grid) == 144  # (6 m / 0.5 m)^2 points
