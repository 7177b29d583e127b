"""The batched ground-truth VecEnv (mor.policy.batched_env) against the per-env path it replaces: a DummyVecEnv of
PoseObservation(MOR env, GroundTruthTracker()) envs with the same seeds and actions."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from sb3_contrib import MaskablePPO
from sb3_contrib.common.maskable.utils import get_action_masks, is_masking_supported
from stable_baselines3.common.vec_env import DummyVecEnv

from mor.errors import ConfigError
from mor.policy.batched_env import BatchedPoseVecEnv
from mor.policy.envs import make_training_env
from mor.policy.features import ObservationLayout, feature_names
from mor.policy.observations import GroundTruthTracker, PoseObservation
from mor.policy.params import ObservationParams, PPOParams
from mor.policy.variants import GROUND_TRUTH
from mor.sim.config import SimConfig
from mor.sim.rules import N_ACTIONS

FEATURES = ObservationParams()  # the default policy.observation settings
LAYOUT = ObservationLayout()  # gt_pose's layout with them

ENV_IDS = {"pick": "MOR/Pick-v0", "drop": "MOR/Drop-v0"}
TOLERANCE = {"rtol": 1e-6, "atol": 1e-6}  # float32


def _per_env(task: str, sim: SimConfig, n_envs: int, uncertainty: bool, horizon: int | None) -> DummyVecEnv:
    return DummyVecEnv([lambda: PoseObservation(
        gym.make(ENV_IDS[task], render_frames=False, horizon=horizon, **sim.model_dump()).unwrapped,
        GroundTruthTracker(), ObservationLayout(uncertainty))] * n_envs)


def _one_line(error: pytest.ExceptionInfo, *names: str) -> None:
    message = str(error.value)
    assert message and "\n" not in message, message
    assert all(name in message for name in names), message


@pytest.mark.parametrize(
    ("task", "shape", "n_objects", "uncertainty", "horizon"),
    [("pick", "square", 3, True, None), ("drop", "square", 3, True, 15), ("pick", "polygon", 5, False, 15),
     ("drop", "polygon", 2, False, None)],
)
def test_same_seeds_and_actions_give_the_per_env_steps(task, shape, n_objects, uncertainty, horizon) -> None:
    """Observations, rewards, dones, masks and the infos training reads, step by step, through episode ends (PICK,
    DROP, obstructions, truncations) and a re-seeding as ``mor.policy.train`` does at each chunk."""
    sim, n_envs = SimConfig(arena=shape, n_objects=n_objects), 6
    reference = _per_env(task, sim, n_envs, uncertainty, horizon)
    batched = BatchedPoseVecEnv(task, sim, n_envs, ObservationLayout(uncertainty), horizon)
    assert batched.observation_space == reference.observation_space
    assert batched.observation_space.shape == (len(feature_names(task, n_objects, ObservationLayout(uncertainty))),)
    rng = np.random.default_rng(0)
    ends = {"terminated": 0, "truncated": 0}
    for seed in (3, 1000):
        reference.seed(seed)
        batched.seed(seed)
        np.testing.assert_allclose(batched.reset(), reference.reset(), **TOLERANCE)
        for _ in range(300):
            masks = get_action_masks(batched)
            np.testing.assert_array_equal(masks, get_action_masks(reference))
            actions = rng.choice(N_ACTIONS, size=n_envs, p=[0.4, 0.25, 0.25, 0.05, 0.05])  # masked ones too
            ours, theirs = batched.step(actions), reference.step(actions)
            for mine, expected in zip(ours[:2], theirs[:2], strict=True):
                np.testing.assert_allclose(mine, expected, **TOLERANCE)
            np.testing.assert_array_equal(ours[2], theirs[2])
            assert ours[1].dtype == np.float32 and ours[0].dtype == np.float32
            for info, expected in zip(ours[3], theirs[3], strict=True):
                if "terminal_observation" not in expected:
                    assert info == {}
                    continue
                np.testing.assert_allclose(info["terminal_observation"], expected["terminal_observation"], **TOLERANCE)
                assert info["metrics"] == expected["metrics"]
                assert info["TimeLimit.truncated"] == expected["TimeLimit.truncated"]
                ends["truncated" if info["TimeLimit.truncated"] else "terminated"] += 1
    assert ends["terminated"] > 0 and (horizon is None or ends["truncated"] > 0)


def test_episode_info_counts_return_and_length() -> None:
    env = BatchedPoseVecEnv("pick", SimConfig(), 4, LAYOUT)
    env.seed(0)
    env.reset()
    returns, lengths = np.zeros(4), np.zeros(4, int)
    for _ in range(200):
        _, rewards, dones, infos = env.step(np.zeros(4, int))  # MOVE until obstructed or truncated
        returns += rewards
        lengths += 1
        for i in np.flatnonzero(dones):
            assert infos[i]["episode"]["l"] == lengths[i]
            assert infos[i]["episode"]["r"] == pytest.approx(returns[i], abs=1e-4)
            returns[i], lengths[i] = 0.0, 0


def test_maskable_ppo_learns_on_it_unchanged() -> None:
    env = BatchedPoseVecEnv("drop", SimConfig(n_objects=2), 8, LAYOUT)
    assert is_masking_supported(env)
    assert get_action_masks(env).shape == (8, N_ACTIONS)
    model = MaskablePPO("MlpPolicy", env, seed=0, device="cpu", n_steps=16, batch_size=32, n_epochs=1,
                        policy_kwargs={"net_arch": [16, 16]})
    model.learn(256)
    assert model.num_timesteps == 256


def test_training_env_is_batched_when_asked() -> None:
    params = PPOParams(n_envs=3, vec_env="batched")
    env = make_training_env("pick", GROUND_TRUTH, SimConfig(), params, FEATURES)
    assert isinstance(env, BatchedPoseVecEnv) and env.num_envs == 3
    assert isinstance(make_training_env("pick", GROUND_TRUTH, SimConfig(), PPOParams(n_envs=2), FEATURES), DummyVecEnv)


@pytest.mark.parametrize("n_envs", [0, -2, 2.5, True])
def test_fewer_than_one_env_is_one_line(n_envs) -> None:
    with pytest.raises(ConfigError) as error:
        BatchedPoseVecEnv("pick", SimConfig(), n_envs, LAYOUT)
    _one_line(error, "n_envs")


def test_a_task_without_a_batched_env_is_one_line() -> None:
    with pytest.raises(ConfigError) as error:
        BatchedPoseVecEnv("decision", SimConfig(), 2, LAYOUT)
    _one_line(error, "decision", "pick", "drop")


@pytest.mark.parametrize("actions", [np.zeros(3, int), np.zeros((4, 1), int), np.zeros(4), np.zeros(4, bool),
                                     np.array([0, 1, 5, 0]), np.array([0, -1, 2, 0]), [0, 1, 2, 3.5]])
def test_bad_actions_are_one_line(actions) -> None:
    env = BatchedPoseVecEnv("pick", SimConfig(), 4, LAYOUT)
    env.seed(0)
    env.reset()
    with pytest.raises(ValueError) as error:
        env.step(actions)
    _one_line(error, "actions", "(4,)")


def test_reset_options_are_refused() -> None:
    env = BatchedPoseVecEnv("pick", SimConfig(), 2, LAYOUT)
    env.set_options({"n_objects": 2})
    with pytest.raises(ConfigError) as error:
        env.reset()
    _one_line(error, "options")


def test_training_on_it_gives_the_weights_and_log_of_the_per_env_path(tmp_path) -> None:
    """The same PPO run (chunks, seeded episode starts, checkpoints) on both paths: the same weights and log."""
    import torch

    from mor.policy.policy_file import load_policy_file
    from mor.policy.signature import PolicySignature
    from mor.policy.train import train_policy

    sim = SimConfig(n_objects=2, image_size=16)
    runs = {}
    for vec_env in ("dummy", "batched"):
        params = PPOParams(steps=192, n_envs=4, n_steps=16, batch_size=32, n_epochs=2, hidden=[16, 16],
                           checkpoint_every=64, vec_env=vec_env)
        out = tmp_path / vec_env
        train_policy(lambda p=params: make_training_env("pick", GROUND_TRUTH, sim, p, FEATURES), params,
                     PolicySignature.of("pick", GROUND_TRUTH, 2, "square", None,
                                        FEATURES), out, 0, vec_env, progress=False)
        runs[vec_env] = (load_policy_file(out / "policy.pth").state_dict(), (out / "log.csv").read_text())
    (dummy_weights, dummy_log), (batched_weights, batched_log) = runs["dummy"], runs["batched"]
    untimed = lambda log: [[v for k, v in zip(log.splitlines()[0].split(","), line.split(","), strict=True)  # noqa: E731
                            if k not in ("wall_seconds", "steps_per_second")] for line in log.splitlines()]
    assert untimed(dummy_log) == untimed(batched_log)
    assert all(torch.equal(dummy_weights[key], batched_weights[key]) for key in dummy_weights)
