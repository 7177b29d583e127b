"""The robot controller's parameters: the ``robot:`` section of a params.yaml profile (``mor.config.Profile``).

Units: metres, seconds, radians. The step sizes default to the simulator's (``mor.sim.rules.MotionNoise``: a MOVE
of 0.15 m, a turn of 10 degrees, the paper's Supplementary D), so that a policy trained in simulation commands the
robot the motion it was trained on.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from mor.params_model import ParamsModel
from mor.sim.rules import MotionNoise
from mor.sim.tags import ArucoTags, TopCamera

_SIM_STEP = MotionNoise()


class ActuatorParams(ParamsModel):
    """How a discrete action becomes geometry_msgs/Twist segments: drive at a speed for distance / speed seconds,
    then a zero Twist; PICK and DROP are events for a gripper or an operator."""

    move_distance_m: float = Field(_SIM_STEP.move_mean, gt=0.0, le=1.0, description="a MOVE's forward distance")
    turn_angle_rad: float = Field(_SIM_STEP.turn_mean, gt=0.0, le=3.1416, description="a turn's angle")
    linear_speed_mps: float = Field(0.1, gt=0.0, le=0.22, description="forward speed (TurtleBot3 Burger: <= 0.22)")
    angular_speed_radps: float = Field(0.5, gt=0.0, le=2.84, description="turn rate (TurtleBot3 Burger: <= 2.84)")
    settle_s: float = Field(0.3, ge=0.0, le=10.0, description="wait after a segment before the next frame is used")
    event_s: float = Field(2.0, ge=0.0, le=60.0, description="time given to a PICK or DROP event")


class SafetyParams(ParamsModel):
    """When the controller stops: it never acts on a frame without a fresh pose."""

    lost_frames: int = Field(3, ge=1, le=1000, description="frames without a pose after which a stop is sent")
    give_up_frames: int = Field(30, ge=1, le=100_000,
                                description="frames without a pose after which the run ends (a replay or the "
                                            "simulator sees the same frame again)")


class RobotParams(ParamsModel):
    """The controller: its tags and top camera, the actuator, the safety stop, the ArUco corner refinement and the
    live node's top-camera topic (the other topics are ``mor.data.real.RealTopics``)."""

    tags: ArucoTags = Field(default_factory=ArucoTags)
    top_camera: TopCamera = Field(default_factory=TopCamera)
    actuator: ActuatorParams = Field(default_factory=ActuatorParams)
    safety: SafetyParams = Field(default_factory=SafetyParams)
    corner_refinement: Literal["contour", "subpix", "none"] = Field(
        "contour", description="cv2.aruco corner refinement (contour: the most accurate heading, docs/robot.md)")
    top_image_topic: str = Field("/top_camera/image_raw/compressed", min_length=1,
                                 description="the top camera's sensor_msgs/CompressedImage topic (live node, replay)")

    @model_validator(mode="after")
    def _tags_below_camera(self) -> RobotParams:
        height = self.top_camera.position_m[2]
        if max(self.tags.agent_height_m, self.tags.object_height_m) >= height:
            raise ValueError(f"tags: agent_height_m and object_height_m must lie below the top camera "
                             f"(top_camera.position_m z = {height})")
        return self


__all__ = ["ActuatorParams", "RobotParams", "SafetyParams"]
