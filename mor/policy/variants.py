"""The policy variants, each defined once: what a policy observes and how it is trained. Everything else asks them.

A variant is a row of the paper's tables before its decision rule (``mor.eval.methods`` adds that): the ground
truth's, the L-Net's with and without its uncertainty, and the paper's three end-to-end CNN baselines. No heavy
imports here: ``mor.config`` reads the names.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from mor.policy.names import TASKS, Task

Source = Literal["truth", "lnet", "pixels"]
BaselineInput = Literal["img", "delta_pose", "landmark"]


@dataclass(frozen=True)
class Variant:
    """One policy variant.

    source: where its observation comes from: the simulator's truth (zero covariances, no rendering), the L-Net's
    streaming estimates from first-person frames, or the frames themselves (an end-to-end baseline).
    uncertainty: whether its observation holds the stated uncertainty (covariances, heading concentration); the
    truth's layout holds it too, as zeros, so that the L-Net variants can start from its policies.
    trains: the skills it trains itself, in order (the decision needs the pick and drop skills).
    warm_start: the variant whose committed policies it fine-tunes when ``policy.lnet_warm_start`` (same layout).
    pick_from: the variant whose Pick skill it plays (a baseline's Pick inputs are the same in all three).
    baseline_input: a baseline's input besides its frames and goal (``mor.policy.baselines``).
    landmark: its world shows a marker at each drop target.
    ablation_of: the variant this one equals but for the uncertainty it does not read (the paper's Table 2).
    search: its observation holds the L-Net's stated belief beyond the Gaussian (which objects are found, which may
    be lost, where the camera has not looked: ``mor.policy.features``), what a policy needs in order to search.
    """

    name: str
    source: Source
    uncertainty: bool
    trains: tuple[Task, ...] = TASKS
    warm_start: str | None = None
    pick_from: str | None = None
    baseline_input: BaselineInput | None = None
    landmark: bool = False
    ablation_of: str | None = None
    search: bool = False

    @property
    def uses_lnet(self) -> bool:
        """Observes the world through the L-Net's estimates."""
        return self.source == "lnet"

    @property
    def is_baseline(self) -> bool:
        """An end-to-end pixel baseline: its skills chained in object order, no decision policy."""
        return self.source == "pixels"


#: every variant, in the tables' order
VARIANTS: dict[str, Variant] = {variant.name: variant for variant in (
    Variant("gt_pose", "truth", uncertainty=True),
    Variant("lnet", "lnet", uncertainty=True, warm_start="gt_pose"),
    Variant("lnet_no_uncertainty", "lnet", uncertainty=False, warm_start="gt_pose", ablation_of="lnet"),
    Variant("lnet_search", "lnet", uncertainty=True, warm_start="gt_pose", search=True),
    Variant("baseline_img", "pixels", uncertainty=False, trains=("pick", "drop"), baseline_input="img"),
    Variant("baseline_delta_pose", "pixels", uncertainty=False, trains=("drop",), pick_from="baseline_img",
            baseline_input="delta_pose"),
    Variant("baseline_landmark", "pixels", uncertainty=False, trains=("drop",), pick_from="baseline_img",
            baseline_input="landmark", landmark=True),
)}
#: the variants that observe a pose belief (the truth's or the L-Net's), the policy training's default
POSE_VARIANTS: tuple[str, ...] = tuple(name for name, variant in VARIANTS.items() if not variant.is_baseline)
#: the variant that sees the true poses, and the one that sees them through the L-Net with its uncertainty
GROUND_TRUTH: Variant = next(v for v in VARIANTS.values() if v.source == "truth")
OURS: Variant = next(v for v in VARIANTS.values() if v.uses_lnet and v.ablation_of is None)


def seed_folder(root: Path, variant: str, seed: int = 0) -> Path:
    """The folder of ``variant``'s run with training seed ``seed`` under ``root`` (a run folder or a card folder):
    ``root/variant`` for seed 0 (the first run, where every earlier run lives), ``root/variant/seed_S`` for S > 0."""
    return root / variant if seed == 0 else root / variant / f"seed_{seed}"


def policy_folder(root: Path, variant: str, task: Task, seed: int = 0) -> Path:
    """Where ``variant``'s ``task`` policy of training seed ``seed`` lives under ``root`` (``seed_folder``/task)."""
    return seed_folder(root, variant, seed) / task
