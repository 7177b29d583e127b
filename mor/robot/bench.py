"""``mor bench robot``: the controller's step on one core (torch.set_num_threads(1)), medians in milliseconds.

The frames are those of sim-as-robot episodes played by the first-person loop's controller (rendered beforehand:
rendering is the camera's job, not the controller's). Each controller then steps through them ``repeats`` times;
per step the pose source's time (ArUco detection and localisation, or the L-Net's streaming step), the policy's,
and the whole ``Controller.step``. The same frames say how well the top camera's tags give the truth
(``detection_quality``).
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from typing import Any

import numpy as np
import torch

from mor.robot.controller import Controller
from mor.robot.params import RobotParams
from mor.robot.pose import ArucoPoseSource, Frame, RobotTask
from mor.robot.sim_robot import SimRobot
from mor.sim.config import SimConfig

#: The step time the controller should stay under (a TurtleBot segment takes about a second).
TARGET_MS = 50.0
#: The loop whose controller plays the timed frames: the first-person one never waits for a tag, whatever the
#: top camera's size.
FRAMES_FROM = "fpv_lnet"


def episode_frames(controller: Controller, sim: SimConfig, params: RobotParams, seed: int,
                   max_frames: int) -> tuple[list[Frame], RobotTask]:
    """``max_frames`` frames (top camera and first-person) of the episodes from reset seed ``seed`` on, played by
    ``controller``, and the first episode's task."""
    robot = SimRobot(sim, params.tags, params.top_camera, top_down=True)
    frames: list[Frame] = []
    tasks: list[RobotTask] = []
    try:
        while len(frames) < max_frames:
            frame, task = robot.reset(seed)
            tasks.append(task)
            controller.start(task)
            frames.append(frame)
            while len(frames) < max_frames and not robot.done and not controller.gave_up:
                frames.append(frame := robot.execute(controller.step(frame).command))
            seed += 1
    finally:
        robot.close()
    return frames, tasks[0]


def detection_quality(source: ArucoPoseSource, frames: list[Frame], task: RobotTask) -> dict[str, Any]:
    """How well the tags give the truth over ``frames``: frames without the robot's pose, object sightings
    missed (objects on the floor whose tag was not found), the median agent position (m) and heading (deg)
    errors."""
    source.start(task)
    position, heading, agent_missed, objects_missed = [], [], 0, 0
    for frame in frames:
        fix = source.localizer.locate(source.detector.detect(frame.top_down))
        agent, _ = frame.truth
        objects_missed += sum(i not in fix.objects for i in range(task.n_objects) if i != frame.held)
        if fix.agent_pose is None:
            agent_missed += 1
            continue
        position.append(float(np.linalg.norm(fix.agent_pose[:2] - agent[:2])))
        heading.append(float(np.degrees(abs(np.angle(np.exp(1j * (fix.agent_pose[2] - agent[2])))))))
    return {"frames": len(frames), "agent_missed": agent_missed, "object_sightings_missed": objects_missed,
            "agent_position_m": round(statistics.median(position), 5) if position else None,
            "heading_deg": round(statistics.median(heading), 3) if heading else None}


def _ms(values: list[float]) -> float:
    return round(statistics.median(values) * 1e3, 3)


def time_controller(controller: Controller, frames: list[Frame], task: RobotTask, repeats: int) -> dict[str, Any]:
    """Median pose source, policy and whole-step times (ms) of ``controller`` over ``frames``, ``repeats`` passes
    after a warm-up pass."""
    pose, policy, step = [], [], []
    for repeat in range(repeats + 1):
        if repeat == 1:  # the first pass warms up (compilation, caches)
            pose, policy, step = [], [], []
        controller.start(task)
        for frame in frames:
            started = time.perf_counter()
            taken = controller.step(frame)
            step.append(time.perf_counter() - started)
            pose.append(taken.reading.seconds)
            policy.append(taken.policy_seconds)
    return {"pose_source_ms": _ms(pose), "policy_ms": _ms(policy), "step_ms": _ms(step),
            "step_ms_p90": round(sorted(step)[int(0.9 * (len(step) - 1))] * 1e3, 3), "steps": len(step)}


def benchmark_robot(controllers: dict[str, Controller], sim: SimConfig, params: RobotParams, frames: int,
                    repeats: int, seed: int = 0) -> dict[str, Any]:
    """Time each named controller (loop name -> controller, ``FRAMES_FROM`` and an ArUco one among them) over the
    same frames, on one torch thread; and the ArUco detection's quality on those frames."""
    torch.set_num_threads(1)
    load = os.getloadavg()[0]  # these machines are shared: how busy this one was when the timing began
    played, task = episode_frames(controllers[FRAMES_FROM], sim, params, seed, frames)
    aruco = next(c.source for c in controllers.values() if isinstance(c.source, ArucoPoseSource))
    return {
        "threads": torch.get_num_threads(), "frames": len(played), "repeats": repeats, "seed": seed,
        "top_camera": [params.top_camera.width, params.top_camera.height], "image_size": sim.image_size,
        "target_ms": TARGET_MS, "machine": {"cpu_count": os.cpu_count(), "processor": platform.processor(),
                                            "python": platform.python_version(), "torch": torch.__version__,
                                            "load_average_1min": round(load, 2)},
        "detection": detection_quality(aruco, played, task),
        "loops": {name: time_controller(controller, played, task, repeats) for name, controller in controllers.items()},
    }


__all__ = ["FRAMES_FROM", "TARGET_MS", "benchmark_robot", "detection_quality", "episode_frames", "time_controller"]
