"""Where the ArUco tags of the paper's real arena (Supplementary D) are, and where the top camera that sees them is.

One description serves the real arena and its stand-in, the simulator's top-down view (``mor.sim.topdown``):
four corner tags at known positions of the arena frame (metres: x east, y north), one tag on top of the robot
(its x axis along the robot's heading, ``agent_yaw_rad`` otherwise), one on top of each object. Raised tags are
seen displaced away from the camera (parallax); the detector corrects it from the camera's position and the tags'
heights. The sizes and the camera's image are what the simulator draws; a real detector does not need them.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from mor.params_model import ParamsModel

#: OpenCV's predefined ArUco dictionaries that a tag layout may name: name -> (bits per side, number of ids).
DICTIONARIES: dict[str, tuple[int, int]] = {
    f"DICT_{bits}X{bits}_{count}": (bits, count) for bits in (4, 5, 6) for count in (50, 100, 250)}

Point2 = list[float]


def _point(value: list[float], size: int, what: str) -> list[float]:
    if len(value) != size:
        raise ValueError(f"{what} needs {size} coordinates (metres), got {len(value)}")
    return value


class ArucoTags(ParamsModel):
    """The tags' ids, positions and heights (metres, arena frame); sizes are the simulator's."""

    dictionary: Literal[tuple(DICTIONARIES)] = Field(  # type: ignore[valid-type]
        "DICT_4X4_50", description="OpenCV's predefined dictionary of every tag")
    corner_ids: list[int] = Field(default_factory=lambda: [0, 1, 2, 3], min_length=4,
                                  description="ids of the corner tags (south-west, south-east, north-east, north-west)")
    corner_positions: list[Point2] = Field(
        default_factory=lambda: [[-3.3, -3.3], [3.3, -3.3], [3.3, 3.3], [-3.3, 3.3]],
        description="(x, y) of each corner tag's centre on the floor, in corner_ids' order, metres")
    agent_id: int = Field(10, ge=0, description="id of the tag on top of the robot")
    object_ids: list[int] = Field(default_factory=lambda: [20, 21, 22, 23, 24], min_length=1, max_length=5,
                                  description="id of the tag on object i (in the task's object order)")
    agent_height_m: float = Field(0.142, ge=0.0, description="height of the robot's tag above the floor")
    object_height_m: float = Field(0.252, ge=0.0, description="height of the objects' tags above the floor")
    agent_yaw_rad: float = Field(0.0, ge=-3.1416, le=3.1416,
                                 description="the robot's heading minus its tag's x axis (radians)")
    agent_size_m: float = Field(0.22, gt=0.0, le=1.0, description="side of the robot's tag with its white margin (sim)")
    object_size_m: float = Field(0.2, gt=0.0, le=1.0, description="side of an object's tag with its margin (sim)")
    corner_size_m: float = Field(0.36, gt=0.0, le=2.0, description="side of a corner tag with its margin (sim)")

    @field_validator("corner_positions")
    @classmethod
    def _corners(cls, value: list[Point2]) -> list[Point2]:
        return [_point(p, 2, "a corner position") for p in value]

    @model_validator(mode="after")
    def _consistent(self) -> ArucoTags:
        if len(self.corner_positions) != len(self.corner_ids):
            raise ValueError(f"corner_positions: needs one (x, y) per corner id ({len(self.corner_ids)}), "
                             f"got {len(self.corner_positions)}")
        ids = [*self.corner_ids, self.agent_id, *self.object_ids]
        repeated = sorted({i for i in ids if ids.count(i) > 1})
        if repeated:
            raise ValueError(f"tag ids must be distinct across corner_ids, agent_id and object_ids; {repeated[0]} "
                             "is used twice")
        count = DICTIONARIES[self.dictionary][1]
        if max(ids) >= count or min(ids) < 0:
            raise ValueError(f"tag ids of {self.dictionary} lie in [0, {count}); got {max(ids)}")
        return self

    def role(self, tag_id: int) -> str | None:
        """'corner', 'agent', 'object' or None (an id of no tag of this layout)."""
        if tag_id in self.corner_ids:
            return "corner"
        if tag_id == self.agent_id:
            return "agent"
        return "object" if tag_id in self.object_ids else None


class TopCamera(ParamsModel):
    """The overhead camera: its optical centre (the detector's parallax correction, real or simulated) and the
    simulator's image of it, looking straight down, image up = north."""

    position_m: list[float] = Field(default_factory=lambda: [0.0, 0.0, 6.5],
                                    description="(x, y, z) of the camera's optical centre, arena frame, metres")
    width: int = Field(1280, ge=64, le=4096, description="image width, pixels (sim)")
    height: int = Field(960, ge=64, le=4096, description="image height, pixels (sim)")
    view_half_extent_m: float = Field(3.6, gt=0.0, le=50.0,
                                      description="half the floor's north-south extent the image covers (sim)")

    @field_validator("position_m")
    @classmethod
    def _position(cls, value: list[float]) -> list[float]:
        _point(value, 3, "the camera position")
        if value[2] <= 0.0:
            raise ValueError(f"the camera must be above the floor (z > 0), got z = {value[2]}")
        return value


__all__ = ["DICTIONARIES", "ArucoTags", "TopCamera"]
