"""``mor robot``: the robot controller's jobs (sim-as-robot evaluation, its card, replay, video, bench): wiring of
``mor.robot`` to the profile, the committed policies and L-Net, and the output paths."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from mor.config import Profile
from mor.errors import ConfigError
from mor.eval.methods import METHODS, method_spec
from mor.locking import writer_lock
from mor.robot.bench import benchmark_robot
from mor.robot.card import write_robot_card
from mor.robot.controller import Controller
from mor.robot.evaluate import make_controller, play_sim_loop
from mor.policy.variants import GROUND_TRUTH, OURS
from mor.robot.policy import (ROBOT_METHODS, HierarchyPolicy, LoadedMethod, evaluation_success,
                              load_method, robot_method, uses_lnet)
from mor.robot.pose import RobotTask
from mor.robot.recording import RunInfo, RunRecorder
from mor.robot.replay import ReplaySummary, replay_bag
from mor.robot.results import LOOPS, loop_row, merge_row, same_episodes
from mor.robot.video import write_run_video
from pipelines import paths
from pipelines.io import write_json
from pipelines.workspaces import workspace_record

VIDEO = "sim_as_robot.gif"


def load_controller(profile: Profile, method: str, source: str) -> tuple[Controller, LoadedMethod]:
    """The controller of ``method`` (its committed policies, checked against the L-Net they observe through) with
    pose source ``source`` (aruco or lnet), and the loaded method (its L-Net, None for a method on the truth)."""
    robot_method(method)
    if source == "lnet" and not uses_lnet(method):
        choices = ", ".join(name for name in ROBOT_METHODS if METHODS[name].uses_lnet)
        raise ConfigError(f"--method: {method!r} was trained on the truth, not on the L-Net's belief; the "
                          f"first-person loop plays an L-Net method ({choices})")
    loaded = load_method(method_spec(method), workspace_record(Path("."), profile), profile)
    policy = HierarchyPolicy.of(loaded, profile.sim)
    return make_controller(profile.robot, source, policy, loaded.lnet), loaded


def sim(profile: Profile, loop: str, method: str, seeds: list[int] | None = None, episodes: int | None = None,
        progress: bool = True) -> dict[str, Any]:
    """Play the evaluation's episodes (the profile's seeds x episodes, or fewer) through ``loop``; records and
    runs under ``datasets/robot/<loop>/``, the row in ``cards/robot/results.json`` and the card."""
    if loop not in LOOPS:
        raise ConfigError(f"--loop: unknown loop {loop!r}; choose one of {', '.join(LOOPS)}")
    controller, loaded = load_controller(profile, method, LOOPS[loop])
    seeds = seeds or profile.evaluate.seeds
    keys = [(seed, episode) for seed in seeds for episode in range(episodes or profile.evaluate.episodes)]
    records_path = paths.ROBOT / loop / f"{method}.jsonl"
    with writer_lock(records_path, f"mor robot sim --loop {loop} --method {method}"):
        records = play_sim_loop(loop, controller, profile.sim, profile.robot, keys, records_path,
                                paths.ROBOT / loop / method, profile.collect.fps, profile.evaluate.horizon, progress)
    row = loop_row(records, profile.evaluate.bootstrap_resamples)
    if not uses_lnet(method):  # the evaluation's play of the same episodes: cheap without the L-Net
        success = evaluation_success(loaded, profile.sim, keys, profile.evaluate.n_envs, profile.evaluate.horizon)
        row["evaluation_same_episodes"] = same_episodes(success, records, profile.evaluate.bootstrap_resamples)
    merge_row(paths.ROBOT_CARD / "results.json", row)
    card()
    return row


def card() -> Path:
    """``cards/robot/README.md`` from ``results.json``, the evaluation's rows and the video (where they exist)."""
    results_path = paths.ROBOT_CARD / "results.json"
    results = json.loads(results_path.read_text()) if results_path.is_file() else {"loops": []}
    references = {}
    for row in results["loops"]:
        path = paths.RESULTS_CARD / "rows" / f"{row['method']}.json"
        if path.is_file():
            references[row["method"]] = json.loads(path.read_text())
    video = VIDEO if (paths.ROBOT_CARD / VIDEO).is_file() else None
    return write_robot_card(paths.ROBOT_CARD / "README.md", results, references, video)


def replay(profile: Profile, bag: Path, method: str, source: str, task: RobotTask | None,
           out: Path | None = None) -> ReplaySummary:
    """Replay ``bag`` through ``method``'s controller with pose source ``source``; the replay's recording in
    ``out`` (default ``datasets/robot/replay/<bag>.mcap``), its episode in ``datasets/robot/replay/episodes/``."""
    controller, _ = load_controller(profile, method, source)
    out = out or paths.ROBOT / "replay" / f"{Path(bag).stem}.mcap"
    return replay_bag(bag, controller, profile.robot, task, out, paths.ROBOT / "replay" / "episodes",
                      profile.sim.image_size, profile.collect.fps)


def video(profile: Profile, recording: Path, out: Path, every: int) -> Path:
    """A run's video from its recording (``mor.robot.video``)."""
    return write_run_video(recording, out, profile.robot, height=360, every=every)


def live(profile: Profile, method: str, source: str, task: RobotTask, max_steps: int) -> tuple[int, Path]:
    """Drive a TurtleBot with ROS 2 (``mor.robot.ros2_node``): recorded to ``datasets/robot/live/<id>.mcap``, its
    episode (source=real) into ``datasets/real/`` where ``mor build-dataset`` takes it in."""
    from mor.robot.ros2_node import import_ros2, run_live  # noqa: PLC0415 - rclpy only here

    import_ros2()  # fail before loading anything when ROS 2 is not there
    controller, _ = load_controller(profile, method, source)
    controller.start(task)
    name = f"live-{time.strftime('%Y%m%d-%H%M%S')}-{method}"
    info = RunInfo(name, "real", "live", method, task, profile.sim.image_size, profile.collect.fps,
                   params=profile.robot.model_dump(mode="json"))
    recording = paths.ROBOT / "live" / f"{name}.mcap"
    with RunRecorder(recording, paths.REAL_EPISODES, info, profile.robot.top_image_topic) as recorder:
        steps = run_live(controller, profile.robot, recorder, max_steps)
    return steps, recording


def bench(profile: Profile, frames: int, repeats: int, out: Path) -> dict[str, Any]:
    """``mor bench robot``: each loop's controller step on one core (the ground truth's method through the tags,
    ours through the first-person frames), over the frames of one sim-as-robot episode."""
    controllers = {"aruco_topdown": load_controller(profile, GROUND_TRUTH.name, "aruco")[0],
                   "fpv_lnet": load_controller(profile, OURS.name, "lnet")[0]}
    result = benchmark_robot(controllers, profile.sim, profile.robot, frames, repeats)
    result["lnet"] = {"compiled": profile.lnet.compile_step, "encoder_precision": profile.lnet.encoder_precision}
    write_json(out, result)
    return result


def task_of(object_classes: list[int], targets: list[tuple[float, float]], seed: int) -> RobotTask:
    """A run's task from the command line's objects and targets (metres)."""
    return RobotTask(np.asarray(object_classes, np.int64), np.asarray(targets, np.float64).reshape(-1, 2), seed)


__all__ = ["bench", "card", "live", "load_controller", "replay", "sim", "task_of", "video"]
