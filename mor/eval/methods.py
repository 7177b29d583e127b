"""The methods the protocol can score, by name, and loading a method's trained policies.

A learned method is an observation variant (``mor.policy.observations.VARIANTS``) with its pick, drop and
decision policies; ``*_nearest_rule`` replaces the learned decision by the nearest-unfixed-object rule; the
baselines (``mor.policy.baselines``) chain their pixel-fed pick and drop skills in object order;
``oracle`` and ``random`` are the simulator's scripted policies.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from mor.errors import ConfigError
from mor.policy.hierarchy import POLICY_FILE, Skill
from mor.policy.names import BASELINE_VARIANTS, PICK_FROM, TASKS, VARIANTS, BaselineVariant, Task, Variant
from mor.policy.signature import ZERO_SHOT_FIELDS, PolicySignature, check_signature

Decision = Literal["learned", "nearest_rule", "object_order", "scripted"]


@dataclass(frozen=True)
class MethodSpec:
    name: str
    variant: Variant | BaselineVariant | None  # None for the scripted policies
    decision: Decision

    @property
    def is_baseline(self) -> bool:
        """An end-to-end pixel baseline (``mor.policy.baselines``): its skills chained in object order."""
        return self.decision == "object_order"

    @property
    def uses_lnet(self) -> bool:
        """Observes the world through the L-Net's estimates (every learned variant but gt_pose)."""
        return self.variant in VARIANTS and self.variant != "gt_pose"

    def skill_owners(self) -> dict[Task, Variant | BaselineVariant]:
        """Whose trained policy each task this method plays is: the variant's own (the decision only where it is
        learned), a baseline's Pick ``PICK_FROM``'s; empty for the scripted policies."""
        if self.variant is None:
            return {}
        if self.is_baseline:
            return {"pick": PICK_FROM, "drop": self.variant}
        return {task: self.variant for task in TASKS if task != "decision" or self.decision == "learned"}


METHODS: dict[str, MethodSpec] = {spec.name: spec for spec in (
    MethodSpec("gt_pose", "gt_pose", "learned"),
    MethodSpec("lnet", "lnet", "learned"),
    MethodSpec("lnet_no_uncertainty", "lnet_no_uncertainty", "learned"),
    MethodSpec("gt_pose_nearest_rule", "gt_pose", "nearest_rule"),
    MethodSpec("lnet_nearest_rule", "lnet", "nearest_rule"),
    *(MethodSpec(name, name, "object_order") for name in BASELINE_VARIANTS),
    MethodSpec("oracle", None, "scripted"),
    MethodSpec("random", None, "scripted"),
)}


def method_spec(name: str) -> MethodSpec:
    """The method called ``name``; a ConfigError listing the known ones otherwise."""
    if name not in METHODS:
        raise ConfigError(f"method: unknown method {name!r}; choose one of {', '.join(METHODS)}")
    return METHODS[name]


def policy_dir(root: Path, variant: Variant, task: Task) -> Path:
    """Where variant ``variant``'s ``task`` policy is trained (``root/variant/task``)."""
    return root / variant / task


@dataclass
class TrainedPolicies:
    """A variant's frozen policies: pick and drop skills and (for a learned decision) the decision policy."""

    pick: Skill
    drop: Skill
    decision: Skill | None

    @classmethod
    def load(cls, root: Path, variant: Variant, n_objects: int, arena: str, lnet_version: str | None,
             with_decision: bool, deterministic: bool = True, zero_shot: bool = False) -> TrainedPolicies:
        """Load ``root/variant/{pick,drop,decision}/policy.pth``, each checked against its ``meta.json``
        (zero_shot: trained in another arena and through another L-Net, ``ZERO_SHOT_FIELDS``)."""
        skills: dict[str, Skill | None] = {"decision": None}
        allow = ZERO_SHOT_FIELDS if zero_shot else ()
        for task in TASKS if with_decision else ("pick", "drop"):
            folder = policy_dir(root, variant, task)
            check_signature(folder / "meta.json", PolicySignature.of(task, variant, n_objects, arena, lnet_version),
                            allow)
            skills[task] = Skill.load(folder / POLICY_FILE, deterministic)
        return cls(skills["pick"], skills["drop"], skills["decision"])

    @classmethod
    def load_baseline(cls, root: Path, variant: BaselineVariant, n_objects: int, arena: str, image_size: int,
                      deterministic: bool = True) -> TrainedPolicies:
        """A baseline's skills (``MethodSpec.skill_owners``: ``PICK_FROM``'s pick and its own drop), each checked
        against its ``meta.json``."""
        skills = {}
        for task, owner in METHODS[variant].skill_owners().items():
            folder = policy_dir(root, owner, task)
            check_signature(folder / "meta.json",
                            PolicySignature.of_baseline(task, owner, n_objects, arena, image_size))
            skills[task] = Skill.load(folder / POLICY_FILE, deterministic)
        return cls(skills["pick"], skills["drop"], None)
