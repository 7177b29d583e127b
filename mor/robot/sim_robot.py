"""Sim-as-robot: the simulator driven through the controller's own interface, the test without hardware.

A command's discrete action is one step of ``MOR/Rearrange-v0`` (with the simulator's own motion noise, so the
episode of reset seed s is the evaluation's episode s as long as the actions agree); a wait or a stop steps
nothing. Frames come from the top camera (``mor.sim.topdown.TopDownScene``, built beside the env from the same
state) and the first-person camera; a virtual clock advances by each command's duration.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Any

import numpy as np

from mor.robot.actuator import Command
from mor.robot.controller import Controller
from mor.robot.pose import Frame, RobotTask
from mor.robot.recording import RunRecorder
from mor.sim import metrics
from mor.sim.config import SimConfig
from mor.sim.tags import ArucoTags, TopCamera
from mor.sim.tasks import RearrangeEnv
from mor.sim.topdown import TopDownScene

CLOCK_START_NS = 1_700_000_000_000_000_000  # the recordings' epoch (as the episodes'): the same run, the same bytes


class SimRobot:
    """``reset(seed) -> (Frame, RobotTask)``, ``execute(command) -> Frame``; ``done`` once the episode ended and
    ``metrics()`` then (or whenever the controller gives up). ``top_down``: render the top camera."""

    def __init__(self, sim: SimConfig, tags: ArucoTags, camera: TopCamera, top_down: bool,
                 horizon: int | None = None) -> None:
        self.env = RearrangeEnv(render_frames=True, horizon=horizon, **sim.model_dump())
        self.top = TopDownScene(self.env.arena, sim.n_objects, tags, camera) if top_down else None
        self.time_ns, self.done = CLOCK_START_NS, False
        self._observation: dict[str, Any] = {}
        self._final: dict[str, float] | None = None

    def _frame(self) -> Frame:
        state = self.env.state
        top = None
        if self.top is not None:
            self.top.set_state(state)
            top = self.top.render_top_down()
        return Frame(self.time_ns, state.held, top, self._observation["image"],
                     (state.agent_pose.copy(), state.object_positions()))

    def reset(self, seed: int) -> tuple[Frame, RobotTask]:
        self._observation, _ = self.env.reset(seed=seed)
        layout = self.env.layout
        if self.top is not None:
            self.top.set_episode(layout.wall_textures, layout.object_classes)
        self.time_ns, self.done, self._final = CLOCK_START_NS, False, None
        return self._frame(), RobotTask(layout.object_classes.copy(), layout.target_positions.copy(), seed)

    def execute(self, command: Command) -> Frame:
        if command.action >= 0:
            self._observation, _, terminated, truncated, info = self.env.step(command.action)
            if terminated or truncated:
                self.done, self._final = True, dict(info["metrics"])
        self.time_ns += int(round(command.duration_s * 1e9))
        return self._frame()

    def metrics(self) -> dict[str, float]:
        """The episode's Success, %FS and %E: the env's at its end, else those of the state now."""
        if self._final is not None:
            return self._final
        positions, targets = self.env.state.object_positions(), self.env.layout.target_positions
        return {"success": metrics.rearrange_success(positions, targets),
                "fixed_strict": metrics.fixed_strict(positions, targets),
                "energy_remaining": metrics.energy_remaining(positions, targets, self.env.layout.initial_positions)}

    def close(self) -> None:
        self.env.close()
        if self.top is not None:
            self.top.close()


@dataclass
class SimEpisode:
    """One sim-as-robot episode: its metrics, the commanded steps, whether the controller gave up, and per step
    with a pose the estimate's agent position error (m), heading error (rad) and the controller's time (s)."""

    metrics: dict[str, float]
    steps: int
    gave_up: bool
    position_errors: list[float]
    heading_errors: list[float]
    step_seconds: list[float]
    frames_without_pose: int


def run_sim_episode(robot: SimRobot, controller: Controller, seed: int,
                    recorder_for: Callable[[RobotTask], RunRecorder] | None = None) -> SimEpisode:
    """Play reset seed ``seed`` with ``controller`` on ``robot`` until the episode ends or the controller gives
    up; ``recorder_for(task)``: the run's recorder (None: nothing recorded)."""
    frame, task = robot.reset(seed)
    controller.start(task)
    episode = SimEpisode({}, 0, False, [], [], [], 0)
    with recorder_for(task) if recorder_for is not None else nullcontext() as recorder:
        while True:
            step = controller.step(frame)
            if recorder is not None:
                recorder.add(step)
            _score(episode, step.reading.agent_pose, frame, step.seconds)
            if controller.gave_up:
                break
            episode.steps += step.command.action >= 0
            frame = robot.execute(step.command)
            if robot.done:
                break
        if recorder is not None:
            recorder.add_last(frame)
    episode.metrics, episode.gave_up = robot.metrics(), controller.gave_up
    return episode


def _score(episode: SimEpisode, estimate: np.ndarray | None, frame: Frame, seconds: float) -> None:
    if estimate is None:
        episode.frames_without_pose += 1
        return
    truth = frame.truth[0]
    episode.position_errors.append(float(np.linalg.norm(estimate[:2] - truth[:2])))
    episode.heading_errors.append(float(abs(np.angle(np.exp(1j * (estimate[2] - truth[2]))))))
    episode.step_seconds.append(seconds)


__all__ = ["SimEpisode", "SimRobot", "run_sim_episode"]
