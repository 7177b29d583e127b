"""Replaying recorded runs: bad bags are one line naming the bag and what is missing; the CLI's errors too."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap_ros2.writer import Writer as Ros2Writer
from robot_helpers import hide_tags, paste
from typer.testing import CliRunner

from mor.config import Profile
from mor.data.real import RealBagError
from mor.data.ros2_messages import MSGDEFS, twist
from mor.errors import MorError
from mor.robot.aruco import TagDetector
from mor.robot.evaluate import make_controller
from mor.robot.policy import HierarchyPolicy
from mor.robot.pose import Frame, RobotTask
from mor.robot.recording import RunInfo, RunRecorder
from mor.robot.replay import replay_bag
from mor.sim.topdown import tag_image
from pipelines.cli import app


def _recording(path: Path, profile: Profile, frames: list[Frame], task: RobotTask) -> Path:
    """A controller-style recording of ``frames`` (the top camera only) with the task's metadata."""
    info = RunInfo("bad", "real", "test", "gt_pose", task, profile.sim.image_size, 10.0)
    with RunRecorder(path, None, info, profile.robot.top_image_topic) as recorder:
        for k, frame in enumerate(frames):
            recorder.add_last(Frame(frame.time_ns + k, frame.held, frame.top_down))
    return path


def _replay(profile: Profile, policy: HierarchyPolicy, bag: Path, tmp_path: Path, task: RobotTask | None = None):
    return replay_bag(bag, make_controller(profile.robot, "aruco", policy), profile.robot, task,
                      tmp_path / "replay.mcap", tmp_path / "episodes", profile.sim.image_size, 10.0)


def _one_line(caught: pytest.ExceptionInfo, bag: Path, *needles: str) -> None:
    message = str(caught.value)
    assert isinstance(caught.value, RealBagError) and "\n" not in message and str(bag) in message, message
    for needle in needles:
        assert needle in message, message


def test_a_bag_without_the_top_camera_names_the_topic(profile: Profile, gt_policy: HierarchyPolicy,
                                                      first_frame: tuple[Frame, RobotTask], tmp_path: Path) -> None:
    bag = tmp_path / "cmd_vel_only.mcap"
    with open(bag, "wb") as stream:
        writer = Ros2Writer(stream)
        schema = writer.register_msgdef("geometry_msgs/msg/Twist", MSGDEFS["geometry_msgs/msg/Twist"])
        writer.write_message("/cmd_vel", schema, twist(0.1, 0.0), log_time=1, publish_time=1)
        writer.finish()
    with pytest.raises(MorError) as caught:
        _replay(profile, gt_policy, bag, tmp_path, first_frame[1])
    _one_line(caught, bag, f"'{profile.robot.top_image_topic}'", "robot.top_image_topic")
    with pytest.raises(MorError) as caught:
        _replay(profile, gt_policy, bag, tmp_path)
    _one_line(caught, bag, "--object-classes and --targets")


def test_unknown_or_missing_tag_ids_are_one_line_errors(profile: Profile, gt_policy: HierarchyPolicy,
                                                        first_frame: tuple[Frame, RobotTask], tmp_path: Path) -> None:
    frame, task = first_frame
    stray = np.repeat(tag_image(profile.robot.tags.dictionary, 33, cell_px=5)[:, :, None], 3, 2)
    bag = _recording(tmp_path / "stray.mcap", profile, [frame, paste(frame, stray, (30, 400))], task)
    with pytest.raises(MorError) as caught:
        _replay(profile, gt_policy, bag, tmp_path)
    _one_line(caught, bag, "frame 1", "tag id(s) [33]", "robot.tags")
    assert not (tmp_path / "replay.mcap").exists()

    blind = hide_tags(frame, TagDetector(profile.robot.tags), [profile.robot.tags.agent_id])
    bag = _recording(tmp_path / "no_robot.mcap", profile, [blind, blind], task)
    with pytest.raises(MorError) as caught:
        _replay(profile, gt_policy, bag, tmp_path)
    _one_line(caught, bag, f"robot.tags.agent_id {profile.robot.tags.agent_id}", "never shows")


def test_the_cli_fails_in_one_line(tmp_path: Path) -> None:
    runner = CliRunner()
    for args, needle in ((["robot", "run", "--object-classes", "0,7,13", "--targets", "1,1;-1,2;0,-1.5"], "rclpy"),
                         (["robot", "sim", "--loop", "sideways"], "--loop: unknown loop 'sideways'"),
                         (["robot", "sim", "--method", "oracle"], "does not read a pose belief"),
                         (["robot", "sim", "--loop", "fpv_lnet", "--method", "gt_pose"], "trained on the truth"),
                         (["robot", "replay", str(tmp_path / "nope.mcap")], "no such file")):
        result = runner.invoke(app, args)
        lines = result.output.strip().splitlines()
        assert result.exit_code == 2 and len(lines) == 1 and needle in lines[0], (args, result.output)
