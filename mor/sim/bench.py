"""``mor bench sim``: environment steps per second with rendering, in one process and one worker per core.

The JSON also holds where a rendered step's time goes (``mor.sim.step_profile``). Every measurement runs in
fresh spawned processes with one llvmpipe render thread each (LP_NUM_THREADS=1), ours and MiniWorld's alike, and
times only the stepping (start-up and warm-up excluded).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import platform
import statistics
import time
from typing import Any

import gymnasium as gym
import numpy as np

from mor.sim.rollout import RandomPolicy
from mor.sim.step_profile import step_profile


def _timed_run(
    env_id: str, steps: int, seed: int, env_kwargs: dict[str, Any], start_together: Any = None
) -> tuple[float, float]:
    """(start, end) in seconds of ``steps`` random-policy steps (resets included), after a short warm-up.

    The clock is ``time.monotonic()``, which is system-wide on Linux, so the spans of several processes compare.
    start_together: a multiprocessing Barrier that all workers pass before timing, so their runs overlap.
    """
    env = gym.make(env_id, **env_kwargs)
    policy = RandomPolicy(env, seed)
    observation, info = env.reset(seed=seed)
    for _ in range(50):
        observation, _, terminated, truncated, info = env.step(policy(observation, info))
        if terminated or truncated:
            observation, info = env.reset()
    if start_together is not None:
        start_together.wait()
    start = time.monotonic()
    for _ in range(steps):
        observation, _, terminated, truncated, info = env.step(policy(observation, info))
        if terminated or truncated:
            observation, info = env.reset()
    end = time.monotonic()
    env.close()
    return start, end


def _worker(env_id: str, steps: int, seed: int, env_kwargs: dict[str, Any], barrier: Any, results: Any) -> None:
    os.environ.setdefault("LP_NUM_THREADS", "1")  # one llvmpipe thread per worker process
    results.put(_timed_run(env_id, steps, seed, env_kwargs, barrier))


def _parallel_steps_per_second(env_id: str, steps: int, workers: int, env_kwargs: dict[str, Any]) -> float:
    """Steps/s of ``workers`` processes stepping their own envs at once: all their steps over the wall-clock time
    from the first start to the last finish (start-up excluded). With one worker, that process's own rate."""
    context = mp.get_context("spawn")
    barrier, results = context.Barrier(workers), context.Queue()
    processes = [
        context.Process(target=_worker, args=(env_id, steps, seed, env_kwargs, barrier, results))
        for seed in range(workers)
    ]
    for process in processes:
        process.start()
    spans = [results.get() for _ in processes]
    for process in processes:
        process.join()
    return combined_steps_per_second(steps, spans)


def combined_steps_per_second(steps: int, spans: list[tuple[float, float]]) -> float:
    """``steps`` per process, each run over its (start, end) span in seconds: all the steps over the wall-clock
    time from the first start to the last end (not the sum of each process's own rate)."""
    wall = max(end for _, end in spans) - min(start for start, _ in spans)
    return steps * len(spans) / wall


MINIWORLD_ENV = "MiniWorld-PickupObjects-v0"


def _miniworld_worker(steps: int, seed: int, results: Any) -> None:
    """MiniWorld's PickupObjects at 64x64, random actions, in its own process (pyglet must go headless first)."""
    os.environ.setdefault("LP_NUM_THREADS", "1")  # the same render settings as our workers
    try:
        import pyglet  # noqa: PLC0415

        pyglet.options["headless"] = True
        import miniworld  # noqa: F401, PLC0415 - registers the envs
    except ImportError as error:
        results.put(f"miniworld not installed ({error}); pip install 'mor[bench]'")
        return
    env = gym.make(MINIWORLD_ENV, obs_width=64, obs_height=64)
    env.action_space.seed(seed)
    env.reset(seed=seed)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    results.put(steps / (time.perf_counter() - start))
    env.close()


def miniworld_steps_per_second(steps: int, seed: int) -> float | str:
    """MiniWorld PickupObjects steps/s (one process), or why it could not run."""
    context = mp.get_context("spawn")
    results = context.Queue()
    process = context.Process(target=_miniworld_worker, args=(steps, seed, results))
    process.start()
    outcome = results.get()
    process.join()
    return outcome


def benchmark_sim(
    env_ids: list[str], steps: int, repeats: int, workers: int, env_kwargs: dict[str, Any]
) -> dict[str, Any]:
    """Median over ``repeats`` of single-process and ``workers``-process steps/s for each env."""
    load_before = os.getloadavg()[0]  # other jobs on the machine skew both figures (docs/assumptions.md)
    results: dict[str, Any] = {}
    for env_id in env_ids:
        single = [_parallel_steps_per_second(env_id, steps, 1, env_kwargs) for _ in range(repeats)]
        parallel = [_parallel_steps_per_second(env_id, steps, workers, env_kwargs) for _ in range(repeats)]
        results[env_id] = {
            "single_process_steps_per_s": statistics.median(single),
            f"{workers}_workers_steps_per_s": statistics.median(parallel),
            "runs_single": single,
            "runs_parallel": parallel,
        }
    peer = [miniworld_steps_per_second(steps, seed) for seed in range(repeats)]
    if all(isinstance(rate, float) for rate in peer):
        results[MINIWORLD_ENV] = {"single_process_steps_per_s": statistics.median(peer), "runs_single": peer}
        for env_id in env_ids:
            results[env_id]["speedup_vs_miniworld"] = (
                results[env_id]["single_process_steps_per_s"] / results[MINIWORLD_ENV]["single_process_steps_per_s"])
    else:
        results[MINIWORLD_ENV] = {"unavailable": next(r for r in peer if isinstance(r, str))}
    return {
        "benchmark": "sim",
        "policy": "random (uniform over unmasked actions; MiniWorld: uniform), resets included",
        "steps_per_run": steps,
        "repeats": repeats,
        "workers": workers,
        "parallel_rate": "all workers' steps over the wall-clock time from the first start to the last finish",
        "env_kwargs": env_kwargs,
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                    "MUJOCO_GL": os.environ.get("MUJOCO_GL"), "load_average_1min_before": load_before},
        "numpy": np.__version__,
        "results": results,
        "step_profile": {env_id: _step_profile_in_fresh_process(env_id, steps, env_kwargs) for env_id in env_ids},
    }


def _step_profile_worker(env_id: str, steps: int, env_kwargs: dict[str, Any]) -> dict[str, Any]:
    os.environ.setdefault("LP_NUM_THREADS", "1")  # the render settings of the rates above
    return step_profile(env_id, steps, 0, env_kwargs)


def _step_profile_in_fresh_process(env_id: str, steps: int, env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """``mor.sim.step_profile.step_profile`` in a spawned process, like every other measurement here."""
    with mp.get_context("spawn").Pool(1) as pool:
        return pool.apply(_step_profile_worker, (env_id, steps, env_kwargs))
