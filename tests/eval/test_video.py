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
from mor.policy.observations import RenderingTruthTracker
from mor.policy.params import ObservationParams
from mor.policy.variants import VARIANTS
from mor.sim.arena import Arena
from mor.sim.config import SimConfig

FEATURES = ObservationParams()  # the default policy.observation settings

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
    decide = decider(method, None, Arena.build(sim.arena, sim.arena_size), FEATURES)
    out = tmp_path / "episode.gif"
    metrics = write_policy_video(out, sim, RenderingTruthTracker(), {"pick": pick, "drop": drop}, decide,
                                 method_inputs(method, FEATURES), seed=5, horizon=HORIZON)
    assert iio.imread(out, index=None).shape[0] == HORIZON + 1  # a frame before each step and one after the last
    (_, played), = play_lockstep("rearrange", [("key", 5)], sim, RenderingTruthTracker(), {"pick": pick, "drop": drop},
                                 decide, method_inputs(method, FEATURES), n_envs=1, horizon=HORIZON)
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


class _Searching(RenderingTruthTracker):
    """The truth's tracker that also states a search belief (uniform over the arena grid), every object still
    searched (or, ``found``, none): what an L-Net tracker keeping the looks gives the video."""

    def __init__(self, arena: Arena, found: bool) -> None:
        super().__init__()
        self.found = found
        from mor.lnet.lost import arena_grid  # noqa: PLC0415

        self.grid = arena_grid(arena, 0.1)  # the default lnet.arena_grid_spacing (m)

    def observe(self, *args, **kwargs):  # noqa: ANN002, ANN003, ANN201
        from dataclasses import replace  # noqa: PLC0415

        from mor.policy.belief import SearchBelief  # noqa: PLC0415

        belief = super().observe(*args, **kwargs)
        search = SearchBelief(np.ones((1, len(self.grid))), self.grid, 0.01, np.array([not self.found]))
        return replace(belief, object_found=np.full((1, belief.n_objects), float(self.found), np.float32),
                       search=search)


def test_the_video_shades_the_search_belief_where_the_tracker_states_one(tmp_path: Path) -> None:
    method = METHODS["baseline_img"]
    sim = sim_of(method, SIM)
    arena = Arena.build(sim.arena, sim.arena_size)
    skills = {"pick": _skill("pick", "baseline_img", sim), "drop": _skill("drop", "baseline_img", sim)}
    frames = {}
    for name, tracker in (("found", _Searching(arena, True)), ("searching", _Searching(arena, False))):
        out = tmp_path / f"{name}.gif"
        write_policy_video(out, sim, tracker, skills, decider(method, None, arena, FEATURES),
                           method_inputs(method, FEATURES), seed=5, horizon=3)
        frames[name] = iio.imread(out, index=None)
    assert frames["found"].shape == frames["searching"].shape
    # the same legend and captions but for "found"/"searching": the shaded floor differs on most of the top view
    changed = np.any(frames["found"] != frames["searching"], axis=-1).mean(axis=(1, 2))
    assert np.all(changed > 0.05), changed
