"""The simulator's parameters: one validated record shared by the envs, ``params.yaml`` and the CLI."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, ValidationError

from mor.errors import ConfigError
from mor.params_model import ParamsModel


class RewardParams(ParamsModel):
    """The weights of the tasks' rewards (paper Eq. 1 and 2, ``mor.sim.tasks``), in reward units; the defaults are
    the paper's."""

    success: float = Field(10.0, ge=0.0, description="paid for a success: Pick's goal object picked, Drop's object "
                           "dropped at its target, and in Rearrange per object newly lying at its target (taken back "
                           "when it leaves)")
    collision: float = Field(1.0, ge=0.0, description="taken on a step whose MOVE was obstructed (every task)")
    step: float = Field(0.01, ge=0.0, description="taken on every Rearrange step (Eq. 2); Pick and Drop have none "
                        "(Eq. 1)")


class SimConfig(ParamsModel):
    """What a world looks like, and what its tasks pay (``rewards``). Distances in metres, image size in pixels
    (square images)."""

    n_objects: int = Field(3, ge=1, le=5, description="objects per episode")
    image_size: int = Field(64, ge=16, le=512, description="first-person image side, pixels")
    arena: Literal["square", "polygon"] = Field("square", description="arena shape")
    arena_size: float = Field(6.0, gt=0.0, le=50.0, description="side of the arena's bounding square, metres")
    texture_pool: Literal["per_side", "symmetric"] = Field(
        "per_side", description="per_side: each wall side has its own texture sub-pool; symmetric: one shared pool"
    )
    landmark: bool = Field(False, description="show a non-colliding marker at each drop target (paper Figure 4)")
    rewards: RewardParams = Field(default_factory=RewardParams, description="the tasks' reward weights; they shape "
                                  "no frame, so collected data does not record them (mor.data.collect)")


def format_validation_error(error: ValidationError, where: str) -> str:
    """One line naming the first offending field of ``error`` under ``where`` and what is wrong with it."""
    first = error.errors()[0]
    place = ": ".join(part for part in (where, ".".join(str(p) for p in first["loc"])) if part)
    prefix = f"{place}: " if place else ""
    if first["type"] == "extra_forbidden":
        return f"{prefix}unknown key; remove it or fix its spelling"
    value = first.get("input")  # a mapping is the model's own input (a missing field, a check across fields): not shown
    shown = "" if isinstance(value, dict) else f" (got {value!r})"
    return f"{prefix}{first['msg'].removeprefix('Value error, ')}{shown}"


def make_sim_config(where: str = "", **values: object) -> SimConfig:
    """A validated ``SimConfig``; raises ``ConfigError`` with one line naming the bad field."""
    try:
        return SimConfig(**values)
    except ValidationError as error:
        raise ConfigError(format_validation_error(error, where)) from None
