"""``mor bench sim``: environment steps per second with rendering, in one process and one worker per core."""

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


def _steps_per_second(
    env_id: str, steps: int, seed: int, env_kwargs: dict[str, Any], start_together: Any = None
) -> float:
    """Random-policy steps/s over ``steps`` steps (resets included), after a short warm-up.

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
    start = time.perf_counter()
    for _ in range(steps):
        observation, _, terminated, truncated, info = env.step(policy(observation, info))
        if terminated or truncated:
            observation, info = env.reset()
    elapsed = time.perf_counter() - start
    env.close()
    return steps / elapsed


def _worker(env_id: str, steps: int, seed: int, env_kwargs: dict[str, Any], barrier: Any, results: Any) -> None:
    os.environ.setdefault("LP_NUM_THREADS", "1")  # one llvmpipe thread per worker process
    results.put(_steps_per_second(env_id, steps, seed, env_kwargs, barrier))


def _parallel_steps_per_second(env_id: str, steps: int, workers: int, env_kwargs: dict[str, Any]) -> float:
    """Summed steps/s of ``workers`` processes stepping their own envs at the same time (start-up excluded)."""
    context = mp.get_context("spawn")
    barrier, results = context.Barrier(workers), context.Queue()
    processes = [
        context.Process(target=_worker, args=(env_id, steps, seed, env_kwargs, barrier, results))
        for seed in range(workers)
    ]
    for process in processes:
        process.start()
    rates = [results.get() for _ in processes]
    for process in processes:
        process.join()
    return float(sum(rates))


def benchmark_sim(
    env_ids: list[str], steps: int, repeats: int, workers: int, env_kwargs: dict[str, Any]
) -> dict[str, Any]:
    """Median over ``repeats`` of single-process and ``workers``-process steps/s for each env."""
    results: dict[str, Any] = {}
    for env_id in env_ids:
        single = [_steps_per_second(env_id, steps, seed, env_kwargs) for seed in range(repeats)]
        parallel = [_parallel_steps_per_second(env_id, steps, workers, env_kwargs) for _ in range(repeats)]
        results[env_id] = {
            "single_process_steps_per_s": statistics.median(single),
            f"{workers}_workers_steps_per_s": statistics.median(parallel),
            "runs_single": single,
            "runs_parallel": parallel,
        }
    return {
        "benchmark": "sim",
        "policy": "random (uniform over unmasked actions), resets included",
        "steps_per_run": steps,
        "repeats": repeats,
        "workers": workers,
        "env_kwargs": env_kwargs,
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                    "MUJOCO_GL": os.environ.get("MUJOCO_GL")},
        "numpy": np.__version__,
        "results": results,
    }
