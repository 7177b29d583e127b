"""Running the L-Net over whole episodes into ``mor.lnet.predictions.Predictions``: episodes of a dataset split (the
PoseNet once, ``frame_estimates``, then the tracker replayed, ``track_episodes``, e.g. once per tracking setting) and
live episodes of the simulator driven by a scripted policy, tracked by the streaming loop (``predict_live``).

Shapes: T frames of one episode, K object slots. Positions in metres, headings in radians.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch.utils.data import DataLoader
from tqdm import tqdm

import mor.sim  # noqa: F401 - registers the environments
from mor.data.schema import MAX_OBJECTS, NO_ACTION
from mor.data.sequences import SequenceWindows
from mor.lnet.loss import previous_actions
from mor.lnet.model import ESTIMATE_FIELDS, LNet, PoseEstimate
from mor.lnet.predictions import Predictions, concatenate, episode_predictions
from mor.lnet.runtime import LNetRunner
from mor.lnet.streaming import StreamingTracker, stack_frames
from mor.sim.config import SimConfig
from mor.sim.rollout import episode_seed, make_policy
from mor.sim.rules import visible

LIVE_ENV = "MOR/Rearrange-v0"

#: What ``frame_estimates`` keeps of an episode besides the PoseNet's estimates (no images: they would not fit).
_EPISODE_FIELDS = ("agent_pose", "object_positions", "held", "visible", "object_classes", "actions")


@torch.no_grad()
def frame_estimates(model: LNet, root: Path, max_episodes: int, device: torch.device, progress: bool = True
                    ) -> list[tuple[PoseEstimate, dict[str, torch.Tensor]]]:
    """The PoseNet over whole episodes of the split at ``root`` (the first ``max_episodes``): per episode its
    estimates (1, T, ...) and the episode's truth and inputs (``_EPISODE_FIELDS``, (1, T, ...)), ready for
    ``track_episodes`` (the tracker replayed without the PoseNet, e.g. once per tracking setting)."""
    episodes = SequenceWindows(root, window=None)
    count = min(max_episodes, len(episodes))
    model.eval()
    loader = DataLoader(torch.utils.data.Subset(episodes, range(count)), batch_size=1)
    return [(model.frame_estimates(batch["images"].to(device), batch["object_classes"].to(device)),
             {name: batch[name].to(device) for name in _EPISODE_FIELDS})
            for batch in tqdm(loader, total=count, desc="PoseNet", unit="ep", disable=not progress)]


def _padded(tensors: list[torch.Tensor], length: int) -> torch.Tensor:
    """(1, T_i, ...) each -> (n, length, ...), each repeating its last frame (the trackers are causal)."""
    return torch.cat([torch.cat([t, t[:, -1:].expand(1, length - t.shape[1], *t.shape[2:])], 1) for t in tensors])


@torch.no_grad()
def track_episodes(model: LNet, episodes: list[tuple[PoseEstimate, dict[str, torch.Tensor]]],
                   batch_size: int = 64) -> Predictions:
    """The model's tracker over ``frame_estimates``' episodes, ``batch_size`` episodes at a time (padded to the
    longest), with the model's current tracking settings -> ``Predictions`` (episodes numbered in order)."""
    model.eval()
    parts = []
    for first in range(0, len(episodes), batch_size):
        chunk = episodes[first:first + batch_size]
        length = max(truth["held"].shape[1] for _, truth in chunk)
        single = PoseEstimate(*(_padded([getattr(e, name) for e, _ in chunk], length) for name in ESTIMATE_FIELDS),
                              frame="ego", visibility_logit=None if chunk[0][0].visibility_logit is None else
                              _padded([e.visibility_logit for e, _ in chunk], length))
        truth = {name: _padded([t[name] for _, t in chunk], length) if name != "object_classes" else
                 torch.cat([t[name] for _, t in chunk]) for name in _EPISODE_FIELDS}
        tracked, _ = model.track(single, truth["object_classes"], truth["held"], previous_actions(truth["actions"]))
        estimate = tracked.to_numpy()
        for i, (_, episode) in enumerate(chunk):
            steps = episode["held"].shape[1]
            parts.append(episode_predictions(
                {name: value[i, :steps] for name, value in estimate.items()},
                *(episode[name][0].cpu().numpy() for name in ("agent_pose", "object_positions", "held", "visible",
                                                              "object_classes")), first + i))
    return concatenate(parts)


def predict(model: LNet, root: Path, max_episodes: int, device: torch.device, progress: bool = True) -> Predictions:
    """Run the L-Net over whole episodes of the split at ``root`` (the first ``max_episodes``)."""
    return track_episodes(model, frame_estimates(model, root, max_episodes, device, progress))


def predict_live(runner: LNetRunner, sim: SimConfig, policy: str, episodes: int, seed: int, n_envs: int = 8,
                 horizon: int | None = None, progress: bool = True) -> Predictions:
    """Run ``episodes`` Rearrange episodes driven by ``policy`` (``oracle`` or ``random``) in ``n_envs``
    environments at once, tracked by the streaming loop (``StreamingTracker``), with the truth from ``info`` and
    visibility by ``rules.visible``; episode ``i`` starts from ``reset(seed=episode_seed(seed, i))``. horizon: the
    env's (None: Rearrange's own, 1000 steps)."""
    envs = [gym.make(LIVE_ENV, horizon=horizon, **sim.model_dump()) for _ in range(min(n_envs, episodes))]
    policies = [make_policy(policy, env, seed + i) for i, env in enumerate(envs)]
    next_episode, parts = 0, []
    records: list[dict[str, list] | None] = [None] * len(envs)
    observations: list[dict] = [{}] * len(envs)
    infos: list[dict] = [{}] * len(envs)
    stream = StreamingTracker(runner, len(envs))
    previous, starting = np.full(len(envs), NO_ACTION), np.ones(len(envs), dtype=bool)
    bar = tqdm(total=episodes, desc=f"predict ({policy})", unit="ep", disable=not progress)

    def start(i: int) -> None:
        nonlocal next_episode
        if hasattr(policies[i], "reset"):
            policies[i].reset()
        observations[i], infos[i] = envs[i].reset(seed=episode_seed(seed, next_episode))
        records[i] = {"index": next_episode, "classes": np.asarray(observations[i]["object_classes"]), "estimates": [],
                      "truth": []}
        next_episode += 1

    for i in range(len(envs)):
        start(i)
    while any(r is not None for r in records):
        estimate = stream.track(stack_frames(observations), previous, starting).to_numpy()
        starting = np.zeros(len(envs), dtype=bool)
        for i, env in enumerate(envs):
            record = records[i]
            if record is None:
                continue  # this env has no episode left; its frames are ignored
            world = env.unwrapped.state
            record["estimates"].append({name: value[i, 0] for name, value in estimate.items()})
            record["truth"].append((infos[i]["agent_pose"], infos[i]["object_positions"], infos[i]["held"],
                                    [visible(world, k) for k in range(world.n_objects)]))
            if record.get("ended"):  # its last frame (after the last action) is recorded too, as in the dataset
                parts.append(_live_episode(record))
                bar.update(1)
                records[i], starting[i] = None, True
                if next_episode < episodes:
                    start(i)
                continue
            action = policies[i](observations[i], infos[i])
            observations[i], _, terminated, truncated, infos[i] = env.step(action)
            previous[i] = action
            record["ended"] = terminated or truncated
    bar.close()
    for env in envs:
        env.close()
    return concatenate(sorted(parts, key=lambda p: p.episode[0]))


def _live_episode(record: dict[str, Any]) -> Predictions:
    """A finished live episode's records -> ``Predictions`` with the objects padded to MAX_OBJECTS slots."""
    estimate = {name: np.stack([e[name] for e in record["estimates"]]) for name in record["estimates"][0]}
    poses, objects, held, seen_now = (np.asarray(column) for column in zip(*record["truth"], strict=True))
    n = objects.shape[1]
    pad = ((0, 0), (0, MAX_OBJECTS - n))
    return episode_predictions(estimate, poses, np.pad(objects, (*pad, (0, 0))), held,
                               np.pad(seen_now.astype(bool), pad),
                               np.pad(record["classes"], (0, MAX_OBJECTS - n), constant_values=-1), record["index"])
