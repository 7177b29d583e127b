"""Stage ``demo``: a rendered episode (first-person + top-down MP4) and the first frame's views as PNG."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym

from mor.config import DemoParams, SimConfig
from mor.sim import TASKS
from mor.sim.rollout import EpisodeRecord, make_policy, run_episode
from mor.sim.views import write_png, write_video


def render_views(sim: SimConfig, task: str, seed: int, out_dir: Path) -> list[Path]:
    """The first-person image and the top-down view of ``task``'s episode ``seed`` at reset, as PNG."""
    env = gym.make(TASKS[task][0], **sim.model_dump())
    try:
        observation, _ = env.reset(seed=seed)
        views = {"first_person": observation["image"], "top_down": env.unwrapped.top_down()}
        return [write_png(out_dir / f"{task}_seed{seed}_{name}.png", image) for name, image in views.items()]
    finally:
        env.close()


def record_video(sim: SimConfig, demo: DemoParams, out: Path) -> EpisodeRecord:
    """Play ``demo.policy`` on ``demo.task`` and write the side-by-side video to ``out`` (.mp4 or .gif)."""
    env = gym.make(TASKS[demo.task][0], render_mode="rgb_array", **sim.model_dump())
    try:
        record = run_episode(env, make_policy(demo.policy, env, demo.seed), demo.seed, record_frames=True)
    finally:
        env.close()
    write_video(out, record.frames, demo.fps)
    return record
