"""Typed parameters: the profiles of ``params.yaml`` (tiny, default, paper), validated with one-line errors."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from mor.data.exploration import ExplorationParams
from mor.errors import ConfigError
from mor.lnet.params import LNetParams
from mor.sim.config import SimConfig, format_validation_error

DEFAULT_PARAMS = Path("params.yaml")
PROFILES: tuple[str, ...] = ("tiny", "default", "paper")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class OracleParams(_Strict):
    """The scripted oracle's evaluation: ``episodes`` per seed, mean +- std over ``seeds``."""

    episodes: int = Field(100, ge=1, le=100_000)
    seeds: list[int] = Field(default_factory=lambda: [0, 1, 2, 3, 4], min_length=1)


class DemoParams(_Strict):
    """The rendered demo episode of ``make repro``."""

    task: Literal["pick", "drop", "rearrange"] = "rearrange"
    policy: Literal["oracle", "random"] = "oracle"
    seed: int = 0
    fps: int = Field(8, ge=1, le=60)


class CollectParams(_Strict):
    """Random-action data collection (stage ``collect``)."""

    episodes: int = Field(2000, ge=1, le=1_000_000)
    episode_steps: int = Field(150, ge=1, le=100_000, description="actions per episode (frames = steps + 1)")
    seed: int = Field(0, ge=0)
    fps: float = Field(10.0, gt=0.0, le=120.0, description="frame rate of the records and datasets")
    workers: int = Field(2, ge=1, le=1024)
    backend: Literal["process", "ray"] = "process"
    exploration: ExplorationParams = Field(default_factory=ExplorationParams)


class BuildParams(_Strict):
    """Manifest, LeRobot splits and dataset card (stage ``build``)."""

    workers: int = Field(2, ge=1, le=1024)
    shard_episodes: int = Field(100, ge=1, description="episodes per build shard (the unit of resumption)")


class Profile(_Strict):
    """One scale profile: every stage's parameters."""

    sim: SimConfig = Field(default_factory=SimConfig)
    oracle: OracleParams = Field(default_factory=OracleParams)
    demo: DemoParams = Field(default_factory=DemoParams)
    collect: CollectParams = Field(default_factory=CollectParams)
    build: BuildParams = Field(default_factory=BuildParams)
    lnet: LNetParams = Field(default_factory=LNetParams)


def load_profile(name: str, path: Path = DEFAULT_PARAMS) -> Profile:
    """Profile ``name`` from ``path`` (params.yaml); raises ConfigError naming the file and the field."""
    if not path.is_file():
        raise ConfigError(f"{path}: no such parameters file; run from the repository root or pass --params")
    try:
        document: Any = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise ConfigError(f"{path}: not valid YAML ({error.__class__.__name__}); fix the syntax") from None
    profiles = document.get("profiles") if isinstance(document, dict) else None
    if not isinstance(profiles, dict):
        raise ConfigError(f"{path}: expected a top-level 'profiles' mapping with {', '.join(PROFILES)}")
    if name not in profiles:
        raise ConfigError(f"{path}: profiles.{name}: no such profile; choose one of {', '.join(profiles)}")
    try:
        return Profile.model_validate(profiles[name] or {})
    except ValidationError as error:
        raise ConfigError(format_validation_error(error, f"{path}: profiles.{name}")) from None
