"""A workspace's committed artefacts that the policy stages read, as one plain record, and its L-Net.

The main workspace is the repository's root; a setting's (Table 3's polygon arena, Table 4's object counts) is
``settings/NAME/``. ``pipelines`` builds the record once from its paths; the library only follows it, so a worker
process or a Ray task needs nothing but the record (all paths absolute).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from mor.policy.variants import Variant

if TYPE_CHECKING:
    from mor.lnet.params import LNetParams
    from mor.lnet.runtime import LNetRunner


@dataclass(frozen=True)
class Workspace:
    """root: the workspace's folder; lnet_card: the folder of the L-Net its L-Net variants observe through (its own,
    or the main workspace's where the setting says ``lnet_from_main``); policy_card: its committed policies
    (``<variant>/<task>/``); main_policy_card: the main workspace's (the same folder outside a setting)."""

    root: Path
    lnet_card: Path
    policy_card: Path
    main_policy_card: Path

    @property
    def is_setting(self) -> bool:
        return self.policy_card != self.main_policy_card


def committed_lnet(workspace: Workspace, variant: Variant, lnet: LNetParams) -> LNetRunner | None:
    """The committed L-Net of ``workspace`` (``model.pt`` + its calibration; compiled when ``lnet.compile_step``,
    with ``lnet.encoder_precision`` and the tracking settings ``lnet.chosen_settings``) for a variant that observes
    through it; None for the others."""
    if not variant.uses_lnet:
        return None
    from mor.lnet.runtime import load_lnet  # noqa: PLC0415 - torch only where needed

    return load_lnet(workspace.lnet_card / "model.pt", compiled=lnet.compile_step,
                     chosen=lnet.chosen_settings(), encoder_precision=lnet.encoder_precision)
