"""The evaluation protocol: every method plays the same episodes (seed s, episode e -> reset seed
``episode_seed(s, e)``) of Pick, Drop and the full Rearrange task; one JSON line per episode (``mor.eval.records``).

Pick and Drop are scored on their own tasks with the method's pick and drop policies (paper Table 1's
"Pick"/"Drop" columns); Rearrange with the whole hierarchy (Success, %FS, %E).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm import tqdm

from mor.atomic import atomic_output
from mor.eval.lockstep import Decide, play_lockstep
from mor.eval.methods import LoadedMethod, Method, TrainedPolicies, load_method, method_spec
from mor.eval.records import EVAL_TASKS, METRICS, claim_records, read_records, seal
from mor.eval.stats import summarize
from mor.policy.belief import PoseBelief
from mor.policy.baselines import baseline_inputs
from mor.policy.envs import make_task_env, variant_sim
from mor.policy.features import Encode, ObservationLayout, observation_vector, pose_inputs
from mor.policy.hierarchy import decision_mask, nearest_unfixed
from mor.policy.params import ObservationParams
from mor.policy.workspace import Workspace
from mor.sim.arena import Arena
from mor.sim.config import SimConfig
from mor.sim.rollout import episode_seed, make_policy, run_episode

if TYPE_CHECKING:
    from mor.config import Profile


def decider(method: Method, policies: TrainedPolicies, arena: Arena, features: ObservationParams) -> Decide:
    """The method's decision for k envs at once: its learned decision policy (reading its variant's layout with
    the profile's ``policy.observation`` settings, ``features``), the nearest-unfixed rule, or (the baselines,
    which hold no pose estimate) the object after the previous decision's, in index order."""
    if method.decision == "nearest_rule":
        return lambda belief, held, targets, last: np.array(
            [nearest_unfixed(belief.take(k), targets[k]) for k in range(len(held))])
    if method.decision == "object_order":
        return lambda belief, held, targets, last: (last + 1) % targets.shape[1]
    layout = ObservationLayout.of(method.variant, features)

    def learned(belief: PoseBelief, held: np.ndarray, targets: np.ndarray, last: np.ndarray) -> np.ndarray:
        vectors = observation_vector(belief, held, "decision", targets, layout, arena)
        return policies.decision.act_batch(vectors, decision_mask(belief.object_mean, targets))

    return learned


def method_inputs(method: Method, features: ObservationParams) -> Encode:
    """What a learned method's skills read: a baseline's pixels and goal, or the pose layout of its variant (with
    the profile's ``policy.observation`` settings, ``features``)."""
    if method.is_baseline:
        return baseline_inputs(method.variant)
    return pose_inputs(ObservationLayout.of(method.variant, features))


def sim_of(method: Method, sim: SimConfig) -> SimConfig:
    """The world the method plays in (``variant_sim``: a baseline's may show its drop targets)."""
    return sim if method.variant is None else variant_sim(method.variant, sim)


def _play_scripted(method: Method, task: str, sim: SimConfig, keys: list[tuple[Any, int]],
                   env_kwargs: dict[str, Any]) -> Iterator[tuple[Any, dict[str, Any]]]:
    """The scripted policies, one episode at a time in one environment of ``task``."""
    env = make_task_env(task, sim, render_frames=False, **env_kwargs)
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


def play_records(loaded: LoadedMethod, sim: SimConfig, keys: list[EpisodeKey], n_envs: int = 8,
                 horizon: int | None = None) -> Iterator[dict[str, Any]]:
    """Play the episodes ``keys`` and yield each one's record as it ends. Learned methods play ``n_envs``
    episodes in lockstep (``mor.eval.lockstep``) with a tracker from the method's ``tracker_factory(n)``; the
    scripted ones play one at a time. ``horizon``: a cap on every episode's steps."""
    import torch  # noqa: PLC0415

    torch.set_num_threads(1)  # small batched forwards: one thread is several times faster on 2 cores (docs/design.md, "Threads")
    env_kwargs = {} if horizon is None else {"horizon": horizon}
    for (task, seed, episode), outcome in _play(loaded, sim, keys, n_envs, env_kwargs):
        yield {"method": loaded.method.name, "task": task, "seed": seed, "episode": episode,
               "reset_seed": episode_seed(seed, episode), **outcome}


def run_protocol(
    loaded: LoadedMethod, sim: SimConfig, seeds: list[int], episodes: int, records_path: Path, n_envs: int = 8,
    progress: bool = True, horizon: int | None = None, run_jobs: RunJobs | None = None,
) -> list[dict[str, Any]]:
    """Play every (task, seed, episode) not yet in ``records_path`` (JSON Lines, appended as records come:
    resumable) and return all of them in protocol order.

    In this process (``play_records``), or, with ``run_jobs``, by whatever runs the ``protocol_jobs`` (worker
    processes or Ray tasks running ``play_job``). What plays the episodes (``LoadedMethod.played_by``: the policies'
    digests and the L-Net's identity) is stored beside the records and sealed into each (``mor.eval.records``);
    records played by anything else are not resumed: one clear error.
    """
    played_by, method = loaded.played_by(), loaded.method
    claim_records(records_path, played_by)
    done = {(r["task"], r["seed"], r["episode"]): r for r in read_records(records_path)}
    todo = [key for key in episode_keys(seeds, episodes) if key not in done]
    with atomic_output(records_path) as partial:  # drop a line cut short by a kill before appending
        partial.write_text("".join(json.dumps(r) + "\n" for r in done.values()))
    if run_jobs is None:
        def run_jobs(jobs: list[list[EpisodeKey]]) -> Iterator[list[dict[str, Any]]]:
            keys = [key for job in jobs for key in job]
            return ([record] for record in play_records(loaded, sim, keys, n_envs, horizon))
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


def _play(loaded: LoadedMethod, sim: SimConfig, todo: list[tuple[str, int, int]], n_envs: int,
          env_kwargs: dict[str, Any]) -> Iterator[tuple[tuple[str, int, int], dict[str, Any]]]:
    method, policies = loaded.method, loaded.policies
    for task in EVAL_TASKS:
        keys = [(key, episode_seed(key[1], key[2])) for key in todo if key[0] == task]
        if not keys:
            continue
        if method.decision == "scripted":
            yield from _play_scripted(method, task, sim, keys, env_kwargs)
            continue
        n = min(n_envs, len(keys))
        skills = {"pick": policies.pick, "drop": policies.drop}
        decide = decider(method, policies, Arena.build(sim.arena, sim.arena_size), loaded.features)
        yield from play_lockstep(task, keys, sim_of(method, sim), loaded.tracker_factory(n), skills, decide,
                                 method_inputs(method, loaded.features), n, **env_kwargs)


#: this worker's loaded methods: each loads once per process (a pool worker or a Ray worker plays many jobs)
_LOADED: dict[tuple[Workspace, str, str, bool, int], LoadedMethod] = {}

#: one parallel evaluation job: (the workspace, the profile, the method's name, zero-shot, the training seed of
#: its policies, its episode keys)
Job = tuple[Workspace, "Profile", str, bool, int, list[EpisodeKey]]


def play_job(job: Job) -> list[dict[str, Any]]:
    """Play one parallel evaluation job (in a worker process or a Ray task) and return its records; the method is
    loaded on the worker's first job and kept for the next ones."""
    workspace, profile, name, zero_shot, training_seed, keys = job
    os.environ.setdefault("LP_NUM_THREADS", "1")  # one llvmpipe render thread per worker
    key = (workspace, profile.model_dump_json(), name, zero_shot, training_seed)
    if key not in _LOADED:
        _LOADED[key] = load_method(method_spec(name), workspace, profile, zero_shot, training_seed)
    evaluate = profile.evaluate
    return list(play_records(_LOADED[key], profile.sim, keys, evaluate.n_envs, evaluate.horizon))


def metric_values(records: list[dict[str, Any]]) -> dict[str, dict[str, list[float]]]:
    """The five metrics of paper Table 1 per evaluation seed: {metric: {seed (str): per-episode values}}."""
    values: dict[str, dict[str, list[float]]] = {}
    for name, (task, key) in METRICS.items():
        by_seed = values.setdefault(name, {})
        for record in records:
            if record["task"] == task:
                by_seed.setdefault(str(record["seed"]), []).append(float(record["metrics"][key]))
    return values


def metric_summaries(records: list[dict[str, Any]], resamples: int) -> dict[str, dict]:
    """The five metrics of paper Table 1, each ``mor.eval.stats.summarize``d over seeds."""
    return {name: summarize({int(seed): v for seed, v in by_seed.items()}, resamples)
            for name, by_seed in metric_values(records).items()}
