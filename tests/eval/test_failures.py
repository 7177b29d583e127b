"""The failure taxonomy: every evaluation episode names how it ended, from the simulator's state."""

from __future__ import annotations

import numpy as np
import pytest

from mor.eval.failures import ENDINGS, EndingDiary, count_endings, sum_endings
from mor.policy.envs import make_task_env
from mor.sim.config import SimConfig
from mor.sim.rules import Action

SIM = SimConfig(n_objects=3, image_size=16)


def _play(task: str, actions, seed: int, horizon: int = 30) -> tuple[str, dict]:
    env = EndingDiary(make_task_env(task, SIM, render_frames=False, horizon=horizon))
    env.reset(seed=seed)
    for step in range(horizon):
        _, _, terminated, truncated, info = env.step(int(actions(step, env)))
        if terminated or truncated:
            return info["ending"], info
    raise AssertionError("the episode did not end within its horizon")


def test_a_pick_at_the_start_names_what_was_in_reach() -> None:
    endings = {_play("pick", lambda step, env: Action.PICK, seed)[0] for seed in range(40)}
    assert endings <= set(ENDINGS["pick"]) and len(endings) >= 2
    assert "PICK with nothing in reach, target never seen" in endings or "PICK with nothing in reach, target seen "\
        "earlier" in endings


def test_turning_in_place_ends_at_the_horizon_and_knows_whether_the_target_was_seen() -> None:
    endings = {_play("pick", lambda step, env: Action.TURN_LEFT, seed, horizon=40)[0] for seed in range(10)}
    assert endings <= {"horizon, target seen", "horizon, target never seen"}
    assert "horizon, target seen" in endings  # a full turn (36 x 10 degrees) sees every object not hidden


@pytest.mark.parametrize("task", ["drop", "rearrange"])
def test_every_ending_is_one_the_task_lists(task: str) -> None:
    rng = np.random.default_rng(0)
    for seed in range(10):
        ending, _ = _play(task, lambda step, env: rng.integers(0, 5), seed, horizon=60)
        assert ending in ENDINGS[task]


def test_counts_list_every_ending_and_add_up_over_runs() -> None:
    records = [{"task": "pick", "ending": "success"}, {"task": "pick", "ending": "obstructed"},
               {"task": "drop", "ending": None}]
    counts = count_endings(records)
    assert set(counts) == {"pick"} and counts["pick"]["success"] == 1 and sum(counts["pick"].values()) == 2
    assert sum_endings([counts, counts])["pick"]["obstructed"] == 2



def test_a_wrong_pick_is_told_apart_by_the_objects_colour() -> None:
    from mor.sim.catalog import object_class

    told = 0
    for seed in range(80):
        env = EndingDiary(make_task_env("pick", SIM, render_frames=False))
        env.reset(seed=seed)
        _, _, _, _, info = env.step(int(Action.PICK))
        if info["picked"] >= 0 and info["picked"] != env.unwrapped.goal_object:
            classes = env.unwrapped.layout.object_classes
            same = object_class(classes[info["picked"]]).colour == object_class(classes[env.unwrapped.goal_object]).colour
            assert info["ending"] == ("picked another object of the same colour" if same
                                      else "picked an object of another colour")
            told += 1
    assert told, "no wrong pick in 80 episodes"
