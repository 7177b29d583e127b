"""The evaluation protocol: every method plays the same episodes (seed s, episode e -> reset seed
``episode_seed(s, e)``) of Pick, Drop and the full Rearrange task; one JSON line per episode (``mor.eval.records``).

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
from mor.eval.lockstep import Decide, play_lockstep
from mor.eval.methods import MethodSpec, TrainedPolicies
from mor.eval.records import EVAL_TASKS, METRICS, claim_records, read_records, seal
from mor.eval.stats import summarize
from mor.policy.belief import PoseBelief
from mor.policy.baselines import baseline_inputs
from mor.policy.envs import baseline_sim, make_task_env
from mor.policy.features import Encode, observation_vector, pose_inputs
from mor.policy.hierarchy import decision_mask, nearest_unfixed
from mor.policy.observations import BatchTracker, has_uncertainty
from mor.sim.arena import Arena
from mor.sim.config import SimConfig
from mor.sim.rollout import episode_seed, make_policy, run_episode


def decider(method: MethodSpec, policies: TrainedPolicies, arena: Arena) -> Decide:
    """The method's decision for k envs at once: its learned decision policy, the nearest-unfixed rule, or (the
    baselines, which hold no pose estimate) the object after the previous decision's, in index order."""
    if method.decision == "nearest_rule":
        return lambda belief, held, targets, last: np.array(
            [nearest_unfixed(belief.take(k), targets[k]) for k in range(len(held))])
    if method.decision == "object_order":
        return lambda belief, held, targets, last: (last + 1) % targets.shape[1]
    uncertainty = has_uncertainty(method.variant)

    def learned(belief: PoseBelief, held: np.ndarray, targets: np.ndarray, last: np.ndarray) -> np.ndarray:
        vectors = observation_vector(belief, held, "decision", targets, uncertainty, arena)
        return policies.decision.act_batch(vectors, decision_mask(belief.object_mean, targets))

    return learned


def method_inputs(method: MethodSpec) -> Encode:
    """What a learned method's skills read: a baseline's pixels and goal, or the pose layout of its variant."""
    if method.is_baseline:
        return baseline_inputs(method.variant)
    return pose_inputs(has_uncertainty(method.variant))


def sim_of(method: MethodSpec, sim: SimConfig) -> SimConfig:
    """The world the method plays in: the landmark baseline's shows its drop targets."""
    return baseline_sim(method.variant, sim) if method.is_baseline else sim


def _play_scripted(method: MethodSpec, task: str, sim: SimConfig, keys: list[tuple[Any, int]],
                   env_kwargs: dict[str, Any]) -> Iterator[tuple[Any, dict[str, Any]]]:
    """The scripted policies, one episode at a time in one environment of ``task``."""
    env = make_task_env("decision" if task == "rearrange" else task, sim, render_frames=False, **env_kwargs)
    try:
        for key, seed in keys:
            record = run_episode(env, make_policy(method.name, env, seed=seed), seed)
            yield key, {"metrics": record.metrics, "steps": record.steps, "return": record.episode_return}
    finally:
        env.close()


def episode_keys(seeds: list[int], episodes: int) -> Iterator[tuple[str, int, int]]:
    for task in EVAL_TASKS:
        for seed in seeds:
            for episode in range(episodes):
                yield task, seed, episode


EpisodeKey = tuple[str, int, int]  # (task, seed, episode)
#: plays the given jobs (lists of episode keys) and yields their records as they come, a few at a time, any order
RunJobs = Callable[[list[list[EpisodeKey]]], Iterator[list[dict[str, Any]]]]


def protocol_jobs(keys: list[EpisodeKey]) -> list[list[EpisodeKey]]:
    """``keys`` grouped into independent jobs, one per (task, seed): the unit a parallel evaluation runs."""
    jobs: dict[tuple[str, int], list[EpisodeKey]] = {}
    for key in keys:
        jobs.setdefault(key[:2], []).append(key)
    return list(jobs.values())


def play_records(method: MethodSpec, sim: SimConfig, keys: list[EpisodeKey], policies: TrainedPolicies | None,
                 tracker_factory: Callable[[int], BatchTracker] | None, n_envs: int = 8, horizon: int | None = None
                 ) -> Iterator[dict[str, Any]]:
    """Play the episodes ``keys`` and yield each one's record as it ends. Learned methods play ``n_envs``
    episodes in lockstep (``mor.eval.lockstep``) with a tracker from ``tracker_factory(n)``; the scripted ones play
    one at a time. ``horizon``: a cap on every episode's steps."""
    import torch  # noqa: PLC0415

    torch.set_num_threads(1)  # small batched forwards: one thread is several times faster on 2 cores (DESIGN.md)
    env_kwargs = {} if horizon is None else {"horizon": horizon}
    for (task, seed, episode), outcome in _play(method, sim, keys, policies, tracker_factory, n_envs, env_kwargs):
        yield {"method": method.name, "task": task, "seed": seed, "episode": episode,
               "reset_seed": episode_seed(seed, episode), **outcome}


def run_protocol(
    method: MethodSpec, sim: SimConfig, seeds: list[int], episodes: int, records_path: Path,
    policies: TrainedPolicies | None = None, tracker_factory: Callable[[int], BatchTracker] | None = None,
    n_envs: int = 8, progress: bool = True, horizon: int | None = None, run_jobs: RunJobs | None = None,
    played_by: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """Play every (task, seed, episode) not yet in ``records_path`` (JSON Lines, appended as records come:
    resumable) and return all of them in protocol order.

    In this process (``play_records`` with ``policies`` and ``tracker_factory``), or, with ``run_jobs``, by
    whatever runs the ``protocol_jobs`` (``pipelines.evaluate``: worker processes or Ray tasks).
    played_by: what plays the episodes (e.g. the policies' digests and the L-Net's identity), stored beside the
    records and sealed into each (``mor.eval.records``); records played by anything else are not resumed: one
    clear error.
    """
    played_by = played_by or {}
    claim_records(records_path, played_by)
    done = {(r["task"], r["seed"], r["episode"]): r for r in read_records(records_path)}
    todo = [key for key in episode_keys(seeds, episodes) if key not in done]
    with atomic_output(records_path) as partial:  # drop a line cut short by a kill before appending
        partial.write_text("".join(json.dumps(r) + "\n" for r in done.values()))
    if run_jobs is None:
        def run_jobs(jobs: list[list[EpisodeKey]]) -> Iterator[list[dict[str, Any]]]:
            keys = [key for job in jobs for key in job]
            return ([record] for record in play_records(method, sim, keys, policies, tracker_factory, n_envs,
                                                         horizon))
    with records_path.open("a") as handle, tqdm(total=len(todo), desc=f"eval {method.name}", unit="ep",
                                                disable=not progress, dynamic_ncols=True) as bar:
        for records in run_jobs(protocol_jobs(todo)) if todo else ():
            for record in records:
                record = seal(record, played_by)
                handle.write(json.dumps(record) + "\n")
                done[(record["task"], record["seed"], record["episode"])] = record
            handle.flush()
            bar.update(len(records))
    return [done[key] for key in episode_keys(seeds, episodes)]


def _play(method: MethodSpec, sim: SimConfig, todo: list[tuple[str, int, int]], policies: TrainedPolicies | None,
          tracker_factory: Callable[[int], BatchTracker] | None, n_envs: int, env_kwargs: dict[str, Any]
          ) -> Iterator[tuple[tuple[str, int, int], dict[str, Any]]]:
    for task in EVAL_TASKS:
        keys = [(key, episode_seed(key[1], key[2])) for key in todo if key[0] == task]
        if not keys:
            continue
        if method.decision == "scripted":
            yield from _play_scripted(method, task, sim, keys, env_kwargs)
            continue
        n = min(n_envs, len(keys))
        skills = {"pick": policies.pick, "drop": policies.drop}
        decide = decider(method, policies, Arena.build(sim.arena, sim.arena_size))
        yield from play_lockstep(task, keys, sim_of(method, sim), tracker_factory(n), skills, decide,
                                 method_inputs(method), n, **env_kwargs)


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
