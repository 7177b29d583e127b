"""The paper's end-to-end baselines (section 5, Supplementary A "Baseline architecture", after Embodied-CLIP):
a CNN on the RGB frame and a linear embedding of the target object's class, concatenated into an MLP policy,
trained with PPO on the Pick and Drop tasks from pixels alone.

Inputs (``BaselineInput``), as in paper Table 1:

- ``img``: the frame (3, H, W) uint8 and the goal as the paper gives it: Pick the target's class id, Drop the
  held object's class id and its target position in world coordinates (metres).
- ``delta_pose``: ``img`` plus, for Drop, the target's distance (m) and bearing (cos, sin) from the agent's true
  pose: privileged information the paper adds ("not a fair comparison", its dagger).
- ``landmark``: ``img`` in an arena that shows a marker at each drop target (paper Figure 4).

Pick sees the same inputs in all three (the extra cues are about drop targets), so one Pick baseline serves
every row (``Variant.pick_from``). The full task chains the two skills in object order (docs/assumptions.md,
"Baselines"): a baseline has no pose estimate to choose the nearest object or to tell a placed one.

Encoders (``BaselineEncoder``): ``nature_cnn``, stable-baselines3's NatureCNN (the ``default`` profile's compact
CNN: a quarter of the L-Net encoder's multiply-adds, so four baselines fit 2 CPU cores; frames of at least 36
pixels), or, through ``mor.lnet.model.build_encoder``, the L-Net's ``compact`` encoder (any frame size: the
``tiny`` profile's) and torchvision's ``resnet18`` / ``resnet50``, randomly initialized (no pretrained weights
can be downloaded here), for the ``paper`` profile; or ``autoencoder``: ``mor.policy.frame_encoder``'s encoder,
pretrained without labels (``mor policy pretrain-encoder``) and frozen, as Embodied-CLIP freezes CLIP.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, NatureCNN

from mor.errors import ConfigError
from mor.lnet.model import CompactEncoder, ResNetEncoder, build_encoder
from mor.policy.frame_encoder import frame_encoder, read_frame_autoencoder
from mor.policy.names import Task
from mor.policy.params import BaselineParams
from mor.policy.variants import BaselineInput, Variant
from mor.sim.catalog import N_CLASSES
from mor.sim.geometry import bearing
from mor.sim.tasks import DropEnv, PickEnv

BaselineEncoder = Literal["nature_cnn", "compact", "resnet18", "resnet50", "autoencoder"]


def baseline_space(task: Task, input_kind: BaselineInput, image_shape: tuple[int, int, int], arena_half: float
                   ) -> spaces.Dict:
    """The observation space of a baseline skill: image (3, H, W) uint8, goal_class Discrete(N_CLASSES), and for
    Drop goal_position (2,) m, plus delta_pose (distance m, cos, sin) with ``delta_pose``."""
    height, width, channels = image_shape
    fields: dict[str, spaces.Space] = {
        "image": spaces.Box(0, 255, (channels, height, width), np.uint8),
        "goal_class": spaces.Discrete(N_CLASSES),
    }
    if task == "drop":
        fields["goal_position"] = spaces.Box(-arena_half, arena_half, (2,), np.float32)
        if input_kind == "delta_pose":
            fields["delta_pose"] = spaces.Box(np.array([0, -1, -1], np.float32),
                                              np.array([4 * arena_half, 1, 1], np.float32))
    return spaces.Dict(fields)


def baseline_observation(task: Task, input_kind: BaselineInput, observation: dict[str, Any], info: dict[str, Any],
                         goal: np.ndarray) -> dict[str, np.ndarray]:
    """One env's baseline observation from its MOR observation and info. goal: Pick the target object's index
    (), Drop the target position (2,) m (the held object's class is the goal class)."""
    classes = np.asarray(observation["object_classes"])
    index = int(goal) if task == "pick" else int(observation["held"])
    result = {"image": np.ascontiguousarray(np.moveaxis(observation["image"], -1, 0)),
              "goal_class": np.int64(classes[min(index, len(classes) - 1)])}
    if task == "drop":
        result["goal_position"] = np.asarray(goal, np.float32)
        if input_kind == "delta_pose":
            pose = np.asarray(info["agent_pose"], np.float64)
            angle = bearing(pose, np.asarray(goal, np.float64))
            distance = np.linalg.norm(np.asarray(goal) - pose[:2])
            result["delta_pose"] = np.array([distance, np.cos(angle), np.sin(angle)], np.float32)
    return result


def baseline_inputs(variant: Variant) -> Callable[..., dict[str, np.ndarray]]:
    """The evaluation's encoding of k envs for a baseline's skills (``mor.policy.features.Encode``): their
    ``baseline_observation``s stacked; the beliefs are not read (a baseline sees pixels and its goal only)."""
    input_kind = variant.baseline_input

    def encode(task: Task, observations: list[dict[str, Any]], infos: list[dict[str, Any]], belief: Any,
               goals: np.ndarray, arena: Any) -> dict[str, np.ndarray]:
        return stack_observations([baseline_observation(task, input_kind, o, i, g)
                                   for o, i, g in zip(observations, infos, goals, strict=True)])

    return encode


def stack_observations(observations: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """k baseline observations -> one dict of (k, ...) arrays, what ``Skill.act_batch`` takes."""
    return {key: np.stack([o[key] for o in observations]) for key in observations[0]}


class BaselineObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """A rendered MOR Pick or Drop env seen as a baseline does (``baseline_space``); ``action_masks()`` is the
    env's. The true agent pose for ``delta_pose`` comes from the env's ``info`` of the same step; the constructor's
    arguments are recorded in ``spec`` (``spec.make()`` builds it again)."""

    def __init__(self, env: gym.Env, input_kind: BaselineInput) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, input_kind=input_kind)
        super().__init__(env)
        base = env.unwrapped
        if not isinstance(base, PickEnv | DropEnv) or not base.render_frames:
            raise TypeError(f"baselines need a rendered MOR/Pick-v0 or Drop-v0 env, got {type(base).__name__}")
        self.task: Task = "pick" if isinstance(base, PickEnv) else "drop"
        self.input_kind = input_kind
        self.observation_space = baseline_space(self.task, input_kind, base.observation_space["image"].shape,
                                                base.arena.half_extent)
        self._info: dict[str, Any] = {}

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        observation, self._info = self.env.reset(**kwargs)
        return self.observation(observation), self._info

    def step(self, action: int) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, self._info = self.env.step(action)
        return self.observation(observation), reward, terminated, truncated, self._info

    def observation(self, observation: dict[str, Any]) -> dict[str, np.ndarray]:
        goal = observation["goal_object"] if self.task == "pick" else observation["goal_position"]
        return baseline_observation(self.task, self.input_kind, observation, self._info, goal)

    def action_masks(self) -> np.ndarray:
        return self.env.unwrapped.action_masks()


class BaselineExtractor(BaseFeaturesExtractor):
    """The image through the encoder -> (N, image_features); every other key flattened (SB3 one-hot encodes
    ``goal_class``, so the policy's first linear layer is the class embedding) and concatenated after it.
    ``autoencoder``: the frozen ``frame_encoder`` with ``latent_channels``, its code flattened to
    image_features = latent_channels x H/8 x W/8 (the ``image_features`` argument is not used).

    ``goal_gating``: Gated-Attention (Chaplot et al., "Gated-Attention Architectures for Task-Oriented Language
    Grounding", AAAI 2018): a linear map of the one-hot ``goal_class`` through a sigmoid scales each channel of the
    encoder's last feature map before the encoder's own pooling or projection, so that the goal can select the
    features of its class while they still have their place in the frame (a frozen encoder's code is gated too:
    the gate is trained)."""

    def __init__(self, observation_space: spaces.Dict, encoder: BaselineEncoder = "compact",
                 image_features: int = 256, latent_channels: int = 16, goal_gating: bool = False) -> None:
        others = sum(spaces.flatdim(space) for key, space in observation_space.spaces.items() if key != "image")
        _, height, width = observation_space["image"].shape
        if encoder == "autoencoder":
            if height % 8 or width % 8:
                raise ValueError(f"the autoencoder encoder needs frames whose sides are multiples of 8, not "
                                 f"{height}x{width}")
            image_features = latent_channels * (height // 8) * (width // 8)
        super().__init__(observation_space, image_features + others)
        if encoder == "nature_cnn":
            self.encoder = NatureCNN(observation_space["image"], image_features, normalized_image=False)
        elif encoder == "autoencoder":
            self.encoder = torch.nn.Sequential(frame_encoder(latent_channels), torch.nn.Flatten())
            self.encoder.requires_grad_(False)  # frozen: PPO's optimizer gets no gradient for it
        else:
            self.encoder = build_encoder(encoder, image_features)
        self.keys = [key for key in observation_space.spaces if key != "image"]
        self.gate = (torch.nn.Linear(spaces.flatdim(observation_space["goal_class"]), map_channels(self.encoder))
                     if goal_gating else None)

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        """observations: image (N, 3, H, W) scaled to [0, 1] by SB3, the rest (N, ...) -> (N, features_dim)."""
        image = observations["image"]
        if self.gate is None:
            encoded = self.encoder(image)
        else:
            # flattened: the rollout buffer keeps a Discrete as (N, 1), which SB3 one-hot encodes to (N, 1, classes)
            gate = torch.sigmoid(self.gate(observations["goal_class"].flatten(1)))[..., None, None]
            encoded = pool_map(self.encoder, last_map(self.encoder, image) * gate)
        return torch.cat([encoded] + [observations[key].flatten(1) for key in self.keys], dim=1)


def last_map(encoder: torch.nn.Module, images: torch.Tensor) -> torch.Tensor:
    """A baseline encoder's last feature map: images (N, 3, H, W) in [0, 1] -> (N, ``map_channels``, h, w)."""
    if isinstance(encoder, NatureCNN):
        return encoder.cnn[:-1](images)  # every layer but the flatten
    if isinstance(encoder, CompactEncoder):
        return encoder.features[:-1](images)  # the 4x4 map, before the flatten
    if isinstance(encoder, ResNetEncoder):
        return encoder.last_map(images)
    return encoder[0](images)  # the autoencoder's code


def pool_map(encoder: torch.nn.Module, spatial: torch.Tensor) -> torch.Tensor:
    """What a baseline encoder does after ``last_map``: (N, C, h, w) -> its image features (N, D)."""
    if isinstance(encoder, NatureCNN):
        return encoder.linear(spatial.flatten(1))
    if isinstance(encoder, CompactEncoder):
        return encoder.project(spatial.flatten(1))
    if isinstance(encoder, ResNetEncoder):
        return encoder.pool(spatial)
    return encoder[1](spatial)


def map_channels(encoder: torch.nn.Module) -> int:
    """The channels of a baseline encoder's ``last_map``."""
    if isinstance(encoder, NatureCNN):
        return encoder.cnn[-3].out_channels  # the last convolution's
    if isinstance(encoder, CompactEncoder | ResNetEncoder):
        return encoder.channels
    return encoder[0][-1].out_channels  # the autoencoder's 1x1 code convolution


def baseline_extractor(settings: BaselineParams, task: Task) -> dict[str, Any]:
    """SB3 ``policy_kwargs`` of a baseline ``task`` skill: ``BaselineExtractor`` with the profile's encoder and width,
    one for the actor and the critic or one each (``settings.share_encoder``); the Pick skill's gated by its
    target's class where ``settings.goal_gating`` (Drop's goal is a position: never)."""
    return {"features_extractor_class": BaselineExtractor, "share_features_extractor": settings.share_encoder,
            "features_extractor_kwargs": {"encoder": settings.encoder, "image_features": settings.image_features,
                                          "latent_channels": settings.pretrain.latent_channels,
                                          "goal_gating": settings.goal_gating and task == "pick"}}


def load_pretrained_encoder(path: Path) -> Callable[[torch.nn.Module], None]:
    """What puts the pretrained encoder at ``path`` (``mor.policy.frame_encoder.ENCODER_FILE``) into a new ``autoencoder`` baseline policy
    (``mor.policy.train.train_policy``'s ``initialize``); ConfigError naming the file when it is missing or was
    made with other code channels."""
    if not path.is_file():
        raise ConfigError(f"{path}: no pretrained encoder for policy.baseline.encoder autoencoder; run mor policy "
                          f"pretrain-encoder first")
    saved = read_frame_autoencoder(path)

    def initialize(policy: torch.nn.Module) -> None:
        try:  # the actor's encoder, and the critic's where it has its own (``share_encoder`` false)
            for extractor in {policy.features_extractor, policy.vf_features_extractor}:
                extractor.encoder[0].load_state_dict(saved["encoder"])
        except RuntimeError:
            raise ConfigError(f"{path}: made with latent_channels {saved['latent_channels']}, other than "
                              f"policy.baseline.pretrain.latent_channels; run mor policy pretrain-encoder again"
                              ) from None

    return initialize
