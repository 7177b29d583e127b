"""The committed L-Net the policy stages observe through (shared wiring, not a stage)."""

from __future__ import annotations

from mor.config import Profile
from mor.lnet.runtime import LNetRunner, load_lnet
from mor.policy.names import Variant
from pipelines import paths


def lnet_runner(variant: Variant, profile: Profile) -> LNetRunner | None:
    """The committed L-Net (``cards/lnet/model.pt`` + calibration; the main workspace's where the setting says
    ``lnet_from_main``; compiled when the profile's ``lnet.compile_step``, with its ``lnet.encoder_precision``) for
    the L-Net variants; None for gt_pose."""
    if variant == "gt_pose":
        return None
    from_main = profile.setting is not None and profile.setting.lnet_from_main
    return load_lnet((paths.MAIN / paths.LNET_CARD if from_main else paths.LNET_CARD) / "model.pt",
                     compiled=profile.lnet.compile_step, data_association=profile.lnet.data_association,
                     encoder_precision=profile.lnet.encoder_precision)
