"""The Pick probe counts each step's class once, reads the skill's own PICK probability there, and compares two
probes of the same episodes per episode."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mor.errors import ConfigError
from mor.eval.pick_probe import (
    FLOOR_IN_SIGHT_M,
    OBSTACLES,
    STEP_CLASSES,
    against_probe,
    belief_by_range,
    probe_pick,
    step_class,
    target_belief_error,
)
from mor.eval.stats import paired_difference
from mor.policy.envs import make_task_env
from mor.policy.hierarchy import Skill
from mor.sim.config import SimConfig
from mor.sim.rules import N_ACTIONS, WALL, Action, first_obstacle
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


class _Forward(Skill):
    """A skill that always MOVEs: its episodes end where the first MOVE is obstructed (or at the horizon)."""

    def __init__(self) -> None:
        super().__init__(None, deterministic=False)

    def probabilities(self, vectors: np.ndarray, masks: np.ndarray) -> np.ndarray:
        p = np.zeros((len(masks), N_ACTIONS))
        p[:, Action.MOVE] = 1.0
        return p


def test_each_obstructed_episode_is_counted_once_by_what_its_move_hit() -> None:
    env = make_task_env("pick", SIM, render_frames=False, horizon=200)
    expected = dict.fromkeys(OBSTACLES, 0)
    for episode in range(8):
        env.reset(seed=30 + episode)
        done = False
        while not done:
            before = env.unwrapped.state.copy()
            _, _, terminated, truncated, info = env.step(int(Action.MOVE))
            done = terminated or truncated
        if info["obstructed"]:
            hit = first_obstacle(before, env.unwrapped.arena, 1.0)  # from the state before the step, independently
            goal = env.unwrapped.goal_object
            expected[OBSTACLES[2] if hit == WALL else OBSTACLES[0] if hit == goal else OBSTACLES[1]] += 1
            np.testing.assert_array_equal(env.unwrapped.state.agent_pose, before.agent_pose)  # nothing moved
    result = probe_pick(env, _Forward(), episodes=8, seed=30)
    assert result["obstructed_by"] == expected
    assert sum(expected.values()) == 8  # driving straight on, each episode ends against something
    assert result["target_belief_by_range"][0]["steps"] == 0  # no belief kept: every bin empty


def test_the_belief_errors_are_grouped_by_the_targets_true_distance() -> None:
    samples = [(0.3, 0.1, 0.1, 0.05, 4.0), (0.35, 0.2, 0.2, 0.05, 16.0), (0.8, 0.0, 0.02, 0.05, 0.2), (9.0, -1, 1, 2, 1)]
    bins = belief_by_range(samples)
    assert [b["steps"] for b in bins] == [2, 0, 1, 0, 0, 1] and bins[-1]["to_m"] is None
    assert bins[0]["from_m"] == 0.0 and bins[1]["from_m"] == pytest.approx(FLOOR_IN_SIGHT_M, abs=0.005)
    assert bins[0]["median_range_error_m"] == pytest.approx(0.15) and bins[0]["inside_95_ellipse"] == 0.5
    assert bins[2]["inside_95_ellipse"] == 1.0 and "median_sigma_m" not in bins[1]


def test_the_truths_belief_holds_its_target_and_has_no_error() -> None:
    from mor.policy.envs import make_policy_env  # noqa: PLC0415
    from mor.policy.features import ObservationLayout  # noqa: PLC0415
    from mor.policy.observations import GroundTruthTracker  # noqa: PLC0415

    env = make_policy_env("pick", SIM, GroundTruthTracker(), ObservationLayout(uncertainty=False))
    samples = []
    for episode in range(20):
        env.reset(seed=episode)
        samples.append(target_belief_error(env))
    seen = [s for s in samples if s is not None]
    assert seen and all(abs(s[1]) < 1e-5 and s[2] < 1e-5 and s[3] == 0.0 and s[4] == 0.0 for s in seen)
