"""The base of every parameter record (``params.yaml``, env keywords, CLI options): closed, immutable and strict, so
that ``episodes: true`` is refused rather than read as 1 (an integer still stands for a float); and the one type of
a list of seeds."""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator, BaseModel, ConfigDict, Field


class ParamsModel(BaseModel):
    """Unknown keys are refused, values are frozen, and no value is coerced to an int or a bool."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


def _distinct(seeds: list[int]) -> list[int]:
    repeated = sorted({seed for seed in seeds if seeds.count(seed) > 1})
    if repeated:
        raise ValueError(f"seeds must be distinct (each plays the same episodes); {repeated[0]} is listed twice")
    return seeds


#: One or more distinct non-negative seeds.
Seeds = Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=1), AfterValidator(_distinct)]
