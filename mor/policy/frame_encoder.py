"""A frame encoder learned without labels, for the pixel baselines (``policy.baseline.encoder: autoencoder``).

The paper's baselines, after Embodied-CLIP, read the frame through a pretrained encoder that PPO does not train.
No registry here ships ImageNet weights, so this one learns from the frames alone: a convolutional autoencoder
trained to reconstruct frames of the data collection's random walk (``mor.data.exploration``, the walk that made
the dataset's episodes), rendered afresh in the profile's world so that this stage does not need the dataset on
disk. No pose, class or action is read. Its code keeps the frame's layout: (latent_channels, H/8, W/8), one
feature vector per 8x8 pixel block, so where a coloured object sits in the frame is still where it sits in the
code (a single pooled vector would have to learn that). Colour is not augmented away (as SimCLR's colour jitter
would): an object's colour is what tells the target from the others.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from mor.data.exploration import ExplorationParams, ExplorationPolicy
from mor.errors import ConfigError
from mor.policy.params import EncoderPretrainParams
from mor.sim.config import SimConfig
from mor.sim.rollout import episode_seed
from mor.tensor_files import load_plain, save_plain

FRAMES_ENV = "MOR/Rearrange-v0"  # the data collection's env (mor.data.collect)
FORMAT = "mor.frame_autoencoder/1"
ENCODER_FILE = "encoder.pth"  # mor policy pretrain-encoder's output, in pipelines.paths.ENCODER_CARD


def frame_encoder(latent_channels: int) -> nn.Sequential:
    """(N, 3, H, W) in [0, 1] -> (N, latent_channels, H/8, W/8): three stride-2 convolutions and a 1x1 code."""
    return nn.Sequential(
        nn.Conv2d(3, 32, 4, stride=2, padding=1), nn.ReLU(),
        nn.Conv2d(32, 64, 4, stride=2, padding=1), nn.ReLU(),
        nn.Conv2d(64, 64, 4, stride=2, padding=1), nn.ReLU(),
        nn.Conv2d(64, latent_channels, 1))


def frame_decoder(latent_channels: int) -> nn.Sequential:
    """``frame_encoder``'s mirror: (N, latent_channels, H/8, W/8) -> (N, 3, H, W) in [0, 1]."""
    return nn.Sequential(
        nn.Conv2d(latent_channels, 64, 1), nn.ReLU(),
        nn.ConvTranspose2d(64, 64, 4, stride=2, padding=1), nn.ReLU(),
        nn.ConvTranspose2d(64, 32, 4, stride=2, padding=1), nn.ReLU(),
        nn.ConvTranspose2d(32, 3, 4, stride=2, padding=1), nn.Sigmoid())


def sample_frames(sim: SimConfig, exploration: ExplorationParams, params: EncoderPretrainParams,
                  progress: bool = True) -> np.ndarray:
    """``params.frames`` first-person frames (N, 3, H, W) uint8 of the exploration walk, episodes of
    ``params.episode_steps`` steps seeded by ``params.seed`` (the same seed gives the same frames)."""
    env = gym.make(FRAMES_ENV, horizon=params.episode_steps, **sim.model_dump())
    frames = np.empty((params.frames, 3, sim.image_size, sim.image_size), np.uint8)
    count, episode = 0, 0
    with tqdm(total=params.frames, desc="frames", unit="frame", disable=not progress) as bar:
        while count < params.frames:
            seed = episode_seed(params.seed, episode)
            policy = ExplorationPolicy(env.unwrapped.arena, exploration, seed, env.unwrapped.noise)
            observation, info = env.reset(seed=seed)
            done = False
            while not done and count < params.frames:
                frames[count] = np.moveaxis(observation["image"], -1, 0)
                count += 1
                bar.update()
                observation, _, terminated, truncated, info = env.step(policy(observation, info))
                done = terminated or truncated
            episode += 1
    env.close()
    return frames


def frame_autoencoder(latent_channels: int) -> nn.Sequential:
    """``frame_encoder`` then ``frame_decoder``: index 0 is the encoder that the baselines keep."""
    return nn.Sequential(frame_encoder(latent_channels), frame_decoder(latent_channels))


def pretrain_autoencoder(frames: np.ndarray, params: EncoderPretrainParams, progress: bool = True
                         ) -> tuple[nn.Sequential, list[dict[str, Any]]]:
    """Train ``frame_encoder`` and its decoder to reconstruct ``frames`` (N, 3, H, W) uint8 (mean squared error on
    [0, 1] pixels, Adam); the last ``params.validation_share`` of the frames (whole episodes' worth, not shuffled
    in) are held out. Returns the ``frame_autoencoder`` and the log: one row per ``params.log_every`` steps with
    the training and validation loss."""
    generator = torch.Generator().manual_seed(params.seed)
    torch.manual_seed(params.seed)
    model = frame_autoencoder(params.latent_channels)
    optimizer = torch.optim.Adam(model.parameters(), lr=params.learning_rate)
    held = max(1, int(len(frames) * params.validation_share))
    train, validation = torch.from_numpy(frames[:-held]), torch.from_numpy(frames[-held:])
    log, recent = [], []
    for step in tqdm(range(1, params.steps + 1), desc="pretrain encoder", unit="step", disable=not progress):
        batch = train[torch.randint(len(train), (params.batch_size,), generator=generator)].float() / 255.0
        loss = nn.functional.mse_loss(model(batch), batch)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        recent.append(loss.item())
        if step % params.log_every == 0 or step == params.steps:
            log.append({"step": step, "train_mse": float(np.mean(recent)),
                        "validation_mse": reconstruction_error(model, validation)})
            recent = []
    return model, log


@torch.no_grad()
def reconstruction_error(model: nn.Module, frames: torch.Tensor, batch_size: int = 256) -> float:
    """Mean squared error of ``model``'s reconstructions of ``frames`` (N, 3, H, W) uint8, on [0, 1] pixels."""
    errors = [nn.functional.mse_loss(model(chunk.float() / 255.0), chunk.float() / 255.0, reduction="sum").item()
              for chunk in frames.split(batch_size)]
    return float(sum(errors) / frames.numel())


def save_frame_autoencoder(model: nn.Sequential, latent_channels: int, path: Path) -> None:
    """``frame_autoencoder``'s weights to ``path`` (plain tensors, ``mor.tensor_files``): encoder and decoder."""
    save_plain({"format": FORMAT, "latent_channels": latent_channels, "encoder": model[0].state_dict(),
                "decoder": model[1].state_dict()}, path)


def read_frame_autoencoder(path: Path) -> dict[str, Any]:
    """What ``save_frame_autoencoder`` wrote: format, latent_channels, encoder and decoder state dicts;
    MorError naming ``path`` when it is not such a file."""
    hint = "run mor policy pretrain-encoder again"
    saved = load_plain(path, "pretrained frame encoder", hint, hint)
    if not isinstance(saved, dict) or saved.get("format") != FORMAT:
        raise ConfigError(f"{path}: not a {FORMAT} file; {hint}")
    return saved
