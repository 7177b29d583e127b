"""Poses from the top camera's ArUco tags, and the controller's refusal to act without a fresh pose."""

from __future__ import annotations

import logging

import cv2
import numpy as np
import pytest
from robot_helpers import hide_tags, paste

from mor.config import Profile
from mor.robot.actuator import Actuator
from mor.robot.aruco import ArenaLocalizer, TagDetector
from mor.robot.controller import Controller
from mor.robot.policy import HierarchyPolicy
from mor.robot.pose import ArucoPoseSource, Frame, RobotTask
from mor.sim.topdown import tag_image


def _source(profile: Profile) -> ArucoPoseSource:
    return ArucoPoseSource(profile.robot.tags, profile.robot.top_camera, profile.robot.corner_refinement)


def test_the_detected_poses_match_the_simulators_truth(profile: Profile, sim_robot) -> None:
    frame, task = sim_robot.reset(7)
    source = _source(profile)
    source.start(task)
    for action in (0, 1, 0):  # three frames: as placed, after a MOVE, after a turn
        reading = source.read(frame, -1)
        agent, objects = frame.truth
        assert np.linalg.norm(reading.agent_pose[:2] - agent[:2]) < 0.01
        assert abs(np.angle(np.exp(1j * (reading.agent_pose[2] - agent[2])))) < np.deg2rad(1.5)
        np.testing.assert_allclose(reading.object_positions, objects, atol=0.02)
        assert not reading.belief.agent_cov.any() and not reading.belief.object_cov.any()  # as gt_pose sees it
        frame = sim_robot.execute(Actuator(profile.robot.actuator).command(action))


def test_raised_tags_need_the_parallax_correction(profile: Profile, first_frame: tuple[Frame, RobotTask]) -> None:
    frame, _ = first_frame
    detections = TagDetector(profile.robot.tags).detect(frame.top_down)
    far = profile.robot.top_camera.model_copy(update={"position_m": [0.0, 0.0, 1e6]})  # no parallax correction
    corrected = ArenaLocalizer(profile.robot.tags, profile.robot.top_camera).locate(detections).agent_pose
    naive = ArenaLocalizer(profile.robot.tags, far).locate(detections).agent_pose
    truth = frame.truth[0]
    assert np.linalg.norm(corrected[:2] - truth[:2]) < 0.01 < np.linalg.norm(naive[:2] - truth[:2])


@pytest.mark.parametrize("hidden", ["corners", "agent"])
def test_without_corner_or_agent_tags_the_controller_stops_and_never_moves(
        hidden: str, profile: Profile, gt_policy: HierarchyPolicy, first_frame: tuple[Frame, RobotTask],
        caplog: pytest.LogCaptureFixture) -> None:
    frame, task = first_frame
    tags, safety = profile.robot.tags, profile.robot.safety
    blind = hide_tags(frame, TagDetector(tags), tags.corner_ids[:1] if hidden == "corners" else [tags.agent_id])
    controller = Controller(_source(profile), gt_policy, Actuator(profile.robot.actuator), safety)
    controller.start(task)
    with caplog.at_level(logging.WARNING):
        steps = [controller.step(blind) for _ in range(safety.lost_frames + 2)]
    assert all(step.command.action == -1 and all(s.is_stop for s in step.command.segments) for step in steps)
    assert [len(step.command.segments) for step in steps] == [0] * (safety.lost_frames - 1) + [1, 0, 0]
    want = f"corner tag(s) {tags.corner_ids[0]} not seen" if hidden == "corners" else f"agent tag {tags.agent_id}"
    assert want in steps[0].reading.problem
    stops = [r for r in caplog.records if "stop: no pose" in r.getMessage()]
    assert len(stops) == 1 and want in stops[0].getMessage()
    assert controller.step(frame).command.action >= 0  # the tags are back: it acts again


def test_a_tag_seen_twice_is_refused_for_that_frame(profile: Profile, first_frame: tuple[Frame, RobotTask],
                                                    caplog: pytest.LogCaptureFixture) -> None:
    frame, task = first_frame
    tags = profile.robot.tags
    corners = TagDetector(tags).detect(frame.top_down).corners_of(tags.agent_id)
    (x0, y0), (x1, y1) = np.floor(corners.min(0)).astype(int) - 4, np.ceil(corners.max(0)).astype(int) + 4
    twice = paste(frame, frame.top_down[y0:y1, x0:x1], (40, 40))  # the robot's tag again, outside the arena
    source = _source(profile)
    source.start(task)
    with caplog.at_level(logging.WARNING):
        reading = source.read(twice, -1)
    assert reading.belief is None and reading.problem == f"agent tag {tags.agent_id} seen twice: refused"
    assert reading.detections.refused == (tags.agent_id,)
    assert any("seen more than once" in r.getMessage() for r in caplog.records)


def test_an_unknown_tag_is_reported_and_ignored(profile: Profile, first_frame: tuple[Frame, RobotTask],
                                                caplog: pytest.LogCaptureFixture) -> None:
    frame, task = first_frame
    stray = cv2.resize(tag_image(profile.robot.tags.dictionary, 33), (40, 40), interpolation=cv2.INTER_NEAREST)
    source = _source(profile)
    source.start(task)
    with caplog.at_level(logging.WARNING):
        reading = source.read(paste(frame, np.repeat(stray[:, :, None], 3, 2), (30, 400)), -1)
    assert reading.detections.unknown == (33,) and reading.belief is not None
    assert any("tag 33 is no tag of robot.tags" in r.getMessage() for r in caplog.records)
