"""Running policies in MOR environments: one episode, or many over seeds with mean +- std metrics."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from mor.sim.oracle import Oracle

Policy = Callable[[dict[str, Any], dict[str, Any]], int]


@dataclass
class EpisodeRecord:
    """One finished episode: its metrics, length, return, and (if asked for) its rendered frames."""

    metrics: dict[str, float]
    steps: int
    episode_return: float
    frames: list[np.ndarray] = field(default_factory=list)


class RandomPolicy:
    """Uniform over the actions the env's mask allows, drawn from its own seeded generator."""

    def __init__(self, env: gym.Env, seed: int = 0) -> None:
        self.env = env.unwrapped
        self.rng = np.random.default_rng(seed)

    def __call__(self, observation: dict[str, Any], info: dict[str, Any]) -> int:
        return int(self.rng.choice(np.flatnonzero(self.env.action_masks())))


def make_policy(name: str, env: gym.Env, seed: int = 0) -> Policy:
    """``oracle`` or ``random`` for ``env``."""
    if name == "oracle":
        return Oracle(env.unwrapped.arena, env.unwrapped.noise)
    if name == "random":
        return RandomPolicy(env, seed)
    raise ValueError(f"policy: unknown policy {name!r}; choose 'oracle' or 'random'")


def run_episode(env: gym.Env, policy: Policy, seed: int, record_frames: bool = False) -> EpisodeRecord:
    """Play one episode from ``env.reset(seed=seed)`` to its end; frames come from ``env.render()``."""
    if hasattr(policy, "reset"):
        policy.reset()
    observation, info = env.reset(seed=seed)
    frames = [env.render()] if record_frames else []
    total, steps = 0.0, 0
    while True:
        observation, reward, terminated, truncated, info = env.step(policy(observation, info))
        total += float(reward)
        steps += 1
        if record_frames:
            frames.append(env.render())
        if terminated or truncated:
            return EpisodeRecord(dict(info["metrics"]), steps, total, frames)


def episode_seed(run_seed: int, episode: int) -> int:
    """The reset seed of episode ``episode`` of run ``run_seed``: disjoint across runs for < 1e6 episodes."""
    return run_seed * 1_000_000 + episode


def evaluate(
    env_id: str, policy_name: str, episodes: int, seeds: list[int], env_kwargs: dict[str, Any], progress: bool = True
) -> dict[str, Any]:
    """Run ``episodes`` episodes per seed; per seed average each metric, then report mean and std over seeds."""
    per_seed: dict[int, dict[str, float]] = {}
    env = gym.make(env_id, **env_kwargs)
    try:
        bar = tqdm(total=episodes * len(seeds), desc=f"{policy_name} {env_id}", unit="ep", disable=not progress)
        for run_seed in seeds:
            policy = make_policy(policy_name, env, seed=run_seed)
            records = [run_episode(env, policy, episode_seed(run_seed, e)) for e in _ticking(range(episodes), bar)]
            per_seed[run_seed] = {
                **{k: float(np.mean([r.metrics[k] for r in records])) for k in records[0].metrics},
                "steps": float(np.mean([r.steps for r in records])),
            }
        bar.close()
    finally:
        env.close()
    names = list(next(iter(per_seed.values())))
    summary = {
        name: {
            "mean": float(np.mean([m[name] for m in per_seed.values()])),
            "std": float(np.std([m[name] for m in per_seed.values()])),
        }
        for name in names
    }
    return {"env_id": env_id, "policy": policy_name, "episodes_per_seed": episodes, "seeds": seeds,
            "env_kwargs": env_kwargs, "summary": summary, "per_seed": {str(k): v for k, v in per_seed.items()}}


def _ticking(items: range, bar: tqdm) -> Any:
    for item in items:
        yield item
        bar.update(1)
