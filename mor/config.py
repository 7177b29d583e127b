"""Typed parameters: the profiles of ``params.yaml`` (tiny, default, paper), validated with one-line errors."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal, TypeVar

import yaml
from pydantic import BaseModel, Field, ValidationError, model_validator

from mor.data.exploration import ExplorationParams
from mor.errors import ConfigError
from mor.lnet.params import LNetParams
from mor.params_model import ParamsModel, Seeds
from mor.policy.params import EvalParams, PolicyParams
from mor.robot.params import RobotParams
from mor.sim.config import SimConfig, format_validation_error

DEFAULT_PARAMS = Path("params.yaml")
PROFILES: tuple[str, ...] = ("tiny", "default", "paper")


class OracleParams(ParamsModel):
    """The scripted oracle's evaluation: ``episodes`` per seed, mean +- std over ``seeds``."""

    episodes: int = Field(100, ge=1, le=100_000)
    seeds: Seeds = Field(default_factory=lambda: [0, 1, 2, 3, 4])


class DemoParams(ParamsModel):
    """The rendered demo episode of ``make repro``."""

    task: Literal["pick", "drop", "rearrange"] = "rearrange"
    policy: Literal["oracle", "random"] = "oracle"
    seed: int = Field(0, ge=0)
    fps: int = Field(8, ge=1, le=60)


class CollectParams(ParamsModel):
    """Random-action data collection (stage ``collect``)."""

    episodes: int = Field(2000, ge=1, le=1_000_000)
    episode_steps: int = Field(150, ge=1, le=100_000, description="actions per episode (frames = steps + 1)")
    seed: int = Field(0, ge=0)
    fps: float = Field(10.0, gt=0.0, le=120.0, description="frame rate of the records and datasets")
    workers: int = Field(2, ge=1, le=1024)
    backend: Literal["process", "ray"] = "process"
    exploration: ExplorationParams = Field(default_factory=ExplorationParams)


class BuildParams(ParamsModel):
    """Manifest, LeRobot splits and dataset card (stage ``build``)."""

    workers: int = Field(2, ge=1, le=1024)
    shard_episodes: int = Field(100, ge=1, description="episodes per build shard (the unit of resumption)")


class SettingParams(ParamsModel):
    """How a setting's workspace (``mor --setting NAME``: paper Tables 3 and 4) reuses the main workspace's work.

    Paths of the main workspace are ``pipelines.paths.MAIN`` (two folders up from ``settings/NAME/``).
    """

    lnet_from_main: bool = Field(False, description="observe through the main workspace's L-Net (no data or L-Net "
                                                    "of the setting's own)")
    finetune_from_main: bool = Field(False, description="every variant's policies start from the main workspace's "
                                                        "policy of the same variant and task and train the "
                                                        "profile's policy.finetune_steps more")


class Profile(ParamsModel):
    """One scale profile: every stage's parameters (``setting``: only in a setting's workspace)."""

    sim: SimConfig = Field(default_factory=SimConfig)
    oracle: OracleParams = Field(default_factory=OracleParams)
    demo: DemoParams = Field(default_factory=DemoParams)
    collect: CollectParams = Field(default_factory=CollectParams)
    build: BuildParams = Field(default_factory=BuildParams)
    lnet: LNetParams = Field(default_factory=LNetParams)
    policy: PolicyParams = Field(default_factory=PolicyParams)
    evaluate: EvalParams = Field(default_factory=EvalParams)
    robot: RobotParams = Field(default_factory=RobotParams)
    setting: SettingParams | None = None

    @model_validator(mode="after")
    def _detection_needs_the_visibility_head(self) -> Profile:
        if self.policy.observation.pick_visibility and not self.lnet.model.visibility:
            raise ValueError("policy.observation.pick_visibility: true reads the L-Net's visibility head; set "
                             "lnet.model.visibility: true (a new L-Net) or pick_visibility: false")
        return self


Model = TypeVar("Model", bound=BaseModel)


def validated(model: type[Model], where: str, **values: Any) -> Model:
    """``model(**values)``; raises ConfigError with one line naming ``where`` and the bad field."""
    try:
        return model(**values)
    except ValidationError as error:
        raise ConfigError(format_validation_error(error, where)) from None


def _read_params(path: Path) -> dict[str, Any]:
    """The parameters file as a mapping with a ``profiles`` mapping; ConfigError naming the file otherwise."""
    if not path.is_file():
        raise ConfigError(f"{path}: no such parameters file; run from the repository root or pass --params")
    try:
        document: Any = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise ConfigError(f"{path}: not valid YAML ({error.__class__.__name__}); fix the syntax") from None
    profiles = document.get("profiles") if isinstance(document, dict) else None
    if not isinstance(profiles, dict):
        raise ConfigError(f"{path}: expected a top-level 'profiles' mapping with {', '.join(PROFILES)}")
    return document


def _profile_name(document: dict[str, Any], name: str | None, path: Path) -> str:
    """``name`` (an explicit ``--profile``) or else the file's ``profile:``, checked to be one of its profiles."""
    if name is None:
        name = document.get("profile")
        if not isinstance(name, str):
            raise ConfigError(f"{path}: profile: expected the name of the active profile (e.g. 'profile: default'); "
                              "set it or pass --profile")
    if name not in document["profiles"]:
        raise ConfigError(f"{path}: profiles.{name}: no such profile; choose one of {', '.join(document['profiles'])}")
    return name


def active_profile(name: str | None = None, path: Path = DEFAULT_PARAMS) -> str:
    """The profile in force: ``name`` when given (an explicit ``--profile``), else ``profile:`` in ``path``.

    ``profile:`` in params.yaml is the one source that both the DVC stages and the ``mor`` commands read.
    """
    return _profile_name(_read_params(path), name, path)


def load_profile(name: str | None = None, path: Path = DEFAULT_PARAMS) -> Profile:
    """Profile ``name`` (default: the file's active ``profile:``) from ``path`` (params.yaml); raises ConfigError
    naming the file and the field."""
    document = _read_params(path)
    name = _profile_name(document, name, path)
    try:
        return Profile.model_validate(document["profiles"][name] or {})
    except ValidationError as error:
        raise ConfigError(format_validation_error(error, f"{path}: profiles.{name}")) from None


def deep_merge(base: dict[str, Any], overlay: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``overlay``'s values, mappings merged key by key (neither argument is changed)."""
    merged = dict(base)
    for key, value in overlay.items():
        merged[key] = deep_merge(merged[key], value) if isinstance(value, dict) and isinstance(
            merged.get(key), dict) else value
    return merged


def setting_document(path: Path, setting: str) -> dict[str, Any]:
    """The parameters file at ``path`` with ``settings.<setting>`` merged into every profile (and no ``settings``):
    the params.yaml of that setting's workspace. ConfigError naming the file when there is no such setting."""
    document = _read_params(path)
    settings = document.get("settings") or {}
    if setting not in settings:
        known = ", ".join(settings) or "none"
        raise ConfigError(f"{path}: settings.{setting}: no such setting; choose one of {known}")
    overlay = settings[setting] or {}
    if not isinstance(overlay, dict):
        raise ConfigError(f"{path}: settings.{setting}: expected a mapping of profile overrides")
    profiles = {name: deep_merge(values or {}, overlay) for name, values in document["profiles"].items()}
    return {**{k: v for k, v in document.items() if k != "settings"}, "profiles": profiles}
