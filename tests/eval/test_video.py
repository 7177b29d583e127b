"""A policy video plays every learned method the way the evaluation does, the pixel-fed baselines included."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from sb3_contrib import MaskablePPO

from mor.eval.lockstep import play_lockstep
from mor.eval.methods import METHODS
from mor.eval.protocol import decider, method_inputs, sim_of
from mor.eval.video import write_policy_video
from mor.policy.baselines import BaselineExtractor, BaselineObservation
from mor.policy.envs import make_task_env
from mor.policy.hierarchy import Skill
from mor.policy.variants import VARIANTS
from mor.policy.observations import RenderingTruthTracker
from mor.sim.arena import Arena
from mor.sim.config import SimConfig

SIM = SimConfig(n_objects=2, image_size=16)
HORIZON = 12


def _skill(task: str, variant: str, sim: SimConfig) -> Skill:
    """An untrained (random-weight) baseline skill: deterministic, so the video and the evaluation must agree."""
    env = BaselineObservation(make_task_env(task, sim, render_frames=True), VARIANTS[variant].baseline_input)
    extractor = {"encoder": "compact", "image_features": 8}
    model = MaskablePPO("MultiInputPolicy", env, seed=0, device="cpu",
                        policy_kwargs={"features_extractor_class": BaselineExtractor,
                                       "features_extractor_kwargs": extractor, "net_arch": [8]})
    return Skill(model)


@pytest.mark.parametrize("variant", [name for name, v in VARIANTS.items() if v.is_baseline])
def test_a_baselines_video_plays_the_episode_its_evaluation_plays(variant: str, tmp_path: Path) -> None:
    method = METHODS[variant]
    sim = sim_of(method, SIM)
    pick, drop = _skill("pick", variant, sim), _skill("drop", variant, sim)
    decide = decider(method, None, Arena.build(sim.arena, sim.arena_size))
    out = tmp_path / "episode.gif"
    metrics = write_policy_video(out, sim, RenderingTruthTracker(), {"pick": pick, "drop": drop}, decide,
                                 method_inputs(method), seed=5, horizon=HORIZON)
    assert iio.imread(out, index=None).shape[0] == HORIZON + 1  # a frame before each step and one after the last
    (_, played), = play_lockstep("rearrange", [("key", 5)], sim, RenderingTruthTracker(), {"pick": pick, "drop": drop},
                                 decide, method_inputs(method), n_envs=1, horizon=HORIZON)
    assert metrics == played["metrics"]


def test_the_caption_states_what_the_lnet_has_found_and_may_have_lost() -> None:
    from dataclasses import replace

    from mor.eval.video import stated_caption
    from mor.policy.belief import PoseBelief

    truth = PoseBelief.from_truth(np.zeros((1, 3)), np.zeros((1, 3, 2)))
    assert stated_caption(truth) == ""  # the truth states nothing beyond its poses
    stated = replace(truth, object_found=np.array([[1.0, 0.0, 1.0]], np.float32),
                     object_lost=np.array([[0.1, 0.2, 0.0]], np.float32))
    assert stated_caption(stated) == "\nL-Net: 0: found, lost 0.10; 1: searching; 2: found"
