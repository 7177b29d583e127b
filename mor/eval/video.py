"""A policy video: one rearrangement episode, the first-person view beside a top-down view of the truth and the
policy's belief (2σ ellipses), drawn by ``mor.lnet.figures.write_estimate_gif``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mor.eval.lockstep import Decide
from mor.lnet.figures import write_estimate_gif
from mor.policy.envs import make_task_env
from mor.policy.features import Encode
from mor.policy.hierarchy import HierarchicalRearrange, Skill
from mor.policy.observations import Tracker
from mor.sim.config import SimConfig

_JITTER = 1e-6  # m²: the ground truth's zero covariances drawn as points


def _tril(covariance: np.ndarray) -> np.ndarray:
    return np.linalg.cholesky(covariance + _JITTER * np.eye(2))


def write_policy_video(path: Path, sim: SimConfig, tracker: Tracker, pick: Skill, drop: Skill, decide: Decide,
                       uncertainty: bool, seed: int, fps: int = 8, horizon: int | None = None,
                       encode: Encode | None = None) -> dict[str, float]:
    """Play one ``MOR/Rearrange-v0`` episode (reset seed ``seed``; ``horizon`` caps its steps) with the hierarchy,
    its skills fed by ``encode`` (``HierarchicalRearrange``), and write it to ``path`` (.mp4 or .gif); returns the
    episode's metrics."""
    env_kwargs = {} if horizon is None else {"horizon": horizon}
    env = HierarchicalRearrange(make_task_env("decision", sim, True, **env_kwargs), tracker, pick, drop, uncertainty,
                                encode)
    frames: dict[str, list] = {name: [] for name in ("images", "poses", "objects", "agent_mean", "agent_tril",
                                                     "heading", "kappa", "object_mean", "object_tril")}

    def record(hierarchy: HierarchicalRearrange) -> None:
        state, belief = hierarchy.env.unwrapped.state, hierarchy.belief
        frames["images"].append(hierarchy.observation["image"])
        frames["poses"].append(state.agent_pose.copy())
        frames["objects"].append(state.object_positions())
        frames["agent_mean"].append(belief.agent_mean[0])
        frames["agent_tril"].append(_tril(belief.agent_cov[0]))
        frames["heading"].append(belief.heading[0])
        frames["kappa"].append(1.0 / max(float(belief.heading_var[0]), _JITTER))
        frames["object_mean"].append(belief.object_mean[0])
        frames["object_tril"].append(_tril(belief.object_cov[0]))

    env.on_step = record
    try:
        env.reset(seed=seed)
        while True:
            choice = int(decide(env.belief, np.array([env.held]), env.targets[None], np.array([env.chain.index]))[0])
            _, _, terminated, truncated, info = env.step(choice)
            if terminated or truncated:
                break
        truth = {"agent_poses": np.stack(frames["poses"]), "object_positions": np.stack(frames["objects"]),
                 "object_classes": env.env.unwrapped.layout.object_classes}
        estimate = {key: np.stack(frames[key]) for key in ("agent_mean", "agent_tril", "heading", "kappa",
                                                           "object_mean", "object_tril")}
        write_estimate_gif(path, env.env.unwrapped.arena, truth, estimate, np.stack(frames["images"]), fps=fps)
    finally:
        env.close()
    return dict(info["metrics"])
