"""The methods the protocol can score, each defined once, and loading a method's committed policies.

A method is a policy variant (``mor.policy.variants``) plus a decision rule, as Habitat-lab's high-level policies
are: ``learned`` (the variant's decision policy), ``nearest_rule`` (the nearest unfixed object), ``object_order``
(a baseline, which holds no pose estimate, takes the objects in index order) or ``scripted`` (the simulator's
``oracle`` and ``random``, no variant).
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from mor.errors import ConfigError
from mor.policy.hierarchy import POLICY_FILE, Skill
from mor.policy.names import TASKS, Task
from mor.policy.params import ObservationParams
from mor.policy.signature import ZERO_SHOT_FIELDS, PolicySignature, check_signature
from mor.policy.variants import VARIANTS, Variant, policy_folder
from mor.policy.workspace import Workspace, committed_lnet
from mor.sim.arena import Arena

if TYPE_CHECKING:
    from mor.config import Profile
    from mor.lnet.runtime import LNetRunner
    from mor.policy.observations import BatchTracker

Decision = Literal["learned", "nearest_rule", "object_order", "scripted"]

#: the variants also scored with the nearest-unfixed-object rule in place of their learned decision (Table 1's
#: check that the decision policy earns its place)
NEAREST_RULE_VARIANTS = ("gt_pose", "lnet")
RULE_SUFFIX = "_nearest_rule"


@dataclass(frozen=True)
class Method:
    name: str
    variant: Variant | None  # None for the scripted policies
    decision: Decision

    @property
    def is_baseline(self) -> bool:
        return self.variant is not None and self.variant.is_baseline

    @property
    def uses_lnet(self) -> bool:
        """Observes the world through the L-Net's estimates."""
        return self.variant is not None and self.variant.uses_lnet

    def skill_owners(self) -> dict[Task, Variant]:
        """Whose trained policy each task this method plays is: the variant's own (the decision only where it is
        learned), a baseline's Pick its ``pick_from``'s; empty for the scripted policies."""
        if self.variant is None:
            return {}
        if self.is_baseline:
            return {"pick": VARIANTS[self.variant.pick_from or self.variant.name], "drop": self.variant}
        return {task: self.variant for task in TASKS if task != "decision" or self.decision == "learned"}


METHODS: dict[str, Method] = {method.name: method for method in (
    *(Method(v.name, v, "object_order" if v.is_baseline else "learned") for v in VARIANTS.values()),
    *(Method(name + RULE_SUFFIX, VARIANTS[name], "nearest_rule") for name in NEAREST_RULE_VARIANTS),
    Method("oracle", None, "scripted"),
    Method("random", None, "scripted"),
)}


def method_spec(name: str) -> Method:
    """The method called ``name``; a ConfigError listing the known ones otherwise."""
    if name not in METHODS:
        raise ConfigError(f"method: unknown method {name!r}; choose one of {', '.join(METHODS)}")
    return METHODS[name]


@dataclass
class TrainedPolicies:
    """A method's frozen policies: pick and drop skills and (for a learned decision) the decision policy; a skill
    ``load_method`` was not asked for (``tasks``) is None."""

    pick: Skill | None
    drop: Skill | None
    decision: Skill | None


@dataclass
class LoadedMethod:
    """A method ready to play: its policies (None for the scripted ones), a factory of trackers for n envs at once
    (``looks=True``: an L-Net tracker also keeps the search belief's looks, for pictures, whether or not the policy
    reads them), the L-Net it observes through and that L-Net's identity (None without one), the committed
    folder of each policy, and the observation settings its pose policies were checked against (the profile's
    ``policy.observation``)."""

    method: Method
    policies: TrainedPolicies | None = None
    tracker_factory: Callable[..., BatchTracker] | None = None
    lnet: LNetRunner | None = None
    folders: dict[Task, Path] = field(default_factory=dict)
    features: ObservationParams = field(default_factory=ObservationParams)

    @property
    def lnet_version(self) -> str | None:
        return None if self.lnet is None else self.lnet.identity

    def played_by(self) -> dict[str, Any]:
        """What plays its episodes, sealed into each record: the policy files' digests and the L-Net's identity."""
        if not self.folders:
            return {}
        return {"policies": policy_digests(self.folders), "lnet_version": self.lnet_version}


def policy_root(workspace: Workspace, zero_shot: bool) -> Path:
    """Where the policies a method plays are committed: the workspace's, or (zero-shot, only in a setting) the
    main workspace's."""
    if not zero_shot:
        return workspace.policy_card
    if not workspace.is_setting:
        raise ConfigError("--zero-shot: plays the main workspace's policies in a setting; run it as "
                          "mor --setting NAME eval run --method M --zero-shot")
    return workspace.main_policy_card


def policy_folders(method: Method, root: Path, training_seed: int = 0) -> dict[Task, Path]:
    """The committed folder of each policy a learned method plays (``Method.skill_owners``) in its run with
    ``training_seed``."""
    return {task: policy_folder(root, owner.name, task, training_seed)
            for task, owner in method.skill_owners().items()}


def policy_digests(folders: dict[Task, Path]) -> dict[str, str]:
    """task -> the digest (``mor.lnet.runtime.file_digest``) of the policy file in its folder."""
    from mor.lnet.runtime import file_digest  # noqa: PLC0415 - torch only where needed

    return {task: file_digest(folder / POLICY_FILE) for task, folder in folders.items()}


def load_method(method: Method, workspace: Workspace, profile: Profile, zero_shot: bool = False,
                training_seed: int = 0, tasks: Collection[Task] = TASKS) -> LoadedMethod:
    """``method``'s committed policies of its run with ``training_seed`` (each checked against its ``meta.json``:
    what it was trained on), its tracker factory and its L-Net; zero_shot: the main workspace's policies through
    this workspace's L-Net; tasks: the policies to load (a probe of one skill needs no other)."""
    if method.variant is None:
        return LoadedMethod(method)
    from mor.policy.observations import GroundTruthBatchTracker, RenderingTruthTracker  # noqa: PLC0415

    sim, deterministic, features = profile.sim, profile.policy.skills_deterministic, profile.policy.observation
    folders = {task: folder for task, folder in policy_folders(method, policy_root(workspace, zero_shot),
                                                                training_seed).items() if task in tasks}
    runner = committed_lnet(workspace, method.variant, profile.lnet)
    version, stated = (runner.identity, runner.stated_identity) if runner is not None else (None, None)
    allow = ZERO_SHOT_FIELDS if zero_shot else ()
    skills: dict[str, Skill] = {}
    for task, folder in folders.items():
        owner = method.skill_owners()[task]
        expected = (PolicySignature.of_baseline(task, owner, sim.n_objects, sim.arena, sim.image_size)
                    if owner.is_baseline else PolicySignature.of(task, owner, sim.n_objects, sim.arena, version,
                                                                 features, stated))
        check_signature(folder / "meta.json", expected, allow)
        skills[task] = Skill.load(folder / POLICY_FILE, deterministic)
    policies = TrainedPolicies(skills.get("pick"), skills.get("drop"), skills.get("decision"))
    if runner is not None:
        from mor.policy.lnet_tracking import LNetBatchTracker  # noqa: PLC0415

        arena, search = Arena.build(sim.arena, sim.arena_size), method.variant.search
        return LoadedMethod(method, policies,
                            lambda n, looks=False: LNetBatchTracker(runner, n, arena if search or looks else None),
                            runner, folders, features)
    tracker = RenderingTruthTracker if method.is_baseline else GroundTruthBatchTracker
    return LoadedMethod(method, policies, lambda n, looks=False: tracker(), None, folders, features)
