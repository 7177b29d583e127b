"""The names the policy layer's parameters use (no heavy imports: ``mor.config`` reads them)."""

from __future__ import annotations

from typing import Literal

Task = Literal["pick", "drop", "decision"]
TASKS: tuple[Task, ...] = ("pick", "drop", "decision")

Variant = Literal["gt_pose", "lnet", "lnet_no_uncertainty"]
VARIANTS: tuple[Variant, ...] = ("gt_pose", "lnet", "lnet_no_uncertainty")

#: the paper's end-to-end CNN baselines (mor.policy.baselines): +Img, +ΔPose, +Landmark
BaselineVariant = Literal["baseline_img", "baseline_delta_pose", "baseline_landmark"]
BASELINE_VARIANTS: tuple[BaselineVariant, ...] = ("baseline_img", "baseline_delta_pose", "baseline_landmark")

#: the variant whose Pick policy each baseline uses (Pick's inputs are the same in all three)
PICK_FROM: BaselineVariant = "baseline_img"


def baseline_tasks(variant: BaselineVariant) -> tuple[Task, ...]:
    """The skills a baseline variant trains itself: all but ``PICK_FROM`` reuse its Pick."""
    return ("pick", "drop") if variant == PICK_FROM else ("drop",)
