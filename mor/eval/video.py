"""A policy video: one rearrangement episode played by the hierarchy (``SkillHierarchy``), the first-person view
beside a top-down view of the truth and the policy's belief (2σ ellipses, ``mor.lnet.figures.write_estimate_gif``;
for an L-Net tracker that keeps the looks, the search belief of the objects not found yet shaded on the floor),
annotated with what the policy does: the targets, the running skill and its object, the action, the held object,
and at the end why the episode ended."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from tqdm import tqdm

from mor.lnet.figures import write_estimate_gif
from mor.policy.envs import make_task_env
from mor.policy.features import Encode
from mor.policy.belief import PoseBelief
from mor.policy.hierarchy import Decide, Skill, SkillHierarchy
from mor.policy.observations import BatchTracker
from mor.sim.catalog import object_class
from mor.sim.config import SimConfig
from mor.sim.rules import Action

_JITTER = 1e-6  # m²: the ground truth's zero covariances drawn as points
_LEGEND = [Line2D([], [], marker="*", color="black", linestyle="", label="truth (agent, objects)"),
           Line2D([], [], marker="o", color="grey", linestyle="", label="belief: mean and 2σ"),
           Line2D([], [], marker="X", color="black", linestyle="", markerfacecolor="white", label="target")]
_SEARCH_LEGEND = Line2D([], [], marker="s", color=plt.get_cmap("Purples")(0.7), linestyle="",
                        label="search belief (not found yet)")


def _tril(covariance: np.ndarray) -> np.ndarray:
    return np.linalg.cholesky(covariance + _JITTER * np.eye(2))


def end_reason(info: dict[str, Any], truncated: bool) -> str:
    """Why a full-task episode ended, in words."""
    if info["metrics"]["success"]:
        return "every object placed"
    if truncated:
        return "out of steps (horizon)"
    return "obstructed" if info.get("obstructed") else "ended"


def stated_caption(belief: PoseBelief) -> str:
    """The stated belief beyond the ellipses, as a caption line: each object found by the L-Net or still searched,
    and its probability of being lost; "" for a belief that states none (the truth's)."""
    if belief.object_found is None:
        return ""
    lost = belief.object_lost[0] if belief.object_lost is not None else np.zeros(belief.n_objects)
    parts = [f"{k}: {'found' if found else 'searching'}" + (f", lost {p:.2f}" if found and p > 0 else "")
             for k, (found, p) in enumerate(zip(belief.object_found[0] > 0.5, lost, strict=True))]
    return "\nL-Net: " + "; ".join(parts)


class _Recorder:
    """Each primitive step's frame, truth, belief and the hierarchy's state, for the video."""

    def __init__(self) -> None:
        self.frames: dict[str, list] = {name: [] for name in (
            "images", "poses", "objects", "agent_mean", "agent_tril", "heading", "kappa", "object_mean",
            "object_tril")}
        self.captions: list[str] = []
        self.search: list[np.ndarray | None] = []  # per step the search belief's density (M,) per m², or None
        self.grid: np.ndarray | None = None  # its grid (M, 2) m, where the tracker states a search belief

    def __call__(self, hierarchy: SkillHierarchy) -> None:
        slot, belief = hierarchy.slots[0], hierarchy.belief
        if belief.search is not None:
            self.grid = belief.search.grid
        searching = belief.object_found is not None and not belief.object_found[0].all()
        self.search.append(belief.search.density[0] if belief.search is not None and searching else None)
        state = slot.env.unwrapped.state
        self.frames["images"].append(slot.observation["image"])
        self.frames["poses"].append(state.agent_pose.copy())
        self.frames["objects"].append(state.object_positions())
        self.frames["agent_mean"].append(belief.agent_mean[0])
        self.frames["agent_tril"].append(_tril(belief.agent_cov[0]))
        self.frames["heading"].append(belief.heading[0])
        self.frames["kappa"].append(1.0 / max(float(belief.heading_var[0]), _JITTER))
        self.frames["object_mean"].append(belief.object_mean[0])
        self.frames["object_tril"].append(_tril(belief.object_cov[0]))
        n = len(slot.targets)
        held = object_class(int(slot.observation["object_classes"][slot.held])).name if slot.held < n else "nothing"
        action = Action(slot.previous).name if slot.previous >= 0 else "–"
        skill = f"{slot.chain.task} object {slot.chain.index}" if slot.chain.task and not slot.done else "–"
        self.captions.append(f"step {slot.steps}  last action {action}\nskill: {skill}  holding: {held}"
                             + stated_caption(belief))


def write_policy_video(path: Path, sim: SimConfig, tracker: BatchTracker, skills: dict[str, Skill], decide: Decide,
                       encode: Encode, seed: int, fps: int = 8, horizon: int | None = None) -> dict[str, float]:
    """Play one ``MOR/Rearrange-v0`` episode (reset seed ``seed``; ``horizon`` caps its steps) with the hierarchy
    (``tracker`` keeps one environment; the skills read ``encode``'s inputs) and write it to ``path`` (.mp4 or
    .gif), with a progress bar over the steps and then the frames; returns the episode's metrics."""
    env_kwargs = {} if horizon is None else {"horizon": horizon}
    env = make_task_env("rearrange", sim, True, **env_kwargs)
    hierarchy, record = SkillHierarchy([env], tracker, skills, encode, "decision"), _Recorder()
    bar = tqdm(total=env.horizon, desc="playing", unit="step", dynamic_ncols=True)

    def on_step(h: SkillHierarchy) -> None:
        record(h)
        bar.update(1)

    try:
        (_, outcome), = hierarchy.play([(None, seed)], decide, on_step)
        bar.total = bar.n
        bar.close()
        slot = hierarchy.slots[0]
        record(hierarchy)  # the world after the last step (the belief drawn is the one before it)
        record.captions[-1] += f"\nended: {end_reason(slot.info, slot.truncated)}"
        layout = env.unwrapped.layout
        frames = record.frames
        truth = {"agent_poses": np.stack(frames["poses"]), "object_positions": np.stack(frames["objects"]),
                 "object_classes": layout.object_classes}
        estimate = {key: np.stack(frames[key]) for key in ("agent_mean", "agent_tril", "heading", "kappa",
                                                           "object_mean", "object_tril")}

        grid = record.grid
        peak = max((float(d.max()) for d in record.search if d is not None), default=0.0)

        def annotate(ax: Axes, t: int) -> None:
            density = record.search[t]
            if density is not None and peak > 0:  # one colour scale over the episode: darker, more likely there
                ax.scatter(*grid.T, c=density, cmap="Purples", vmin=0.0, vmax=peak, marker="s", s=6,
                           alpha=0.6, linewidths=0, zorder=0)
            for k, target in enumerate(layout.target_positions):
                ax.plot(*target, "X", color=object_class(int(layout.object_classes[k])).rgb, markeredgecolor="black",
                        markersize=8, zorder=6)
            ax.set_title("", loc="center")
            ax.set_title(record.captions[t], fontsize=7, loc="left")
            handles = _LEGEND + ([_SEARCH_LEGEND] if grid is not None else [])
            ax.legend(handles=handles, fontsize=6, loc="lower left", framealpha=0.8)

        write_estimate_gif(path, env.unwrapped.arena, truth, estimate, np.stack(frames["images"]), fps=fps,
                           annotate=annotate, progress="writing")
    finally:
        env.close()
    return outcome["metrics"]
