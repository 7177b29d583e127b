"""Sim-as-robot: the controller plays the evaluation's hierarchy, its runs are recorded, replayed, imported and
taken in by the dataset build, and the top camera leaves the simulator's own frames alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mor.config import Profile
from mor.data.episode_io import read_episode, read_metadata
from mor.data.real import RealTopics, RosBag, executed_actions, import_rosbag, make_import_params
from mor.eval.methods import method_spec
from mor.eval.protocol import play_records
from mor.robot.actuator import Actuator
from mor.robot.bench import time_controller
from mor.robot.controller import Controller
from mor.robot.evaluate import make_controller
from mor.robot.policy import HierarchyPolicy, load_method, truth_belief
from mor.robot.pose import Frame, PoseReading, RobotTask
from mor.robot.recording import METADATA, RunInfo, RunRecorder
from mor.robot.replay import replay_bag
from mor.robot.sim_robot import SimRobot, run_sim_episode
from mor.robot.video import write_run_video
from mor.sim.tasks import RearrangeEnv
from pipelines.shapes import profile_shape
from pipelines.workspaces import workspace_record

REPO_ROOT = Path(__file__).resolve().parents[2]
HORIZON = 6  # the sim_robot fixture's


class TruthSource:
    """The simulator's truth as a pose source: the controller must then play exactly what the evaluation plays."""

    camera = "none"

    def start(self, task: RobotTask) -> None:
        pass

    def read(self, frame: Frame, previous_action: int) -> PoseReading:
        return PoseReading(truth_belief(*frame.truth), *frame.truth)


def test_the_controller_plays_the_hierarchy_as_the_evaluation_does(profile: Profile, gt_policy: HierarchyPolicy,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO_ROOT)
    loaded = load_method(method_spec("gt_pose"), workspace_record(REPO_ROOT, profile), profile)
    keys = [("rearrange", 0, episode) for episode in range(2)]
    evaluated = list(play_records(loaded, profile.sim, keys, 2, horizon=40))
    robot = SimRobot(profile.sim, profile.robot.tags, profile.robot.top_camera, top_down=False, horizon=40)
    controller = Controller(TruthSource(), gt_policy, Actuator(profile.robot.actuator), profile.robot.safety)
    try:
        for record in evaluated:
            played = run_sim_episode(robot, controller, record["reset_seed"])
            assert (played.metrics, played.steps) == (record["metrics"], record["steps"])
    finally:
        robot.close()


def _record(profile: Profile, controller: Controller, robot: SimRobot, folder: Path, seed: int) -> Path:
    def recorder(task: RobotTask) -> RunRecorder:
        info = RunInfo("robot-test", "sim", "aruco_topdown", "gt_pose", task, profile.sim.image_size, 10.0,
                       robot.env.layout.wall_textures, profile.robot.model_dump(mode="json"))
        return RunRecorder(folder / "run.mcap", folder / "episodes", info, profile.robot.top_image_topic)

    played = run_sim_episode(robot, controller, seed, recorder)
    assert played.steps == HORIZON and played.frames_without_pose == 0 and max(played.position_errors) < 0.01
    return folder / "run.mcap"


def test_a_run_is_recorded_replayed_imported_and_taken_in_by_the_build(
        profile: Profile, gt_policy: HierarchyPolicy, sim_robot: SimRobot, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    controller = make_controller(profile.robot, "aruco", gt_policy)
    bag = _record(profile, controller, sim_robot, tmp_path, seed=3)
    with RosBag(bag) as opened:
        counts = {topic: count for topic, (_, count) in opened.topics.items()}
        meta = {r.name: dict(r.metadata) for r in opened.reader.iter_metadata()}[METADATA]
    topics = RealTopics()
    for topic in (topics.image, profile.robot.top_image_topic, topics.agent_pose, topics.held,
                  "/sim/truth/robot_pose", "/mor/detections"):
        assert counts[topic] >= HORIZON, topic
    assert counts[topics.action] == HORIZON and counts[topics.cmd_vel] >= HORIZON and meta["seed"] == "3"

    episode = read_episode(tmp_path / "episodes" / "robot-test.mcap")
    assert (episode.header.source, episode.header.seed, episode.n_frames) == ("sim", 3, HORIZON + 1)
    assert episode.images.shape == (HORIZON + 1, profile.sim.image_size, profile.sim.image_size, 3)
    replayed = replay_bag(bag, controller, profile.robot, None, tmp_path / "replay.mcap", None,
                          profile.sim.image_size, 10.0)
    assert replayed.compared == HORIZON and replayed.agreeing == HORIZON  # the same images: the same decisions
    commands = np.array([*replayed.actions[:HORIZON], -1])
    assert episode.actions.tolist() == executed_actions(commands, episode.agent_poses).tolist()

    monkeypatch.chdir(REPO_ROOT)
    path = tmp_path / "episodes" / "robot-test.mcap"
    assert profile_shape(profile).mismatch(path, read_metadata(path)) is None  # mor build-dataset takes it in
    imported = import_rosbag(bag, tmp_path / "real", topics, make_import_params(
        n_objects=3, object_classes=episode.header.object_classes.tolist(),
        target_positions=[tuple(t) for t in episode.header.target_positions], image_size=profile.sim.image_size))
    assert read_episode(imported, with_images=False).header.source == "real"
    video = write_run_video(bag, tmp_path / "run.gif", profile.robot, height=120)
    assert video.stat().st_size > 0


def test_the_first_person_loop_runs_through_the_lnet(profile: Profile, sim_robot: SimRobot) -> None:
    loaded = load_method(method_spec("lnet"), workspace_record(REPO_ROOT, profile), profile)
    controller = make_controller(profile.robot, "lnet", HierarchyPolicy.of(loaded, profile.sim), loaded.lnet)
    played = run_sim_episode(sim_robot, controller, 5)
    assert played.steps == HORIZON and len(played.position_errors) == HORIZON
    assert np.isfinite(played.position_errors).all()
    frame, task = sim_robot.reset(5)
    timing = time_controller(controller, [frame, sim_robot.execute(controller.step(frame).command)], task, 1)
    assert timing["steps"] == 2 and timing["step_ms"] >= timing["pose_source_ms"] > 0


def test_the_top_camera_leaves_the_first_person_frames_and_the_states_alone(profile: Profile,
                                                                            sim_robot: SimRobot) -> None:
    plain = RearrangeEnv(horizon=HORIZON, **profile.sim.model_dump())
    try:
        observation, _ = plain.reset(seed=11)
        frame, _ = sim_robot.reset(11)
        actuator = Actuator(profile.robot.actuator)
        for action in (0, 1, 0, 2):
            assert np.array_equal(frame.first_person, observation["image"])
            np.testing.assert_array_equal(frame.truth[0], plain.state.agent_pose)
            frame = sim_robot.execute(actuator.command(action))
            observation, *_ = plain.step(action)
        assert frame.top_down.shape == (profile.robot.top_camera.height, profile.robot.top_camera.width, 3)
    finally:
        plain.close()
