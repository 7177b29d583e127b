"""What a trained policy was trained on, stored beside its weights and checked when it is loaded."""

from __future__ import annotations

import json
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from mor.atomic import atomic_output
from mor.errors import ConfigError
from mor.policy.features import GATE_FIELDS, SEARCH_FIELDS, VISIBILITY_FIELDS, ObservationLayout, feature_names
from mor.policy.names import Task
from mor.policy.params import ObservationParams
from mor.policy.variants import VARIANTS, Variant


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
    stated_version: str | None = None
    features: ObservationParams = Field(default_factory=ObservationParams)

    @classmethod
    def of(cls, task: Task, variant: Variant, n_objects: int, arena: str, lnet_version: str | None,
           features: ObservationParams, stated_version: str | None = None) -> PolicySignature:
        """A pose variant's: its ``feature_names`` in its layout with ``features`` (the profile's
        ``policy.observation``); ``lnet_version`` only where it observes through the L-Net, ``stated_version``
        (``mor.lnet.runtime.stated_identity``) only where it reads the stated belief too (``Variant.search``)."""
        layout = ObservationLayout.of(variant, features)
        return cls(task=task, variant=variant.name, n_objects=n_objects, arena=arena,
                   observation=feature_names(task, n_objects, layout),
                   lnet_version=lnet_version if variant.uses_lnet else None,
                   stated_version=stated_version if variant.search else None, features=layout.recorded_features(task))

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


def warm_start_names(path: Path, signature: PolicySignature) -> list[str]:
    """The feature names of the policy whose meta.json is ``path``, for ``signature``'s policy to start from
    (``mor.policy.train.warm_start`` copies weights by name); ConfigError naming the setting where an observation
    setting that both layouts read differs (the same name would carry another quantity; the PICK gate masks an
    action and changes no feature, and the L-Net's detection adds features of its own names, so they may differ)."""
    source = read_signature(path)
    both_search = all(VARIANTS[s.variant].search for s in (source, signature) if s.variant in VARIANTS)
    fields = tuple(name for name in ObservationParams.model_fields
                   if (both_search or name not in SEARCH_FIELDS) and name not in GATE_FIELDS + VISIBILITY_FIELDS)
    _check_features(path, source.features, signature.features, fields)
    return source.observation


def _check_features(path: Path, have: ObservationParams, want: ObservationParams, fields: tuple[str, ...]) -> None:
    """ConfigError naming the first of ``fields`` (a ``policy.observation`` setting) that differs."""
    for name in fields:
        if getattr(have, name) != getattr(want, name):
            raise ConfigError(f"{path}: the policy was trained with policy.observation.{name}={getattr(have, name)!r} "
                              f"but this run needs {getattr(want, name)!r}; retrain it (mor policy train) or choose "
                              "matching settings")


#: what a zero-shot evaluation (a policy played in another arena, through that arena's L-Net) may differ in
ZERO_SHOT_FIELDS = ("arena", "lnet_version", "stated_version")


def check_signature(path: Path, expected: PolicySignature, allow: tuple[str, ...] = ()) -> None:
    """Raise ConfigError naming both sides when the policy at ``path`` (its meta.json) was trained otherwise
    (``allow``: fields that may differ, e.g. ``ZERO_SHOT_FIELDS``)."""
    found = read_signature(path)
    for field in (f for f in ("task", "variant", "n_objects", "arena", "lnet_version", "stated_version")
                  if f not in allow):
        have, want = getattr(found, field), getattr(expected, field)
        if have != want:
            raise ConfigError(f"{path}: the policy was trained with {field}={have!r} but this run needs {want!r}; "
                              "retrain it (mor policy train) or choose matching settings")
    _check_features(path, found.features, expected.features, tuple(ObservationParams.model_fields))
    if found.observation != expected.observation:
        raise ConfigError(f"{path}: the policy's observation layout ({len(found.observation)} features) differs from "
                          f"this version's ({len(expected.observation)}); retrain it (mor policy train)")
