"""The end-to-end CNN baselines: what each input variant sees, the encoder, and the object-order decision."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3.common.preprocessing import preprocess_obs

from mor.data.exploration import ExplorationParams
from mor.errors import ConfigError
from mor.eval.methods import METHODS
from mor.eval.protocol import decider, sim_of
from mor.policy.baselines import (BaselineExtractor, BaselineObservation, baseline_extractor, baseline_inputs,
                                  load_pretrained_encoder)
from mor.policy.envs import make_task_env
from mor.policy.frame_encoder import frame_autoencoder, pretrain_autoencoder, sample_frames, save_frame_autoencoder
from mor.policy.params import BaselineParams, EncoderPretrainParams, ObservationParams
from mor.policy.signature import PolicySignature
from mor.policy.variants import VARIANTS
from mor.sim.config import SimConfig
from mor.sim.geometry import bearing

FEATURES = ObservationParams()  # the default policy.observation settings

SIM = SimConfig(n_objects=3, image_size=32)

BASELINES = [v for v in VARIANTS.values() if v.is_baseline]


def test_pick_sees_the_frame_and_the_target_class_only() -> None:
    env = BaselineObservation(make_task_env("pick", SIM, render_frames=True), "delta_pose")
    observation, _ = env.reset(seed=3)
    raw = env.unwrapped
    assert set(observation) == {"image", "goal_class"}
    assert observation["image"].shape == (3, 32, 32) and observation["image"].dtype == np.uint8
    assert observation["goal_class"] == raw.layout.object_classes[raw.goal_object]
    assert env.observation_space.contains(observation)
    env.close()


def test_delta_pose_is_the_targets_distance_and_bearing_from_the_true_pose() -> None:
    env = BaselineObservation(make_task_env("drop", SIM, render_frames=True), "delta_pose")
    observation, info = env.reset(seed=5)
    for action in (0, 1, 0):
        observation, *_, info = env.step(action)
    target, pose = np.asarray(observation["goal_position"]), info["agent_pose"]
    distance, cos, sin = observation["delta_pose"]
    assert distance == pytest.approx(np.linalg.norm(target - pose[:2]), abs=1e-5)
    assert np.arctan2(sin, cos) == pytest.approx(bearing(pose, target), abs=1e-5)
    assert observation["goal_class"] == env.unwrapped.layout.object_classes[info["held"]]
    assert env.observation_space.contains(observation)
    env.close()


def test_img_drop_has_no_relative_pose_and_landmark_shows_the_targets() -> None:
    env = BaselineObservation(make_task_env("drop", SIM, render_frames=True), "img")
    assert set(env.observation_space.spaces) == {"image", "goal_class", "goal_position"}
    env.close()
    assert sim_of(METHODS["baseline_landmark"], SIM).landmark and not sim_of(METHODS["baseline_img"], SIM).landmark


def test_baselines_refuse_unrendered_envs() -> None:
    with pytest.raises(TypeError, match="rendered"):
        BaselineObservation(make_task_env("pick", SIM, render_frames=False), "img")


@pytest.mark.parametrize("encoder", ["compact", "nature_cnn", "resnet18", "resnet50"])
def test_the_extractor_concatenates_image_features_and_the_one_hot_goal(encoder: str) -> None:
    sim = SimConfig(n_objects=3, image_size=48)  # NatureCNN needs frames of at least 36 pixels
    env = BaselineObservation(make_task_env("drop", sim, render_frames=True), "delta_pose")
    observation, _ = env.reset(seed=0)
    extractor = BaselineExtractor(env.observation_space, encoder, image_features=32)
    batch = {key: torch.as_tensor(np.asarray(value)[None]) for key, value in observation.items()}
    features = extractor(preprocess_obs(batch, env.observation_space))
    assert features.shape == (1, 32 + 24 + 2 + 3) == (1, extractor.features_dim)
    env.close()


@pytest.mark.parametrize("encoder", ["compact", "nature_cnn", "resnet18", "autoencoder"])
def test_a_goal_gated_encoder_is_the_encoder_split_at_its_last_map_and_reads_the_goal(encoder: str) -> None:
    sim = SimConfig(n_objects=3, image_size=48)
    env = BaselineObservation(make_task_env("pick", sim, render_frames=True), "img")
    observation, _ = env.reset(seed=0)
    torch.manual_seed(0)
    plain = BaselineExtractor(env.observation_space, encoder, image_features=32, latent_channels=4)
    gated = BaselineExtractor(env.observation_space, encoder, image_features=32, latent_channels=4, goal_gating=True)
    assert plain.gate is None and not any(key.startswith("gate") for key in plain.state_dict())
    gated.load_state_dict({**gated.state_dict(), **plain.state_dict()})
    gated.eval(), plain.eval()
    batch = preprocess_obs({key: torch.as_tensor(np.asarray(value)[None]) for key, value in observation.items()},
                           env.observation_space)
    with torch.no_grad():
        torch.nn.init.zeros_(gated.gate.weight)
        torch.nn.init.constant_(gated.gate.bias, 30.0)  # every gate open: the encoder as it is
        assert torch.allclose(gated(batch), plain(batch), atol=1e-5)
        torch.nn.init.normal_(gated.gate.weight), torch.nn.init.zeros_(gated.gate.bias)
        other = {**batch, "goal_class": batch["goal_class"].roll(1, dims=1)}
        width = gated.features_dim - 24
        assert not torch.allclose(gated(batch)[:, :width], gated(other)[:, :width])
        assert torch.equal(plain(batch)[:, :width], plain(other)[:, :width])
        pair = {key: torch.as_tensor(np.stack([value, value])) for key, value in observation.items()}
        stored = preprocess_obs({**pair, "goal_class": pair["goal_class"][:, None]}, env.observation_space)
        assert torch.allclose(gated(stored), gated(batch).repeat(2, 1), atol=1e-6)  # as PPO's rollout buffer keeps a Discrete: (N, 1)
    env.close()


def test_only_the_pick_skill_is_gated() -> None:
    settings = BaselineParams(goal_gating=True)
    assert baseline_extractor(settings, "pick")["features_extractor_kwargs"]["goal_gating"]
    assert not baseline_extractor(settings, "drop")["features_extractor_kwargs"]["goal_gating"]
    assert not baseline_extractor(BaselineParams(), "pick")["features_extractor_kwargs"]["goal_gating"]


def test_only_baseline_img_trains_a_pick_and_the_signature_names_the_inputs() -> None:
    assert [v.trains for v in BASELINES] == [("pick", "drop"), ("drop",), ("drop",)]
    signature = PolicySignature.of_baseline("drop", VARIANTS["baseline_delta_pose"], 3, "square", 64)
    assert signature.observation == ["delta_pose[3]", "goal_class[24]", "goal_position[2]", "image[3, 64, 64]"]


def test_the_evaluation_encoding_equals_the_training_wrapper() -> None:
    for variant in BASELINES:
        env = BaselineObservation(make_task_env("drop", SIM, render_frames=True), variant.baseline_input)
        wrapped, _ = env.reset(seed=1)
        raw = env.unwrapped._observation()
        info = env._info
        batch = baseline_inputs(variant)("drop", [raw], [info], None, np.asarray([raw["goal_position"]]), None)
        for key, value in wrapped.items():
            np.testing.assert_array_equal(batch[key][0], value)
        env.close()


def test_the_object_order_rule_takes_the_object_after_the_last() -> None:
    decide = decider(METHODS["baseline_img"], None, None, FEATURES)
    targets = np.zeros((3, 3, 2))
    assert decide(None, np.array([3, 3, 3]), targets, np.array([-1, 0, 2])).tolist() == [0, 1, 0]


class _Policy(torch.nn.Module):
    """What the encoder loader reads of an SB3 policy: the actor's features extractor and the critic's (the same
    one where they share it)."""

    def __init__(self, extractor: BaselineExtractor, critic: BaselineExtractor | None = None) -> None:
        super().__init__()
        self.features_extractor = extractor
        self.vf_features_extractor = critic if critic is not None else extractor


PRETRAIN = EncoderPretrainParams(frames=48, episode_steps=16, steps=30, batch_size=8, log_every=10,
                                 validation_share=0.25, seed=3)


def test_the_walks_frames_are_seeded_and_the_autoencoder_learns_them() -> None:
    frames = sample_frames(SIM, ExplorationParams(), PRETRAIN, progress=False)
    assert frames.shape == (48, 3, 32, 32) and frames.dtype == np.uint8
    np.testing.assert_array_equal(frames, sample_frames(SIM, ExplorationParams(), PRETRAIN, progress=False))
    other = sample_frames(SIM, ExplorationParams(), PRETRAIN.model_copy(update={"seed": 4}), progress=False)
    assert not np.array_equal(frames, other)
    model, log = pretrain_autoencoder(frames, PRETRAIN, progress=False)
    assert [row["step"] for row in log] == [10, 20, 30]
    assert log[-1]["validation_mse"] < log[0]["validation_mse"]  # held-out frames: it learns, not only memorizes
    again, _ = pretrain_autoencoder(frames, PRETRAIN, progress=False)
    for mine, theirs in zip(model.state_dict().values(), again.state_dict().values(), strict=True):
        torch.testing.assert_close(mine, theirs, rtol=0, atol=0)


def test_the_autoencoder_extractor_is_frozen_and_loads_the_pretrained_weights(tmp_path) -> None:
    env = BaselineObservation(make_task_env("pick", SIM, render_frames=True), "img")
    extractor = BaselineExtractor(env.observation_space, "autoencoder", latent_channels=4)
    assert extractor.features_dim == 4 * 4 * 4 + 24
    assert not any(p.requires_grad for p in extractor.encoder.parameters())
    with pytest.raises(ConfigError, match=r"encoder.pth: no pretrained encoder .* mor policy pretrain-encoder"):
        load_pretrained_encoder(tmp_path / "encoder.pth")
    model = frame_autoencoder(4)
    save_frame_autoencoder(model, 4, tmp_path / "encoder.pth")
    critic = BaselineExtractor(env.observation_space, "autoencoder", latent_channels=4)  # share_encoder false
    load_pretrained_encoder(tmp_path / "encoder.pth")(_Policy(extractor, critic))
    for loaded in (extractor, critic):
        for mine, theirs in zip(loaded.encoder[0].state_dict().values(), model[0].state_dict().values(), strict=True):
            torch.testing.assert_close(mine, theirs, rtol=0, atol=0)
    save_frame_autoencoder(frame_autoencoder(8), 8, tmp_path / "wide.pth")
    with pytest.raises(ConfigError, match=r"wide.pth: made with latent_channels 8"):
        load_pretrained_encoder(tmp_path / "wide.pth")(_Policy(extractor))
    env.close()
