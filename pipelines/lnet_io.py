"""Loading the trained L-Net for the stages that use it, checked against the current data and profile."""

from __future__ import annotations

import json
from pathlib import Path

import torch

from mor.config import Profile
from mor.data.manifest import manifest_version, read_manifest
from mor.data.sequences import SequenceWindows
from mor.lnet.evaluate import Calibration
from mor.lnet.model import LNet
from mor.lnet.train import load_model, pick_device, signature
from pipelines import paths


def load_trained(profile: Profile, checkpoint: Path) -> tuple[LNet, torch.device]:
    """The checkpoint's model, after checking it matches this profile's model, the data version and image size."""
    version = manifest_version(read_manifest(paths.MANIFEST))
    image_size = SequenceWindows(paths.LEROBOT / "test", window=1).image_size
    device = pick_device()
    return load_model(checkpoint, signature(profile.lnet.model, version, image_size), device), device


def load_calibration(path: Path) -> Calibration:
    values = json.loads(path.read_text())
    return Calibration(values["agent_scale"], values["object_scale"], values["kappa_scale"])
