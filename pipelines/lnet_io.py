"""The trained L-Net of this checkout's run, checked against the current data and profile (``mor.lnet.runtime``)."""

from __future__ import annotations

from pathlib import Path

from mor.config import Profile
from mor.data.manifest import manifest_version, read_manifest
from mor.lnet.checkpoint import signature
from mor.lnet.runtime import LNetRunner, load_lnet
from mor.lnet.train import pick_device
from pipelines import paths


def load_trained(profile: Profile, checkpoint: Path, calibrated: bool = True) -> LNetRunner:
    """``load_lnet`` of ``checkpoint``, refusing one made with another model config, dataset version or image
    size than this profile and the current manifest, or calibrated with other tracking settings
    (``lnet.data_association``, ``lnet.gate``, ``lnet.negative_information``, ``lnet.not_found_sigma``,
    ``lnet.search_max_looks``, ``lnet.arena_grid_spacing``); with the profile's ``lnet.encoder_precision``."""
    expected = signature(profile.lnet.model, manifest_version(read_manifest(paths.MANIFEST)), profile.sim.image_size)
    return load_lnet(checkpoint, pick_device(), expected, calibrated, chosen=profile.lnet.chosen_settings(),
                     encoder_precision=profile.lnet.encoder_precision)
