"""The controller: at each frame, a pose source's belief -> the method's hierarchy -> the actuator's command.

It never acts on a frame without a fresh pose: it waits (sends nothing); after ``safety.lost_frames`` such frames
in a row it sends a stop (a zero Twist) and logs it, once; after ``safety.give_up_frames`` it gives up (a replay
or the simulator would show it the same frame again). Each step's timings: the pose source's (detection or the
L-Net) and the policy's, in seconds.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

from mor.data.schema import NO_ACTION
from mor.robot.actuator import STOP, WAIT, Actuator, Command
from mor.robot.params import SafetyParams
from mor.robot.policy import HierarchyPolicy
from mor.robot.pose import Frame, PoseReading, PoseSource, RobotTask

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Step:
    """One controller step: the frame, the pose reading, the command sent, the skill that chose it (pick, drop;
    'none' without a pose), a note (a stop, giving up) and the policy's time in seconds."""

    index: int
    frame: Frame
    reading: PoseReading
    command: Command
    skill: str
    note: str | None = None
    policy_seconds: float = 0.0

    @property
    def seconds(self) -> float:
        """The controller's time for this step: the pose source's and the policy's, seconds."""
        return self.reading.seconds + self.policy_seconds


class Controller:
    """``start(task)``, then ``step(frame) -> Step`` for each new frame, executing each step's command before the
    next frame is taken; ``gave_up`` once it has seen ``give_up_frames`` frames without a pose in a row."""

    def __init__(self, source: PoseSource, policy: HierarchyPolicy, actuator: Actuator, safety: SafetyParams) -> None:
        self.source, self.policy, self.actuator, self.safety = source, policy, actuator, safety
        self.task: RobotTask | None = None
        self.steps = self.lost = 0
        self.gave_up = False
        self._pending = self._previous = NO_ACTION

    def start(self, task: RobotTask) -> None:
        self.task, self.steps, self.lost, self.gave_up = task, 0, 0, False
        self._pending = self._previous = NO_ACTION
        self.source.start(task)
        self.policy.start(task.seed)

    def step(self, frame: Frame) -> Step:
        assert self.task is not None, "call start(task) first"
        if self._pending != NO_ACTION:  # the last command's action was executed: the hierarchy moves on
            self.policy.advance(self._pending, frame.held)
        self._previous, self._pending = self._pending, NO_ACTION
        reading = self.source.read(frame, self._previous)
        index, self.steps = self.steps, self.steps + 1
        if reading.belief is None:
            return Step(index, frame, reading, *self._without_pose(reading.problem))
        self.lost = 0
        started = time.perf_counter()
        action = self.policy.act(reading.belief, frame.held, self.task.target_positions)
        self._pending = action
        return Step(index, frame, reading, self.actuator.command(action), self.policy.skill,
                    policy_seconds=time.perf_counter() - started)

    def _without_pose(self, problem: str | None) -> tuple[Command, str, str | None]:
        self.lost += 1
        if self.lost >= self.safety.give_up_frames:
            self.gave_up = True
            note = f"gave up: no pose for {self.lost} frames ({problem})"
            logger.error(note)
            return STOP, "none", note
        if self.lost == self.safety.lost_frames:
            note = f"stop: no pose for {self.lost} frames ({problem}); waiting"
            logger.warning(note)
            return STOP, "none", note
        return WAIT, "none", None


__all__ = ["Controller", "Step"]
