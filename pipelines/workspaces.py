"""The library's record of a workspace (``mor.policy.workspace.Workspace``), built from this repository's paths
(shared wiring of the policy, evaluation and robot stages, not a stage)."""

from __future__ import annotations

from pathlib import Path

from mor.config import Profile
from mor.policy.workspace import Workspace
from pipelines import paths


def workspace_record(folder: Path, profile: Profile) -> Workspace:
    """The workspace at ``folder`` (the current one: "."; from the main one: "." or ``settings/NAME``) with
    ``profile`` as it sees it, as the library's record (``mor.policy.workspace.Workspace``, absolute paths)."""
    root = folder.resolve()
    main = root if profile.setting is None else (root / paths.MAIN).resolve()
    lnet_from_main = profile.setting is not None and profile.setting.lnet_from_main
    return Workspace(root=root, lnet_card=(main if lnet_from_main else root) / paths.LNET_CARD,
                     policy_card=root / paths.POLICY_CARD, main_policy_card=main / paths.POLICY_CARD)
