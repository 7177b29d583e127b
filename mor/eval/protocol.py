"""The evaluation protocol: every method plays the same episodes (seed s, episode e -> reset seed
``episode_seed(s, e)``) of Pick, Drop and the full Rearrange task; one JSON line per episode.

Pick and Drop are scored on their own tasks with the method's pick and drop policies (paper Table 1's
"Pick"/"Drop" columns); Rearrange with the whole hierarchy (Success, %FS, %E).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from mor.atomic import atomic_output
from mor.eval.methods import MethodSpec, TrainedPolicies
from mor.eval.stats import summarize
from mor.policy.envs import make_policy_env, make_task_env
from mor.policy.hierarchy import HierarchicalRearrange, nearest_unfixed
from mor.policy.observations import Tracker, has_uncertainty
from mor.sim.config import SimConfig
from mor.sim.rollout import episode_seed, make_policy, run_episode

EVAL_TASKS = ("pick", "drop", "rearrange")
METRICS = {"pick_success": ("pick", "success"), "drop_success": ("drop", "success"),
           "rearrange_success": ("rearrange", "success"), "fixed_strict": ("rearrange", "fixed_strict"),
           "energy_remaining": ("rearrange", "energy_remaining")}


def _play_learned(method: MethodSpec, policies: TrainedPolicies, task: str, sim: SimConfig, tracker: Tracker,
                  seed: int) -> dict[str, Any]:
    """One episode of ``task`` by a learned method -> {metrics, steps, return}."""
    uncertainty = has_uncertainty(method.variant)
    if task == "rearrange":
        env = make_policy_env("decision", sim, tracker, uncertainty, (policies.pick, policies.drop))
        act = _decision_actor(method, policies, env)
    else:
        env = make_policy_env(task, sim, tracker, uncertainty)
        skill = policies.pick if task == "pick" else policies.drop
        act = lambda vector: skill.act(vector, env.action_masks())  # noqa: E731
    try:
        vector, info = env.reset(seed=seed)
        total, steps = 0.0, 0
        while True:
            vector, reward, terminated, truncated, info = env.step(act(vector))
            total += float(reward)
            steps += int(info.get("primitive_steps", 1))
            if terminated or truncated:
                return {"metrics": dict(info["metrics"]), "steps": steps, "return": total}
    finally:
        env.close()


def _decision_actor(method: MethodSpec, policies: TrainedPolicies, env: HierarchicalRearrange
                    ) -> Callable[[np.ndarray], int]:
    if method.decision == "nearest_rule":
        return lambda vector: nearest_unfixed(env.belief, env.targets)
    return lambda vector: policies.decision.act(vector, env.action_masks())


def _play_scripted(method: MethodSpec, task: str, sim: SimConfig, seed: int) -> dict[str, Any]:
    env = make_task_env("decision" if task == "rearrange" else task, sim, render_frames=False)
    try:
        record = run_episode(env, make_policy(method.name, env, seed=seed), seed)
    finally:
        env.close()
    return {"metrics": record.metrics, "steps": record.steps, "return": record.episode_return}


def episode_keys(seeds: list[int], episodes: int) -> Iterator[tuple[str, int, int]]:
    for task in EVAL_TASKS:
        for seed in seeds:
            for episode in range(episodes):
                yield task, seed, episode


def run_protocol(
    method: MethodSpec, sim: SimConfig, seeds: list[int], episodes: int, records_path: Path,
    policies: TrainedPolicies | None = None, tracker_factory: Callable[[], Tracker] | None = None,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Play every (task, seed, episode) not yet in ``records_path`` (JSON Lines, appended: resumable)."""
    done = {(r["task"], r["seed"], r["episode"]): r for r in read_records(records_path)}
    todo = [key for key in episode_keys(seeds, episodes) if key not in done]
    with atomic_output(records_path) as partial:  # drop a line cut short by a kill before appending
        partial.write_text("".join(json.dumps(r) + "\n" for r in done.values()))
    with records_path.open("a") as handle, tqdm(total=len(todo), desc=f"eval {method.name}", unit="ep",
                                                disable=not progress, dynamic_ncols=True) as bar:
        for task, seed, episode in todo:
            reset_seed = episode_seed(seed, episode)
            if method.decision == "scripted":
                outcome = _play_scripted(method, task, sim, reset_seed)
            else:
                outcome = _play_learned(method, policies, task, sim, tracker_factory(), reset_seed)
            record = {"method": method.name, "task": task, "seed": seed, "episode": episode,
                      "reset_seed": reset_seed, **outcome}
            handle.write(json.dumps(record) + "\n")
            handle.flush()
            done[(task, seed, episode)] = record
            bar.update(1)
    return [done[key] for key in episode_keys(seeds, episodes)]


def read_records(path: Path) -> list[dict[str, Any]]:
    """The per-episode records of ``path``; a line cut short by a kill is dropped (it is played again)."""
    if not path.is_file():
        return []
    records = []
    for line in path.read_text().splitlines():
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return records


def metric_summaries(records: list[dict[str, Any]], resamples: int) -> dict[str, dict]:
    """The five metrics of paper Table 1, each ``mor.eval.stats.summarize``d over seeds."""
    summaries = {}
    for name, (task, key) in METRICS.items():
        by_seed: dict[int, list[float]] = {}
        for record in records:
            if record["task"] == task:
                by_seed.setdefault(record["seed"], []).append(float(record["metrics"][key]))
        summaries[name] = summarize(by_seed, resamples)
    return summaries
