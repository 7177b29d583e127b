"""Lockstep evaluation plays exactly the episodes that one-at-a-time play gives, for gt_pose and the L-Net."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sb3_contrib import MaskablePPO

from mor.eval.failures import ENDINGS
from mor.eval.lockstep import play_lockstep
from mor.eval.methods import METHODS, TrainedPolicies
from mor.eval.protocol import decider
from mor.lnet.calibration_file import FittedCalibration
from mor.lnet.model import LNet
from mor.lnet.params import LNetConfig
from mor.lnet.runtime import LNetRunner
from mor.policy.envs import make_policy_env
from mor.policy.features import ObservationLayout, pose_inputs
from mor.policy.hierarchy import Skill
from mor.policy.lnet_tracking import LNetBatchTracker, LNetTracker
from mor.policy.observations import GroundTruthBatchTracker, GroundTruthTracker
from mor.policy.params import ObservationParams
from mor.sim.arena import Arena
from mor.sim.config import SimConfig

FEATURES = ObservationParams()  # the default policy.observation settings

SIM = SimConfig(n_objects=2, image_size=16)
ARENA = Arena.build("square", 6.0)


def _skill(task: str, seed: int) -> Skill:
    """An untrained (random-weight) policy: deterministic, so any two players must agree on every action."""
    env = make_policy_env(task, SIM, GroundTruthTracker(), ObservationLayout())
    return Skill(MaskablePPO("MlpPolicy", env, seed=seed, device="cpu", policy_kwargs={"net_arch": [8, 8]}))


class HashSkill:
    """A deterministic stand-in policy whose action hashes the observation, so it ends episodes within a few steps
    and any difference in the belief (e.g. a tracker state leaking between episodes) changes what it does."""

    def __init__(self, final_action: int) -> None:
        self.final_action = final_action

    def act_batch(self, vectors: np.ndarray, masks: np.ndarray, rngs=None) -> np.ndarray:
        codes = np.floor(np.abs(vectors).sum(-1) * 1000).astype(int)
        return np.where(codes % 5 == 0, self.final_action, codes % 3)

    def act(self, vector: np.ndarray, mask: np.ndarray, rng=None) -> int:
        return int(self.act_batch(vector[None], mask[None])[0])


@pytest.fixture(scope="module")
def quick() -> TrainedPolicies:
    return TrainedPolicies(HashSkill(3), HashSkill(4), None)


@pytest.fixture(scope="module")
def policies() -> TrainedPolicies:
    pick, drop = _skill("pick", 0), _skill("drop", 1)
    decision_env = make_policy_env("decision", SIM, GroundTruthTracker(), ObservationLayout(), (pick, drop))
    decision = Skill(MaskablePPO("MlpPolicy", decision_env, seed=2, device="cpu", policy_kwargs={"net_arch": [8]}))
    return TrainedPolicies(pick, drop, decision)


HORIZON = 40  # short episodes keep the test fast; the rules under test do not depend on the horizon


def _one_at_a_time(task: str, seed: int, tracker, policies: TrainedPolicies, method: str) -> dict:
    if task != "rearrange":
        env = make_policy_env(task, SIM, tracker, ObservationLayout(), horizon=HORIZON)
        skill = policies.pick if task == "pick" else policies.drop
        rng = np.random.default_rng(seed)  # as the lockstep player seeds each episode's draws
        act = lambda vector: skill.act(vector, env.action_masks(), rng)  # noqa: E731
    else:
        env = make_policy_env("decision", SIM, tracker, ObservationLayout(), (policies.pick, policies.drop),
                              horizon=HORIZON)
        decide = decider(METHODS[method], policies, ARENA, FEATURES)
        act = lambda vector: int(decide(env.belief, np.array([env.slot.held]), env.slot.targets[None],
                                            np.array([env.slot.chain.index]))[0])  # noqa: E731
    vector, _ = env.reset(seed=seed)
    total, steps = 0.0, 0
    while True:
        vector, reward, terminated, truncated, info = env.step(act(vector))
        total, steps = total + reward, steps + info.get("primitive_steps", 1)
        if terminated or truncated:
            env.close()
            return {"metrics": info["metrics"], "steps": steps}


@pytest.mark.parametrize(("task", "method"), [("pick", "gt_pose"), ("drop", "gt_pose"), ("rearrange", "gt_pose"),
                                              ("rearrange", "gt_pose_nearest_rule")])
@pytest.mark.parametrize("deterministic", [True, False])
def test_lockstep_equals_one_episode_at_a_time(task: str, method: str, deterministic: bool, policies: TrainedPolicies,
                                               quick: TrainedPolicies) -> None:
    for skill in (policies.pick, policies.drop):
        skill.deterministic = deterministic  # sampled skills draw from each episode's own generator
    if task == "rearrange":  # keep the full task short: quick skills, the real decision policy or rule
        policies = TrainedPolicies(quick.pick, quick.drop, policies.decision)
    keys = [((task, 0, e), 100 + e) for e in range(3)]
    skills = {"pick": policies.pick, "drop": policies.drop}
    played = dict(play_lockstep(task, keys, SIM, GroundTruthBatchTracker(), skills,
                                decider(METHODS[method], policies, ARENA,
                                        FEATURES), pose_inputs(ObservationLayout()), n_envs=2,
                                horizon=HORIZON))
    for key, seed in keys:
        alone = _one_at_a_time(task, seed, GroundTruthTracker(), policies, method)
        assert played[key]["metrics"] == alone["metrics"] and played[key]["steps"] == alone["steps"], key


def test_lockstep_with_the_lnet_equals_one_tracker_per_episode(quick: TrainedPolicies) -> None:
    torch.manual_seed(0)
    runner = LNetRunner(LNet(LNetConfig(feature_dim=16, mlp_hidden=16, lstm_hidden=16)), FittedCalibration(), 16,
                        "test")
    keys = [(("rearrange", 0, e), 200 + e) for e in range(3)]
    played = dict(play_lockstep("rearrange", keys, SIM, LNetBatchTracker(runner, 2),
                                {"pick": quick.pick, "drop": quick.drop}, decider(METHODS["lnet_nearest_rule"], quick,
                                                                                  ARENA, FEATURES),
                                pose_inputs(ObservationLayout()), n_envs=2, horizon=HORIZON))
    for key, seed in keys:
        alone = _one_at_a_time("rearrange", seed, LNetTracker(runner), quick, "lnet_nearest_rule")
        assert played[key] == {**alone, "return": played[key]["return"], "ending": played[key]["ending"]}, key
        assert played[key]["ending"] in ENDINGS["rearrange"]
