"""Where a rendered environment step's time goes, part by part (``mor bench sim`` writes it; docs/performance.md).

One process plays a random-policy episode stream once to record states and actions, then times, over those same
steps: the step without rendering (rules, rewards, ``info``: ``render_frames=False``), the scene update
(``Scene.set_state``: mocap poses, ``mj_kinematics``, ``mj_camlight``), the draw call (``Scene.draw``: MuJoCo
builds its scene and issues the OpenGL commands), rasterization (``glFinish``: with llvmpipe, the CPU draws the
pixels here) and the read-back with its copy (``Scene.read_pixels``); and the whole rendered step. "other" is
what the parts, each timed in its own loop, do not add up to in whole steps: mostly the cache cost of alternating
Python with rendering (the wrappers and the observation dict are already in the step without rendering).
Times are microseconds per step: CPU (``time.process_time``, every thread of the process) and wall clock.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym

from mor.sim.rollout import RandomPolicy

PARTS: tuple[str, ...] = ("step_without_render", "scene_update", "draw_calls", "rasterize", "read_back_and_copy")


def _timed(run: Callable[[], Any]) -> tuple[float, float]:
    """(CPU seconds, wall seconds) of ``run()``."""
    cpu, wall = time.process_time(), time.perf_counter()
    run()
    return time.process_time() - cpu, time.perf_counter() - wall


def step_profile(env_id: str, steps: int, seed: int, env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """Microseconds per step of each part of ``steps`` random-policy steps (resets included) of ``env_id``.

    Returns {"cpu_us": {part: us}, "wall_us": {part: us}} with the parts of ``PARTS``, "whole_rendered_step"
    and "other" (whole step minus the parts), and "render_share_cpu": the draw calls, rasterization and read-back
    over the whole step's CPU time.
    """
    from OpenGL import GL  # noqa: PLC0415 - after the scene chose the GL platform

    env = gym.make(env_id, **env_kwargs)
    plain = gym.make(env_id, render_frames=False, **env_kwargs)
    policy = RandomPolicy(env, seed)
    observation, info = env.reset(seed=seed)
    actions, states = [], []
    for _ in range(steps):
        actions.append(policy(observation, info))
        observation, _, terminated, truncated, info = env.step(actions[-1])
        states.append(env.unwrapped.state.copy())
        if terminated or truncated:
            observation, info = env.reset()

    def play(target: gym.Env) -> Callable[[], None]:
        def run() -> None:
            target.reset(seed=seed)
            for action in actions:
                _, _, terminated, truncated, _ = target.step(action)
                if terminated or truncated:
                    target.reset()
        return run

    scene = env.unwrapped._ensure_scene()
    cpu = dict.fromkeys(PARTS, 0.0)
    wall = dict.fromkeys(PARTS, 0.0)
    cpu["step_without_render"], wall["step_without_render"] = _timed(play(plain))
    for state in states:
        for part, run in (("scene_update", lambda: scene.set_state(state)), ("draw_calls", scene.draw),
                          ("rasterize", GL.glFinish), ("read_back_and_copy", scene.read_pixels)):
            c, w = _timed(run)
            cpu[part] += c
            wall[part] += w
    cpu["whole_rendered_step"], wall["whole_rendered_step"] = _timed(play(env))
    env.close()
    plain.close()
    out: dict[str, Any] = {}
    for name, totals in (("cpu_us", cpu), ("wall_us", wall)):
        totals["other"] = max(0.0, totals["whole_rendered_step"] - sum(totals[p] for p in PARTS))
        out[name] = {part: round(1e6 * seconds / steps, 1) for part, seconds in totals.items()}
    render = sum(cpu[p] for p in ("draw_calls", "rasterize", "read_back_and_copy"))
    out["render_share_cpu"] = round(render / cpu["whole_rendered_step"], 3)
    return out
