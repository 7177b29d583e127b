"""What a trained policy was trained on, stored beside its weights and checked when it is loaded."""

from __future__ import annotations

import json
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from mor.atomic import atomic_output
from mor.errors import ConfigError
from mor.policy.features import ObservationLayout, feature_names
from mor.policy.names import Task
from mor.policy.params import ObservationParams
from mor.policy.variants import Variant


class PolicySignature(BaseModel):
    """A policy's observation layout and world: a checkpoint loads only where all of these match. ``features``: the
    observation settings it was trained with (``policy.observation``; a file from before they were settings has
    none, and was trained with their defaults)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    task: Task
    variant: str
    n_objects: int
    arena: str
    observation: list[str]
    lnet_version: str | None = None
    features: ObservationParams = Field(default_factory=ObservationParams)

    @classmethod
    def of(cls, task: Task, variant: Variant, n_objects: int, arena: str, lnet_version: str | None,
           features: ObservationParams) -> PolicySignature:
        """A pose variant's: its ``feature_names`` in its layout with ``features`` (the profile's
        ``policy.observation``); ``lnet_version`` only where it observes through the L-Net."""
        names = feature_names(task, n_objects, ObservationLayout.of(variant, features))
        return cls(task=task, variant=variant.name, n_objects=n_objects, arena=arena, observation=names,
                   lnet_version=lnet_version if variant.uses_lnet else None, features=features)

    @classmethod
    def of_baseline(cls, task: Task, variant: Variant, n_objects: int, arena: str, image_size: int
                    ) -> PolicySignature:
        """A baseline skill's: its observation is ``mor.policy.baselines.baseline_space``, named key(shape)."""
        from mor.policy.baselines import baseline_space  # noqa: PLC0415 - torch-free callers

        space = baseline_space(task, variant.baseline_input, (image_size, image_size, 3), 1.0)
        names = [f"{key}{list(value.shape or (int(value.n),))}" for key, value in space.spaces.items()]
        return cls(task=task, variant=variant.name, n_objects=n_objects, arena=arena, observation=names)


def write_signature(path: Path, signature: PolicySignature) -> None:
    with atomic_output(path) as partial:
        partial.write_text(json.dumps(signature.model_dump(), indent=2) + "\n")


def read_signature(path: Path) -> PolicySignature:
    """The signature stored at ``path`` (a policy's meta.json); ConfigError naming it when it is missing."""
    if not path.is_file():
        raise ConfigError(f"{path}: no such policy metadata; train the policy first (mor policy train)")
    return PolicySignature.model_validate(json.loads(path.read_text()))


#: what a zero-shot evaluation (a policy played in another arena, through that arena's L-Net) may differ in
ZERO_SHOT_FIELDS = ("arena", "lnet_version")


def check_signature(path: Path, expected: PolicySignature, allow: tuple[str, ...] = ()) -> None:
    """Raise ConfigError naming both sides when the policy at ``path`` (its meta.json) was trained otherwise
    (``allow``: fields that may differ, e.g. ``ZERO_SHOT_FIELDS``)."""
    found = read_signature(path)
    named = {"features": "policy.observation"}  # the params.yaml key of a signature field, where it has one
    for field in (f for f in ("task", "variant", "n_objects", "arena", "lnet_version", "features") if f not in allow):
        have, want = getattr(found, field), getattr(expected, field)
        if field == "features" and have != want:
            key = next(k for k in ObservationParams.model_fields if getattr(have, k) != getattr(want, k))
            field, have, want = f"{named[field]}.{key}", getattr(have, key), getattr(want, key)
        if have != want:
            raise ConfigError(f"{path}: the policy was trained with {field}={have!r} but this run needs {want!r}; "
                              "retrain it (mor policy train) or choose matching settings")
    if found.observation != expected.observation:
        raise ConfigError(f"{path}: the policy's observation layout ({len(found.observation)} features) differs from "
                          f"this version's ({len(expected.observation)}); retrain it (mor policy train)")
