"""The decision semi-MDP chains the skills as documented; training resumes; checkpoints are checked."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from mor.errors import ConfigError
from mor.policy.envs import make_policy_env, make_training_env
from mor.policy.features import ObservationLayout
from mor.policy.hierarchy import HierarchicalRearrange, nearest_unfixed, skill_mask
from mor.policy.observations import GroundTruthTracker
from mor.policy.params import ObservationParams, PPOParams
from mor.policy.signature import PolicySignature, check_signature, write_signature
from mor.policy.train import train_policy
from mor.policy.variants import VARIANTS
from mor.sim.config import SimConfig
from mor.sim.oracle import Oracle
from mor.sim.rules import Action, WorldState

FEATURES = ObservationParams()  # the default policy.observation settings

SIM = SimConfig(n_objects=2, image_size=16)
TINY_PPO = PPOParams(steps=64, n_envs=2, n_steps=16, batch_size=16, n_epochs=1, hidden=[8, 8], checkpoint_every=32)


class OracleSkill:
    """A 'skill' that plays the scripted oracle on the env's true state (to test the hierarchy's mechanics)."""

    def __init__(self, task: str) -> None:
        self.task, self.env, self.goal, self.calls = task, None, None, []

    def act_batch(self, inputs: np.ndarray, masks: np.ndarray, rngs: list[np.random.Generator] | None = None
                  ) -> np.ndarray:
        """The oracle's action for the one env the hierarchy plays (``Skill.act_batch`` with k = 1)."""
        mask = masks[0]
        base = self.env.env.unwrapped
        state = WorldState(base.state.agent_pose.copy(), base.state.object_positions(), base.state.held)
        oracle = Oracle(base.arena, base.noise)
        action = (oracle.pick(state, self.goal) if self.task == "pick"
                  else oracle.drop(state, base.layout.target_positions[state.held]))
        self.calls.append(action)
        assert mask[action], f"{self.task} skill took a masked action"
        return np.array([action])


def test_skill_masks_remove_what_the_subtasks_remove() -> None:
    assert not skill_mask("pick")[Action.DROP] and skill_mask("pick")[Action.PICK]
    assert not skill_mask("drop")[Action.PICK] and skill_mask("drop")[Action.DROP]


def test_one_decision_runs_the_pick_skill_then_the_drop_skill() -> None:
    pick, drop = OracleSkill("pick"), OracleSkill("drop")
    env = make_policy_env("decision", SIM, GroundTruthTracker(), ObservationLayout(), (pick, drop))
    assert isinstance(env, HierarchicalRearrange)
    pick.env = drop.env = env
    env.reset(seed=1)
    pick.goal = 0
    _, reward, terminated, truncated, info = env.step(0)
    assert pick.calls[-1] == Action.PICK and drop.calls[-1] == Action.DROP
    assert info["primitive_steps"] == len(pick.calls) + len(drop.calls)
    assert reward > 0  # object 0 was placed at its target (Eq. 2 pays +10)
    env.close()


def test_the_nearest_rule_with_oracle_skills_solves_the_task() -> None:
    pick, drop = OracleSkill("pick"), OracleSkill("drop")
    env = make_policy_env("decision", SIM, GroundTruthTracker(), ObservationLayout(), (pick, drop))
    pick.env = drop.env = env
    solved = 0
    for seed in range(3):
        env.reset(seed=seed)
        while True:
            pick.goal = nearest_unfixed(env.belief, env.slot.targets)
            _, _, terminated, truncated, info = env.step(pick.goal)
            if terminated or truncated:
                solved += info["metrics"]["success"]
                break
    assert solved == 3
    env.close()


def test_training_writes_its_outputs_and_resumes_from_the_checkpoint(tmp_path: Path) -> None:
    signature = PolicySignature.of("pick", VARIANTS["gt_pose"], 2, "square", None, FEATURES)
    make = lambda params: lambda: make_training_env("pick", VARIANTS["gt_pose"], SIM, params, FEATURES)  # noqa: E731
    first = train_policy(make(TINY_PPO), TINY_PPO, signature, tmp_path, 0, "pick", progress=False)
    assert first["steps"] == 64
    for name in ("checkpoint.pt", "policy.pth", "meta.json", "log.csv", "learning_curve.png", "summary.json"):
        assert (tmp_path / name).is_file(), name
    longer = TINY_PPO.model_copy(update={"steps": 128})
    second = train_policy(make(longer), longer, signature, tmp_path, 0, "pick", progress=False)
    assert second["steps"] == 128
    with (tmp_path / "log.csv").open() as handle:
        steps = [int(row["steps"]) for row in csv.DictReader(handle)]
    assert steps == sorted(steps) and steps[-1] == 128 and steps[0] < 64  # appended, not restarted
    other = PolicySignature.of("pick", VARIANTS["gt_pose"], 2, "polygon", None,
                               FEATURES)  # e.g. another world or another L-Net
    with pytest.raises(ConfigError, match=r"checkpoint.pt: not resumed.*arena='square' but this run needs 'polygon'"):
        train_policy(make(longer), longer, other, tmp_path, 0, "pick", progress=False)


def test_a_policy_of_another_layout_is_one_clear_error(tmp_path: Path) -> None:
    write_signature(tmp_path / "meta.json", PolicySignature.of("pick", VARIANTS["gt_pose"], 3, "square", None,
                                                               FEATURES))
    with pytest.raises(ConfigError, match=r"n_objects=3 but this run needs 2"):
        check_signature(tmp_path / "meta.json", PolicySignature.of("pick", VARIANTS["gt_pose"], 2, "square", None,
                                                                   FEATURES))
    write_signature(tmp_path / "meta.json", PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "abc", FEATURES))
    with pytest.raises(ConfigError, match=r"lnet_version='abc' but this run needs 'def'"):
        check_signature(tmp_path / "meta.json", PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "def",
                                                                   FEATURES))
    assert json.loads((tmp_path / "meta.json").read_text())["variant"] == "lnet"


def test_the_policy_benchmark_measures_every_path_in_one_run() -> None:
    import torch

    from mor.lnet.calibration_file import FittedCalibration
    from mor.lnet.model import LNet
    from mor.lnet.params import LNetConfig
    from mor.lnet.runtime import LNetRunner
    from mor.policy.bench import bench_policy

    torch.manual_seed(0)
    runner = LNetRunner(LNet(LNetConfig(feature_dim=16, mlp_hidden=16, lstm_hidden=16)), FittedCalibration(), 16,
                        "test")
    in_two_workers = TINY_PPO.model_copy(update={"env_workers": 2})  # training's rendered path, and in process
    result = bench_policy(SIM, in_two_workers, FEATURES, runner, seconds=0.2, repeats=1, progress=False)
    assert set(result["steps_per_second"]) == {f"{kind}_{name}" for kind in ("env", "ppo") for name in (
        "gt_pose", "gt_pose_per_env", "lnet", "lnet_in_process")} | {"env_gt_pose_n64"}
    assert result["env_workers"] == 2
    assert set(result["batched_over_per_env"]) == {"env", "ppo"}
    assert all(rate > 0 for rate in result["steps_per_second"].values())


def test_the_policy_benchmark_without_an_lnet_measures_the_ground_truths_paths_only() -> None:
    from mor.policy.bench import bench_policy

    result = bench_policy(SIM, TINY_PPO, FEATURES, None, seconds=0.2, repeats=1, progress=False)
    assert set(result["steps_per_second"]) == {f"{kind}_{name}" for kind in ("env", "ppo")
                                               for name in ("gt_pose", "gt_pose_per_env")} | {"env_gt_pose_n64"}
    assert result["lnet_encoder"] is None and "ppo_lnet" not in result["targets"]
    assert (result["hidden"], result["n_envs"]) == (list(TINY_PPO.hidden), TINY_PPO.n_envs)
