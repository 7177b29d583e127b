"""Sim-as-robot evaluation: the controller plays the evaluation's episodes on ``SimRobot``, one at a time, each one
recorded and written as an episode; one JSON line per episode (resumable: a line is appended as an episode ends,
and what the records hold is not played again).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from tqdm import tqdm

from mor.robot.actuator import Actuator
from mor.robot.controller import Controller
from mor.robot.params import RobotParams
from mor.robot.policy import HierarchyPolicy, LNetRunner
from mor.robot.pose import ArucoPoseSource, LNetPoseSource, RobotTask
from mor.robot.recording import RunInfo, RunRecorder
from mor.robot.results import LOOPS, episode_record, read_records
from mor.robot.sim_robot import SimRobot, run_sim_episode
from mor.sim.config import SimConfig
from mor.sim.rollout import episode_seed


def make_controller(params: RobotParams, source: str, policy: HierarchyPolicy,
                    runner: LNetRunner | None = None) -> Controller:
    """The controller with pose source ``source`` (aruco: the top camera's tags; lnet: the first-person frames
    through ``runner``), ``policy`` and the actuator and safety stop of ``params``."""
    if source == "aruco":
        pose = ArucoPoseSource(params.tags, params.top_camera, params.corner_refinement)
    elif runner is not None:
        pose = LNetPoseSource(runner, policy.search_arena)
    else:
        raise ValueError("the lnet pose source needs the trained L-Net (runner)")
    return Controller(pose, policy, Actuator(params.actuator), params.safety)


def episode_id(loop: str, method: str, seed: int, episode: int) -> str:
    """The id (and file stem) of a sim-as-robot run's recording and episode."""
    return f"robot-{loop}-{method}-s{seed}-e{episode:04d}"


def play_sim_loop(loop: str, controller: Controller, sim: SimConfig, params: RobotParams, keys: list[tuple[int, int]],
                  records_path: Path, runs_dir: Path, fps: float, horizon: int | None = None,
                  progress: bool = True) -> list[dict[str, Any]]:
    """Play the episodes ``keys`` ((seed, episode) pairs) not yet in ``records_path`` with ``controller`` on the
    simulator (``loop``: aruco_topdown renders the top camera); record each run to
    ``runs_dir/recordings/<id>.mcap`` and its episode to ``runs_dir/episodes/<id>.mcap`` (frames at ``fps``).
    Returns every record of ``keys``, in their order."""
    torch.set_num_threads(1)  # small forwards of one robot: one thread is faster on 2 cores (docs/design.md, "Threads")
    method = controller.policy.method
    done = {(r["seed"], r["episode"]): r for r in read_records(records_path) if r["method"] == method}
    todo = [key for key in keys if key not in done]
    robot = SimRobot(sim, params.tags, params.top_camera, top_down=LOOPS[loop] == "aruco", horizon=horizon)
    records_path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with records_path.open("a") as handle, tqdm(total=len(todo), desc=f"{loop} {method}", unit="ep",
                                                    disable=not progress, dynamic_ncols=True) as bar:
            for seed, episode in todo:
                reset_seed = episode_seed(seed, episode)
                played = run_sim_episode(robot, controller, reset_seed,
                                         _recorder(loop, method, seed, episode, robot, sim, params, runs_dir, fps))
                done[(seed, episode)] = record = episode_record(loop, method, seed, episode, reset_seed, played)
                handle.write(json.dumps(record) + "\n")
                handle.flush()
                bar.update(1)
    finally:
        robot.close()
    return [done[key] for key in keys]


def _recorder(loop: str, method: str, seed: int, episode: int, robot: SimRobot, sim: SimConfig, params: RobotParams,
              runs_dir: Path, fps: float) -> Callable[[RobotTask], RunRecorder]:
    name = episode_id(loop, method, seed, episode)

    def make(task: RobotTask) -> RunRecorder:
        info = RunInfo(name, "sim", loop, method, task, sim.image_size, fps, robot.env.layout.wall_textures,
                       params.model_dump(mode="json"))
        return RunRecorder(runs_dir / "recordings" / f"{name}.mcap", runs_dir / "episodes", info,
                           params.top_image_topic)

    return make


__all__ = ["episode_id", "make_controller", "play_sim_loop"]
