"""The Pick probe counts each step's class once and reads the skill's own PICK probability there."""

from __future__ import annotations

import numpy as np

from mor.eval.pick_probe import STEP_CLASSES, probe_pick, step_class
from mor.policy.envs import make_task_env
from mor.policy.hierarchy import Skill
from mor.sim.config import SimConfig
from mor.sim.rules import Action, N_ACTIONS

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


def test_a_skill_that_never_picks_plays_to_the_horizon() -> None:
    env = make_task_env("pick", SIM, render_frames=False, horizon=10)
    result = probe_pick(env, _Fixed(0.0), episodes=3, seed=7)
    assert sum(result["steps"].values()) == 30 and result["success"] == 0.0
    assert all(p in (None, 0.0) for p in result["pick_probability"].values())
