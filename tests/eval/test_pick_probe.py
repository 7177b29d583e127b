"""The Pick probe counts each step's class once, reads the skill's own PICK probability there, and compares two
probes of the same episodes per episode."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mor.errors import ConfigError
from mor.eval.pick_probe import STEP_CLASSES, against_probe, probe_pick, step_class
from mor.eval.stats import paired_difference
from mor.policy.envs import make_task_env
from mor.policy.hierarchy import Skill
from mor.sim.config import SimConfig
from mor.sim.rules import Action, N_ACTIONS
from pipelines.evaluate import read_probe

SIM = SimConfig(n_objects=2, image_size=16)


class _Fixed(Skill):
    """A skill with the same action probabilities everywhere: PICK with probability ``pick``, else turning left
    (drawn, as the protocol plays skills)."""

    def __init__(self, pick: float) -> None:
        super().__init__(None, deterministic=False)
        self.pick = pick

    def probabilities(self, vectors: np.ndarray, masks: np.ndarray) -> np.ndarray:
        p = np.zeros((len(masks), N_ACTIONS))
        p[:, Action.PICK], p[:, Action.TURN_LEFT] = self.pick, 1.0 - self.pick
        return p


def test_a_skill_that_always_picks_ends_each_episode_at_its_first_step() -> None:
    env = make_task_env("pick", SIM, render_frames=False, horizon=10)
    firsts = []
    for episode in range(6):
        env.reset(seed=50 + episode)
        firsts.append(step_class(env))
    result = probe_pick(env, _Fixed(1.0), episodes=6, seed=50)
    assert sum(result["steps"].values()) == 6  # one step each: the PICK
    assert result["steps"] == {name: firsts.count(name) for name in STEP_CLASSES}
    assert all(p in (None, 1.0) for p in result["pick_probability"].values())
    assert result["success"] == firsts.count("target in reach") / 6 == result["target_ever_in_reach"]
    assert result["outcomes"] == [int(name == "target in reach") for name in firsts]


def test_a_skill_that_never_picks_plays_to_the_horizon() -> None:
    env = make_task_env("pick", SIM, render_frames=False, horizon=10)
    result = probe_pick(env, _Fixed(0.0), episodes=3, seed=7)
    assert sum(result["steps"].values()) == 30 and result["success"] == 0.0
    assert all(p in (None, 0.0) for p in result["pick_probability"].values())


def test_two_probes_on_the_same_episodes_are_compared_per_episode() -> None:
    better, worse = [1] * 60 + [0] * 40, [1] * 40 + [0] * 60  # the same 100 episodes: 20 turned into successes
    found = paired_difference(better, worse, resamples=2000)
    assert found["mean"] == pytest.approx(0.2) and found["verdict"] == "helps" and found["ci95"][0] > 0
    assert paired_difference(worse, better, resamples=2000)["verdict"] == "hurts"
    assert paired_difference(better, better, resamples=2000)["verdict"] == "no evidence"
    with pytest.raises(ValueError, match="100 episodes against 99"):
        paired_difference(better, worse[:99])


def test_a_probe_to_compare_against_must_have_played_the_same_episodes(tmp_path: Path) -> None:
    probe = tmp_path / "probe.json"
    probe.write_text(json.dumps({"episodes": 3, "seed": 1000, "outcomes": [1, 0, 1]}))
    assert read_probe(probe, 3, 1000)["outcomes"] == [1, 0, 1]
    for episodes, seed in ((4, 1000), (3, 7)):
        with pytest.raises(ConfigError, match="did not play these episodes"):
            read_probe(probe, episodes, seed)
    probe.write_text("[1, 2")
    with pytest.raises(ConfigError, match="not a readable probe JSON"):
        read_probe(probe, 3, 1000)


def test_a_probe_against_another_states_the_per_episode_difference_and_its_verdict() -> None:
    ours = {"success": 0.6, "outcomes": [1] * 60 + [0] * 40}
    theirs = {"success": 0.4, "outcomes": [1] * 40 + [0] * 60}
    found = against_probe(ours, theirs, "theirs.json")
    assert (found["file"], found["success"]) == ("theirs.json", 0.4)
    assert found["difference"]["mean"] == pytest.approx(0.2) and found["difference"]["verdict"] == "helps"
