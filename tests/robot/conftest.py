"""Shared fixtures of the robot controller's tests: the default profile (the committed policies were trained for
it), the gt_pose policy, a sim-as-robot and its first frame."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from mor.config import Profile, load_profile
from mor.eval.methods import method_spec
from mor.robot.policy import HierarchyPolicy, load_method
from mor.robot.pose import Frame, RobotTask
from mor.robot.sim_robot import SimRobot
from mor.sim.rollout import episode_seed
from pipelines.workspaces import workspace_record

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def profile() -> Profile:
    return load_profile("default", REPO_ROOT / "params.yaml")


@pytest.fixture(scope="session")
def gt_policy(profile: Profile) -> HierarchyPolicy:
    return HierarchyPolicy.of(load_method(method_spec("gt_pose"), workspace_record(REPO_ROOT, profile), profile),
                              profile.sim)


@pytest.fixture
def sim_robot(profile: Profile) -> Iterator[SimRobot]:
    robot = SimRobot(profile.sim, profile.robot.tags, profile.robot.top_camera, top_down=True, horizon=6)
    yield robot
    robot.close()


@pytest.fixture(scope="module")
def first_frame(profile: Profile) -> tuple[Frame, RobotTask]:
    """The first frame (both cameras) and the task of the evaluation's episode (seed 0, episode 0)."""
    robot = SimRobot(profile.sim, profile.robot.tags, profile.robot.top_camera, top_down=True)
    try:
        return robot.reset(episode_seed(0, 0))
    finally:
        robot.close()
