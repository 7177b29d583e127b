"""Discrete actions as Twist segments, and the ``robot:`` parameters of params.yaml."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mor.config import PROFILES, Profile, load_profile, validated
from mor.errors import ConfigError
from mor.robot.actuator import Actuator
from mor.robot.params import RobotParams
from mor.sim.rules import Action, MotionNoise

PARAMS = Path(__file__).resolve().parents[2] / "params.yaml"


def test_actions_become_twist_segments_with_the_simulators_step_sizes(profile: Profile) -> None:
    params = profile.robot.actuator
    assert (params.move_distance_m, params.turn_angle_rad) == (MotionNoise().move_mean, MotionNoise().turn_mean)
    actuator = Actuator(params)
    move = actuator.command(Action.MOVE)
    drive, settle = move.segments
    assert drive.linear_mps * drive.duration_s == pytest.approx(0.15) and drive.angular_radps == 0.0
    assert settle.is_stop and settle.duration_s == params.settle_s and move.event is None
    for action, sign in ((Action.TURN_LEFT, 1.0), (Action.TURN_RIGHT, -1.0)):
        turn = actuator.command(action).segments[0]
        assert turn.angular_radps * turn.duration_s == pytest.approx(sign * np.deg2rad(10.0))
    for action in (Action.PICK, Action.DROP):
        event = actuator.command(action)
        assert event.event == action.name and all(s.is_stop for s in event.segments)


def test_every_profile_has_valid_robot_parameters() -> None:
    for name in PROFILES:
        assert isinstance(load_profile(name, PARAMS).robot, RobotParams)


@pytest.mark.parametrize(("values", "needle"), [
    ({"tags": {"agent_id": 0}}, "0 is used twice"),
    ({"tags": {"corner_positions": [[0.0, 0.0]] * 3}}, "corner_positions"),
    ({"tags": {"object_ids": [20, 60]}}, "lie in [0, 50)"),
    ({"tags": {"agent_height_m": 9.0}}, "below the top camera"),
    ({"top_camera": {"position_m": [0.0, 0.0]}}, "top_camera.position_m"),
    ({"actuator": {"linear_speed_mps": 1.0}}, "actuator.linear_speed_mps"),
    ({"safety": {"lost_frames": 0}}, "safety.lost_frames"),
    ({"actuator": {"speed": 1.0}}, "unknown key"),
])
def test_bad_robot_parameters_are_one_line_errors(values: dict, needle: str) -> None:
    with pytest.raises(ConfigError) as caught:
        validated(RobotParams, "params.yaml: profiles.default.robot", **values)
    message = str(caught.value)
    assert "\n" not in message and needle in message and message.startswith("params.yaml: profiles.default.robot")
